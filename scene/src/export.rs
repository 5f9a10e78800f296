//! Writing object sets to disk so any tool can render them: one folder per
//! object holding `NAME.obj` + `NAME.mtl` + one PNG per textured material,
//! plus a `models_info.json` summary (metres) that [`crate::mesh_io::load_object_dir`]
//! reads back for the symmetries.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Matrix3, Matrix4, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::model::{Mesh, ObjectSet, Symmetry};

/// Why an export failed; every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    #[error("{path}: cannot write: {error}")]
    Io { path: PathBuf, error: std::io::Error },
    #[error("{path}: cannot write image: {error}")]
    Image { path: PathBuf, error: image::ImageError },
    #[error("{path}: texture of {width}x{height} holds {len} bytes, expected width*height*3")]
    BadTexture { path: PathBuf, width: u32, height: u32, len: usize },
    #[error("object name '{0}' cannot be a folder name (use letters, digits, '_', '-', '.')")]
    BadName(String),
}

/// Summary of an exported object set (`models_info.json`). Lengths in metres.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelsInfo {
    /// Always `"metres"`.
    pub units: String,
    pub objects: Vec<ModelInfo>,
}

/// One object of [`ModelsInfo`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelInfo {
    pub name: String,
    /// 1-based class id (its position in the set).
    pub class_id: u16,
    /// Mesh path relative to the summary file.
    pub mesh: String,
    pub triangles: usize,
    /// Largest distance between two surface points (metres).
    pub diameter: f64,
    pub bbox_min: [f64; 3],
    pub bbox_max: [f64; 3],
    pub symmetry: SymmetryInfo,
}

/// A [`Symmetry`] in plain JSON: discrete transforms as row-major 4x4 matrices
/// (translation in metres), continuous as an axis through an origin (metres).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum SymmetryInfo {
    None,
    Discrete { transforms: Vec<[f64; 16]> },
    Continuous { axis: [f64; 3], origin: [f64; 3] },
}

impl From<&Symmetry> for SymmetryInfo {
    fn from(s: &Symmetry) -> Self {
        match s {
            Symmetry::None => SymmetryInfo::None,
            Symmetry::Discrete(v) => SymmetryInfo::Discrete {
                transforms: v
                    .iter()
                    .map(|t| {
                        let m = t.to_homogeneous();
                        std::array::from_fn(|k| m[(k / 4, k % 4)])
                    })
                    .collect(),
            },
            Symmetry::Continuous { axis, origin } => {
                SymmetryInfo::Continuous { axis: [axis.x, axis.y, axis.z], origin: [origin.x, origin.y, origin.z] }
            }
        }
    }
}

impl SymmetryInfo {
    /// Back to a [`Symmetry`]; rotation parts are re-orthonormalised.
    pub fn to_symmetry(&self) -> Symmetry {
        match self {
            SymmetryInfo::None => Symmetry::None,
            SymmetryInfo::Discrete { transforms } => Symmetry::Discrete(
                transforms
                    .iter()
                    .map(|m| {
                        let m = Matrix4::from_row_slice(m);
                        let r = nearest_rotation(m.fixed_view::<3, 3>(0, 0).into_owned());
                        Isometry3::from_parts(
                            Translation3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]),
                            UnitQuaternion::from_rotation_matrix(&r),
                        )
                    })
                    .collect(),
            ),
            SymmetryInfo::Continuous { axis, origin } => {
                Symmetry::Continuous { axis: Vector3::from(*axis), origin: Point3::from(*origin) }
            }
        }
    }
}

/// The rotation closest to `m` (SVD projection; exact for 180-degree turns,
/// where iterative fitting from the identity fails).
fn nearest_rotation(m: Matrix3<f64>) -> Rotation3<f64> {
    let svd = m.svd(true, true);
    match (svd.u, svd.v_t) {
        (Some(u), Some(v_t)) => {
            let mut r = u * v_t;
            if r.determinant() < 0.0 {
                let mut u = u;
                u.column_mut(2).neg_mut();
                r = u * v_t;
            }
            Rotation3::from_matrix_unchecked(r)
        }
        _ => Rotation3::identity(),
    }
}

impl ModelsInfo {
    /// The declared symmetry of the object called `name`, if listed.
    pub fn symmetry_of(&self, name: &str) -> Option<Symmetry> {
        self.objects.iter().find(|o| o.name == name).map(|o| o.symmetry.to_symmetry())
    }
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> ExportError + '_ {
    move |error| ExportError::Io { path: path.to_owned(), error }
}

fn valid_name(name: &str) -> bool {
    !name.is_empty()
        && name != "."
        && name != ".."
        && name.chars().all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'))
}

/// Writes every object of `set` to `dir/NAME/NAME.{obj,mtl}` (+ PNG textures)
/// and `dir/models_info.json`. Creates `dir` if needed; overwrites files.
/// Returns the path of `models_info.json`.
pub fn export_objects(set: &ObjectSet, dir: &Path) -> Result<PathBuf, ExportError> {
    std::fs::create_dir_all(dir).map_err(io_err(dir))?;
    let mut info = ModelsInfo { units: "metres".into(), objects: Vec::new() };
    for (i, object) in set.objects.iter().enumerate() {
        if !valid_name(&object.name) {
            return Err(ExportError::BadName(object.name.clone()));
        }
        let folder = dir.join(&object.name);
        let obj = write_obj(&object.mesh, &folder, &object.name)?;
        info.objects.push(ModelInfo {
            name: object.name.clone(),
            class_id: i as u16 + 1,
            mesh: obj.strip_prefix(dir).unwrap_or(&obj).to_string_lossy().replace('\\', "/"),
            triangles: object.mesh.triangles.len(),
            diameter: object.diameter,
            bbox_min: object.bbox_min.coords.into(),
            bbox_max: object.bbox_max.coords.into(),
            symmetry: SymmetryInfo::from(&object.symmetry),
        });
    }
    let path = dir.join("models_info.json");
    let json = serde_json::to_string_pretty(&info).expect("ModelsInfo always serialises");
    std::fs::write(&path, json + "\n").map_err(io_err(&path))?;
    Ok(path)
}

/// Writes one mesh as `dir/stem.obj` + `dir/stem.mtl` + `dir/stem_mN.png` per
/// textured material (positions in metres, full `f32` precision). Returns the OBJ path.
pub fn write_obj(mesh: &Mesh, dir: &Path, stem: &str) -> Result<PathBuf, ExportError> {
    if !valid_name(stem) {
        return Err(ExportError::BadName(stem.to_owned()));
    }
    std::fs::create_dir_all(dir).map_err(io_err(dir))?;
    let n = mesh.positions.len();
    let has_uv = mesh.uvs.len() == n && n > 0;
    let mut mtl = String::new();
    for (k, m) in mesh.materials.iter().enumerate() {
        // MTL multiplies map_Kd by Kd, and our texture replaces the colour:
        // a used texture gets Kd 1 so other tools show the texture as is.
        let [r, g, b] = if m.texture.is_some() && has_uv { [1.0; 3] } else { m.diffuse };
        let _ = writeln!(mtl, "newmtl m{k}\nKa 0 0 0\nKd {r} {g} {b}\nKs 0 0 0\nd 1\nillum 1");
        if let Some(t) = &m.texture {
            let file = format!("{stem}_m{k}.png");
            let path = dir.join(&file);
            if t.rgb.len() != t.width as usize * t.height as usize * 3 {
                return Err(ExportError::BadTexture { path, width: t.width, height: t.height, len: t.rgb.len() });
            }
            image::save_buffer(&path, &t.rgb, t.width, t.height, image::ExtendedColorType::Rgb8)
                .map_err(|error| ExportError::Image { path: path.clone(), error })?;
            let _ = writeln!(mtl, "map_Kd {file}");
        }
        mtl.push('\n');
    }
    let mtl_path = dir.join(format!("{stem}.mtl"));
    std::fs::write(&mtl_path, mtl).map_err(io_err(&mtl_path))?;

    let has_normal = mesh.normals.len() == n && n > 0;
    let has_color = mesh.colors.len() == n && n > 0;
    let mut obj = format!("# fusepose object '{stem}', metres\nmtllib {stem}.mtl\no {stem}\n");
    for (i, p) in mesh.positions.iter().enumerate() {
        let _ = write!(obj, "v {} {} {}", p[0], p[1], p[2]);
        if has_color {
            let c = mesh.colors[i].map(|c| c as f32 / 255.0);
            let _ = write!(obj, " {} {} {}", c[0], c[1], c[2]);
        }
        obj.push('\n');
    }
    if has_uv {
        for t in &mesh.uvs {
            let _ = writeln!(obj, "vt {} {}", t[0], t[1]);
        }
    }
    if has_normal {
        for v in &mesh.normals {
            let _ = writeln!(obj, "vn {} {} {}", v[0], v[1], v[2]);
        }
    }
    let mut current = None;
    for (t, tri) in mesh.triangles.iter().enumerate() {
        let material = mesh.triangle_materials.get(t).copied().unwrap_or(0);
        if current != Some(material) && (material as usize) < mesh.materials.len() {
            let _ = writeln!(obj, "usemtl m{material}");
            current = Some(material);
        }
        obj.push('f');
        for &i in tri {
            let i = i + 1;
            let _ = match (has_uv, has_normal) {
                (true, true) => write!(obj, " {i}/{i}/{i}"),
                (true, false) => write!(obj, " {i}/{i}"),
                (false, true) => write!(obj, " {i}//{i}"),
                (false, false) => write!(obj, " {i}"),
            };
        }
        obj.push('\n');
    }
    let obj_path = dir.join(format!("{stem}.obj"));
    std::fs::write(&obj_path, obj).map_err(io_err(&obj_path))?;
    Ok(obj_path)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::builtin::builtin_objects;
    use crate::mesh_io::{load_mesh, load_object_dir};

    fn temp_dir(test: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("fusepose-export-{}-{test}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        dir
    }

    #[test]
    fn exported_builtins_load_back_identically() {
        let set = builtin_objects();
        let dir = temp_dir("round-trip");
        let info_path = export_objects(&set, &dir).unwrap();
        for object in &set.objects {
            let mesh = load_mesh(&dir.join(&object.name).join(format!("{}.obj", object.name)), 1.0).unwrap();
            assert_eq!(mesh.positions.len(), object.mesh.positions.len(), "{}", object.name);
            assert_eq!(mesh.triangles.len(), object.mesh.triangles.len());
            let (lo, hi) = crate::surface::bounding_box(&mesh);
            assert!((lo - object.bbox_min).norm() < 1e-6 && (hi - object.bbox_max).norm() < 1e-6, "{}", object.name);
            let (a, b) = (&mesh.materials[0], &object.mesh.materials[0]);
            assert_eq!(a.texture, b.texture, "{}: texture pixels differ", object.name);
            // A used texture is written with Kd 1 (MTL multiplies map_Kd by Kd).
            assert_eq!(a.diffuse, if b.texture.is_some() { [1.0; 3] } else { b.diffuse });
        }
        // The summary reloads with the same names, class ids and symmetries.
        let info: ModelsInfo = serde_json::from_str(&std::fs::read_to_string(&info_path).unwrap()).unwrap();
        assert_eq!(info.objects.len(), set.len());
        let reloaded = load_object_dir(&dir, 1.0).unwrap();
        for (a, b) in set.objects.iter().zip(&reloaded.objects) {
            assert_eq!(a.name, b.name);
            assert!((a.diameter - b.diameter).abs() < 1e-6);
            let (sa, sb) = (a.symmetry.sampled(4), b.symmetry.sampled(4));
            assert_eq!(sa.len(), sb.len(), "{}", a.name);
            for (x, y) in sa.iter().zip(&sb) {
                assert!((x.to_homogeneous() - y.to_homogeneous()).abs().max() < 1e-9, "{}", a.name);
            }
        }
    }

    /// Renders a mesh head-on, lit by ambient light only, so pixels show the albedo.
    fn render_albedo(mesh: &Mesh) -> crate::render::RenderTarget {
        use crate::render::{Lighting, RenderItem, RenderSettings, RenderTarget, render_scene};
        let k = crate::Intrinsics { fx: 400.0, fy: 400.0, cx: 63.5, cy: 63.5, width: 128, height: 128 };
        let (lo, hi) = crate::surface::bounding_box(mesh);
        let size = (hi - lo).norm();
        let pose = crate::Pose::from_parts(
            nalgebra::Translation3::new(0.0, 0.0, 2.5 * size),
            UnitQuaternion::from_euler_angles(0.4, 0.7, 0.2),
        );
        let settings = RenderSettings {
            lighting: Lighting { ambient: [1.0; 3], lights: vec![], points: vec![] },
            ..Default::default()
        };
        let mut t = RenderTarget::for_intrinsics(&k);
        render_scene(&[RenderItem { mesh, pose, instance_label: 1, shadow_mesh: None }], &k, &settings, &mut t)
            .unwrap();
        t
    }

    #[test]
    fn export_then_load_renders_the_same_colours() {
        let set = builtin_objects();
        let dir = temp_dir("mtl-colours");
        export_objects(&set, &dir).unwrap();
        for object in &set.objects {
            let obj = dir.join(&object.name).join(format!("{}.obj", object.name));
            let mtl = std::fs::read_to_string(obj.with_extension("mtl")).unwrap();
            assert!(mtl.contains("Kd 1 1 1\nKs") && mtl.contains("map_Kd"), "{}: {mtl}", object.name);
            let loaded = load_mesh(&obj, 1.0).unwrap();
            let (a, b) = (render_albedo(&object.mesh), render_albedo(&loaded));
            assert!(a.labels().iter().filter(|&&l| l != 0).count() > 500, "{} not in view", object.name);
            assert_eq!(a.labels(), b.labels(), "{}", object.name);
            let worst = a.rgb().iter().zip(b.rgb()).map(|(x, y)| (*x as i32 - *y as i32).abs()).max().unwrap();
            assert!(worst <= 1, "{}: colours differ by {worst} after export and load", object.name);
        }
        // A user's MTL with Kd 0.5 and a white texture: albedo 0.5 (sRGB 188), as in other tools.
        let user = temp_dir("mtl-user");
        std::fs::create_dir_all(&user).unwrap();
        image::save_buffer(user.join("white.png"), &[255u8; 12], 2, 2, image::ExtendedColorType::Rgb8).unwrap();
        std::fs::write(user.join("q.mtl"), "newmtl m\nKd 0.5 0.5 0.5\nmap_Kd white.png\n").unwrap();
        std::fs::write(
            user.join("q.obj"),
            "mtllib q.mtl\nv -0.1 -0.1 0\nv 0.1 -0.1 0\nv 0.1 0.1 0\nv -0.1 0.1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl m\nf 1/1 2/2 3/3 4/4\n",
        )
        .unwrap();
        let quad = load_mesh(&user.join("q.obj"), 1.0).unwrap();
        let t = render_albedo(&quad);
        let i = t.labels().iter().position(|&l| l == 1).unwrap();
        assert_eq!(&t.rgb()[i * 3..i * 3 + 3], &[188, 188, 188]);
    }

    #[test]
    fn bad_object_names_are_refused() {
        let mut set = builtin_objects();
        set.objects.truncate(1);
        set.objects[0].name = "../escape".into();
        assert!(matches!(export_objects(&set, &temp_dir("bad-name")), Err(ExportError::BadName(_))));
    }
}
