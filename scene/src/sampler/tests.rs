//! Sampler tests: determinism, physical plausibility (resting, no
//! interpenetration), camera ranges, occlusion targeting and render truth.

use super::backdrop::{box_mesh, plain_material};
use super::*;
use crate::{Mesh, ObjectModel, Symmetry};
use nalgebra::Point3;

/// A small object set of boxes (object frame: origin at the bbox centre, z up).
fn box_set() -> ObjectSet {
    let sizes = [[0.08f32, 0.06, 0.10], [0.05, 0.05, 0.12], [0.16, 0.06, 0.21], [0.09, 0.09, 0.04], [0.07, 0.03, 0.07]];
    let objects = sizes
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let half = [s[0] / 2.0, s[1] / 2.0, s[2] / 2.0];
            let mesh = box_mesh(half, 1.0, plain_material("c", [0.2 + 0.15 * i as f32, 0.5, 0.7 - 0.1 * i as f32]));
            model(&format!("box{i}"), mesh, half)
        })
        .collect();
    ObjectSet { objects }
}

fn model(name: &str, mesh: Mesh, half: [f32; 3]) -> ObjectModel {
    let h = half.map(|x| x as f64);
    ObjectModel {
        name: name.into(),
        samples: mesh.positions.iter().map(|p| Point3::new(p[0] as f64, p[1] as f64, p[2] as f64)).collect(),
        mesh,
        symmetry: Symmetry::None,
        diameter: 2.0 * (h[0] * h[0] + h[1] * h[1] + h[2] * h[2]).sqrt(),
        bbox_min: Point3::new(-h[0], -h[1], -h[2]),
        bbox_max: Point3::new(h[0], h[1], h[2]),
    }
}

fn k_quarter() -> Intrinsics {
    Intrinsics { fx: 533.4, fy: 533.7, cx: 156.5, cy: 120.4, width: 320, height: 240 }
}

#[test]
fn same_seed_same_scene_and_frame_other_seed_differs() {
    let set = box_set();
    let cfg = SamplerConfig { views: 2, ..Default::default() };
    let a = sample_scene(&set, &cfg, 42).unwrap();
    let b = sample_scene(&set, &cfg, 42).unwrap();
    let c = sample_scene(&set, &cfg, 43).unwrap();
    assert_eq!(a.objects, b.objects);
    assert_eq!(a.views, b.views);
    assert_eq!(a.lighting, b.lighting);
    assert_eq!(a.backdrop.table, b.backdrop.table);
    assert_ne!(a.objects, c.objects);
    assert_ne!(a.views, c.views);
    let k = k_quarter();
    let (mut ta, mut tb) = (RenderTarget::for_intrinsics(&k), RenderTarget::for_intrinsics(&k));
    let noise = NoiseConfig::default();
    let fa = render_view(&a, &set, 1, &k, &noise, &mut ta).unwrap();
    let fb = render_view(&b, &set, 1, &k, &noise, &mut tb).unwrap();
    assert_eq!(fa, fb);
    assert_eq!(ta.rgb(), tb.rgb());
    assert_eq!(ta.depth_u16(), tb.depth_u16());
    assert_eq!(ta.labels(), tb.labels());
}

#[test]
fn objects_rest_on_the_table_without_interpenetrating() {
    let set = box_set();
    let cfg = SamplerConfig { max_objects: 5, ..Default::default() };
    let mut close_pairs = 0;
    for seed in 0..20 {
        let s = sample_scene(&set, &cfg, seed).unwrap();
        assert!((3..=5).contains(&s.objects.len()));
        let classes: Vec<u16> = s.objects.iter().map(|o| o.class_id).collect();
        let mut unique = classes.clone();
        unique.sort();
        unique.dedup();
        assert_eq!(unique.len(), classes.len(), "duplicate classes without allow_duplicates");
        for (i, o) in s.objects.iter().enumerate() {
            assert_eq!(o.instance_label as usize, i + 1);
            let m = set.by_class(o.class_id).unwrap();
            let zs: Vec<f64> = m
                .mesh
                .positions
                .iter()
                .map(|p| (o.table_from_object * Point3::new(p[0] as f64, p[1] as f64, p[2] as f64)).z)
                .collect();
            let min_z = zs.iter().cloned().fold(f64::INFINITY, f64::min);
            assert!(min_z.abs() < 1e-6, "object {i} floats or sinks: lowest point at {min_z} m");
            // Resting on a face: at least 4 vertices touch the table.
            assert!(zs.iter().filter(|z| z.abs() < 1e-6).count() >= 4);
        }
        // No vertex of one box inside another (boxes: exact test).
        for (i, a) in s.objects.iter().enumerate() {
            for (j, b) in s.objects.iter().enumerate() {
                if i == j {
                    continue;
                }
                let mb = set.by_class(b.class_id).unwrap();
                let inv_b = b.table_from_object.inverse();
                let ma = set.by_class(a.class_id).unwrap();
                for p in &ma.mesh.positions {
                    let q = inv_b * (a.table_from_object * Point3::new(p[0] as f64, p[1] as f64, p[2] as f64));
                    let inside = (0..3).all(|c| q[c].abs() < mb.bbox_max[c] - 1e-6);
                    assert!(!inside, "seed {seed}: a corner of object {i} is inside object {j}");
                }
                let gap = (a.table_from_object.translation.vector - b.table_from_object.translation.vector).xy().norm();
                if gap < 0.5 * (ma.diameter + mb.diameter) * 0.6 {
                    close_pairs += 1;
                }
            }
        }
    }
    assert!(close_pairs > 10, "objects should often be close: {close_pairs} close pairs");
}

#[test]
fn cameras_respect_distance_and_elevation_ranges() {
    let set = box_set();
    let cfg = SamplerConfig { views: 4, ..Default::default() };
    for seed in 0..5 {
        let mut s = sample_scene(&set, &cfg, seed).unwrap();
        let mut again = s.clone();
        s.add_views(&set, &cfg, 4, 99).unwrap();
        again.add_views(&set, &cfg, 4, 99).unwrap();
        assert_eq!(s.views, again.views, "add_views is deterministic");
        assert_eq!(s.views.len(), 8);
        assert_ne!(s.views[0], s.views[4]);
        for v in &s.views {
            let eye = v.camera_from_table.inverse() * Point3::origin();
            assert!(eye.z > 0.1, "camera below or at the table: {eye}");
            // The optical axis passes near the objects' centroid.
            let centroid =
                s.objects.iter().map(|o| o.table_from_object.translation.vector).sum::<nalgebra::Vector3<f64>>()
                    / s.objects.len() as f64;
            let c = v.camera_from_table * Point3::new(centroid.x, centroid.y, 0.05);
            assert!(c.z > 0.4 && c.z < 1.6, "look-at distance {}", c.z);
            assert!(c.x.abs() < 0.1 && c.y.abs() < 0.1, "look-at point off axis: {c}");
            // Elevation of the view ray (from the look-at point) in 15..75° (+ jitter slack).
            let d = eye - Point3::new(centroid.x, centroid.y, 0.05);
            let elev = (d.z / d.norm()).asin().to_degrees();
            assert!(elev > 10.0 && elev < 80.0, "elevation {elev}");
        }
    }
}

#[test]
fn render_view_truth_matches_the_rendered_planes() {
    let set = box_set();
    let s = sample_scene(&set, &SamplerConfig::default(), 7).unwrap();
    let k = k_quarter();
    let mut t = RenderTarget::for_intrinsics(&k);
    let truth = render_view(&s, &set, 0, &k, &NoiseConfig::off(), &mut t).unwrap();
    assert_eq!(truth.objects.len(), s.objects.len());
    let poses = s.object_poses(0).unwrap();
    let mut seen = 0;
    for (o, pose) in truth.objects.iter().zip(&poses) {
        assert_eq!(&o.pose, pose);
        let count = t.labels().iter().filter(|&&l| l == o.instance_label).count() as u32;
        assert_eq!(count, o.visible_pixels);
        assert!(o.visible_fraction >= 0.0 && o.visible_fraction <= 1.0);
        if o.visible_pixels > 0 {
            seen += 1;
        }
        // Back-projected pixels lie on the posed box.
        let m = set.by_class(o.class_id).unwrap();
        let inv = o.pose.inverse();
        for v in 0..k.height {
            for u in 0..k.width {
                let i = (v * k.width + u) as usize;
                if t.labels()[i] != o.instance_label {
                    continue;
                }
                let z = t.depth_m()[i] as f64;
                assert!(z > 0.0, "label pixel without depth");
                let q = inv * k.back_project(u as f64, v as f64, z);
                let outside = (0..3).map(|c| (q[c].abs() - m.bbox_max[c]).max(0.0)).fold(0.0, f64::max);
                let inside = (0..3).map(|c| m.bbox_max[c] - q[c].abs()).fold(f64::INFINITY, f64::min);
                assert!(outside < 1e-4 && inside < 1e-4, "pixel ({u},{v}) off the surface");
            }
        }
    }
    assert!(seen >= 1, "no object visible");
    // The background (table, room) fills the frame: every pixel has depth.
    assert!(t.depth_m().iter().all(|&z| z > 0.0));
    // Class label plane.
    let lut = truth.class_lut();
    let mut classes = Vec::new();
    t.map_labels(&lut, &mut classes);
    for (i, &c) in classes.iter().enumerate() {
        let l = t.labels()[i];
        let expect = if l == 0 { 0 } else { truth.objects[l as usize - 1].class_id };
        assert_eq!(c, expect);
    }
    let mut t2 = RenderTarget::for_intrinsics(&k);
    render_view_labelled(&s, &set, 0, &k, &NoiseConfig::off(), LabelKind::Class, &mut t2).unwrap();
    assert_eq!(t2.labels(), &classes[..]);
}

#[test]
fn occlusion_targeting_finds_partly_hidden_objects() {
    let set = box_set();
    let cfg = SamplerConfig { target_occlusion: Some((0.3, 0.7)), views: 3, ..Default::default() };
    let k = cfg.intrinsics;
    let mut t = RenderTarget::for_intrinsics(&k);
    let (mut met, mut total) = (0, 0);
    for seed in 0..4 {
        let s = sample_scene(&set, &cfg, seed).unwrap();
        for (vi, v) in s.views.iter().enumerate() {
            total += 1;
            if !v.occlusion_target_met {
                continue;
            }
            met += 1;
            let truth = render_view(&s, &set, vi, &k, &NoiseConfig::off(), &mut t).unwrap();
            // Quarter-resolution probe: allow a little slack at full resolution.
            let ok = truth
                .objects
                .iter()
                .any(|o| o.alone_pixels > 300 && (0.25..=0.75).contains(&(1.0 - o.visible_fraction)));
            assert!(
                ok,
                "seed {seed} view {vi}: no object 30–70 % hidden: {:?}",
                truth.objects.iter().map(|o| 1.0 - o.visible_fraction).collect::<Vec<_>>()
            );
        }
    }
    assert!(met * 4 >= total * 3, "target met in only {met} of {total} views");
}

#[test]
fn bad_configs_and_sets_are_errors() {
    let set = box_set();
    let bad = |cfg: SamplerConfig| matches!(sample_scene(&set, &cfg, 1), Err(SamplerError::InvalidConfig(_)));
    assert!(bad(SamplerConfig { min_objects: 0, ..Default::default() }));
    assert!(bad(SamplerConfig { min_objects: 5, max_objects: 4, ..Default::default() }));
    assert!(bad(SamplerConfig { camera_elevation_deg: (10.0, 90.0), ..Default::default() }));
    assert!(bad(SamplerConfig { camera_distance_m: (0.0, 1.0), ..Default::default() }));
    assert!(bad(SamplerConfig { views: 0, ..Default::default() }));
    assert!(bad(SamplerConfig { target_occlusion: Some((0.8, 0.2)), ..Default::default() }));
    assert_eq!(
        sample_scene(&ObjectSet::default(), &SamplerConfig::default(), 1).unwrap_err(),
        SamplerError::EmptyObjectSet
    );
    // Far more objects than fit on the table: a placement error, not a hang.
    let crowd = SamplerConfig { min_objects: 120, max_objects: 120, allow_duplicates: true, ..Default::default() };
    assert!(matches!(sample_scene(&set, &crowd, 1), Err(SamplerError::Placement { .. })));
    let s = sample_scene(&set, &SamplerConfig::default(), 1).unwrap();
    let k = k_quarter();
    let mut t = RenderTarget::for_intrinsics(&k);
    assert!(matches!(render_view(&s, &set, 5, &k, &NoiseConfig::off(), &mut t), Err(SamplerError::NoSuchView { .. })));
    let small = ObjectSet { objects: set.objects[..1].to_vec() };
    assert!(matches!(
        render_view(&s, &small, 0, &k, &NoiseConfig::off(), &mut t),
        Err(SamplerError::UnknownClass { .. })
    ));
}

#[test]
fn duplicates_fill_scenes_from_small_sets() {
    let set = box_set();
    let small = ObjectSet { objects: set.objects[..2].to_vec() };
    let s = sample_scene(&small, &SamplerConfig { min_objects: 4, max_objects: 4, ..Default::default() }, 3).unwrap();
    assert_eq!(s.objects.len(), 4);
}

/// Closest point on triangle (a, b, c) to p (Ericson, Real-Time Collision Detection 5.1.5).
fn closest_on_triangle(p: &Point3<f64>, a: &Point3<f64>, b: &Point3<f64>, c: &Point3<f64>) -> Point3<f64> {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(&ap), ac.dot(&ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return *a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(&bp), ac.dot(&bp));
    if d3 >= 0.0 && d4 <= d3 {
        return *b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(&cp), ac.dot(&cp));
    if d6 >= 0.0 && d5 <= d6 {
        return *c;
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

fn distance_to_mesh(p: &Point3<f64>, mesh: &Mesh) -> f64 {
    let pt = |i: u32| {
        let q = mesh.positions[i as usize];
        Point3::new(q[0] as f64, q[1] as f64, q[2] as f64)
    };
    mesh.triangles
        .iter()
        .map(|t| (closest_on_triangle(p, &pt(t[0]), &pt(t[1]), &pt(t[2])) - p).norm())
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn builtin_scenes_rest_render_and_back_project_onto_the_meshes() {
    let set = crate::builtin::builtin_objects();
    let k = k_quarter();
    let mut t = RenderTarget::for_intrinsics(&k);
    let cfg = SamplerConfig { target_occlusion: Some((0.3, 0.7)), ..Default::default() };
    for seed in 0..3 {
        let s = sample_scene(&set, &cfg, seed).unwrap();
        assert!((3..=8).contains(&s.objects.len()));
        for o in &s.objects {
            let m = set.by_class(o.class_id).unwrap();
            let min_z = m
                .mesh
                .positions
                .iter()
                .map(|p| (o.table_from_object * Point3::new(p[0] as f64, p[1] as f64, p[2] as f64)).z)
                .fold(f64::INFINITY, f64::min);
            assert!(min_z.abs() < 1e-6, "{} floats or sinks: {min_z}", m.name);
        }
        let truth = render_view(&s, &set, 0, &k, &NoiseConfig::off(), &mut t).unwrap();
        let (mut n, mut sum) = (0usize, 0.0);
        for o in &truth.objects {
            let m = set.by_class(o.class_id).unwrap();
            let inv = o.pose.inverse();
            let mut count = 0u32;
            for (i, &l) in t.labels().iter().enumerate() {
                if l != o.instance_label {
                    continue;
                }
                count += 1;
                let z = t.depth_m()[i] as f64;
                assert!(z > 0.0, "label pixel without depth");
                if i % 5 != 0 {
                    continue;
                }
                let (u, v) = ((i % k.width as usize) as f64, (i / k.width as usize) as f64);
                let q = inv * k.back_project(u, v, z);
                let d = distance_to_mesh(&q, &m.mesh);
                assert!(d < 2e-3, "{}: pixel ({u},{v}) is {d} m off the mesh", m.name);
                sum += d;
                n += 1;
            }
            assert_eq!(count, o.visible_pixels);
        }
        assert!(n > 100, "too few object pixels: {n}");
        let mean = sum / n as f64;
        assert!(mean < 1e-3, "seed {seed}: mean distance {mean} m");
    }
}
