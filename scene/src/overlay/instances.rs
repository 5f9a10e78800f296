//! Instance tints: several copies of one class told apart in an overlay.
//!
//! [`super::tint_labels`] colours pixels by class, so two touching copies of
//! one object look like one region. Here every instance of an instance plane
//! gets its own shade of its class colour ([`instance_colour`]: the class
//! colour for the first, then lighter and darker shades), and the pixels
//! where two instances meet are drawn white, so a cut between copies shows
//! even where two shades are alike (a heap of more than
//! [`INSTANCE_SHADES`] copies).

use image::RgbImage;

use super::{OverlayError, label_colour};

/// Shades before [`instance_colour`] repeats.
pub const INSTANCE_SHADES: usize = 6;

/// Colour of the line where two instances meet.
pub const INSTANCE_BORDER: [u8; 3] = [255, 255, 255];

/// The colour of the `ordinal`-th instance (0-based) of `class_id` in a
/// frame: the class colour ([`label_colour`]) for the first, then in turn
/// lighter and darker shades of it; repeats after [`INSTANCE_SHADES`].
pub fn instance_colour(class_id: u16, ordinal: usize) -> [u8; 3] {
    let c = label_colour(class_id).map(f32::from);
    // Towards white by a share, or scaled towards black.
    let shade = |white: f32, scale: f32| c.map(|v| ((v * scale) + (255.0 - v * scale) * white).round() as u8);
    match ordinal % INSTANCE_SHADES {
        0 => shade(0.0, 1.0),
        1 => shade(0.55, 1.0),
        2 => shade(0.0, 0.5),
        3 => shade(0.8, 1.0),
        4 => shade(0.0, 0.3),
        _ => shade(0.35, 0.7),
    }
}

/// Alpha-blends each instance's pixels towards its own colour and draws the
/// borders between instances in [`INSTANCE_BORDER`]. `ids` holds an instance
/// id per pixel (row-major, 0 = none); `instances` lists each instance to
/// draw as `(id, class id)`, in the order their ordinals are counted per
/// class (pixels of other ids are left as they are). Returns each listed
/// instance's colour, in `instances`' order, for its pose's outline.
pub fn tint_instances(
    img: &mut RgbImage,
    ids: &[u32],
    instances: &[(u32, u16)],
    alpha: f32,
) -> Result<Vec<[u8; 3]>, OverlayError> {
    let (width, height) = img.dimensions();
    let expected = width as usize * height as usize;
    if ids.len() != expected {
        return Err(OverlayError::PlaneSize { width, height, expected, got: ids.len() });
    }
    let colours: Vec<[u8; 3]> = instances
        .iter()
        .enumerate()
        .map(|(i, &(_, class))| instance_colour(class, instances[..i].iter().filter(|&&(_, c)| c == class).count()))
        .collect();
    let colour_of = |id: u32| (id != 0).then(|| instances.iter().position(|&(i, _)| i == id)).flatten();
    let a = if alpha.is_finite() { alpha.clamp(0.0, 1.0) } else { 0.0 };
    let w = width as usize;
    // One lookup per run of equal ids: planes are mostly long runs.
    let mut last = (0u32, None);
    for (p, &id) in ids.iter().enumerate() {
        if id != last.0 {
            last = (id, colour_of(id));
        }
        let Some(k) = last.1 else { continue };
        let (u, v) = (p % w, p / w);
        let meets_another = |q: usize| ids[q] != id && colour_of(ids[q]).is_some();
        let border = (u + 1 < w && meets_another(p + 1))
            || (u > 0 && meets_another(p - 1))
            || (p + w < ids.len() && meets_another(p + w))
            || (p >= w && meets_another(p - w));
        let px = img.get_pixel_mut(u as u32, v as u32);
        if border {
            px.0 = INSTANCE_BORDER;
        } else {
            for (out, c) in px.0.iter_mut().zip(colours[k]) {
                *out = ((1.0 - a) * *out as f32 + a * c as f32).round() as u8;
            }
        }
    }
    Ok(colours)
}
