//! Where touching copies meet, read from the depth image alone: concave
//! creases and depth steps, as a [`ContactMap`] for the second look's cut
//! ([`crate::recut::CutProposal::Creases`]).
//!
//! The objects fusepose poses are convex or nearly so (boxes, cans,
//! bottles), so where two of them touch the measured surface folds away
//! from the camera (two cans side by side: a valley several millimetres
//! deep within a centimetre of the contact) or steps (one copy in front of
//! the other). A pixel is on the band when the surface a few millimetres
//! either side of it, along any of four directions, lies in front of it by
//! more than [`CREASE_M`] (the point lies behind the chord between its
//! neighbours, measured in inverse depth so that a slanted plane reads as
//! flat), when a 4-neighbour's depth steps by more than [`STEP_M`] + [`STEP_PER_M`] × z,
//! or when it has no depth (a sensor's holes fall at the steps). Locally
//! convex surfaces (a can's front, a box's edges) are never on it; one
//! object's own concave parts (a mug's inside, a bowl's) are, and the
//! second look's checks (each piece's pose must pass and lie apart from
//! the others) refuse their cuts.
//!
//! [`DepthCreases`] reads one pixel on demand; [`CreaseBand`] marks a
//! region's box once, at every second pixel along each axis (the band is
//! several pixels wide, and each step between two pixels is next to one
//! marked pixel), so a cut's flood reads a byte per pixel. Its buffer is
//! sized per frame size; marking allocates nothing.

use crate::contact_cut::ContactMap;
use crate::frame::FrameView;

/// Depth a point must lie behind the chord between its neighbours to be on
/// a crease (metres).
pub const CREASE_M: f32 = 0.004;
/// Half the chord: how far either side of a pixel its neighbours are taken
/// (metres, projected at the pixel's depth; 2 to [`MAX_SPAN_PX`] pixels).
pub const SPAN_M: f32 = 0.008;
/// Most pixels either side of a pixel the chord reaches.
pub const MAX_SPAN_PX: f32 = 16.0;
/// A depth step between 4-neighbours of more than this plus
/// [`STEP_PER_M`] × z is an edge between surfaces (metres).
pub const STEP_M: f32 = 0.008;
/// The step's growth with depth (sensor noise grows with z).
pub const STEP_PER_M: f32 = 0.01;

/// The crease map of one frame's depth.
pub struct DepthCreases<'a> {
    frame: &'a FrameView<'a>,
}

impl<'a> DepthCreases<'a> {
    pub fn new(frame: &'a FrameView<'a>) -> Self {
        Self { frame }
    }

    fn depth(&self, u: isize, v: isize) -> Option<f32> {
        let (w, h) = (self.frame.width() as isize, self.frame.height() as isize);
        if u < 0 || v < 0 || u >= w || v >= h {
            return None;
        }
        self.frame.depth.metres((v * w + u) as usize)
    }

    /// How far the point at `(u, v)` lies behind the chord between its
    /// neighbours, the deepest of four directions (metres; negative on a
    /// convex surface), or `None` when no direction has both neighbours.
    pub fn concavity(&self, u: usize, v: usize) -> Option<f32> {
        let (u, v) = (u as isize, v as isize);
        let z = self.depth(u, v)?;
        let r = (SPAN_M * self.frame.intrinsics.fx as f32 / z).clamp(2.0, MAX_SPAN_PX).round() as isize;
        [(1, 0), (0, 1), (1, 1), (1, -1)]
            .into_iter()
            .filter_map(|(du, dv)| {
                let a = self.depth(u - r * du, v - r * dv)?;
                let b = self.depth(u + r * du, v + r * dv)?;
                // In inverse depth a plane is affine in the pixel, so its
                // second difference is zero at any slant.
                Some(z * z * (0.5 * (1.0 / a + 1.0 / b) - 1.0 / z))
            })
            .reduce(f32::max)
    }

    /// Whether a 4-neighbour's depth steps away from this pixel's (or is missing).
    pub fn steps(&self, u: usize, v: usize) -> bool {
        let (u, v) = (u as isize, v as isize);
        let Some(z) = self.depth(u, v) else { return true };
        let limit = STEP_M + STEP_PER_M * z;
        let (w, h) = (self.frame.width() as isize, self.frame.height() as isize);
        [(1, 0), (-1, 0), (0, 1), (0, -1)].into_iter().any(|(du, dv)| {
            let (nu, nv) = (u + du, v + dv);
            nu >= 0 && nv >= 0 && nu < w && nv < h && self.depth(nu, nv).is_none_or(|n| (n - z).abs() > limit)
        })
    }
}

impl DepthCreases<'_> {
    /// Whether the pixel is on the band: a step, a hole, or a crease of
    /// [`CREASE_M`] or more.
    pub fn on_band(&self, u: usize, v: usize) -> bool {
        self.steps(u, v) || self.concavity(u, v).is_some_and(|c| c >= CREASE_M)
    }
}

impl ContactMap for DepthCreases<'_> {
    /// 1 on a step or a hole; else the crease depth over twice
    /// [`CREASE_M`], clamped to 0..1 (so the band, 0.5 and up, starts at
    /// [`CREASE_M`]).
    fn contact_at(&self, u: usize, v: usize) -> Option<f32> {
        if self.steps(u, v) {
            return Some(1.0);
        }
        let c = self.concavity(u, v).unwrap_or(0.0);
        Some((c / (2.0 * CREASE_M)).clamp(0.0, 1.0))
    }
}

/// The band of a frame's boxes at half resolution, marked box by box.
#[derive(Default)]
pub struct CreaseBand {
    /// 1 on the band, per 2 × 2 pixel cell.
    band: Vec<u8>,
    /// Cells per row and column.
    cols: usize,
    rows: usize,
}

impl CreaseBand {
    /// Sizes the buffer for frames of `width` × `height` (allocates only
    /// when the size changes).
    pub fn resize(&mut self, width: usize, height: usize) {
        (self.cols, self.rows) = (width.div_ceil(2), height.div_ceil(2));
        if self.band.len() != self.cols * self.rows {
            self.band = vec![0; self.cols * self.rows];
        }
    }

    /// Marks the cells of `bbox` (`[u0, v0, u1, v1]`, inclusive pixels)
    /// whose top-left pixel `in_region` (a frame pixel index) from `frame`'s
    /// depth, each by that pixel; the box's other cells read 0.
    pub fn mark(&mut self, frame: &FrameView<'_>, bbox: [usize; 4], in_region: impl Fn(usize) -> bool) {
        let creases = DepthCreases::new(frame);
        let [u0, v0, u1, v1] = bbox;
        let w = frame.width();
        for j in v0 / 2..=(v1 / 2).min(self.rows.saturating_sub(1)) {
            for i in u0 / 2..=(u1 / 2).min(self.cols.saturating_sub(1)) {
                let on = in_region(2 * j * w + 2 * i) && creases.on_band(2 * i, 2 * j);
                self.band[j * self.cols + i] = on as u8;
            }
        }
    }
}

impl ContactMap for CreaseBand {
    /// 1 on the band, 0 off it, as last marked; `None` outside the frame.
    fn contact_at(&self, u: usize, v: usize) -> Option<f32> {
        let (i, j) = (u / 2, v / 2);
        (i < self.cols && j < self.rows).then(|| self.band[j * self.cols + i] as f32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{ColorFormat, DepthPlane};
    use fusepose_scene::Intrinsics;

    const K: Intrinsics = Intrinsics { fx: 600.0, fy: 600.0, cx: 160.0, cy: 120.0, width: 320, height: 240 };

    /// Depth of each pixel from `z(x, y)` on the ray (x, y in metres per metre of depth).
    fn cast(surface: impl Fn(f64, f64) -> Option<f32>) -> Vec<f32> {
        let (w, h) = (K.width as usize, K.height as usize);
        (0..w * h)
            .map(|p| {
                let (x, y) = (((p % w) as f64 - K.cx) / K.fx, ((p / w) as f64 - K.cy) / K.fy);
                surface(x, y).unwrap_or(0.0)
            })
            .collect()
    }

    fn with_depth<R>(depth: &[f32], f: impl FnOnce(&DepthCreases<'_>) -> R) -> R {
        let color = vec![0u8; depth.len() * 3];
        let view = FrameView {
            intrinsics: K,
            color_format: ColorFormat::Rgb8,
            color: &color,
            depth: DepthPlane::F32(depth),
            labels: None,
        };
        f(&DepthCreases::new(&view))
    }

    /// Ray (x, y, 1) against the vertical cylinder of radius `r` whose axis
    /// passes through (`cx`, ·, `cz`): the nearer hit's depth.
    fn cylinder(x: f64, cx: f64, cz: f64, r: f64) -> Option<f64> {
        // |(t x - cx, t - cz)| = r  →  (x² + 1) t² − 2 (x cx + cz) t + cx² + cz² − r² = 0.
        let (a, b, c) = (x * x + 1.0, -2.0 * (x * cx + cz), cx * cx + cz * cz - r * r);
        let disc = b * b - 4.0 * a * c;
        (disc >= 0.0).then(|| (-b - disc.sqrt()) / (2.0 * a))
    }

    #[test]
    fn a_slanted_plane_is_flat_at_any_depth() {
        // z = 0.6 + 0.4 x_world: 1/z affine in the pixel.
        let depth = cast(|x, y| Some((0.6 / (1.0 - 0.4 * x - 0.2 * y)) as f32));
        with_depth(&depth, |c| {
            for (u, v) in [(40, 40), (160, 120), (280, 200), (100, 180)] {
                let k = c.concavity(u, v).unwrap();
                assert!(k.abs() < 2e-4, "concavity {k} m at ({u}, {v})");
                assert!(c.contact_at(u, v).unwrap() < 0.01);
            }
        });
    }

    #[test]
    fn two_cans_side_by_side_meet_on_a_crease_their_fronts_are_off_it() {
        // Two cans of radius 3.3 cm touching at x = 0, axes 0.5 m away.
        let (r, cz) = (0.033, 0.5);
        let depth = cast(|x, _| {
            let a = cylinder(x, -r, cz, r);
            let b = cylinder(x, r, cz, r);
            a.into_iter().chain(b).reduce(f64::min).map(|z| z as f32)
        });
        with_depth(&depth, |c| {
            let row = 120;
            let band: Vec<usize> = (0..320).filter(|&u| c.contact_at(u, row).is_some_and(|p| p >= 0.5)).collect();
            // The fronts (x = ±3.3 cm at 0.467 m: columns 160 ± 42) are convex.
            for u in [110, 118, 202, 210] {
                assert!(c.contact_at(u, row).unwrap() < 0.5, "front column {u} on the band");
                // Straight along the axis, convex across it.
                assert!(c.concavity(u, row).unwrap() < 1e-4);
            }
            // The contact column and its neighbours are on it, and the band
            // is narrow: it parts the two fronts without eating them.
            assert!(band.contains(&159) && band.contains(&160), "band {band:?}");
            let near: Vec<usize> = band.iter().copied().filter(|u| (140..=180).contains(u)).collect();
            assert!(near.len() <= 20, "band {near:?}");
        });
    }

    #[test]
    fn the_half_resolution_band_holds_every_step_and_the_crease() {
        // A step between columns 200 and 201 (an odd pair) and two cans.
        let (r, cz) = (0.033, 0.5);
        let depth = cast(|x, _| {
            if x > (200.5 - K.cx) / K.fx {
                return Some(0.6);
            }
            let a = cylinder(x, -r, cz, r);
            let b = cylinder(x, r, cz, r);
            a.into_iter().chain(b).reduce(f64::min).map(|z| z as f32).or(Some(0.6))
        });
        let color = vec![0u8; depth.len() * 3];
        let view = FrameView {
            intrinsics: K,
            color_format: ColorFormat::Rgb8,
            color: &color,
            depth: DepthPlane::F32(&depth),
            labels: None,
        };
        let mut band = CreaseBand::default();
        band.resize(320, 240);
        band.mark(&view, [100, 100, 230, 140], |_| true);
        let row: Vec<u8> = (100..=230).map(|u| band.contact_at(u, 120).unwrap() as u8).collect();
        let on = |u: usize| row[u - 100] == 1;
        assert!(on(200) || on(201), "the step");
        assert!(on(159) || on(160), "the crease");
        for u in [110, 118, 184, 190, 220] {
            assert!(!on(u), "column {u} on the band");
        }
        // Off the marked box nothing is on it; off the frame there is no value.
        assert_eq!(band.contact_at(20, 20), Some(0.0));
        assert_eq!(band.contact_at(320, 0), None);
    }

    #[test]
    fn steps_and_holes_are_on_the_band_and_the_surfaces_beside_them_are_not() {
        // Left half 0.5 m, right half 0.56 m, one hole.
        let mut depth = cast(|x, _| Some(if x < 0.0 { 0.5 } else { 0.56 }));
        depth[60 * 320 + 60] = 0.0;
        with_depth(&depth, |c| {
            assert_eq!(c.contact_at(159, 120), Some(1.0));
            assert_eq!(c.contact_at(160, 120), Some(1.0));
            assert_eq!(c.contact_at(60, 60), Some(1.0), "the hole");
            assert_eq!(c.contact_at(61, 60), Some(1.0), "beside the hole");
            // Beside the 6 cm step the surfaces are flat: off the band.
            for u in [100, 150, 170, 250] {
                assert!(c.contact_at(u, 120).unwrap() < 0.5, "column {u}");
            }
        });
    }
}
