//! Tests of the built-in set: sizes, symmetries (checked against the actual
//! surface), normals, textures, determinism.

use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};

use super::*;
use crate::model::Mesh;

/// Closest point on triangle `abc` to `p` (Ericson, Real-Time Collision Detection 5.1.5).
fn closest_on_triangle(p: Point3<f64>, a: Point3<f64>, b: Point3<f64>, c: Point3<f64>) -> Point3<f64> {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(&ap), ac.dot(&ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(&bp), ac.dot(&bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(&cp), ac.dot(&cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    a + ab * (vb * denom) + ac * (vc * denom)
}

fn corner(mesh: &Mesh, i: u32) -> Point3<f64> {
    let p = mesh.positions[i as usize];
    Point3::new(p[0] as f64, p[1] as f64, p[2] as f64)
}

/// Distance from `p` to the mesh surface (metres), brute force.
fn distance_to_surface(mesh: &Mesh, p: Point3<f64>) -> f64 {
    mesh.triangles
        .iter()
        .map(|t| (closest_on_triangle(p, corner(mesh, t[0]), corner(mesh, t[1]), corner(mesh, t[2])) - p).norm())
        .fold(f64::INFINITY, f64::min)
}

/// Largest distance from the transformed samples (every 4th) to the surface.
fn worst_distance_after(object: &ObjectModel, transform: &Isometry3<f64>) -> f64 {
    object.samples.iter().step_by(4).map(|s| distance_to_surface(&object.mesh, transform * s)).fold(0.0, f64::max)
}

fn by_name<'a>(set: &'a ObjectSet, name: &str) -> &'a ObjectModel {
    set.by_class(set.class_of(name).unwrap()).unwrap()
}

#[test]
fn builtin_set_has_eight_distinct_textured_objects() {
    let set = builtin_objects();
    assert!(set.len() >= 8);
    let names: Vec<_> = set.objects.iter().map(|o| o.name.as_str()).collect();
    assert_eq!(names, BUILTIN_NAMES);
    let mut dominant = Vec::new();
    for o in &set.objects {
        assert!(o.mesh.triangles.len() <= 4000, "{} has {} triangles", o.name, o.mesh.triangles.len());
        assert_eq!(o.mesh.uvs.len(), o.mesh.positions.len());
        assert_eq!(o.mesh.normals.len(), o.mesh.positions.len());
        let tex = o.mesh.materials[0].texture.as_ref().expect("every built-in object is textured");
        assert_eq!(tex.rgb.len(), (tex.width * tex.height * 3) as usize);
        assert!(o.mesh.uvs.iter().all(|uv| (0.0..=1.0).contains(&uv[0]) && (0.0..=1.0).contains(&uv[1])));
        // Origin at the bbox centre.
        assert!((o.bbox_min.coords + o.bbox_max.coords).norm() < 1e-6, "{} not centred", o.name);
        let mean: Vec<f64> = (0..3)
            .map(|k| tex.rgb.iter().skip(k).step_by(3).map(|&c| c as f64).sum::<f64>() / (tex.rgb.len() / 3) as f64)
            .collect();
        dominant.push((o.name.clone(), mean));
    }
    // Textures differ: mean colours of any two objects are apart (0..255 scale).
    for (i, (a, ca)) in dominant.iter().enumerate() {
        for (b, cb) in &dominant[i + 1..] {
            let d = ca.iter().zip(cb).map(|(x, y)| (x - y).powi(2)).sum::<f64>().sqrt();
            assert!(d > 12.0, "{a} and {b} look alike (mean colour distance {d:.1})");
        }
    }
}

#[test]
fn builtin_sizes_are_realistic() {
    let set = builtin_objects();
    let extent = |name: &str| {
        let o = by_name(&set, name);
        o.bbox_max - o.bbox_min
    };
    let close = |v: Vector3<f64>, e: [f64; 3], tol: f64| (0..3).all(|k| (v[k] - e[k]).abs() < tol);
    assert!(close(extent("cracker_box"), [0.16, 0.06, 0.21], 1e-6));
    assert!(close(extent("sugar_box"), [0.09, 0.04, 0.175], 1e-6));
    assert!(close(extent("tomato_soup_can"), [0.066, 0.066, 0.10], 1e-6));
    assert!(close(extent("coffee_can"), [0.10, 0.10, 0.14], 1e-6));
    assert!(close(extent("mustard_bottle"), [0.095, 0.058, 0.19], 1e-3), "{}", extent("mustard_bottle"));
    assert!(close(extent("bowl"), [0.16, 0.16, 0.053], 1e-6));
    assert!(close(extent("wood_block"), [0.085, 0.085, 0.2], 1e-6));
    let mug = extent("mug");
    assert!((mug.z - 0.09).abs() < 1e-6 && mug.x > 0.1 && (mug.y - 0.08).abs() < 1e-6, "{mug}");
    let cracker = by_name(&set, "cracker_box");
    assert!((cracker.diameter - (0.16f64.powi(2) + 0.06f64.powi(2) + 0.21f64.powi(2)).sqrt()).abs() < 1e-6);
}

#[test]
fn declared_symmetries_map_each_surface_onto_itself() {
    let set = builtin_objects();
    let bowl = by_name(&set, "bowl");
    assert!(matches!(bowl.symmetry, Symmetry::Continuous { .. }));
    for t in bowl.symmetry.sampled(7).iter().skip(1) {
        // Tolerance: tessellation sagitta r (1 - cos(pi / 48)) = 0.17 mm at r = 8 cm.
        let worst = worst_distance_after(bowl, t);
        assert!(worst < 4e-4, "bowl rotated moves samples {worst} m off the surface");
    }
    let block = by_name(&set, "wood_block");
    let Symmetry::Discrete(transforms) = &block.symmetry else { panic!("wood block must be discretely symmetric") };
    assert_eq!(transforms.len(), 7, "square-section box: 8 rotations including identity");
    for t in transforms {
        let worst = worst_distance_after(block, t);
        assert!(worst < 1e-6, "wood block symmetry {t} moves samples {worst} m off the surface");
    }
    let symmetric: Vec<_> = set.objects.iter().filter(|o| o.symmetry.is_symmetric()).map(|o| o.name.as_str()).collect();
    assert_eq!(symmetric, ["bowl", "wood_block"], "cans, mug and bottle carry labels/handles: not symmetric");
}

#[test]
fn asymmetric_objects_really_are_not_symmetric() {
    let set = builtin_objects();
    let quarter =
        Isometry3::from_parts(Default::default(), UnitQuaternion::from_axis_angle(&Vector3::z_axis(), FRAC_PI_2));
    let half = Isometry3::from_parts(Default::default(), UnitQuaternion::from_axis_angle(&Vector3::z_axis(), PI_F64));
    let mug = by_name(&set, "mug");
    assert!(worst_distance_after(mug, &quarter) > 0.01, "the handle must move off the surface");
    let bottle = by_name(&set, "mustard_bottle");
    assert!(worst_distance_after(bottle, &half) > 0.004, "the off-centre nozzle must break the symmetry");
    // A box with three different sides: a quarter turn is no symmetry.
    assert!(worst_distance_after(by_name(&set, "cracker_box"), &quarter) > 0.01);
}

const PI_F64: f64 = std::f64::consts::PI;

#[test]
fn triangle_winding_and_normals_face_outward() {
    let set = builtin_objects();
    for o in &set.objects {
        let m = &o.mesh;
        let mut agree = 0usize;
        for t in &m.triangles {
            let [a, b, c] = t.map(|i| corner(m, i));
            let face = (b - a).cross(&(c - a));
            let n: Vector3<f64> = t.iter().map(|&i| Vector3::from(m.normals[i as usize].map(|x| x as f64))).sum();
            if face.dot(&n) > 0.0 {
                agree += 1;
            }
        }
        assert_eq!(agree, m.triangles.len(), "{}: vertex normals disagree with winding", o.name);
    }
    // Convex closed objects: every face points away from the centre.
    for name in ["cracker_box", "sugar_box", "tomato_soup_can", "coffee_can", "wood_block"] {
        let m = &by_name(&set, name).mesh;
        for t in &m.triangles {
            let [a, b, c] = t.map(|i| corner(m, i));
            let centroid = (a.coords + b.coords + c.coords) / 3.0;
            assert!((b - a).cross(&(c - a)).dot(&centroid) > 0.0, "{name}: inward face");
        }
    }
}

#[test]
fn symmetric_objects_have_textures_that_respect_the_symmetry() {
    let set = builtin_objects();
    let tex = by_name(&set, "bowl").mesh.materials[0].texture.clone().unwrap();
    for row in tex.rgb.chunks_exact(tex.width as usize * 3) {
        assert!(row.chunks_exact(3).all(|px| px == &row[..3]), "bowl texture rows must be uniform");
    }
    let tex = by_name(&set, "wood_block").mesh.materials[0].texture.clone().unwrap();
    let px = |x: u32, y: u32| &tex.rgb[((y * tex.width + x) * 3) as usize..][..3];
    let half = tex.width / 2;
    for y in 0..tex.height {
        for x in 0..half {
            assert_eq!(px(x, y), px(half - 1 - x, y), "side grain mirror-symmetric");
            assert_eq!(px(x, y), px(x, tex.height - 1 - y), "side grain constant along the block");
        }
    }
    for y in 0..tex.height {
        for x in 0..half {
            assert_eq!(px(half + x, y), px(half + y, x), "end rings invariant under quarter turns");
        }
    }
}

#[test]
fn builtin_objects_are_deterministic() {
    let (a, b) = (builtin_objects(), builtin_objects());
    for (x, y) in a.objects.iter().zip(&b.objects) {
        assert_eq!(x.mesh, y.mesh);
        assert_eq!(x.samples, y.samples);
    }
}

#[test]
fn box_symmetry_groups_have_the_right_size() {
    assert_eq!(box_symmetries([0.1, 0.2, 0.3]).len(), 3);
    assert_eq!(box_symmetries([0.1, 0.1, 0.3]).len(), 7);
    assert_eq!(box_symmetries([0.1, 0.1, 0.1]).len(), 23);
}
