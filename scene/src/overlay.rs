//! Pose overlays: draw estimated (or true) poses onto an RGB8 camera image so
//! a person can judge them at a glance, and save the result as a PNG.
//!
//! What is drawn, per object ([`OverlayObject`]):
//! - the object's axes, projected with the intrinsics from the pose's origin:
//!   x red, y green, z blue, each [`OverlayStyle::axis_fraction`] of the
//!   object's diameter long;
//! - its silhouette outline (the mesh rasterised at the pose, boundary pixels
//!   only) and/or its projected object-frame bounding box, in the object's colour.
//!
//! Plus, per frame: a label-map tint ([`tint_labels`], colour per class id from
//! [`label_colour`], alpha-blended) or an instance tint that tells copies of
//! one class apart ([`tint_instances`]: a shade per instance, white where two
//! meet), and a text-free legend of colour swatches ([`draw_legend`]).
//!
//! Projection is [`Intrinsics::project`] (pixel centres at integer
//! coordinates, the renderer's convention), so an overlay of the true pose lies
//! on the rendered object. Drawing is hand-rolled (clipped Bresenham lines,
//! edge-function triangle fill): a few dozen lines, where a drawing crate
//! would add a large dependency tree to every build of this crate.
//!
//! ```no_run
//! use fusepose_scene::{builtin::builtin_objects, overlay, Intrinsics, Pose};
//! let set = builtin_objects();
//! let k = Intrinsics::YCB_VIDEO;
//! let mut img = image::RgbImage::new(k.width, k.height);
//! let pose = Pose::translation(0.0, 0.0, 0.6);
//! let objects = [overlay::OverlayObject::new(set.by_class(1).unwrap(), 1, pose)];
//! overlay::draw_poses(&mut img, &k, &objects, &overlay::OverlayStyle::default());
//! overlay::save_png(&img, "overlay.png").unwrap();
//! ```

use crate::{Intrinsics, ObjectModel, Pose};
use image::{Rgb, RgbImage};
use nalgebra::Point3;
use std::path::Path;

pub use crate::contact_sheet::label_colour;
pub use instances::{INSTANCE_BORDER, INSTANCE_SHADES, instance_colour, tint_instances};

mod instances;

/// Axis colours: x red, y green, z blue.
pub const AXIS_COLOURS: [[u8; 3]; 3] = [[255, 0, 0], [0, 255, 0], [0, 0, 255]];

/// Geometry closer than this to the camera (metres) is not drawn.
pub const OVERLAY_Z_NEAR_M: f64 = 0.01;

/// Why an overlay could not be built or written.
#[derive(Debug, thiserror::Error)]
pub enum OverlayError {
    #[error("plane has {got} elements but a {width}x{height} image needs {expected}")]
    PlaneSize { width: u32, height: u32, expected: usize, got: usize },
    #[error("writing the PNG: {0}")]
    Write(#[from] image::ImageError),
}

/// One object to draw: its model, class id (picks the colour) and pose
/// (object → camera, metres).
#[derive(Clone, Copy, Debug)]
pub struct OverlayObject<'a> {
    pub model: &'a ObjectModel,
    pub class_id: u16,
    pub pose: Pose,
    /// Colour of the outline and bounding box; [`label_colour`] of the class by default.
    pub colour: [u8; 3],
}

impl<'a> OverlayObject<'a> {
    /// An object drawn in its class colour.
    pub fn new(model: &'a ObjectModel, class_id: u16, pose: Pose) -> Self {
        OverlayObject { model, class_id, pose, colour: label_colour(class_id) }
    }

    /// The same object drawn in another colour (e.g. white for ground truth).
    pub fn with_colour(self, colour: [u8; 3]) -> Self {
        OverlayObject { colour, ..self }
    }
}

/// What [`draw_poses`] draws.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OverlayStyle {
    /// Axis length as a fraction of the object's diameter (0 = no axes).
    pub axis_fraction: f64,
    /// Draw the boundary of the mesh's projected silhouette.
    pub silhouette: bool,
    /// Draw the projected object-frame bounding box (12 edges).
    pub bounding_box: bool,
    /// Line thickness in pixels (≥ 1).
    pub thickness: u32,
}

impl Default for OverlayStyle {
    fn default() -> Self {
        OverlayStyle { axis_fraction: 0.5, silhouette: true, bounding_box: false, thickness: 2 }
    }
}

/// Wraps an RGB8 plane (row-major, 3 bytes per pixel) as an image.
pub fn rgb_image(width: u32, height: u32, rgb: &[u8]) -> Result<RgbImage, OverlayError> {
    let expected = width as usize * height as usize * 3;
    if rgb.len() != expected {
        return Err(OverlayError::PlaneSize { width, height, expected, got: rgb.len() });
    }
    Ok(RgbImage::from_raw(width, height, rgb.to_vec()).expect("length checked above"))
}

/// Alpha-blends each labelled pixel towards its class colour:
/// `out = (1 - alpha) * in + alpha * label_colour(label)`; label 0 is left as is.
/// `labels` is row-major with one entry per pixel; `alpha` is clamped to 0..=1.
pub fn tint_labels(img: &mut RgbImage, labels: &[u16], alpha: f32) -> Result<(), OverlayError> {
    let (width, height) = img.dimensions();
    let expected = width as usize * height as usize;
    if labels.len() != expected {
        return Err(OverlayError::PlaneSize { width, height, expected, got: labels.len() });
    }
    let a = if alpha.is_finite() { alpha.clamp(0.0, 1.0) } else { 0.0 };
    for (px, &label) in img.pixels_mut().zip(labels) {
        if label != 0 {
            let c = label_colour(label);
            for (out, c) in px.0.iter_mut().zip(c) {
                *out = ((1.0 - a) * *out as f32 + a * c as f32).round() as u8;
            }
        }
    }
    Ok(())
}

/// Draws every object's silhouette outline / bounding box, then its axes on top.
/// Parts behind the camera or outside the image are skipped; never panics.
pub fn draw_poses(img: &mut RgbImage, k: &Intrinsics, objects: &[OverlayObject<'_>], style: &OverlayStyle) {
    let thickness = style.thickness.max(1);
    for o in objects {
        if style.silhouette {
            draw_silhouette(img, k, o, thickness);
        }
        if style.bounding_box {
            draw_bounding_box(img, k, o, thickness);
        }
    }
    if style.axis_fraction > 0.0 {
        for o in objects {
            draw_axes(img, k, o, style.axis_fraction * o.model.diameter, thickness);
        }
    }
}

/// Draws the object's axes from its origin, `length_m` metres each.
pub fn draw_axes(img: &mut RgbImage, k: &Intrinsics, o: &OverlayObject<'_>, length_m: f64, thickness: u32) {
    let origin = o.pose * Point3::origin();
    // Draw z last: it points at or away from the camera and is shortest on screen.
    for axis in 0..3 {
        let mut tip = Point3::origin();
        tip[axis] = length_m;
        draw_segment(img, k, &origin, &(o.pose * tip), AXIS_COLOURS[axis], thickness);
    }
}

/// Draws the 12 edges of the object-frame bounding box at the pose.
pub fn draw_bounding_box(img: &mut RgbImage, k: &Intrinsics, o: &OverlayObject<'_>, thickness: u32) {
    let (lo, hi) = (o.model.bbox_min, o.model.bbox_max);
    let corner = |i: usize| {
        o.pose
            * Point3::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            )
    };
    for i in 0..8usize {
        for bit in [1, 2, 4] {
            if i & bit == 0 {
                draw_segment(img, k, &corner(i), &corner(i | bit), o.colour, thickness);
            }
        }
    }
}

/// Rasterises the mesh at the pose into a mask and paints the mask's boundary
/// (mask pixels with a 4-neighbour outside it). Coverage uses pixel centres,
/// as the renderer does.
pub fn draw_silhouette(img: &mut RgbImage, k: &Intrinsics, o: &OverlayObject<'_>, thickness: u32) {
    let (w, h) = img.dimensions();
    let mask = silhouette_mask(k, o, w, h);
    let inside = |u: i64, v: i64| u >= 0 && v >= 0 && u < w as i64 && v < h as i64 && mask[(v * w as i64 + u) as usize];
    for v in 0..h as i64 {
        for u in 0..w as i64 {
            if inside(u, v) && !(inside(u - 1, v) && inside(u + 1, v) && inside(u, v - 1) && inside(u, v + 1)) {
                stamp(img, u, v, o.colour, thickness);
            }
        }
    }
}

/// The pixels (row-major, `w * h`) whose centres the posed mesh covers.
/// Triangles with a vertex closer than [`OVERLAY_Z_NEAR_M`] are skipped.
pub fn silhouette_mask(k: &Intrinsics, o: &OverlayObject<'_>, w: u32, h: u32) -> Vec<bool> {
    let mut mask = vec![false; w as usize * h as usize];
    let projected: Vec<Option<(f64, f64)>> = o
        .model
        .mesh
        .positions
        .iter()
        .map(|p| {
            let c = o.pose * Point3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            if c.z < OVERLAY_Z_NEAR_M { None } else { k.project(&c) }
        })
        .collect();
    for tri in &o.model.mesh.triangles {
        let [a, b, c] = tri.map(|i| projected.get(i as usize).copied().flatten());
        let (Some(a), Some(b), Some(c)) = (a, b, c) else {
            continue;
        };
        fill_triangle(&mut mask, w, h, a, b, c);
    }
    mask
}

/// Marks pixels whose centres lie inside (or on the edge of) the 2D triangle, either winding.
fn fill_triangle(mask: &mut [bool], w: u32, h: u32, a: (f64, f64), b: (f64, f64), c: (f64, f64)) {
    let edge = |p: (f64, f64), q: (f64, f64), x: f64, y: f64| (q.0 - p.0) * (y - p.1) - (q.1 - p.1) * (x - p.0);
    let area = edge(a, b, c.0, c.1);
    if area == 0.0 || !area.is_finite() {
        return;
    }
    let u0 = a.0.min(b.0).min(c.0).ceil().max(0.0);
    let u1 = a.0.max(b.0).max(c.0).floor().min(w as f64 - 1.0);
    let v0 = a.1.min(b.1).min(c.1).ceil().max(0.0);
    let v1 = a.1.max(b.1).max(c.1).floor().min(h as f64 - 1.0);
    if u0 > u1 || v0 > v1 {
        return;
    }
    let s = area.signum();
    for v in v0 as u32..=v1 as u32 {
        for u in u0 as u32..=u1 as u32 {
            let (x, y) = (u as f64, v as f64);
            if s * edge(a, b, x, y) >= 0.0 && s * edge(b, c, x, y) >= 0.0 && s * edge(c, a, x, y) >= 0.0 {
                mask[v as usize * w as usize + u as usize] = true;
            }
        }
    }
}

/// Projects a camera-frame segment and draws it; skipped when either end is
/// nearer than [`OVERLAY_Z_NEAR_M`].
fn draw_segment(img: &mut RgbImage, k: &Intrinsics, p: &Point3<f64>, q: &Point3<f64>, colour: [u8; 3], thickness: u32) {
    if p.z < OVERLAY_Z_NEAR_M || q.z < OVERLAY_Z_NEAR_M {
        return;
    }
    if let (Some(a), Some(b)) = (k.project(p), k.project(q)) {
        draw_line(img, a, b, colour, thickness);
    }
}

/// A line between pixel coordinates, clipped to the image first so far-away
/// end points cost nothing (Liang–Barsky), then walked with Bresenham.
pub fn draw_line(img: &mut RgbImage, a: (f64, f64), b: (f64, f64), colour: [u8; 3], thickness: u32) {
    let (w, h) = img.dimensions();
    let Some((a, b)) = clip(a, b, w as f64 - 1.0, h as f64 - 1.0) else {
        return;
    };
    let (mut x, mut y) = (a.0.round() as i64, a.1.round() as i64);
    let (x1, y1) = (b.0.round() as i64, b.1.round() as i64);
    let (dx, dy) = ((x1 - x).abs(), -(y1 - y).abs());
    let (sx, sy) = (if x < x1 { 1 } else { -1 }, if y < y1 { 1 } else { -1 });
    let mut err = dx + dy;
    loop {
        stamp(img, x, y, colour, thickness);
        if x == x1 && y == y1 {
            break;
        }
        let e2 = 2 * err;
        if e2 >= dy {
            err += dy;
            x += sx;
        }
        if e2 <= dx {
            err += dx;
            y += sy;
        }
    }
}

/// Clips segment a-b to the rectangle [0, xmax] x [0, ymax]; `None` when outside or not finite.
fn clip(a: (f64, f64), b: (f64, f64), xmax: f64, ymax: f64) -> Option<((f64, f64), (f64, f64))> {
    if ![a.0, a.1, b.0, b.1].iter().all(|v| v.is_finite()) {
        return None;
    }
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [(-dx, a.0), (dx, xmax - a.0), (-dy, a.1), (dy, ymax - a.1)] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let r = q / p;
            if p < 0.0 {
                t0 = t0.max(r);
            } else {
                t1 = t1.min(r);
            }
        }
    }
    (t0 <= t1).then_some(((a.0 + t0 * dx, a.1 + t0 * dy), (a.0 + t1 * dx, a.1 + t1 * dy)))
}

/// Paints a `thickness`-wide square centred on (u, v), clipped to the image.
fn stamp(img: &mut RgbImage, u: i64, v: i64, colour: [u8; 3], thickness: u32) {
    let t = thickness.max(1) as i64;
    let (w, h) = (img.width() as i64, img.height() as i64);
    for dv in -(t - 1) / 2..=t / 2 {
        for du in -(t - 1) / 2..=t / 2 {
            let (x, y) = (u + du, v + dv);
            if x >= 0 && y >= 0 && x < w && y < h {
                img.put_pixel(x as u32, y as u32, Rgb(colour));
            }
        }
    }
}

/// Side of a legend swatch in pixels.
pub const LEGEND_SWATCH_PX: u32 = 12;

/// A text-free legend in the top-left corner: one swatch per class id in the
/// given order, its class colour framed in white, stacked downwards.
/// Map swatches to names in your own caption (see [`label_colour`]).
pub fn draw_legend(img: &mut RgbImage, class_ids: &[u16]) {
    let s = LEGEND_SWATCH_PX as i64;
    for (i, &class_id) in class_ids.iter().enumerate() {
        let (x0, y0) = (4, 4 + i as i64 * (s + 4));
        let c = label_colour(class_id);
        for y in y0..y0 + s {
            for x in x0..x0 + s {
                let border = x == x0 || y == y0 || x == x0 + s - 1 || y == y0 + s - 1;
                stamp(img, x, y, if border { [255, 255, 255] } else { c }, 1);
            }
        }
    }
}

/// Writes the image as a PNG (creating nothing else: the directory must exist).
pub fn save_png(img: &RgbImage, path: impl AsRef<Path>) -> Result<(), OverlayError> {
    img.save_with_format(path, image::ImageFormat::Png)?;
    Ok(())
}

#[cfg(test)]
mod tests;
