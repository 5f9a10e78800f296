//! Depth-sensor model tests: measured statistics on rendered planes and boxes
//! against the documented formulas and geometry.

use super::*;
use crate::render::{
    CameraResponse, DirectionalLight, ItemShading, Lighting, NoiseConfig, RenderItem, RenderSettings, apply_noise,
    render_scene,
};
use crate::sampler::backdrop::{box_mesh, plain_material, quad_mesh};
use crate::{Intrinsics, Mesh, Pose};
use nalgebra::{Translation3, UnitQuaternion, Vector3};

fn k() -> Intrinsics {
    Intrinsics { fx: 500.0, fy: 500.0, cx: 159.5, cy: 119.5, width: 320, height: 240 }
}

fn pose(axis_angle: [f64; 3], t: [f64; 3]) -> Pose {
    Pose::from_parts(
        Translation3::new(t[0], t[1], t[2]),
        UnitQuaternion::from_scaled_axis(Vector3::new(axis_angle[0], axis_angle[1], axis_angle[2])),
    )
}

/// A plane facing the camera at distance `z` with a grey albedo.
fn wall(albedo: f32) -> Mesh {
    quad_mesh(3.0, 3.0, 1.0, plain_material("wall", [albedo; 3]))
}

fn facing(z: f64) -> Pose {
    pose([std::f64::consts::PI, 0.0, 0.0], [0.0, 0.0, z])
}

fn render(items: &[RenderItem<'_>], settings: &RenderSettings) -> RenderTarget {
    let k = k();
    let mut t = RenderTarget::for_intrinsics(&k);
    render_scene(items, &k, settings, &mut t).unwrap();
    t
}

/// Structured light with every effect but the one under test switched off.
fn sl_quiet() -> StructuredLightParams {
    StructuredLightParams {
        subpixel_step_px: 0.0,
        projector_shadows: false,
        edge_hole_prob: 0.0,
        flying_pixel_prob: 0.0,
        lateral_sigma_px: 0.0,
        lateral_angle_px: 0.0,
        random_dropout_prob: 0.0,
        dark_dropout_prob: 0.0,
        specular_dropout_prob: 0.0,
        ..Default::default()
    }
}

fn tof_quiet() -> TofParams {
    TofParams {
        multipath_gain: 0.0,
        edge_mix_prob: 0.0,
        edge_dropout_prob: 0.0,
        random_dropout_prob: 0.0,
        ..Default::default()
    }
}

fn std_dev(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    (mean, (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt())
}

#[test]
fn structured_light_axial_noise_follows_nguyen_et_al() {
    let p = sl_quiet();
    // The published curve: 1.2 mm at 0.4 m, 1.219 mm at 0.5 m, 1.884 mm at 1 m.
    assert!((p.axial_sigma_m(0.5) - 0.001219).abs() < 1e-9);
    assert!((p.axial_sigma_m(1.0) - 0.001884).abs() < 1e-9);
    let mesh = wall(0.5);
    for z in [0.5, 1.0] {
        let mut t = render(
            &[RenderItem { mesh: &mesh, pose: facing(z), instance_label: 1, shadow_mesh: None }],
            &RenderSettings::default(),
        );
        let truth = t.depth_m().to_vec();
        apply_depth_sensor_model(&mut t, &DepthSensorModel::StructuredLight(p.clone()), 7);
        let d: Vec<f64> = t.depth_m().iter().zip(&truth).map(|(&a, &b)| a as f64 - b as f64).collect();
        assert!(t.depth_m().iter().all(|&v| v > 0.0), "a quiet model must not drop pixels");
        let (mean, sd) = std_dev(&d);
        let sigma = p.axial_sigma_m(z);
        assert!((sd / sigma - 1.0).abs() < 0.03, "z {z}: sd {sd} vs σ {sigma}");
        assert!(mean.abs() < sigma * 0.02, "z {z}: bias {mean}");
    }
}

#[test]
fn structured_light_depth_lies_on_the_disparity_grid() {
    let p = StructuredLightParams { random_dropout_prob: 0.0, ..Default::default() };
    let mesh = wall(0.5);
    let mut t = render(
        &[RenderItem { mesh: &mesh, pose: facing(1.0), instance_label: 1, shadow_mesh: None }],
        &RenderSettings::default(),
    );
    apply_depth_sensor_model(&mut t, &DepthSensorModel::StructuredLight(p.clone()), 3);
    let fb = k().fx * p.baseline_m;
    let mut levels: Vec<i64> = Vec::new();
    for &z in t.depth_m().iter().filter(|&&z| z > 0.0) {
        let steps = fb / z as f64 / p.subpixel_step_px;
        assert!((steps - steps.round()).abs() < 2e-3, "depth {z} is off the disparity grid ({steps} steps)");
        levels.push(steps.round() as i64);
    }
    levels.sort();
    levels.dedup();
    // At 1 m with f·b = 25 px the depth step is z²·0.125/25 = 5 mm: σ 1.9 mm
    // spreads over a handful of neighbouring levels, no more.
    assert!((3..=9).contains(&levels.len()), "levels {levels:?}");
    let z_step = 1.0 / (levels[levels.len() / 2] as f64 * p.subpixel_step_px / fb)
        - 1.0 / ((levels[levels.len() / 2] + 1) as f64 * p.subpixel_step_px / fb);
    assert!((z_step - 0.005).abs() < 0.0003, "step {z_step}");
}

#[test]
fn projector_shadow_falls_left_of_a_box_by_the_disparity_difference() {
    let p = StructuredLightParams { projector_shadows: true, ..sl_quiet() };
    let (wall_mesh, cube) = (wall(0.5), box_mesh([0.05; 3], 1.0, plain_material("c", [0.5; 3])));
    let items = [
        RenderItem { mesh: &wall_mesh, pose: facing(1.2), instance_label: 0, shadow_mesh: None },
        RenderItem { mesh: &cube, pose: pose([0.0; 3], [0.0, 0.0, 0.7]), instance_label: 1, shadow_mesh: None },
    ];
    let mut t = render(&items, &RenderSettings::default());
    let labels = t.labels().to_vec();
    apply_depth_sensor_model(&mut t, &DepthSensorModel::StructuredLight(p.clone()), 1);
    let k = k();
    // Projector ray through the cube's front-left edge (x −0.05, z 0.65) meets the wall at
    // x = b + (−0.05 − b)·1.2/0.65; the camera sees the cube's edge at x = −0.05·… .
    let b = p.baseline_m;
    let shadow_start = k.cx + k.fx * (b + (-0.05 - b) * 1.2 / 0.65) / 1.2;
    let cube_edge = k.cx + k.fx * -0.05 / 0.65;
    let width = cube_edge - shadow_start;
    assert!((width - k.fx * b * (1.0 / 0.65 - 1.0 / 1.2)).abs() < 1e-9);
    let row = k.cy.round() as u32;
    let missing = |u: u32| t.depth_m()[(row * k.width + u) as usize] == 0.0;
    let mut checked = 0;
    for u in 0..k.width {
        let uf = u as f64;
        if labels[(row * k.width + u) as usize] != 0 {
            assert!(!missing(u), "the cube itself at u {u} lost depth");
            continue;
        }
        if uf > shadow_start + 1.0 && uf < cube_edge - 1.0 {
            assert!(missing(u), "u {u} lies in the projector's shadow but has depth");
            checked += 1;
        } else if uf < shadow_start - 1.0 || uf > cube_edge + 1.0 {
            assert!(!missing(u), "u {u} is lit by the projector but lost depth");
        }
    }
    assert!(checked >= 14, "shadow band {checked} px, expected about {width:.1}");
}

#[test]
fn structured_light_drops_dark_glossy_and_steep_surfaces() {
    let p = StructuredLightParams { random_dropout_prob: 0.0, ..StructuredLightParams::default() };
    let model = DepthSensorModel::StructuredLight(p.clone());
    let missing = |t: &RenderTarget| t.depth_m().iter().filter(|&&z| z == 0.0).count() as f64 / t.pixel_count() as f64;
    // Black absorbs the pattern: about dark_dropout_prob of the pixels go.
    let (black, grey) = (wall(0.0), wall(0.5));
    let mut t = render(
        &[RenderItem { mesh: &black, pose: facing(1.0), instance_label: 1, shadow_mesh: None }],
        &RenderSettings::default(),
    );
    apply_depth_sensor_model(&mut t, &model, 2);
    assert!((missing(&t) - p.dark_dropout_prob).abs() < 0.03, "black wall: {} missing", missing(&t));
    let mut t = render(
        &[RenderItem { mesh: &grey, pose: facing(1.0), instance_label: 1, shadow_mesh: None }],
        &RenderSettings::default(),
    );
    apply_depth_sensor_model(&mut t, &model, 2);
    assert_eq!(missing(&t), 0.0);
    // Glare: a glossy wall lit head-on loses depth in its highlight.
    let glossy = RenderSettings {
        lighting: Lighting {
            ambient: [0.1; 3],
            lights: vec![DirectionalLight { direction: Vector3::new(0.0, 0.0, -1.0), color: [0.6; 3] }],
            points: vec![],
        },
        item_shading: vec![ItemShading { specular: 0.05, shininess: 400.0, ..Default::default() }],
        camera_response: CameraResponse::default(),
        ..Default::default()
    };
    let mut t = render(&[RenderItem { mesh: &grey, pose: facing(1.0), instance_label: 1, shadow_mesh: None }], &glossy);
    let glare: Vec<usize> =
        (0..t.pixel_count()).filter(|&i| t.specular()[i] as f64 > p.specular_threshold * 255.0).collect();
    assert!(glare.len() > 200 && glare.len() < t.pixel_count() / 2, "{} glare pixels", glare.len());
    apply_depth_sensor_model(&mut t, &model, 4);
    let lost = glare.iter().filter(|&&i| t.depth_m()[i] == 0.0).count() as f64 / glare.len() as f64;
    assert!((lost - p.specular_dropout_prob).abs() < 0.08, "glare dropout {lost}");
    // Steeper than 75°: no depth; below 73°: depth.
    let k = k();
    let slant = pose([80f64.to_radians() + std::f64::consts::PI, 0.0, 0.0], [0.0, 0.0, 1.5]);
    let mut t = render(
        &[RenderItem { mesh: &grey, pose: slant, instance_label: 1, shadow_mesh: None }],
        &RenderSettings::default(),
    );
    let truth = t.depth_m().to_vec();
    apply_depth_sensor_model(&mut t, &DepthSensorModel::StructuredLight(sl_quiet()), 5);
    let n = slant.rotation * Vector3::z();
    let (mut dropped, mut kept) = (0, 0);
    for v in 0..k.height {
        for u in 0..k.width {
            let i = (v * k.width + u) as usize;
            if truth[i] == 0.0 {
                continue;
            }
            let ray = Vector3::new((u as f64 - k.cx) / k.fx, (v as f64 - k.cy) / k.fy, 1.0).normalize();
            let angle = n.dot(&ray).abs().acos().to_degrees();
            if angle > 75.5 {
                assert_eq!(t.depth_m()[i], 0.0, "({u},{v}) at {angle:.1}° kept depth");
                dropped += 1;
            } else if angle < 74.5 {
                assert!(t.depth_m()[i] > 0.0, "({u},{v}) at {angle:.1}° lost depth");
                kept += 1;
            }
        }
    }
    assert!(dropped > 500 && kept > 500, "dropped {dropped}, kept {kept}");
}

#[test]
fn edges_get_holes_flying_pixels_and_ragged_outlines() {
    let (wall_mesh, cube) = (wall(0.5), box_mesh([0.05; 3], 1.0, plain_material("c", [0.5; 3])));
    let items = [
        RenderItem { mesh: &wall_mesh, pose: facing(1.2), instance_label: 0, shadow_mesh: None },
        RenderItem { mesh: &cube, pose: pose([0.3, 0.4, 0.0], [0.0, 0.0, 0.7]), instance_label: 1, shadow_mesh: None },
    ];
    let base = render(&items, &RenderSettings::default());
    let truth = base.depth_m().to_vec();
    let k = k();
    let edge: Vec<usize> = (0..base.pixel_count())
        .filter(|&i| {
            let (x, y) = (i % k.width as usize, i / k.width as usize);
            discontinuity(&truth, k.width as usize, k.height as usize, x, y, 0.03).is_some()
        })
        .collect();
    assert!(edge.len() > 100);
    let between = |t: &RenderTarget| {
        edge.iter()
            .filter(|&&i| {
                let z = t.depth_m()[i];
                z > 0.72 && z < 1.15
            })
            .count()
    };
    for (name, model) in [
        ("structured light", DepthSensorModel::StructuredLight(StructuredLightParams::default())),
        ("tof", DepthSensorModel::Tof(TofParams::default())),
    ] {
        let mut t = base.clone();
        apply_depth_sensor_model(&mut t, &model, 11);
        let holes = edge.iter().filter(|&&i| t.depth_m()[i] == 0.0).count();
        assert!(holes * 10 > edge.len(), "{name}: only {holes} of {} edge pixels are holes", edge.len());
        assert!(between(&t) * 20 > edge.len(), "{name}: only {} flying pixels", between(&t));
        // Away from edges nothing flies.
        let far_off = (0..t.pixel_count())
            .filter(|i| !edge.contains(i) && t.depth_m()[*i] > 0.0)
            .filter(|&i| (t.depth_m()[i] - truth[i]).abs() > 0.05)
            .count();
        assert!(far_off < 100, "{name}: {far_off} non-edge pixels far from the truth");
    }
}

#[test]
fn tof_noise_grows_with_distance_over_amplitude() {
    let p = tof_quiet();
    assert!((p.axial_sigma_m(2.0) - 2.0 * p.axial_sigma_m(1.0)).abs() < 1e-12);
    assert!((p.sigma_m(1.0, 0.25) - 4.0 * p.axial_sigma_m(1.0)).abs() < 1e-12);
    let k = k();
    for (z, albedo) in [(0.5, 1.0f32), (1.0, 1.0), (1.0, 0.25)] {
        let mesh = wall(albedo);
        let mut t = render(
            &[RenderItem { mesh: &mesh, pose: facing(z), instance_label: 1, shadow_mesh: None }],
            &RenderSettings::default(),
        );
        let truth = t.depth_m().to_vec();
        apply_depth_sensor_model(&mut t, &DepthSensorModel::Tof(p.clone()), 8);
        // Normalised residuals over the central pixels (incidence within 3°).
        let mut r = Vec::new();
        for v in 0..k.height {
            for u in 0..k.width {
                let (rx, ry) = ((u as f64 - k.cx) / k.fx, (v as f64 - k.cy) / k.fy);
                let cos = 1.0 / (1.0 + rx * rx + ry * ry).sqrt();
                if cos < 0.9986 {
                    continue;
                }
                let i = (v * k.width + u) as usize;
                let a = (t.reflectance()[i] as f64 / 255.0) * cos;
                r.push((t.depth_m()[i] as f64 - truth[i] as f64) / p.sigma_m(truth[i] as f64, a));
            }
        }
        let (mean, sd) = std_dev(&r);
        assert!(r.len() > 1500, "{} central pixels", r.len());
        assert!((sd - 1.0).abs() < 0.05, "z {z}, albedo {albedo}: normalised sd {sd}");
        assert!(mean.abs() < 0.05, "bias {mean}");
    }
    // Too weak a return: no depth.
    let dark = wall(0.02);
    let mut t = render(
        &[RenderItem { mesh: &dark, pose: facing(1.0), instance_label: 1, shadow_mesh: None }],
        &RenderSettings::default(),
    );
    apply_depth_sensor_model(&mut t, &DepthSensorModel::Tof(p), 8);
    assert!(t.depth_m().iter().all(|&z| z == 0.0));
}

#[test]
fn tof_multipath_reads_long_in_a_concave_corner_only() {
    let p = TofParams { sigma_at_1m_m: 0.0, ..tof_quiet() };
    let p = TofParams { multipath_gain: TofParams::default().multipath_gain, ..p };
    let k = k();
    let panel = quad_mesh(0.4, 1.5, 1.0, plain_material("p", [0.6; 3]));
    // Two panels meeting along the vertical line x = 0 at depth `corner_z`,
    // each turned 45° about y: `inside` opens towards the camera (concave).
    let corner = |inside: bool| {
        let (a, zc) = if inside { (std::f64::consts::FRAC_PI_4, 1.0) } else { (-std::f64::consts::FRAC_PI_4, 0.8) };
        let h = 0.4 * std::f64::consts::FRAC_1_SQRT_2;
        let dz = if inside { -h } else { h };
        let left = pose([0.0, std::f64::consts::PI - a, 0.0], [-h, 0.0, zc + dz]);
        let right = pose([0.0, std::f64::consts::PI + a, 0.0], [h, 0.0, zc + dz]);
        let mut t = render(
            &[
                RenderItem { mesh: &panel, pose: left, instance_label: 1, shadow_mesh: None },
                RenderItem { mesh: &panel, pose: right, instance_label: 2, shadow_mesh: None },
            ],
            &RenderSettings::default(),
        );
        let truth = t.depth_m().to_vec();
        apply_depth_sensor_model(&mut t, &DepthSensorModel::Tof(p.clone()), 3);
        (t, truth)
    };
    let row = k.cy as u32;
    let bias_at = |t: &RenderTarget, truth: &[f32], u: u32| {
        let i = (row * k.width + u) as usize;
        if t.depth_m()[i] == 0.0 || truth[i] == 0.0 { f64::NAN } else { t.depth_m()[i] as f64 - truth[i] as f64 }
    };
    let (t, truth) = corner(true);
    // The corner column is the farthest point of the row.
    let cu = (0..k.width)
        .max_by(|&a, &b| truth[(row * k.width + a) as usize].total_cmp(&truth[(row * k.width + b) as usize]))
        .unwrap();
    assert!((cu as f64 - k.cx).abs() < 2.0, "corner at u {cu}");
    let near: Vec<f64> = (cu - 2..=cu + 2).map(|u| bias_at(&t, &truth, u)).filter(|b| b.is_finite()).collect();
    let mean_near = near.iter().sum::<f64>() / near.len() as f64;
    assert!(mean_near > 0.003 && mean_near <= p.multipath_max_m, "corner bias {mean_near} m");
    for u in [cu - 60, cu + 60] {
        let b = bias_at(&t, &truth, u);
        assert!(b.abs() < 2e-4, "plane at u {u} biased by {b}");
    }
    // Convex: no multipath anywhere on the row.
    let (t, truth) = corner(false);
    let worst = (40..k.width - 40).map(|u| bias_at(&t, &truth, u)).filter(|b| b.is_finite()).fold(0.0, f64::max);
    assert!(worst < 2e-4, "convex edge biased by {worst}");
}

#[test]
fn ideal_keeps_depth_basic_equals_the_original_model_and_all_are_seeded() {
    let (wall_mesh, cube) = (wall(0.5), box_mesh([0.05; 3], 1.0, plain_material("c", [0.3; 3])));
    let items = [
        RenderItem { mesh: &wall_mesh, pose: facing(1.2), instance_label: 0, shadow_mesh: None },
        RenderItem { mesh: &cube, pose: pose([0.3, 0.4, 0.0], [0.0, 0.0, 0.7]), instance_label: 1, shadow_mesh: None },
    ];
    let base = render(&items, &RenderSettings::default());
    let mut ideal = base.clone();
    apply_depth_sensor(&mut ideal, DepthSensor::Ideal, 1);
    assert_eq!(ideal.depth_u16(), base.depth_u16());
    let mut basic = base.clone();
    apply_depth_sensor(&mut basic, DepthSensor::Basic, 42);
    let mut original = base.clone();
    apply_noise(&mut original, &NoiseConfig::default(), 42);
    assert_eq!(basic.depth_m(), original.depth_m());
    assert_eq!(basic.depth_u16(), original.depth_u16());
    assert_eq!(basic.rgb(), base.rgb(), "depth models leave colour alone");
    for sensor in [DepthSensor::StructuredLight, DepthSensor::Tof] {
        let run = |seed| {
            let mut t = base.clone();
            apply_depth_sensor(&mut t, sensor, seed);
            t
        };
        let (a, b, c) = (run(5), run(5), run(6));
        assert_eq!(a.depth_u16(), b.depth_u16(), "{sensor}");
        assert_ne!(a.depth_u16(), c.depth_u16(), "{sensor}");
        assert_eq!(a.labels(), base.labels());
        assert_eq!(a.rgb(), base.rgb());
        for (z, zu) in a.depth_m().iter().zip(a.depth_u16()) {
            assert_eq!(*zu, crate::render::depth_to_u16(*z as f64));
        }
    }
}
