//! Overlay tests: expected pixels come from the pinhole formula written out
//! here, and the silhouette is checked against the renderer's own label map.

use super::*;
use crate::builtin::builtin_objects;
use crate::render::{RenderItem, RenderSettings, RenderTarget, render_scene};
use nalgebra::{Translation3, UnitQuaternion, Vector3};

/// Off-centre principal point and fx != fy, so swapped or dropped terms show.
fn k_small() -> Intrinsics {
    Intrinsics { fx: 500.0, fy: 530.0, cx: 151.3, cy: 127.6, width: 320, height: 240 }
}

fn pose(axis_angle: [f64; 3], t: [f64; 3]) -> Pose {
    Pose::from_parts(
        Translation3::new(t[0], t[1], t[2]),
        UnitQuaternion::from_scaled_axis(Vector3::new(axis_angle[0], axis_angle[1], axis_angle[2])),
    )
}

/// u = fx x / z + cx, v = fy y / z + cy, rounded to the nearest pixel.
fn pixel_of(k: &Intrinsics, p: [f64; 3]) -> (u32, u32) {
    ((k.fx * p[0] / p[2] + k.cx).round() as u32, (k.fy * p[1] / p[2] + k.cy).round() as u32)
}

fn coloured_pixels(img: &RgbImage) -> usize {
    img.pixels().filter(|p| p.0 != [0, 0, 0]).count()
}

#[test]
fn axes_start_at_the_projected_translation_and_follow_the_rotation() {
    let set = builtin_objects();
    let model = set.by_class(1).unwrap();
    let k = k_small();
    let t = [0.03, -0.02, 0.7];
    // Rotation of -90 deg about camera z: object x -> camera -y (up in the image),
    // object y -> camera +x (right).
    let o = OverlayObject::new(model, 1, pose([0.0, 0.0, -std::f64::consts::FRAC_PI_2], t));
    let style = OverlayStyle { axis_fraction: 0.5, silhouette: false, bounding_box: false, thickness: 1 };
    let mut img = RgbImage::new(k.width, k.height);
    draw_poses(&mut img, &k, &[o], &style);

    let len = 0.5 * model.diameter;
    let origin = pixel_of(&k, t);
    // z is drawn last and starts at the origin.
    assert_eq!(img.get_pixel(origin.0, origin.1).0, AXIS_COLOURS[2], "axis origin is not at the projected translation");
    let x_tip = pixel_of(&k, [t[0], t[1] - len, t[2]]);
    let y_tip = pixel_of(&k, [t[0] + len, t[1], t[2]]);
    assert!(x_tip.1 + 20 < origin.1, "x axis should point up in the image");
    assert!(y_tip.0 > origin.0 + 20, "y axis should point right in the image");
    assert_eq!(img.get_pixel(x_tip.0, x_tip.1).0, AXIS_COLOURS[0]);
    assert_eq!(img.get_pixel(y_tip.0, y_tip.1).0, AXIS_COLOURS[1]);
    // Nothing beyond the tips.
    assert_eq!(img.get_pixel(x_tip.0, x_tip.1 - 3).0, [0, 0, 0]);
    assert_eq!(img.get_pixel(y_tip.0 + 3, y_tip.1).0, [0, 0, 0]);
    // The z axis points away, so on screen it runs from the origin towards the principal point.
    let z_tip = pixel_of(&k, [t[0], t[1], t[2] + len]);
    assert_eq!(img.get_pixel(z_tip.0, z_tip.1).0, AXIS_COLOURS[2]);
}

#[test]
fn silhouette_mask_matches_the_rendered_label_map() {
    let set = builtin_objects();
    let k = k_small();
    for class_id in [1u16, 6] {
        let model = set.by_class(class_id).unwrap();
        let p = pose([0.4, -0.7, 0.3], [-0.02, 0.01, 0.65]);
        let mut target = RenderTarget::for_intrinsics(&k);
        let item = RenderItem { mesh: &model.mesh, pose: p, instance_label: 1, shadow_mesh: None };
        render_scene(&[item], &k, &RenderSettings::default(), &mut target).unwrap();
        let mask = silhouette_mask(&k, &OverlayObject::new(model, class_id, p), k.width, k.height);
        let (mut inter, mut union) = (0usize, 0usize);
        for (m, &l) in mask.iter().zip(target.labels()) {
            inter += (*m && l == 1) as usize;
            union += (*m || l == 1) as usize;
        }
        assert!(union > 500, "object too small to judge: {union} px");
        let iou = inter as f64 / union as f64;
        assert!(iou > 0.97, "class {class_id}: silhouette IoU with the render is {iou:.3}");
    }
}

#[test]
fn outline_hugs_the_silhouette_and_leaves_the_inside_alone() {
    let set = builtin_objects();
    let k = k_small();
    let model = set.by_class(2).unwrap();
    let o = OverlayObject::new(model, 2, pose([0.2, 0.3, 0.1], [0.0, 0.0, 0.6]));
    let mask = silhouette_mask(&k, &o, k.width, k.height);
    let mut img = RgbImage::new(k.width, k.height);
    draw_silhouette(&mut img, &k, &o, 1);
    let (w, h) = (k.width as usize, k.height as usize);
    let mut outline = 0;
    for v in 1..h - 1 {
        for u in 1..w - 1 {
            let i = v * w + u;
            let interior = mask[i] && mask[i - 1] && mask[i + 1] && mask[i - w] && mask[i + w];
            let drawn = img.get_pixel(u as u32, v as u32).0 == o.colour;
            assert_eq!(drawn, mask[i] && !interior, "pixel ({u}, {v})");
            outline += drawn as usize;
        }
    }
    assert!(outline > 100);
}

#[test]
fn bounding_box_corners_land_on_their_projections() {
    let set = builtin_objects();
    let k = k_small();
    let model = set.by_class(8).unwrap();
    let p = pose([0.3, 0.5, 0.0], [0.01, 0.0, 0.8]);
    let o = OverlayObject::new(model, 8, p).with_colour([255, 255, 0]);
    let mut img = RgbImage::new(k.width, k.height);
    draw_bounding_box(&mut img, &k, &o, 1);
    for i in 0..8 {
        let c = Point3::new(
            if i & 1 == 0 { model.bbox_min.x } else { model.bbox_max.x },
            if i & 2 == 0 { model.bbox_min.y } else { model.bbox_max.y },
            if i & 4 == 0 { model.bbox_min.z } else { model.bbox_max.z },
        );
        let c = p * c;
        let (u, v) = pixel_of(&k, [c.x, c.y, c.z]);
        assert_eq!(img.get_pixel(u, v).0, [255, 255, 0], "corner {i} at ({u}, {v})");
    }
    // 12 edges only: the box's projected centre is not painted.
    let centre = p * nalgebra::center(&model.bbox_min, &model.bbox_max);
    let (u, v) = pixel_of(&k, [centre.x, centre.y, centre.z]);
    assert_eq!(img.get_pixel(u, v).0, [0, 0, 0]);
}

#[test]
fn label_tint_blends_labelled_pixels_only() {
    let mut img = RgbImage::from_pixel(4, 2, Rgb([100, 100, 100]));
    let labels = [0u16, 3, 0, 0, 0, 0, 0, 5];
    tint_labels(&mut img, &labels, 0.25).unwrap();
    assert_eq!(img.get_pixel(0, 0).0, [100, 100, 100]);
    let c = label_colour(3);
    let want = c.map(|c| (0.75 * 100.0 + 0.25 * c as f32).round() as u8);
    assert_eq!(img.get_pixel(1, 0).0, want);
    assert_ne!(img.get_pixel(3, 1).0, [100, 100, 100]);
    assert!(matches!(tint_labels(&mut img, &labels[1..], 0.5), Err(OverlayError::PlaneSize { .. })));
    assert!(matches!(rgb_image(4, 2, &[0; 23]), Err(OverlayError::PlaneSize { .. })));
}

#[test]
fn touching_copies_get_their_own_shades_and_a_white_line_between_them() {
    // A 6x3 plane: two touching instances of class 2 (ids 7 and 9), one of
    // class 4 (id 3) apart from them, and id 5 unlisted (left as it is).
    #[rustfmt::skip]
    let ids: [u32; 18] = [
        7, 7, 9, 9, 0, 3,
        7, 7, 9, 9, 0, 3,
        0, 0, 0, 0, 0, 5,
    ];
    let mut img = RgbImage::from_pixel(6, 3, Rgb([100, 100, 100]));
    let colours = tint_instances(&mut img, &ids, &[(7, 2), (9, 2), (3, 4)], 1.0).unwrap();
    // The first copy of a class keeps the class colour; the second is another shade of it.
    assert_eq!(colours, vec![label_colour(2), instance_colour(2, 1), label_colour(4)]);
    assert_ne!(colours[0], colours[1]);
    assert_eq!(img.get_pixel(0, 0).0, colours[0]);
    assert_eq!(img.get_pixel(3, 1).0, colours[1]);
    // Where the copies meet (columns 1 and 2), a white line; none where an
    // instance meets the background or the unlisted id.
    for v in 0..2 {
        assert_eq!(img.get_pixel(1, v).0, INSTANCE_BORDER);
        assert_eq!(img.get_pixel(2, v).0, INSTANCE_BORDER);
    }
    assert_eq!(img.get_pixel(5, 1).0, colours[2]);
    assert_eq!(img.get_pixel(4, 0).0, [100, 100, 100]);
    assert_eq!(img.get_pixel(5, 2).0, [100, 100, 100]);
    assert!(matches!(tint_instances(&mut img, &ids[1..], &[], 0.5), Err(OverlayError::PlaneSize { .. })));
}

#[test]
fn a_heap_of_copies_gets_distinct_shades_before_they_repeat() {
    for class in 1..=8u16 {
        let shades: Vec<[u8; 3]> = (0..INSTANCE_SHADES).map(|k| instance_colour(class, k)).collect();
        for (i, a) in shades.iter().enumerate() {
            for b in &shades[i + 1..] {
                let d: i32 = a.iter().zip(b).map(|(&x, &y)| (x as i32 - y as i32).abs()).sum();
                assert!(d >= 30, "class {class}: shades {a:?} and {b:?} too alike");
            }
        }
        assert_eq!(instance_colour(class, INSTANCE_SHADES), shades[0]);
    }
}

#[test]
fn poses_behind_the_camera_or_not_finite_draw_nothing() {
    let set = builtin_objects();
    let k = k_small();
    let model = set.by_class(3).unwrap();
    let mut img = RgbImage::new(k.width, k.height);
    let style = OverlayStyle { bounding_box: true, ..OverlayStyle::default() };
    let behind = OverlayObject::new(model, 3, pose([0.0; 3], [0.0, 0.0, -0.5]));
    let nan = OverlayObject::new(model, 3, pose([0.0; 3], [f64::NAN, 0.0, 0.5]));
    let far_off = OverlayObject::new(model, 3, pose([0.0; 3], [1e9, -1e9, 0.5]));
    draw_poses(&mut img, &k, &[behind, nan, far_off], &style);
    assert_eq!(coloured_pixels(&img), 0);
}

#[test]
fn legend_and_png_round_trip() {
    let mut img = rgb_image(40, 40, &[7u8; 40 * 40 * 3]).unwrap();
    draw_legend(&mut img, &[2, 5]);
    let s = LEGEND_SWATCH_PX;
    assert_eq!(img.get_pixel(4 + s / 2, 4 + s / 2).0, label_colour(2));
    assert_eq!(img.get_pixel(4 + s / 2, 4 + s + 4 + s / 2).0, label_colour(5));
    assert_eq!(img.get_pixel(4, 4).0, [255, 255, 255]);
    let path = std::env::temp_dir().join(format!("fusepose_overlay_test_{}.png", std::process::id()));
    save_png(&img, &path).unwrap();
    let back = image::open(&path).unwrap().to_rgb8();
    std::fs::remove_file(&path).ok();
    assert_eq!(back, img);
}
