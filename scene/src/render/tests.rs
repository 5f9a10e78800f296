//! Renderer tests on hand-built meshes (planes, boxes) with analytic answers.

use super::*;
use crate::sampler::backdrop::{box_mesh, plain_material, quad_mesh, textured_material};
use crate::{Intrinsics, Mesh, Pose, Texture};
use nalgebra::{Point3, Translation3, UnitQuaternion, Vector3};

fn k_small() -> Intrinsics {
    Intrinsics { fx: 500.0, fy: 510.0, cx: 159.3, cy: 121.7, width: 320, height: 240 }
}

fn pose(axis_angle: [f64; 3], t: [f64; 3]) -> Pose {
    Pose::from_parts(
        Translation3::new(t[0], t[1], t[2]),
        UnitQuaternion::from_scaled_axis(Vector3::new(axis_angle[0], axis_angle[1], axis_angle[2])),
    )
}

fn grey() -> crate::Material {
    plain_material("grey", [0.5; 3])
}

fn render(items: &[RenderItem<'_>], k: &Intrinsics) -> RenderTarget {
    let mut t = RenderTarget::for_intrinsics(k);
    render_scene(items, k, &RenderSettings::default(), &mut t).unwrap();
    t
}

/// Distance from an object-frame point to the surface of a centred box.
fn box_surface_distance(p: &Point3<f64>, half: [f64; 3]) -> f64 {
    let q = Vector3::new(p.x.abs() - half[0], p.y.abs() - half[1], p.z.abs() - half[2]);
    let outside = Vector3::new(q.x.max(0.0), q.y.max(0.0), q.z.max(0.0)).norm();
    let inside = q.x.max(q.y).max(q.z).min(0.0);
    (outside + inside).abs()
}

#[test]
fn tilted_plane_depth_matches_analytic_depth_within_one_u16_unit() {
    let k = k_small();
    let mesh = quad_mesh(0.3, 0.3, 1.0, grey());
    let p = pose([0.5, -0.35, 0.1], [0.02, -0.01, 1.0]);
    let t = render(&[RenderItem { mesh: &mesh, pose: p, instance_label: 3, shadow_mesh: None }], &k);
    let n = p.rotation * Vector3::z();
    let d = n.dot(&p.translation.vector);
    let inv = p.inverse();
    let (mut covered, mut holes) = (0, 0);
    for v in 0..k.height {
        for u in 0..k.width {
            let i = (v * k.width + u) as usize;
            let ray = Vector3::new((u as f64 - k.cx) / k.fx, (v as f64 - k.cy) / k.fy, 1.0);
            let z = d / n.dot(&ray);
            let hit = inv * Point3::from(ray * z);
            let inside = hit.x.abs() < 0.3 - 0.002 && hit.y.abs() < 0.3 - 0.002;
            if t.depth_m()[i] > 0.0 {
                covered += 1;
                let expect = depth_to_u16(z) as i32;
                assert!(
                    (t.depth_u16()[i] as i32 - expect).abs() <= 1,
                    "pixel ({u},{v}): {} vs {expect}",
                    t.depth_u16()[i]
                );
                assert!((t.depth_m()[i] as f64 - z).abs() < 2e-5);
                assert_eq!(t.labels()[i], 3);
            } else if inside {
                holes += 1;
            }
        }
    }
    assert!(covered > 10_000, "plane covers {covered} pixels");
    assert_eq!(holes, 0, "pixels inside the plane left uncovered");
    assert_eq!(t.coverage()[0].alone_pixels, covered);
    assert_eq!(t.coverage()[0].visible_pixels, covered);
}

#[test]
fn back_projected_box_depth_lies_on_the_posed_box_surface() {
    let k = k_small();
    let half = [0.04f32, 0.03, 0.05];
    let mesh = box_mesh(half, 1.0, grey());
    let p = pose([0.3, 0.5, 0.2], [0.01, 0.02, 0.6]);
    let t = render(&[RenderItem { mesh: &mesh, pose: p, instance_label: 7, shadow_mesh: None }], &k);
    let inv = p.inverse();
    let (mut n, mut sum, mut max) = (0usize, 0.0f64, 0.0f64);
    for v in 0..k.height {
        for u in 0..k.width {
            let i = (v * k.width + u) as usize;
            if t.labels()[i] != 7 {
                assert_eq!(t.depth_m()[i], 0.0);
                continue;
            }
            let z = t.depth_m()[i] as f64;
            assert!(z > 0.0, "label pixel without depth");
            let q = inv * k.back_project(u as f64, v as f64, z);
            let dist = box_surface_distance(&q, half.map(|h| h as f64));
            sum += dist;
            max = max.max(dist);
            n += 1;
        }
    }
    assert!(n > 1000, "box covers {n} pixels");
    let mean = sum / n as f64;
    assert!(mean < 1e-3, "mean distance {mean} m");
    assert!(max < 1e-4, "max distance {max} m");
}

#[test]
fn visible_fraction_is_one_alone_and_drops_behind_an_occluder() {
    let k = k_small();
    let mesh = box_mesh([0.05, 0.05, 0.05], 1.0, grey());
    let back =
        RenderItem { mesh: &mesh, pose: pose([0.2, 0.3, 0.0], [0.0, 0.0, 0.8]), instance_label: 1, shadow_mesh: None };
    let front =
        RenderItem { mesh: &mesh, pose: pose([0.0, 0.4, 0.1], [0.06, 0.0, 0.6]), instance_label: 2, shadow_mesh: None };
    let alone = render(&[back], &k);
    let a = alone.coverage()[0];
    assert_eq!(a.visible_pixels, a.alone_pixels);
    assert_eq!(a.visible_fraction(), 1.0);
    let bbox = a.bbox.unwrap();
    assert!(bbox.width() > 20 && bbox.height() > 20);

    let both = render(&[back, front], &k);
    let (b, f) = (both.coverage()[0], both.coverage()[1]);
    assert_eq!(b.alone_pixels, a.alone_pixels, "alone count must not depend on occluders");
    assert!(b.visible_fraction() > 0.05 && b.visible_fraction() < 0.9, "fraction {}", b.visible_fraction());
    assert_eq!(f.visible_fraction(), 1.0);
    let labelled = |l: u16| both.labels().iter().filter(|&&x| x == l).count() as u32;
    assert_eq!(labelled(1), b.visible_pixels);
    assert_eq!(labelled(2), f.visible_pixels);
    // Order of the items does not change the picture.
    let swapped = render(&[front, back], &k);
    assert_eq!(swapped.labels(), both.labels());
    assert_eq!(swapped.depth_u16(), both.depth_u16());
}

#[test]
fn texture_quadrants_appear_where_expected() {
    let k = k_small();
    // 2x2 texture, top row first: red, green / blue, white.
    let tex = Texture { width: 2, height: 2, rgb: vec![255, 0, 0, 0, 255, 0, 0, 0, 255, 255, 255, 255] };
    // A quad facing the camera: object +x → image right, object +y → image up.
    let mesh = quad_mesh(0.2, 0.2, 1.0, textured_material("quadrants", tex));
    let p = pose([std::f64::consts::PI, 0.0, 0.0], [0.0, 0.0, 1.0]);
    let settings = RenderSettings {
        lighting: Lighting { ambient: [1.0; 3], lights: vec![], points: vec![] },
        texture_filter: TextureFilter::Nearest,
        ..Default::default()
    };
    let mut t = RenderTarget::for_intrinsics(&k);
    render_scene(&[RenderItem { mesh: &mesh, pose: p, instance_label: 1, shadow_mesh: None }], &k, &settings, &mut t)
        .unwrap();
    let at = |x: f64, y: f64| {
        // Object-frame point → pixel.
        let c = p * Point3::new(x, y, 0.0);
        let (u, v) = k.project(&c).unwrap();
        let i = (v.round() as usize * k.width as usize + u.round() as usize) * 3;
        [t.rgb()[i], t.rgb()[i + 1], t.rgb()[i + 2]]
    };
    assert_eq!(at(-0.1, 0.1), [255, 0, 0], "top left");
    assert_eq!(at(0.1, 0.1), [0, 255, 0], "top right");
    assert_eq!(at(-0.1, -0.1), [0, 0, 255], "bottom left");
    assert_eq!(at(0.1, -0.1), [255, 255, 255], "bottom right");
    // And the top-left quadrant is at the top left of the image.
    let (u, v) = k.project(&(p * Point3::new(-0.1, 0.1, 0.0))).unwrap();
    assert!(u < k.cx && v < k.cy);
}

#[test]
fn perspective_correct_vertex_colours() {
    let k = k_small();
    // A strongly slanted quad, black at its near edge and white at its far edge.
    let mut mesh = quad_mesh(0.2, 0.2, 1.0, grey());
    mesh.colors = vec![[0, 0, 0], [0, 0, 0], [255, 255, 255], [255, 255, 255]];
    mesh.uvs.clear();
    let p = pose([-1.1, 0.0, 0.0], [0.0, 0.0, 0.7]);
    let settings = RenderSettings {
        lighting: Lighting { ambient: [1.0; 3], lights: vec![], points: vec![] },
        ..Default::default()
    };
    let mut t = RenderTarget::for_intrinsics(&k);
    render_scene(&[RenderItem { mesh: &mesh, pose: p, instance_label: 1, shadow_mesh: None }], &k, &settings, &mut t)
        .unwrap();
    // The 3D midline (y = 0) must be mid grey in linear light: sRGB 188.
    let c = p * Point3::new(0.0, 0.0, 0.0);
    let (u, v) = k.project(&c).unwrap();
    let i = (v.round() as usize * k.width as usize + u.round() as usize) * 3;
    let g = t.rgb()[i] as i32;
    assert!((g - 188).abs() <= 6, "midline grey {g}");
}

#[test]
fn geometry_behind_the_near_plane_is_clipped() {
    let k = k_small();
    // A 10 m floor 0.3 m below the camera (y down), passing under and behind it.
    let mesh = quad_mesh(5.0, 5.0, 1.0, grey());
    let p = pose([std::f64::consts::FRAC_PI_2, 0.0, 0.0], [0.0, 0.3, 0.0]);
    let n = p.rotation * Vector3::z();
    assert!((n - Vector3::new(0.0, -1.0, 0.0)).norm() < 1e-9);
    let t = render(&[RenderItem { mesh: &mesh, pose: p, instance_label: 1, shadow_mesh: None }], &k);
    let mut covered = 0;
    for v in 0..k.height {
        for u in 0..k.width {
            let i = (v * k.width + u) as usize;
            let ry = (v as f64 - k.cy) / k.fy;
            let z = if ry > 0.0 { 0.3 / ry } else { f64::INFINITY };
            let z_m = t.depth_m()[i] as f64;
            if z_m > 0.0 {
                covered += 1;
                assert!(z_m >= DEFAULT_Z_NEAR_M);
                assert!((t.depth_u16()[i] as i32 - depth_to_u16(z) as i32).abs() <= 1);
            } else {
                // Uncovered only above the horizon or beyond the 5 m edge.
                assert!(z > 4.9, "row {v} should see the floor at {z} m");
            }
        }
    }
    assert!(covered > 10_000);
}

#[test]
fn bad_input_is_an_error_not_a_panic() {
    let k = k_small();
    let mut t = RenderTarget::new(10, 10);
    let mesh = box_mesh([0.1; 3], 1.0, grey());
    let item = RenderItem { mesh: &mesh, pose: pose([0.0; 3], [0.0, 0.0, 1.0]), instance_label: 1, shadow_mesh: None };
    assert!(matches!(
        render_scene(&[item], &k, &RenderSettings::default(), &mut t),
        Err(RenderError::SizeMismatch { .. })
    ));
    let mut t = RenderTarget::for_intrinsics(&k);
    let mut bad = mesh.clone();
    bad.triangles.push([0, 1, 999]);
    let r = render_scene(&[RenderItem { mesh: &bad, ..item }], &k, &RenderSettings::default(), &mut t);
    assert!(matches!(r, Err(RenderError::BadMesh { item: 0, .. })));
    let mut bad = mesh.clone();
    bad.normals.pop();
    assert!(render_scene(&[RenderItem { mesh: &bad, ..item }], &k, &RenderSettings::default(), &mut t).is_err());
    let mut nan_pose = item;
    nan_pose.pose.translation.vector.x = f64::NAN;
    assert_eq!(
        render_scene(&[nan_pose], &k, &RenderSettings::default(), &mut t),
        Err(RenderError::BadPose { item: 0 })
    );
    let settings = RenderSettings { z_near: 0.0, ..Default::default() };
    assert!(matches!(render_scene(&[item], &k, &settings, &mut t), Err(RenderError::BadZNear(_))));
    // Non-finite vertices are skipped, not drawn.
    let mut odd = mesh.clone();
    odd.positions[0] = [f32::NAN, 0.0, 0.0];
    render_scene(&[RenderItem { mesh: &odd, ..item }], &k, &RenderSettings::default(), &mut t).unwrap();
    // An empty mesh renders nothing.
    let empty = Mesh::default();
    render_scene(&[RenderItem { mesh: &empty, ..item }], &k, &RenderSettings::default(), &mut t).unwrap();
    assert!(t.labels().iter().all(|&l| l == 0));
    assert_eq!(t.coverage()[0].visible_fraction(), 0.0);
}

/// A camera-facing plane at 1 m, optionally noisy.
fn noisy_plane(cfg: &NoiseConfig, seed: u64) -> RenderTarget {
    let k = k_small();
    let mesh = quad_mesh(2.0, 2.0, 1.0, grey());
    let mut t = render(
        &[RenderItem { mesh: &mesh, pose: pose([0.0; 3], [0.0, 0.0, 1.0]), instance_label: 1, shadow_mesh: None }],
        &k,
    );
    apply_noise(&mut t, cfg, seed);
    t
}

#[test]
fn depth_noise_has_the_model_sigma() {
    let cfg = NoiseConfig {
        depth_step_per_m: 0.0,
        random_dropout_prob: 0.0,
        edge_dropout_prob: 0.0,
        ..NoiseConfig::default()
    };
    let t = noisy_plane(&cfg, 11);
    let d: Vec<f64> = t.depth_m().iter().filter(|&&z| z > 0.0).map(|&z| z as f64 - 1.0).collect();
    assert_eq!(d.len(), t.pixel_count());
    let mean = d.iter().sum::<f64>() / d.len() as f64;
    let sd = (d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / d.len() as f64).sqrt();
    let sigma = cfg.depth_sigma(1.0);
    assert!((sigma - 0.001884).abs() < 1e-6);
    assert!((sd / sigma - 1.0).abs() < 0.05, "sd {sd} vs sigma {sigma}");
    assert!(mean.abs() < 5e-5, "bias {mean}");
    // u16 follows the noisy metres.
    for (z, zu) in t.depth_m().iter().zip(t.depth_u16()) {
        assert_eq!(*zu, depth_to_u16(*z as f64));
    }
}

#[test]
fn noise_is_deterministic_switchable_and_quantised() {
    let a = noisy_plane(&NoiseConfig::default(), 5);
    let b = noisy_plane(&NoiseConfig::default(), 5);
    let c = noisy_plane(&NoiseConfig::default(), 6);
    assert_eq!(a.depth_u16(), b.depth_u16());
    assert_eq!(a.rgb(), b.rgb());
    assert_ne!(a.depth_u16(), c.depth_u16());
    let off = noisy_plane(&NoiseConfig::off(), 5);
    assert!(off.depth_u16().iter().all(|&z| z == 10_000));
    // Quantisation: every valid depth has 1/z on the disparity grid.
    let step = NoiseConfig::default().depth_step_per_m;
    let valid: Vec<f32> = a.depth_m().iter().copied().filter(|&z| z > 0.0).collect();
    assert!(valid.len() > a.pixel_count() * 9 / 10, "too much dropout");
    for z in valid {
        let q = 1.0 / (z as f64 * step);
        assert!((q - q.round()).abs() < 1e-3, "depth {z} off the quantisation grid");
    }
}

#[test]
fn noise_drops_depth_at_discontinuities_and_grazing_angles() {
    let k = k_small();
    let floor = quad_mesh(2.0, 2.0, 1.0, grey());
    // A plane turned 80° about x: incidence angles span about 67°..93°.
    let graze = pose([80f64.to_radians(), 0.0, 0.0], [0.0, 0.0, 1.5]);
    let mut t = render(&[RenderItem { mesh: &floor, pose: graze, instance_label: 1, shadow_mesh: None }], &k);
    let truth = t.depth_m().to_vec();
    let cfg = NoiseConfig { edge_dropout_prob: 0.0, random_dropout_prob: 0.0, ..NoiseConfig::default() };
    apply_noise(&mut t, &cfg, 1);
    let n = graze.rotation * Vector3::z();
    let (mut dropped, mut kept) = (0, 0);
    for v in 0..k.height {
        for u in 0..k.width {
            let i = (v * k.width + u) as usize;
            if truth[i] == 0.0 {
                continue;
            }
            let ray = Vector3::new((u as f64 - k.cx) / k.fx, (v as f64 - k.cy) / k.fy, 1.0).normalize();
            let angle = n.dot(&ray).abs().acos().to_degrees();
            let has_depth = t.depth_m()[i] > 0.0;
            if angle > 78.5 {
                assert!(!has_depth, "pixel ({u},{v}) at {angle:.1}° kept depth");
                dropped += 1;
            } else if angle < 77.5 {
                assert!(has_depth, "pixel ({u},{v}) at {angle:.1}° lost depth");
                kept += 1;
            }
        }
    }
    assert!(dropped > 1000 && kept > 1000, "dropped {dropped}, kept {kept}");

    let wall = RenderItem { mesh: &floor, pose: pose([0.0; 3], [0.0, 0.0, 1.2]), instance_label: 0, shadow_mesh: None };
    let cube = box_mesh([0.05; 3], 1.0, grey());
    let item = RenderItem { mesh: &cube, pose: pose([0.0; 3], [0.0, 0.0, 0.7]), instance_label: 1, shadow_mesh: None };
    let mut t = render(&[wall, item], &k);
    apply_noise(&mut t, &NoiseConfig { grazing_angle_deg: 90.0, ..NoiseConfig::default() }, 2);
    // The cube's silhouette: label changes between horizontal neighbours.
    let (mut edge, mut edge_missing) = (0, 0);
    for i in 1..t.pixel_count() {
        if t.labels()[i] != t.labels()[i - 1] {
            edge += 1;
            if t.depth_m()[i] == 0.0 || t.depth_m()[i - 1] == 0.0 {
                edge_missing += 1;
            }
        }
    }
    assert!(edge > 20);
    assert!(edge_missing as f64 > 0.6 * edge as f64, "{edge_missing} of {edge} edges lost depth");
}

/// Plain white light from `dir` (towards the light, camera frame) with some ambient.
fn one_light(dir: [f64; 3], ambient: f32, intensity: f32) -> Lighting {
    Lighting {
        ambient: [ambient; 3],
        lights: vec![DirectionalLight { direction: Vector3::from(dir).normalize(), color: [intensity; 3] }],
        points: vec![],
    }
}

/// Does the ray from `p` along `d` hit the axis-aligned box [lo, hi]?
fn ray_hits_box(p: &Vector3<f64>, d: &Vector3<f64>, lo: [f64; 3], hi: [f64; 3]) -> bool {
    let (mut t0, mut t1) = (1e-9, f64::INFINITY);
    for a in 0..3 {
        if d[a].abs() < 1e-15 {
            if p[a] < lo[a] || p[a] > hi[a] {
                return false;
            }
            continue;
        }
        let (mut ta, mut tb) = ((lo[a] - p[a]) / d[a], (hi[a] - p[a]) / d[a]);
        if ta > tb {
            std::mem::swap(&mut ta, &mut tb);
        }
        t0 = f64::max(t0, ta);
        t1 = f64::min(t1, tb);
    }
    t0 <= t1
}

#[test]
fn box_on_a_plane_casts_the_geometric_shadow() {
    let k = k_small();
    // A plane 1 m away facing the camera, a 10 cm cube standing on it
    // (camera frame: the cube spans z 0.9..1.0), lit from the left and front.
    let plane = quad_mesh(0.6, 0.6, 1.0, grey());
    let cube = box_mesh([0.05; 3], 1.0, grey());
    let plane_pose = pose([std::f64::consts::PI, 0.0, 0.0], [0.0, 0.0, 1.0]);
    let cube_pose = pose([0.0; 3], [-0.05, 0.02, 0.95]);
    let items = [
        RenderItem { mesh: &plane, pose: plane_pose, instance_label: 0, shadow_mesh: None },
        RenderItem { mesh: &cube, pose: cube_pose, instance_label: 1, shadow_mesh: None },
    ];
    let light = Vector3::new(-0.8, 0.25, -0.55).normalize();
    let settings = RenderSettings {
        lighting: one_light([light.x, light.y, light.z], 0.2, 0.8),
        shadows: ShadowSettings { enabled: true, ..Default::default() },
        ..Default::default()
    };
    let mut t = RenderTarget::for_intrinsics(&k);
    render_scene(&items, &k, &settings, &mut t).unwrap();
    // Without shadows the plane is uniformly lit: the reference colours.
    let mut unshadowed = RenderTarget::for_intrinsics(&k);
    let no_shadow = RenderSettings { shadows: ShadowSettings::default(), ..settings.clone() };
    render_scene(&items, &k, &no_shadow, &mut unshadowed).unwrap();
    let (lo, hi) = ([-0.1, -0.03, 0.9], [0.0, 0.07, 1.0]);
    let (mut shadow_px, mut lit_px, mut wrong) = (0, 0, Vec::new());
    for v in 0..k.height {
        for u in 0..k.width {
            let i = (v * k.width + u) as usize;
            if t.labels()[i] != 0 || t.depth_m()[i] == 0.0 {
                continue;
            }
            let p = k.back_project(u as f64, v as f64, t.depth_m()[i] as f64).coords;
            let shadowed = ray_hits_box(&p, &light, lo, hi);
            // Skip the penumbra: pixels whose neighbours (±2 px) disagree.
            let near_edge = [(-2.0, 0.0), (2.0, 0.0), (0.0, -2.0), (0.0, 2.0)].iter().any(|(du, dv)| {
                let q = k.back_project(u as f64 + du, v as f64 + dv, 1.0).coords;
                ray_hits_box(&q, &light, lo, hi) != shadowed
            });
            if near_edge {
                continue;
            }
            let (g, g_ref) = (t.rgb()[i * 3] as i32, unshadowed.rgb()[i * 3] as i32);
            if shadowed {
                shadow_px += 1;
                // Ambient only: sRGB of 0.5 * 0.2 = 0.1 linear is 89.
                if (g - 89).abs() > 3 {
                    wrong.push((u, v, g, "shadow"));
                }
            } else {
                lit_px += 1;
                if (g - g_ref).abs() > 2 {
                    wrong.push((u, v, g, "lit"));
                }
            }
        }
    }
    assert!(shadow_px > 800, "shadow footprint too small: {shadow_px} px");
    assert!(lit_px > 20_000, "{lit_px} lit px");
    assert!(
        wrong.len() * 200 < shadow_px + lit_px,
        "{} of {} pixels disagree with the geometric shadow, e.g. {:?}",
        wrong.len(),
        shadow_px + lit_px,
        &wrong[..wrong.len().min(8)]
    );
    // The shadow falls on the side away from the light (+x, right of the cube).
    let cube_box = t.coverage()[1].bbox.unwrap();
    let dark_right = (cube_box.u_max + 3..k.width).filter(|&u| {
        let i = ((cube_box.v_min + cube_box.v_max) / 2 * k.width + u) as usize;
        t.rgb()[i * 3] < 100
    });
    assert!(dark_right.count() > 10, "no shadow to the right of the cube");
}

/// `plane` 1 m in front of the camera, facing it: a floor that receives shadows.
fn floor_facing_camera(plane: &Mesh) -> RenderItem<'_> {
    RenderItem {
        mesh: plane,
        pose: pose([std::f64::consts::PI, 0.0, 0.0], [0.0, 0.0, 1.0]),
        instance_label: 0,
        shadow_mesh: None,
    }
}

#[test]
fn shadows_are_off_by_default_and_items_before_first_caster_cast_none() {
    let k = k_small();
    let plane = quad_mesh(0.6, 0.6, 1.0, grey());
    let cube = box_mesh([0.05; 3], 1.0, grey());
    let items = [
        floor_facing_camera(&plane),
        RenderItem { mesh: &cube, pose: pose([0.0; 3], [-0.05, 0.02, 0.95]), instance_label: 1, shadow_mesh: None },
    ];
    assert!(!RenderSettings::default().shadows.enabled);
    let lighting = one_light([-0.8, 0.25, -0.55], 0.2, 0.8);
    let render_with = |shadows: ShadowSettings| {
        // Exposure 1.01 forces the per-pixel mode when shadows are off too.
        let camera_response = CameraResponse { exposure: 1.0001, ..Default::default() };
        let s = RenderSettings { lighting: lighting.clone(), shadows, camera_response, ..Default::default() };
        let mut t = RenderTarget::for_intrinsics(&k);
        render_scene(&items, &k, &s, &mut t).unwrap();
        t
    };
    let none = render_with(ShadowSettings::default());
    let cube_not_casting =
        render_with(ShadowSettings { enabled: true, first_caster: 0, end_caster: 1, ..Default::default() });
    let all = render_with(ShadowSettings { enabled: true, ..Default::default() });
    let dark =
        |t: &RenderTarget| t.rgb().chunks_exact(3).zip(t.labels()).filter(|(c, l)| **l == 0 && c[0] < 100).count();
    assert_eq!(dark(&none), 0);
    assert_eq!(dark(&cube_not_casting), 0, "the plane alone must not shadow itself");
    assert!(dark(&all) > 500);
}

#[test]
fn a_coarse_shadow_mesh_casts_the_shadow_of_the_fine_one_and_is_not_drawn() {
    let k = k_small();
    let plane = quad_mesh(0.6, 0.6, 1.0, grey());
    let mut fine = crate::shadow_mesh::sphere(150, 0.04);
    fine.materials = vec![grey()];
    let coarse = crate::shadow_mesh::shadow_mesh(&fine, 0.08 / crate::shadow_mesh::CELLS_PER_DIAMETER).unwrap();
    assert!(coarse.triangles.len() * 3 < fine.triangles.len());
    let lighting = one_light([-0.8, 0.25, -0.55], 0.2, 0.8);
    let render_with = |shadow_mesh: Option<&Mesh>| {
        let items = [
            floor_facing_camera(&plane),
            RenderItem { mesh: &fine, pose: pose([0.0; 3], [-0.05, 0.02, 0.9]), instance_label: 1, shadow_mesh },
        ];
        let shadows = ShadowSettings { enabled: true, map_size: 512, ..Default::default() };
        let s = RenderSettings { lighting: lighting.clone(), shadows, ..Default::default() };
        let mut t = RenderTarget::for_intrinsics(&k);
        render_scene(&items, &k, &s, &mut t).unwrap();
        t
    };
    let (a, b) = (render_with(None), render_with(Some(&coarse)));
    // The colour pass draws the fine mesh either way.
    assert_eq!(a.labels(), b.labels());
    assert_eq!(a.depth_u16(), b.depth_u16());
    let dark = |t: &RenderTarget| -> Vec<bool> {
        t.rgb().chunks_exact(3).zip(t.labels()).map(|(c, l)| *l == 0 && c[0] < 100).collect()
    };
    let (da, db) = (dark(&a), dark(&b));
    let shadow = da.iter().filter(|&&d| d).count();
    let differ = da.iter().zip(&db).filter(|(x, y)| x != y).count();
    assert!(shadow > 300, "the sphere casts a shadow on the plane ({shadow} px)");
    assert!(differ * 20 < shadow, "{differ} of {shadow} shadow pixels differ");
    // And it is what the shadow pass draws: moved 6 cm, the shadow moves.
    let mut moved = coarse.clone();
    moved.positions.iter_mut().for_each(|p| p[1] += 0.06);
    let dm = dark(&render_with(Some(&moved)));
    let overlap = da.iter().zip(&dm).filter(|(x, y)| **x && **y).count();
    assert!(overlap * 2 < shadow, "a moved shadow mesh left {overlap} of {shadow} shadow pixels in place");
}

#[test]
fn per_pixel_mode_matches_gouraud_on_flat_faces_and_adds_highlights() {
    let k = k_small();
    let cube = box_mesh([0.08; 3], 1.0, plain_material("c", [0.4, 0.3, 0.2]));
    let items = [RenderItem {
        mesh: &cube,
        pose: pose([0.4, 0.6, 0.1], [0.0, 0.0, 0.8]),
        instance_label: 1,
        shadow_mesh: None,
    }];
    let lighting = one_light([0.3, -0.7, -0.65], 0.3, 0.7);
    let gouraud = RenderSettings { lighting: lighting.clone(), ..Default::default() };
    let mut a = RenderTarget::for_intrinsics(&k);
    render_scene(&items, &k, &gouraud, &mut a).unwrap();
    let lit = RenderSettings { item_shading: vec![ItemShading::default()], ..gouraud.clone() };
    assert!(lit.per_pixel() && !gouraud.per_pixel());
    let mut b = RenderTarget::for_intrinsics(&k);
    render_scene(&items, &k, &lit, &mut b).unwrap();
    let max_diff = a.rgb().iter().zip(b.rgb()).map(|(x, y)| (*x as i32 - *y as i32).abs()).max().unwrap();
    assert!(max_diff <= 1, "flat faces: Gouraud and per-pixel differ by {max_diff}");
    assert_eq!(a.depth_u16(), b.depth_u16());
    assert_eq!(a.labels(), b.labels());
    assert_eq!(a.reflectance(), b.reflectance());

    // A glossy plane facing the camera, light from behind the camera: the
    // highlight sits where the normal bisects light and view (the image centre
    // for a head-on light), and nowhere without specular.
    let plane = quad_mesh(0.5, 0.5, 1.0, grey());
    let items = [RenderItem {
        mesh: &plane,
        pose: pose([std::f64::consts::PI, 0.0, 0.0], [0.0, 0.0, 1.0]),
        instance_label: 1,
        shadow_mesh: None,
    }];
    let glossy = RenderSettings {
        lighting: one_light([0.0, 0.0, -1.0], 0.1, 0.5),
        item_shading: vec![ItemShading { specular: 0.3, shininess: 200.0, ..Default::default() }],
        ..Default::default()
    };
    let mut g = RenderTarget::for_intrinsics(&k);
    render_scene(&items, &k, &glossy, &mut g).unwrap();
    let at = |t: &RenderTarget, u: u32, v: u32| t.rgb()[((v * k.width + u) * 3) as usize];
    let (cu, cv) = (k.cx.round() as u32, k.cy.round() as u32);
    assert!(at(&g, cu, cv) >= 250, "no highlight at the centre: {}", at(&g, cu, cv));
    assert!(at(&g, 5, 5) < 200, "highlight spreads to the corner: {}", at(&g, 5, 5));
    assert!(g.specular()[(cv * k.width + cu) as usize] > 100);
    assert!(g.specular()[(5 * k.width + 5) as usize] < 50);
}

#[test]
fn camera_response_scales_linear_light_and_darkens_corners() {
    let k = k_small();
    let plane = quad_mesh(2.0, 2.0, 1.0, grey());
    let items = [RenderItem {
        mesh: &plane,
        pose: pose([std::f64::consts::PI, 0.0, 0.0], [0.0, 0.0, 1.0]),
        instance_label: 1,
        shadow_mesh: None,
    }];
    let base = RenderSettings {
        lighting: Lighting { ambient: [0.4; 3], lights: vec![], points: vec![] },
        ..Default::default()
    };
    let render_with = |resp: CameraResponse| {
        let mut t = RenderTarget::for_intrinsics(&k);
        render_scene(&items, &k, &RenderSettings { camera_response: resp, ..base.clone() }, &mut t).unwrap();
        t
    };
    // Linear 0.5 * 0.4 = 0.2 → sRGB 124; exposure 2 and red gain 1.5 → 0.4 / 0.6 linear.
    let t = render_with(CameraResponse { exposure: 2.0, white_balance: [1.5, 1.0, 1.0], ..Default::default() });
    let c = &t.rgb()[((120 * k.width + 160) * 3) as usize..][..3];
    assert_eq!(c, &[203, 170, 170]);
    let t = render_with(CameraResponse { vignetting: 0.5, ..Default::default() });
    let centre = t.rgb()[((121 * k.width + 159) * 3) as usize];
    let corner = t.rgb()[0];
    assert!(centre == 124 && corner < 100, "centre {centre}, corner {corner}");
    let t = render_with(CameraResponse { gamma: 2.0, ..Default::default() });
    // Encoded 124/255 = 0.486 → 0.486^(1/2) = 0.697 → 178.
    assert!((t.rgb()[((120 * k.width + 160) * 3) as usize] as i32 - 178).abs() <= 1);
}

#[test]
fn colour_jitter_keeps_grey_and_rotates_hue() {
    let s = ItemShading::default().with_color_jitter(120.0, 1.0, 1.0);
    let m = s.albedo_transform;
    let apply = |c: [f32; 3]| -> [f32; 3] { std::array::from_fn(|i| (0..3).map(|j| m[i][j] * c[j]).sum()) };
    let grey = apply([0.3; 3]);
    assert!(grey.iter().all(|g| (g - 0.3).abs() < 1e-5), "{grey:?}");
    // A 120° turn about the grey axis maps red to green.
    let r = apply([1.0, 0.0, 0.0]);
    assert!((r[1] - 1.0).abs() < 1e-5 && r[0].abs() < 1e-5 && r[2].abs() < 1e-5, "{r:?}");
    let half = ItemShading::default().with_color_jitter(0.0, 0.0, 0.5).albedo_transform;
    let c = (0..3).map(|j| half[0][j] * [0.9, 0.3, 0.0][j]).sum::<f32>();
    assert!((c - 0.2).abs() < 1e-5, "desaturated at half value: {c}");
}

#[test]
fn point_lights_fall_off_with_the_squared_distance() {
    let k = k_small();
    let plane = quad_mesh(2.0, 2.0, 1.0, grey());
    let items = [RenderItem {
        mesh: &plane,
        pose: pose([std::f64::consts::PI, 0.0, 0.0], [0.0, 0.0, 1.0]),
        instance_label: 1,
        shadow_mesh: None,
    }];
    let render_at = |z: f64| {
        let lighting = Lighting {
            ambient: [0.0; 3],
            lights: vec![],
            points: vec![PointLight { position: Point3::new(0.0, 0.0, 1.0 - z), color: [0.4 * (z * z) as f32; 3] }],
        };
        let mut t = RenderTarget::for_intrinsics(&k);
        render_scene(&items, &k, &RenderSettings { lighting, ..Default::default() }, &mut t).unwrap();
        t.rgb()[((122 * k.width + 159) * 3) as usize]
    };
    // Colour scaled by d², so the facing point gets 0.4 · 0.5 = 0.2 linear (124) at any distance.
    assert_eq!(render_at(0.5), 124);
    assert_eq!(render_at(0.8), 124);
}
