//! Loader tests: every file is written by the test itself into a temp folder.

use std::path::{Path, PathBuf};

use super::checks::MissingTextures;
use super::*;

/// A fresh empty folder under the system temp dir, unique per test.
fn temp_dir(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("fusepose-mesh-io-{}-{test}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// A 2x1 RGB PNG: red, blue.
fn write_png(dir: &Path, name: &str) -> Vec<u8> {
    let rgb = vec![255, 0, 0, 0, 0, 255];
    image::save_buffer(dir.join(name), &rgb, 2, 1, image::ExtendedColorType::Rgb8).unwrap();
    rgb
}

/// A unit cube in OBJ: quads, UVs, normals, two materials (+z face uses `lid`).
const CUBE_OBJ: &str = "\
mtllib cube.mtl
v -0.5 -0.5 -0.5
v 0.5 -0.5 -0.5
v 0.5 0.5 -0.5
v -0.5 0.5 -0.5
v -0.5 -0.5 0.5
v 0.5 -0.5 0.5
v 0.5 0.5 0.5
v -0.5 0.5 0.5
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vn 0 0 -1
vn 0 0 1
vn 0 -1 0
vn 0 1 0
vn 1 0 0
vn -1 0 0
usemtl body
f 1/1/1 4/4/1 3/3/1 2/2/1
f 1/1/3 2/2/3 6/3/3 5/4/3
f 3/1/4 4/2/4 8/3/4 7/4/4
f 2/1/5 3/2/5 7/3/5 6/4/5
f 1/1/6 5/2/6 8/3/6 4/4/6
usemtl lid
f 5/1/2 6/2/2 7/3/2 8/4/2
";

const CUBE_MTL: &str = "\
newmtl body
Kd 0.8 0.1 0.1
map_Kd body.png

newmtl lid
Kd 0.1 0.2 0.9
";

#[test]
fn obj_with_materials_texture_normals_and_uvs_loads() {
    let dir = temp_dir("obj-ok");
    let obj = write(&dir, "cube.obj", CUBE_OBJ);
    write(&dir, "cube.mtl", CUBE_MTL);
    let pixels = write_png(&dir, "body.png");
    let mesh = load_mesh(&obj, 1.0).unwrap();
    assert_eq!(mesh.triangles.len(), 12, "6 quads triangulate to 12 triangles");
    assert_eq!(mesh.uvs.len(), mesh.positions.len());
    assert_eq!(mesh.normals.len(), mesh.positions.len());
    assert_eq!(mesh.materials.len(), 2);
    let body = mesh.materials.iter().position(|m| m.name == "body").unwrap();
    let lid = mesh.materials.iter().position(|m| m.name == "lid").unwrap();
    let texture = mesh.materials[body].texture.as_ref().expect("body texture loaded");
    assert_eq!((texture.width, texture.height), (2, 1));
    // map_Kd is multiplied by Kd 0.8 0.1 0.1 (linear light).
    assert_eq!(
        texture,
        &crate::mesh_io::obj::tint_texture(&Texture { width: 2, height: 1, rgb: pixels }, [0.8, 0.1, 0.1])
    );
    assert_eq!(mesh.materials[lid].diffuse, [0.1, 0.2, 0.9]);
    assert!(mesh.materials[lid].texture.is_none());
    // Exactly the two +z triangles use the lid material, and their vertices are at z = 0.5.
    let lid_tris: Vec<_> =
        mesh.triangles.iter().zip(&mesh.triangle_materials).filter(|(_, m)| **m as usize == lid).collect();
    assert_eq!(lid_tris.len(), 2);
    for (t, _) in lid_tris {
        for &i in t {
            assert_eq!(mesh.positions[i as usize][2], 0.5);
            assert_eq!(mesh.normals[i as usize], [0.0, 0.0, 1.0]);
        }
    }
}

#[test]
fn obj_scale_converts_millimetres_to_metres() {
    let dir = temp_dir("obj-scale");
    let obj = write(&dir, "tri.obj", "v 0 0 0\nv 100 0 0\nv 0 200 0\nf 1 2 3\n");
    let mesh = load_mesh(&obj, 0.001).unwrap();
    assert!((mesh.positions[1][0] - 0.1).abs() < 1e-7 && (mesh.positions[2][1] - 0.2).abs() < 1e-7);
    // No normals in the file: computed, facing +z for a CCW triangle in the xy plane.
    assert_eq!(mesh.normals, vec![[0.0, 0.0, 1.0]; 3]);
    assert_eq!(mesh.materials.len(), 1, "a default material is always present");
    assert!(matches!(load_mesh(&obj, 0.0), Err(MeshError::BadScale { .. })));
}

#[test]
fn missing_texture_falls_back_to_the_material_colour() {
    let dir = temp_dir("obj-missing-texture");
    let obj = write(&dir, "cube.obj", CUBE_OBJ);
    write(&dir, "cube.mtl", CUBE_MTL); // names body.png, which is not written
    let mesh = load_mesh(&obj, 1.0).unwrap();
    let body = mesh.materials.iter().find(|m| m.name == "body").unwrap();
    assert!(body.texture.is_none());
    assert_eq!(body.diffuse, [0.8, 0.1, 0.1]);
}

#[test]
fn missing_mtl_file_still_loads_with_default_material() {
    let dir = temp_dir("obj-missing-mtl");
    let obj = write(&dir, "cube.obj", CUBE_OBJ); // cube.mtl absent
    let mesh = load_mesh(&obj, 1.0).unwrap();
    assert_eq!(mesh.triangles.len(), 12);
    assert!(mesh.triangle_materials.iter().all(|&m| (m as usize) < mesh.materials.len()));
}

#[test]
fn malformed_obj_error_names_file_and_line() {
    let dir = temp_dir("obj-bad");
    let obj = write(&dir, "broken.obj", "# comment\nv 0 0 0\nv 1 0 zero\nv 0 1 0\nf 1 2 3\n");
    let err = load_mesh(&obj, 1.0).unwrap_err();
    let text = err.to_string();
    assert!(text.contains("broken.obj") && text.contains("line 3"), "{text}");
    assert!(matches!(err, MeshError::Parse { line: Some(3), .. }));
}

#[test]
fn obj_face_index_out_of_range_is_an_error_not_a_panic() {
    let dir = temp_dir("obj-oob");
    let obj = write(&dir, "oob.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n");
    let text = load_mesh(&obj, 1.0).unwrap_err().to_string();
    assert!(text.contains("oob.obj"), "{text}");
    let empty = write(&dir, "empty.obj", "# nothing\n");
    assert!(load_mesh(&empty, 1.0).unwrap_err().to_string().contains("empty.obj"));
}

#[test]
fn unreadable_and_unsupported_files_name_the_file() {
    let dir = temp_dir("io");
    let missing = dir.join("nope.obj");
    assert!(matches!(load_mesh(&missing, 1.0), Err(MeshError::Io { .. })));
    assert!(load_mesh(&missing, 1.0).unwrap_err().to_string().contains("nope.obj"));
    let stl = write(&dir, "part.stl", "solid x\n");
    assert!(matches!(load_mesh(&stl, 1.0), Err(MeshError::UnsupportedFormat { .. })));
}

const SQUARE_PLY_HEADER: &str = "\
ply
format ascii 1.0
comment a square (one quad) and a triangle
element vertex 5
property float x
property float y
property float z
property uchar red
property uchar green
property uchar blue
property float s
property float t
element face 2
property list uchar int vertex_indices
end_header
";

#[test]
fn ascii_ply_with_colours_uvs_and_quads_loads() {
    let dir = temp_dir("ply-ascii");
    let text = format!(
        "{SQUARE_PLY_HEADER}0 0 0 255 0 0 0 0\n1 0 0 0 255 0 1 0\n1 1 0 0 0 255 1 1\n0 1 0 10 20 30 0 1\n0 0 1 1 2 3 0.5 0.5\n4 0 1 2 3\n3 0 1 4\n"
    );
    let ply = write(&dir, "square.ply", &text);
    let mesh = load_mesh(&ply, 1.0).unwrap();
    assert_eq!(mesh.positions.len(), 5);
    assert_eq!(mesh.triangles, vec![[0, 1, 2], [0, 2, 3], [0, 1, 4]], "quad is fan-triangulated");
    assert_eq!(mesh.colors[0], [255, 0, 0]);
    assert_eq!(mesh.colors[3], [10, 20, 30]);
    assert_eq!(mesh.uvs[2], [1.0, 1.0]);
    assert_eq!(mesh.normals.len(), 5, "normals computed when absent");
    assert_eq!(mesh.normals[2], [0.0, 0.0, 1.0]);
}

/// A binary little-endian PLY: float xyz + float normals + uchar colours, one
/// triangle and one quad (int indices).
fn binary_ply_bytes() -> Vec<u8> {
    let header = "ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n";
    let mut b = header.as_bytes().to_vec();
    let verts = [[0.0f32, 0.0, 0.0], [2.0, 0.0, 0.0], [2.0, 3.0, 0.0], [0.0, 3.0, 0.0]];
    for (i, v) in verts.iter().enumerate() {
        for c in v.iter().chain(&[0.0f32, 0.0, 1.0]) {
            b.extend_from_slice(&c.to_le_bytes());
        }
        b.extend_from_slice(&[i as u8 * 60, 100, 200]);
    }
    b.push(3);
    for i in [0i32, 1, 2] {
        b.extend_from_slice(&i.to_le_bytes());
    }
    b.push(4);
    for i in [0i32, 1, 2, 3] {
        b.extend_from_slice(&i.to_le_bytes());
    }
    b
}

#[test]
fn binary_little_endian_ply_loads() {
    let dir = temp_dir("ply-binary");
    let path = dir.join("plate.ply");
    std::fs::write(&path, binary_ply_bytes()).unwrap();
    let mesh = load_mesh(&path, 0.5).unwrap();
    assert_eq!(mesh.positions, vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.5, 0.0], [0.0, 1.5, 0.0]]);
    assert_eq!(mesh.triangles, vec![[0, 1, 2], [0, 1, 2], [0, 2, 3]]);
    assert_eq!(mesh.colors[2], [120, 100, 200]);
    assert_eq!(mesh.normals[3], [0.0, 0.0, 1.0]);
}

#[test]
fn truncated_binary_ply_is_an_error_naming_the_file() {
    let dir = temp_dir("ply-truncated");
    let path = dir.join("cut.ply");
    let bytes = binary_ply_bytes();
    std::fs::write(&path, &bytes[..bytes.len() - 7]).unwrap();
    let text = load_mesh(&path, 1.0).unwrap_err().to_string();
    assert!(text.contains("cut.ply"), "{text}");
}

#[test]
fn malformed_ascii_ply_error_names_file_and_line() {
    let dir = temp_dir("ply-bad");
    // Line 17 (the second vertex) has a word where a number belongs.
    let text = format!(
        "{SQUARE_PLY_HEADER}0 0 0 255 0 0 0 0\n1 zero 0 0 255 0 1 0\n1 1 0 0 0 255 1 1\n0 1 0 1 2 3 0 1\n0 0 1 1 2 3 0 0\n3 0 1 2\n3 0 2 3\n"
    );
    let ply = write(&dir, "bad.ply", &text);
    let err = load_mesh(&ply, 1.0).unwrap_err();
    let text = err.to_string();
    assert!(text.contains("bad.ply") && text.contains("line 17"), "{text}");
    // Face index past the vertex count.
    let oob = format!(
        "{SQUARE_PLY_HEADER}0 0 0 1 1 1 0 0\n1 0 0 1 1 1 0 0\n1 1 0 1 1 1 0 0\n0 1 0 1 1 1 0 0\n0 0 1 1 1 1 0 0\n3 0 1 2\n3 0 1 7\n"
    );
    let text = load_mesh(&write(&dir, "oob.ply", &oob), 1.0).unwrap_err().to_string();
    assert!(text.contains("oob.ply") && text.contains("vertex 7"), "{text}");
    let garbage = write(&dir, "garbage.ply", "this is not a ply file\n");
    assert!(load_mesh(&garbage, 1.0).unwrap_err().to_string().contains("garbage.ply"));
}

#[test]
fn ply_texture_file_comment_loads_the_texture() {
    let dir = temp_dir("ply-texture");
    let pixels = write_png(&dir, "skin.png");
    let text = SQUARE_PLY_HEADER.replace("comment a square", "comment TextureFile skin.png\ncomment a square");
    let ply = write(
        &dir,
        "tex.ply",
        &format!(
            "{text}0 0 0 1 1 1 0 0\n1 0 0 1 1 1 1 0\n1 1 0 1 1 1 1 1\n0 1 0 1 1 1 0 1\n0 0 1 1 1 1 0 0\n4 0 1 2 3\n3 0 1 4\n"
        ),
    );
    let mesh = load_mesh(&ply, 1.0).unwrap();
    assert_eq!(mesh.materials[0].texture.as_ref().unwrap().rgb, pixels);
}

#[test]
fn object_dir_loads_folders_and_files_sorted_with_declared_symmetry() {
    let dir = temp_dir("object-dir");
    std::fs::create_dir_all(dir.join("zebra_cube")).unwrap();
    write(&dir.join("zebra_cube"), "cube.obj", CUBE_OBJ);
    write(&dir.join("zebra_cube"), "cube.mtl", CUBE_MTL);
    write_png(&dir.join("zebra_cube"), "body.png");
    write(&dir, "apple.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    write(&dir, "notes.txt", "not a mesh");
    let set = load_object_dir(&dir, 1.0).unwrap();
    let names: Vec<_> = set.objects.iter().map(|o| o.name.as_str()).collect();
    assert_eq!(names, ["apple", "zebra_cube"]);
    let cube = &set.objects[1];
    assert!((cube.diameter - 3f64.sqrt()).abs() < 1e-6);
    assert_eq!(cube.samples.len(), crate::surface::SURFACE_SAMPLES);
    assert_eq!(cube.symmetry, Symmetry::None);

    // A models_info.json declares symmetry (and fixes order).
    let info = r#"{"units":"metres","objects":[{"name":"zebra_cube","class_id":1,"mesh":"zebra_cube/cube.obj","triangles":12,"diameter":1.7,"bbox_min":[-0.5,-0.5,-0.5],"bbox_max":[0.5,0.5,0.5],"symmetry":{"kind":"continuous","axis":[0,0,1],"origin":[0,0,0.25]}}]}"#;
    write(&dir, "models_info.json", info);
    let set = load_object_dir(&dir, 0.5).unwrap();
    assert_eq!(set.objects[0].name, "zebra_cube");
    assert_eq!(
        set.objects[0].symmetry,
        Symmetry::Continuous { axis: nalgebra::Vector3::z(), origin: nalgebra::Point3::new(0.0, 0.0, 0.125) }
    );
    write(&dir, "models_info.json", "{ not json");
    assert!(load_object_dir(&dir, 1.0).unwrap_err().to_string().contains("models_info.json"));
    let empty = temp_dir("object-dir-empty");
    assert!(matches!(load_object_dir(&empty, 1.0), Err(MeshError::NoMesh { .. })));
}

/// Real meshes: the five YCB objects next to the repository (not part of it).
#[test]
fn loads_the_ycb_sample_meshes() {
    let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/objects/ycb-sample"));
    if !root.is_dir() {
        eprintln!("skipping: ../shared/objects/ycb-sample not found");
        return;
    }
    let set = load_object_dir(root, 1.0).unwrap();
    let names: Vec<_> = set.objects.iter().map(|o| o.name.as_str()).collect();
    assert_eq!(names, ["YcbBanana", "YcbFoamBrick", "YcbMasterChefCan", "YcbPowerDrill", "YcbScissors"]);
    for o in &set.objects {
        let m = &o.mesh;
        let textured = m.materials.iter().any(|mat| mat.texture.is_some());
        let extent = o.bbox_max - o.bbox_min;
        eprintln!(
            "{:18} vertices {:6} triangles {:6} textured {:5} diameter {:.1} mm extent {:.0}x{:.0}x{:.0} mm",
            o.name,
            m.positions.len(),
            m.triangles.len(),
            textured,
            o.diameter * 1e3,
            extent.x * 1e3,
            extent.y * 1e3,
            extent.z * 1e3
        );
        assert_eq!(textured, o.name == "YcbBanana" || o.name == "YcbScissors", "{}", o.name);
        assert!(!m.triangles.is_empty() && m.uvs.len() == m.positions.len());
        // Household objects: between 5 cm and 40 cm across, in metres.
        assert!((0.05..0.4).contains(&o.diameter), "{} diameter {}", o.name, o.diameter);
    }
    // The master chef can is ~102 mm across and ~140 mm tall: diameter ~0.17 m.
    let can = &set.objects[2];
    assert!((can.diameter - 0.172).abs() < 0.015, "can diameter {}", can.diameter);
}

// ---- Checks on users' mesh folders (mesh_io::checks): each bad case, its message. ----

/// A right triangle with legs `a` and `b` (file units) in the xy plane: diameter √(a² + b²).
fn triangle_obj(a: f64, b: f64) -> String {
    format!("v 0 0 0\nv {a} 0 0\nv 0 {b} 0\nf 1 2 3\n")
}

fn dir_error(dir: &Path, scale: f64) -> String {
    load_object_dir(dir, scale).unwrap_err().to_string()
}

#[test]
fn check_millimetre_mesh_names_the_file_its_size_and_scale_fix() {
    let dir = temp_dir("check-mm");
    let obj = write(&dir, "can.obj", &triangle_obj(120.0, 160.0)); // 200 mm read as 200 m
    assert_eq!(
        dir_error(&dir, 1.0),
        format!(
            "{}: the mesh is 200.000 m across as loaded (scale 1); it looks like it is in millimetres. \
             Graspable objects are 1 cm – 1 m: load it with `--scale 0.001` (it would be 0.200 m)",
            obj.display()
        )
    );
    // With the suggested scale it loads, 0.2 m across.
    let set = load_object_dir(&dir, 0.001).unwrap();
    assert!((set.objects[0].diameter - 0.2).abs() < 1e-6);
}

#[test]
fn check_centimetre_mesh_suggests_centimetres_and_mentions_millimetres() {
    let dir = temp_dir("check-cm");
    let obj = write(&dir, "box.obj", &triangle_obj(12.0, 16.0)); // 20 cm read as 20 m
    assert_eq!(
        dir_error(&dir, 1.0),
        format!(
            "{}: the mesh is 20.000 m across as loaded (scale 1); it looks like it is in centimetres. \
             Graspable objects are 1 cm – 1 m: load it with `--scale 0.01` (it would be 0.200 m); \
             if it is in millimetres, `--scale 0.001` (0.020 m)",
            obj.display()
        )
    );
}

#[test]
fn check_metre_mesh_loaded_as_millimetres_is_too_small() {
    let dir = temp_dir("check-tiny");
    let obj = write(&dir, "mug.obj", &triangle_obj(0.06, 0.08)); // 10 cm in metres, with --scale 0.001
    assert_eq!(
        dir_error(&dir, 0.001),
        format!(
            "{}: the mesh is 0.000 m across as loaded (scale 0.001); it looks like it is in metres but was \
             loaded as millimetres. Graspable objects are 1 cm – 1 m: load it with `--scale 1` (it would be 0.100 m)",
            obj.display()
        )
    );
    // Tiny and not explained by units (2 mm across in metres): named, no scale guess.
    let dir = temp_dir("check-implausible");
    let obj = write(&dir, "speck.obj", &triangle_obj(0.0012, 0.0016));
    assert_eq!(
        dir_error(&dir, 1.0),
        format!(
            "{}: the mesh is 0.002 m across as loaded (scale 1), implausible for a graspable object \
             (1 cm – 1 m) and not explained by mm/cm units; rescale the file so that it is in metres",
            obj.display()
        )
    );
}

#[test]
fn check_missing_texture_warns_by_default_and_fails_when_strict() {
    let dir = temp_dir("check-missing-texture");
    std::fs::create_dir_all(dir.join("cube")).unwrap();
    let obj = write(&dir.join("cube"), "cube.obj", &CUBE_OBJ.replace("v 0.5", "v 0.05").replace("v -0.5", "v -0.05"));
    let mtl = write(&dir.join("cube"), "cube.mtl", CUBE_MTL); // names body.png, not written
    let png = dir.join("cube").join("body.png");
    let (set, warnings) = load_object_dir_checked(&dir, 1.0, MissingTextures::Warn).unwrap();
    assert_eq!(set.len(), 1);
    assert_eq!(warnings.len(), 1);
    assert_eq!(
        warnings[0].to_string(),
        format!(
            "{}: texture {} named by {} does not exist; rendering the material colour instead \
             (put the image there, or delete the `map_Kd` line to silence this)",
            obj.display(),
            png.display(),
            mtl.display()
        )
    );
    let err = load_object_dir_checked(&dir, 1.0, MissingTextures::Fail).unwrap_err().to_string();
    assert_eq!(
        err,
        format!(
            "{}: texture {} named by {} does not exist; put the image there, or delete the `map_Kd` line \
             from {} to render the material colour instead",
            obj.display(),
            png.display(),
            mtl.display(),
            mtl.display()
        )
    );
}

#[test]
fn check_undecodable_texture_is_an_error_even_by_default() {
    let dir = temp_dir("check-bad-texture");
    let obj = write(&dir, "cube.obj", &CUBE_OBJ.replace("v 0.5", "v 0.05").replace("v -0.5", "v -0.05"));
    let mtl = write(&dir, "cube.mtl", CUBE_MTL);
    let png = write(&dir, "body.png", "this is not a PNG");
    let err = dir_error(&dir, 1.0);
    let expected_start =
        format!("{}: texture {} named by {} cannot be decoded (", obj.display(), png.display(), mtl.display());
    assert!(err.starts_with(&expected_start), "{err}");
    assert!(
        err.ends_with(&format!(
            "); put the image there, or delete the `map_Kd` line from {} to render the material colour instead",
            mtl.display()
        )),
        "{err}"
    );
}

#[test]
fn check_ply_texture_error_names_the_ply_header_line() {
    let dir = temp_dir("check-ply-texture");
    let ply = write(
        &dir,
        "tri.ply",
        "ply\nformat ascii 1.0\ncomment TextureFile tex.png\nelement vertex 3\nproperty float x\n\
         property float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\n\
         end_header\n0 0 0\n0.1 0 0\n0 0.1 0\n3 0 1 2\n",
    );
    let err = load_object_dir_checked(&dir, 1.0, MissingTextures::Fail).unwrap_err().to_string();
    assert_eq!(
        err,
        format!(
            "{}: texture {} named by {} does not exist; put the image there, or delete the \
             `comment TextureFile` line from {} to render the material colour instead",
            ply.display(),
            dir.join("tex.png").display(),
            ply.display(),
            ply.display()
        )
    );
}

#[test]
fn check_empty_mesh_is_named() {
    let dir = temp_dir("check-empty");
    let obj = write(&dir, "wire.obj", "v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nl 1 2\nl 2 3\n");
    assert_eq!(
        dir_error(&dir, 1.0),
        format!(
            "{}: the mesh has no triangles (points or lines only?); export it as a triangle or polygon mesh",
            obj.display()
        )
    );
}

#[test]
fn check_degenerate_and_non_finite_meshes_are_named() {
    let dir = temp_dir("check-degenerate");
    let obj = write(&dir, "flat.obj", "v 0 0 0\nv 0.1 0 0\nv 0.2 0 0\nf 1 2 3\nf 1 1 2\n");
    assert_eq!(
        dir_error(&dir, 1.0),
        format!(
            "{}: all 2 triangles have zero area (flat or collapsed geometry); re-export the mesh with its surface",
            obj.display()
        )
    );
    let dir = temp_dir("check-non-finite");
    let obj = write(&dir, "nan.obj", "v 0 0 0\nv 0.1 0 0\nv 0 NaN 0\nf 1 2 3\n");
    assert_eq!(
        dir_error(&dir, 1.0),
        format!(
            "{}: vertex 2 has a non-finite coordinate (NaN or infinite); repair or re-export the mesh",
            obj.display()
        )
    );
}

#[test]
fn check_huge_mesh_warns_with_its_triangle_count() {
    let path = Path::new("/data/scan.ply");
    let mut mesh = Mesh { positions: vec![[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.1, 0.0]], ..Mesh::default() };
    mesh.triangles = vec![[0, 1, 2]; checks::HUGE_TRIANGLES + 1];
    let warnings = checks::check_mesh(path, &mesh, &[], MissingTextures::Warn).unwrap();
    assert_eq!(
        warnings.iter().map(ToString::to_string).collect::<Vec<_>>(),
        ["/data/scan.ply: 2000001 triangles (more than 2000000) slow rendering and training; \
          decimate it (e.g. MeshLab's quadric edge collapse to ~100 k triangles)"]
    );
    mesh.triangles.truncate(checks::HUGE_TRIANGLES);
    assert!(checks::check_mesh(path, &mesh, &[], MissingTextures::Warn).unwrap().is_empty());
}

#[test]
fn check_duplicate_object_names_name_both_paths() {
    let dir = temp_dir("check-duplicate");
    std::fs::create_dir_all(dir.join("a")).unwrap();
    let nested = write(&dir.join("a"), "a.obj", &triangle_obj(0.1, 0.1));
    let flat = write(&dir, "a.obj", &triangle_obj(0.1, 0.1));
    // Paths in order: `a/a.obj` sorts before `a.obj` (component-wise).
    assert_eq!(
        dir_error(&dir, 1.0),
        format!(
            "two meshes give the object name 'a': {} and {}; rename or remove one \
             (names must differ in more than letter case)",
            nested.display(),
            flat.display()
        )
    );

    let dir = temp_dir("check-duplicate-case");
    let upper = write(&dir, "Mug.obj", &triangle_obj(0.1, 0.1));
    let lower = write(&dir, "mug.obj", &triangle_obj(0.1, 0.1));
    let err = dir_error(&dir, 1.0);
    assert!(err.starts_with("two meshes give the object name '"), "{err}");
    assert!(err.contains(&format!("{} and {}", upper.display(), lower.display())), "{err}");
}

#[test]
fn symmetry_suggestions_follow_the_geometry() {
    use checks::{SymmetrySuggestion, suggest_symmetry};
    let set = crate::builtin::builtin_objects();
    let bowl = &set.objects[set.class_of("bowl").unwrap() as usize - 1];
    match suggest_symmetry(bowl) {
        SymmetrySuggestion::Continuous { axis } => assert!(axis.z.abs() > 0.99, "{axis:?}"),
        other => panic!("bowl: {other}"),
    }
    // The mug's handle breaks its body's rotational symmetry.
    let mug = &set.objects[set.class_of("mug").unwrap() as usize - 1];
    assert_eq!(suggest_symmetry(mug), SymmetrySuggestion::None);
    let block = crate::model::ObjectModel::from_mesh(
        "block",
        crate::surface::tests::box_mesh([0.1, 0.06, 0.03]),
        Symmetry::None,
    )
    .unwrap();
    assert!(matches!(suggest_symmetry(&block), SymmetrySuggestion::Box { .. }));
    // An irregular tetrahedron has no rotational symmetry.
    let tetra = Mesh {
        positions: vec![[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.05, 0.0], [0.01, 0.02, 0.07]],
        triangles: vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3]],
        ..Mesh::default()
    };
    let tetra = crate::model::ObjectModel::from_mesh("tetra", tetra, Symmetry::None).unwrap();
    assert_eq!(suggest_symmetry(&tetra), SymmetrySuggestion::None);
}

#[test]
fn a_warning_is_logged_once_per_process() {
    let text = "a.obj: texture t.png named by a.mtl does not exist (test-only message)";
    assert!(first_time(text), "first time");
    assert!(!first_time(text), "second time");
    assert!(first_time("another test-only message"));
}
