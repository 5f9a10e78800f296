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
        shadow_mesh: None,
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

// ---- Randomisation, depth sensors and several instances per class ----

use crate::render::{DepthSensor, Randomize, RenderSettings, render_scene};

fn ideal(k: &Intrinsics, randomize: Randomize) -> ViewOptions {
    ViewOptions { intrinsics: *k, depth_sensor: DepthSensor::Ideal, randomize }
}

#[test]
fn training_scenes_and_frames_are_deterministic() {
    let set = box_set();
    let cfg = SamplerConfig { views: 2, plain_share: 0.0, ..SamplerConfig::training() };
    let k = k_quarter();
    let a = sample_scene(&set, &cfg, 21).unwrap();
    let b = sample_scene(&set, &cfg, 21).unwrap();
    let c = sample_scene(&set, &cfg, 22).unwrap();
    assert_eq!(a.objects, b.objects);
    assert_eq!(a.views, b.views);
    assert_eq!(a.lighting, b.lighting);
    assert_eq!(a.backdrop.room, b.backdrop.room);
    assert_eq!(a.extras.distractors.len(), b.extras.distractors.len());
    assert_ne!(a.views, c.views);
    let (mut ta, mut tb, mut tc) =
        (RenderTarget::for_intrinsics(&k), RenderTarget::for_intrinsics(&k), RenderTarget::for_intrinsics(&k));
    for view in 0..2 {
        let fa = render_view(&a, &set, view, &k, &NoiseConfig::default(), &mut ta).unwrap();
        let fb = render_view(&b, &set, view, &k, &NoiseConfig::default(), &mut tb).unwrap();
        assert_eq!(fa, fb);
        assert_eq!(ta.rgb(), tb.rgb());
        assert_eq!(ta.depth_u16(), tb.depth_u16());
        assert_eq!(ta.labels(), tb.labels());
    }
    render_view(&c, &set, 0, &k, &NoiseConfig::default(), &mut tc).unwrap();
    render_view(&a, &set, 0, &k, &NoiseConfig::default(), &mut ta).unwrap();
    assert_ne!(ta.rgb(), tc.rgb());
    // Views of one scene get their own appearance (camera, effects).
    let mut t1 = RenderTarget::for_intrinsics(&k);
    let f0 = render_view(&a, &set, 0, &k, &NoiseConfig::default(), &mut ta).unwrap();
    let f1 = render_view(&a, &set, 1, &k, &NoiseConfig::default(), &mut t1).unwrap();
    assert_ne!(f0.intrinsics, f1.intrinsics);
}

#[test]
fn off_and_basic_options_reproduce_render_view() {
    let set = box_set();
    let s = sample_scene(&set, &SamplerConfig::default(), 7).unwrap();
    assert_eq!((s.randomize, s.depth_sensor), (Randomize::Off, DepthSensor::Basic));
    let k = k_quarter();
    let (mut a, mut b) = (RenderTarget::for_intrinsics(&k), RenderTarget::for_intrinsics(&k));
    let fa = render_view(&s, &set, 0, &k, &NoiseConfig::default(), &mut a).unwrap();
    let opts = ViewOptions { intrinsics: k, depth_sensor: DepthSensor::Basic, randomize: Randomize::Off };
    assert_eq!(opts, ViewOptions::for_scene(&s, &k));
    let fb = render_view_with(&s, &set, 0, &opts, &mut b).unwrap();
    assert_eq!(fa, fb);
    assert_eq!(a.rgb(), b.rgb());
    assert_eq!(a.depth_u16(), b.depth_u16());
    assert_eq!(fa.intrinsics, k, "no jitter without randomisation");
    // Ideal: exact depth, same picture geometry.
    let mut c = RenderTarget::for_intrinsics(&k);
    render_view_with(&s, &set, 0, &ideal(&k, Randomize::Off), &mut c).unwrap();
    let mut exact = RenderTarget::for_intrinsics(&k);
    render_view(&s, &set, 0, &k, &NoiseConfig::off(), &mut exact).unwrap();
    assert_eq!(c.depth_u16(), exact.depth_u16());
}

#[test]
fn jittered_intrinsics_are_the_ones_used_and_reported() {
    let set = box_set();
    let cfg = SamplerConfig { views: 3, plain_share: 0.0, ..SamplerConfig::training() };
    let k = k_quarter();
    let mut t = RenderTarget::for_intrinsics(&k);
    let mut checked = 0;
    for seed in 0..4 {
        let s = sample_scene(&set, &cfg, 300 + seed).unwrap();
        for view in 0..s.views.len() {
            let truth = render_view_with(&s, &set, view, &ideal(&k, Randomize::Default), &mut t).unwrap();
            let j = truth.intrinsics;
            assert_ne!(j, k);
            assert!((j.fx / k.fx - 1.0).abs() <= 0.05 * 1.0001 && (j.fy / k.fy - 1.0).abs() <= 0.0555);
            assert!((j.cx - k.cx).abs() <= 10.0 && (j.cy - k.cy).abs() <= 10.0);
            assert_eq!((j.width, j.height), (k.width, k.height));
            // Depth back-projected with the reported camera lies on the boxes.
            for o in &truth.objects {
                let m = set.by_class(o.class_id).unwrap();
                let inv = o.pose.inverse();
                for (i, &l) in t.labels().iter().enumerate() {
                    if l != o.instance_label || i % 3 != 0 {
                        continue;
                    }
                    let (u, v) = ((i % k.width as usize) as f64, (i / k.width as usize) as f64);
                    let q = inv * j.back_project(u, v, t.depth_m()[i] as f64);
                    let outside = (0..3).map(|c| (q[c].abs() - m.bbox_max[c]).max(0.0)).fold(0.0, f64::max);
                    assert!(outside < 2e-4, "pixel ({u},{v}) is {outside} m off its box");
                    checked += 1;
                }
            }
        }
    }
    assert!(checked > 500);
}

#[test]
fn distractors_are_background_and_never_in_the_truth() {
    let set = box_set();
    let cfg = SamplerConfig { views: 2, plain_share: 0.0, ..SamplerConfig::training() };
    let k = k_quarter();
    let mut t = RenderTarget::for_intrinsics(&k);
    let mut probe = RenderTarget::for_intrinsics(&k);
    let (mut distractor_px, mut scenes_with) = (0, 0);
    for seed in 0..8 {
        let s = sample_scene(&set, &cfg, 500 + seed).unwrap();
        scenes_with += usize::from(!s.extras.distractors.is_empty());
        for view in 0..s.views.len() {
            let truth = render_view_with(&s, &set, view, &ideal(&k, Randomize::Default), &mut t).unwrap();
            assert_eq!(truth.objects.len(), s.objects.len());
            let labelled = t.labels().iter().filter(|&&l| l != 0).count() as u32;
            assert_eq!(labelled, truth.objects.iter().map(|o| o.visible_pixels).sum::<u32>());
            assert!(t.labels().iter().all(|&l| l as usize <= s.objects.len()));
            // Where a distractor is the nearest surface, the label is 0.
            let mut items = s.render_items(&set, view).unwrap();
            let first = 2 + s.objects.len();
            for item in items[first..].iter_mut() {
                item.instance_label = 999;
            }
            render_scene(&items, &truth.intrinsics, &RenderSettings::default(), &mut probe).unwrap();
            for (i, &l) in probe.labels().iter().enumerate() {
                if l == 999 && t.depth_m()[i] == probe.depth_m()[i] {
                    assert_eq!(t.labels()[i], 0, "distractor pixel labelled");
                    distractor_px += 1;
                }
            }
        }
    }
    assert!(scenes_with >= 4, "distractors in only {scenes_with} of 8 scenes");
    assert!(distractor_px > 200, "distractors visible in only {distractor_px} pixels");
}

#[test]
fn border_occluders_stay_near_the_edge_and_in_front() {
    let set = box_set();
    let s = sample_scene(&set, &SamplerConfig::training(), 77).unwrap();
    let k = k_quarter();
    let cam = s.views[0].camera_from_table;
    let mut rng = Pcg64Mcg::seed_from_u64(3);
    let centroid = s.objects.iter().fold(Vector3::zeros(), |a, o| a + o.table_from_object.translation.vector)
        / s.objects.len() as f64;
    let scene_z = (cam * Point3::from(centroid)).z;
    let mut placed = 0;
    for i in 0..40 {
        let mesh = &s.extras.occluders[i % s.extras.occluders.len()];
        let Some(pose) = distractors::border_occluder_pose(&mut rng, &s, &set, mesh, &k, &cam) else {
            continue;
        };
        placed += 1;
        let c = Point3::from(pose.translation.vector);
        let r = mesh.positions.iter().map(|p| (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt()).fold(0.0f32, f32::max);
        assert!(c.z + r as f64 <= 0.7 * scene_z + 1e-9 && c.z - r as f64 >= 0.05 - 1e-9, "occluder at {} m", c.z);
        let (u, v) = k.project(&c).unwrap();
        // Signed distance of the centre to the nearest border (negative outside).
        let border = u.min(k.width as f64 - 1.0 - u).min(v).min(k.height as f64 - 1.0 - v);
        let rho = k.fx * r as f64 / c.z;
        // It reaches 5–30 % into the image from that border.
        let reach = border + rho;
        assert!(reach >= 0.04 * k.height as f64 && reach <= 0.31 * k.width as f64, "reach {reach} px");
    }
    assert!(placed > 30, "placed {placed} of 40");
}

#[test]
fn copies_of_a_class_get_their_own_labels_and_touch_in_pairs_and_heaps() {
    let set = box_set();
    let cfg = SamplerConfig {
        min_objects: 2,
        max_objects: 3,
        instances_per_class: (1, 2),
        pair_probability: 1.0,
        heap_probability: 1.0,
        ..SamplerConfig::default()
    };
    let k = k_quarter();
    let mut t = RenderTarget::for_intrinsics(&k);
    let (mut heaps, mut stacked, mut pairs) = (0, 0, 0);
    for seed in 0..12 {
        let s = sample_scene(&set, &cfg, 40 + seed).unwrap();
        for (i, o) in s.objects.iter().enumerate() {
            assert_eq!(o.instance_label as usize, i + 1);
        }
        // Group copies by class.
        let mut by_class: std::collections::BTreeMap<u16, Vec<&PlacedObject>> = Default::default();
        for o in &s.objects {
            by_class.entry(o.class_id).or_default().push(o);
        }
        let corners = |o: &PlacedObject| -> Vec<Point3<f64>> {
            let m = set.by_class(o.class_id).unwrap();
            (0..8)
                .map(|c| {
                    o.table_from_object
                        * Point3::new(
                            if c & 1 == 0 { m.bbox_min.x } else { m.bbox_max.x },
                            if c & 2 == 0 { m.bbox_min.y } else { m.bbox_max.y },
                            if c & 4 == 0 { m.bbox_min.z } else { m.bbox_max.z },
                        )
                })
                .collect()
        };
        // No box corner inside another box (exact for boxes, all layers).
        for a in &s.objects {
            for b in &s.objects {
                if a.instance_label == b.instance_label {
                    continue;
                }
                let mb = set.by_class(b.class_id).unwrap();
                let inv = b.table_from_object.inverse();
                for p in corners(a) {
                    let q = inv * p;
                    assert!(!(0..3).all(|c| q[c].abs() < mb.bbox_max[c] - 1e-6), "seed {seed}: copies interpenetrate");
                }
                // Nothing floats below the table.
                assert!(corners(a).iter().all(|p| p.z > -1e-6));
            }
        }
        // Heaps: every copy lies within 0.5 mm (footprint gap) of another copy.
        for copies in by_class.values() {
            if copies.len() >= 4 {
                heaps += 1;
                stacked += copies
                    .iter()
                    .filter(|o| corners(o).iter().map(|p| p.z).fold(f64::INFINITY, f64::min) > 1e-4)
                    .count();
            }
            if copies.len() == 2 {
                pairs += 1;
            }
        }
        let truth = render_view_with(&s, &set, 0, &ideal(&k, Randomize::Off), &mut t).unwrap();
        assert_eq!(truth.objects.len(), s.objects.len());
        for o in &truth.objects {
            let count = t.labels().iter().filter(|&&l| l == o.instance_label).count() as u32;
            assert_eq!(count, o.visible_pixels);
        }
        let distinct: std::collections::BTreeSet<u16> = t.labels().iter().copied().filter(|&l| l != 0).collect();
        assert!(distinct.len() >= 3, "seed {seed}: only {} instances visible", distinct.len());
    }
    assert!(heaps >= 10, "{heaps} heaps");
    assert!(stacked >= 3, "{stacked} copies lying on top of others");
    assert!(pairs >= 6, "{pairs} pairs");
}

#[test]
fn pair_and_heap_copies_touch() {
    let set = box_set();
    let rests: Vec<Vec<placement::RestPose>> = set.objects.iter().map(placement::rest_poses).collect();
    let cfg = SamplerConfig { min_objects: 1, max_objects: 1, pair_probability: 1.0, ..SamplerConfig::default() };
    let footprint = |o: &PlacedObject| {
        let m = set.by_class(o.class_id).unwrap();
        let rest = rests[o.class_id as usize - 1].iter().find(|r| {
            let q = o.table_from_object.rotation * r.rotation.inverse();
            // The rest whose rotation differs from the pose by a yaw only.
            (q * nalgebra::Vector3::z() - nalgebra::Vector3::z()).norm() < 1e-6
        });
        let _ = m;
        let rest = rest.unwrap();
        let q = o.table_from_object.rotation * rest.rotation.inverse();
        let yaw = q.euler_angles().2;
        placement::Footprint::of(rest, yaw, o.table_from_object.translation.vector.xy())
    };
    for seed in 0..10 {
        let s = sample_scene(&set, &cfg, 900 + seed).unwrap();
        assert_eq!(s.objects.len(), 2, "seed {seed}: a pair is two copies");
        let (a, b) = (footprint(&s.objects[0]), footprint(&s.objects[1]));
        assert!(!a.overlaps(&b, 0.0), "seed {seed}: pair overlaps");
        assert!(a.overlaps(&b, 0.0031), "seed {seed}: pair more than 3 mm apart");
    }
    let heap = SamplerConfig { min_objects: 1, max_objects: 1, heap_probability: 1.0, ..SamplerConfig::default() };
    for seed in 0..10 {
        let s = sample_scene(&set, &heap, 950 + seed).unwrap();
        assert!((4..=8).contains(&s.objects.len()), "seed {seed}: heap of {}", s.objects.len());
        let base: Vec<placement::Footprint> = s
            .objects
            .iter()
            .filter(|o| {
                let m = set.by_class(o.class_id).unwrap();
                let lowest = (0..8)
                    .map(|c| {
                        (o.table_from_object
                            * Point3::new(
                                if c & 1 == 0 { m.bbox_min.x } else { m.bbox_max.x },
                                if c & 2 == 0 { m.bbox_min.y } else { m.bbox_max.y },
                                if c & 4 == 0 { m.bbox_min.z } else { m.bbox_max.z },
                            ))
                        .z
                    })
                    .fold(f64::INFINITY, f64::min);
                lowest.abs() < 1e-6
            })
            .map(footprint)
            .collect();
        assert!(base.len() >= 2);
        for (i, a) in base.iter().enumerate() {
            let touching = base.iter().enumerate().any(|(j, b)| i != j && a.overlaps(b, 0.0005));
            assert!(touching, "seed {seed}: heap copy {i} touches no other copy");
        }
    }
}

#[test]
fn training_cameras_span_grazing_to_top_down_and_cut_objects_at_edges() {
    let set = box_set();
    let cfg = SamplerConfig { views: 4, plain_share: 0.0, ..SamplerConfig::training() };
    let k = cfg.intrinsics;
    let (mut grazing, mut top_down, mut near, mut far, mut cut, mut frames) = (0, 0, 0, 0, 0, 0);
    for seed in 0..30 {
        let s = sample_scene(&set, &cfg, 1200 + seed).unwrap();
        let centroid = s.objects.iter().fold(Vector3::zeros(), |a, o| a + o.table_from_object.translation.vector)
            / s.objects.len() as f64;
        for v in &s.views {
            frames += 1;
            let eye = v.camera_from_table.inverse() * Point3::origin();
            let d = eye - Point3::new(centroid.x, centroid.y, 0.05);
            let elev = (d.z / d.norm()).asin().to_degrees();
            assert!(d.norm() < 1.5 + 0.2 && d.norm() > 0.3 - 0.15, "distance {}", d.norm());
            grazing += usize::from(elev < 15.0);
            top_down += usize::from(elev > 80.0);
            near += usize::from(d.norm() < 0.5);
            far += usize::from(d.norm() > 1.2);
            // Cameras keep clear of the objects.
            for o in &s.objects {
                let m = set.by_class(o.class_id).unwrap();
                assert!((eye - Point3::from(o.table_from_object.translation.vector)).norm() > 0.5 * m.diameter);
            }
            let poses: Vec<Pose> = s.objects.iter().map(|o| v.camera_from_table * o.table_from_object).collect();
            let at_edge = poses.iter().any(|p| {
                let c = Point3::from(p.translation.vector);
                k.project(&c).is_some_and(|(u, v)| {
                    u.min(k.width as f64 - u).min(v).min(k.height as f64 - v) < 0.1 * k.width as f64
                })
            });
            cut += usize::from(at_edge);
        }
    }
    assert!(grazing > 3 && top_down > 3, "grazing {grazing}, top-down {top_down} of {frames}");
    assert!(near > 3 && far > 3, "near {near}, far {far}");
    assert!(cut * 5 > frames, "objects at the image edge in only {cut} of {frames} views");
}

#[test]
fn plain_share_draws_that_share_of_scenes_in_the_original_domain() {
    let set = box_set();
    let mixed = SamplerConfig { plain_share: 0.25, ..SamplerConfig::training() };
    let all_random = SamplerConfig { plain_share: 0.0, ..SamplerConfig::training() };
    let plain_cfg = SamplerConfig { randomize: Randomize::Off, depth_sensor: DepthSensor::Basic, ..mixed.clone() };
    let mut plain = 0;
    for seed in 0..200u64 {
        let s = sample_scene(&set, &mixed, 4000 + seed).unwrap();
        if s.randomize == Randomize::Off {
            plain += 1;
            assert_eq!(s.depth_sensor, DepthSensor::Basic);
            assert!(s.extras.distractors.is_empty());
            // Exactly the scene the un-randomised sampler draws for this seed.
            let p = sample_scene(&set, &plain_cfg, 4000 + seed).unwrap();
            assert_eq!((s.objects, s.views), (p.objects, p.views));
        } else {
            // Scenes not chosen are unchanged by the share.
            let r = sample_scene(&set, &all_random, 4000 + seed).unwrap();
            assert_eq!((s.objects, s.views, s.lighting), (r.objects, r.views, r.lighting));
            assert_eq!(s.depth_sensor, DepthSensor::StructuredLight);
        }
    }
    assert!((35..=65).contains(&plain), "{plain} of 200 scenes plain at share 0.25");
    assert!(matches!(
        SamplerConfig { plain_share: 1.5, ..SamplerConfig::training() }.validate(),
        Err(SamplerError::InvalidConfig(_))
    ));
}
