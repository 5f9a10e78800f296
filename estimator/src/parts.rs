//! Pieces of one object: same-class regions that an occluder split apart.
//!
//! An object partly hidden behind a nearer one can show up in the label
//! plane as two or more separate regions of its class. Each piece alone gives
//! the estimator fewer points and a worse pose, and the extra pieces become
//! extra (ghost) estimates. [`PartJoiner`] joins two regions of one class
//! when their points, seen together, fit inside one object: every point of
//! one lies within the class's extent (its diameter, metres) of every point
//! of the other. Two objects of one class farther apart than that stay two
//! instances; two that nearly touch can still be joined, which is the price
//! of a class-label plane. Instance-label planes never come here: their
//! instance ids are the producer's and already whole (`Workspace::prepare`
//! skips joining for them).
//!
//! The test runs on up to [`SAMPLES`] points per region, taken at an even
//! stride over its valid-depth pixels. Buffers are sized in
//! [`PartJoiner::new`] for `max_instances` regions; joining never allocates.

use fusepose_scene::ObjectSet;

use crate::frame::FrameView;
use crate::instances::InstanceFinder;
use crate::sampling::back_project;

/// Per-class extents for [`PartJoiner::new`] / `Workspace::join_parts`:
/// each object's diameter × `factor`, metres; empty (never join) when
/// `factor` is not positive.
pub fn extents(objects: &ObjectSet, factor: f32) -> Vec<f32> {
    if factor.is_nan() || factor <= 0.0 {
        return Vec::new();
    }
    objects.objects.iter().map(|o| (o.diameter * factor as f64) as f32).collect()
}

/// Per-class extents (index = class id − 1), metres: the largest distance
/// between two points of one object. Non-finite or non-positive entries,
/// and classes past the table, read as 0 (never join or cut that class).
#[derive(Clone, Debug, Default)]
pub struct ClassExtents(Vec<f32>);

impl ClassExtents {
    pub fn new(extents: &[f32]) -> Self {
        Self(extents.iter().map(|&e| if e.is_finite() && e > 0.0 { e } else { 0.0 }).collect())
    }

    /// The extent of class id `class` (0 when it has none).
    pub fn of(&self, class: u16) -> f32 {
        (class as usize).checked_sub(1).and_then(|k| self.0.get(k)).copied().unwrap_or(0.0)
    }
}

/// Points per region used by the fit test.
pub const SAMPLES: usize = 64;

/// Joins same-class regions that fit inside one object; see the module doc.
#[derive(Debug)]
pub struct PartJoiner {
    extents: ClassExtents,
    /// [max_instances × SAMPLES] points, camera frame, metres.
    samples: Vec<[f32; 3]>,
    /// Sampled points per region.
    counts: Vec<usize>,
    /// Per region: index of the region it joins (itself when none).
    root: Vec<usize>,
    /// Component ids of the regions, in the finder's order before joining.
    ids: Vec<(u32, u16)>,
}

impl PartJoiner {
    /// A joiner for at most `max_instances` regions per frame; `extents[k]`
    /// is the extent of class id k + 1 in metres (an object's diameter, times
    /// a slack for depth noise). Non-finite or negative extents never join.
    pub fn new(extents: &[f32], max_instances: usize) -> Self {
        Self {
            extents: ClassExtents::new(extents),
            samples: vec![[0.0; 3]; max_instances * SAMPLES],
            counts: vec![0; max_instances],
            root: vec![0; max_instances],
            ids: Vec::with_capacity(max_instances),
        }
    }

    /// Joins the pieces among `finder`'s kept regions of the last frame;
    /// returns how many regions were joined into another.
    pub fn join(&mut self, finder: &mut InstanceFinder, frame: &FrameView<'_>) -> u32 {
        let kept = finder.components();
        let n = kept.len().min(self.counts.len());
        self.ids.clear();
        for (k, c) in kept[..n].iter().enumerate() {
            self.ids.push((c.component_id, c.class_id));
            self.root[k] = k;
            self.counts[k] = 0;
        }
        // Only classes with an extent and more than one region need points.
        for k in 0..n {
            let (_, class) = self.ids[k];
            if self.extents.of(class) > 0.0 && self.ids[..n].iter().filter(|(_, c)| *c == class).count() > 1 {
                self.sample(finder, k, frame);
            }
        }
        let mut joined = 0;
        for i in 0..n {
            if self.root[i] != i {
                continue;
            }
            let (_, class) = self.ids[i];
            let extent = self.extents.of(class);
            if extent <= 0.0 {
                continue;
            }
            for j in i + 1..n {
                if self.root[j] != j || self.ids[j].1 != class || self.counts[j] == 0 {
                    continue;
                }
                let fits = (0..j).filter(|&m| self.root[m] == i).all(|m| self.fits(m, j, extent));
                if fits {
                    self.root[j] = i;
                    joined += 1;
                }
            }
        }
        for j in 0..n {
            let i = self.root[j];
            if i != j {
                finder.join(self.ids[i].0, self.ids[j].0);
            }
        }
        joined
    }

    /// Whether every sampled point of region `a` is within `extent` of every one of `b`.
    fn fits(&self, a: usize, b: usize, extent: f32) -> bool {
        if self.counts[a] == 0 || self.counts[b] == 0 {
            return false;
        }
        let pa = &self.samples[a * SAMPLES..a * SAMPLES + self.counts[a]];
        let pb = &self.samples[b * SAMPLES..b * SAMPLES + self.counts[b]];
        let e2 = extent * extent;
        pa.iter().all(|p| {
            pb.iter().all(|q| {
                let d = [p[0] - q[0], p[1] - q[1], p[2] - q[2]];
                d[0] * d[0] + d[1] * d[1] + d[2] * d[2] <= e2
            })
        })
    }

    /// Samples up to [`SAMPLES`] valid-depth points of region `k`, evenly strided.
    fn sample(&mut self, finder: &InstanceFinder, k: usize, frame: &FrameView<'_>) {
        let c = finder.components()[k];
        let ids = finder.component_ids();
        let w = frame.width();
        let [u0, v0, u1, v1] = c.bbox.map(|x| x as usize);
        // Valid-depth pixels of the region in raster order: (u, v, depth in metres).
        let region = || {
            (v0..=v1).flat_map(move |v| (u0..=u1).map(move |u| (u, v))).filter_map(|(u, v)| {
                let p = v * w + u;
                frame.depth.metres(p).filter(|_| ids[p] == c.component_id).map(|z| (u, v, z))
            })
        };
        let stride = region().count().div_ceil(SAMPLES).max(1);
        let out = &mut self.samples[k * SAMPLES..(k + 1) * SAMPLES];
        let mut taken = 0;
        for ((u, v, z), slot) in region().step_by(stride).zip(out.iter_mut()) {
            *slot = back_project(frame, u, v, z);
            taken += 1;
        }
        self.counts[k] = taken;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{ColorFormat, DepthPlane, LabelPlane};
    use crate::instances::InstanceLimits;
    use fusepose_scene::Intrinsics;

    const W: usize = 64;
    const H: usize = 32;

    fn intrinsics() -> Intrinsics {
        Intrinsics { fx: 100.0, fy: 100.0, cx: 32.0, cy: 16.0, width: W as u32, height: H as u32 }
    }

    /// Class 1 in columns [u0, u1] of rows 8..24, at 1 m (depth in 0.1 mm units).
    fn paint(labels: &mut [u8], depth: &mut [u16], u0: usize, u1: usize) {
        for v in 8..24 {
            for u in u0..=u1 {
                labels[v * W + u] = 1;
                depth[v * W + u] = 10_000;
            }
        }
    }

    fn joined(extent: f32, regions: &[(usize, usize)]) -> (u32, Vec<u32>) {
        let (mut labels, mut depth) = (vec![0u8; W * H], vec![0u16; W * H]);
        for &(u0, u1) in regions {
            paint(&mut labels, &mut depth, u0, u1);
        }
        let colour = vec![0u8; W * H * 3];
        let frame = FrameView {
            intrinsics: intrinsics(),
            color_format: ColorFormat::Rgb8,
            color: &colour,
            depth: DepthPlane::U16 { data: &depth, scale: 1e-4 },
            labels: Some(LabelPlane::U8(&labels)),
        };
        let mut finder = InstanceFinder::new();
        let limits = InstanceLimits { min_pixels: 1, max_instances: 4, num_classes: 0 };
        finder.find(&LabelPlane::U8(&labels), W, H, limits);
        let mut joiner = PartJoiner::new(&[extent], 4);
        let n = joiner.join(&mut finder, &frame);
        (n, finder.components().iter().map(|c| c.pixels).collect())
    }

    #[test]
    fn pieces_that_fit_one_object_are_joined() {
        // Two 8-column pieces 4 columns apart: at 1 m and f = 100 px the
        // farthest points are 19 px = 0.19 m across and 0.15 m down (0.24 m).
        let (n, pixels) = joined(0.30, &[(10, 17), (22, 29)]);
        assert_eq!(n, 1);
        assert_eq!(pixels, vec![256]);
    }

    #[test]
    fn pieces_farther_apart_than_the_object_stay_apart() {
        let (n, pixels) = joined(0.20, &[(10, 17), (22, 29)]);
        assert_eq!(n, 0);
        assert_eq!(pixels, vec![128, 128]);
        // A class without an extent is never joined.
        let (n, _) = joined(0.0, &[(10, 17), (22, 29)]);
        assert_eq!(n, 0);
    }

    #[test]
    fn three_pieces_join_only_when_all_fit_together() {
        // Left and right each fit the middle (largest) piece, but not each
        // other: left joins first (raster order), then right no longer fits.
        let (n, pixels) = joined(0.27, &[(0, 7), (12, 21), (24, 31)]);
        assert_eq!(n, 1);
        assert_eq!(pixels, vec![288, 128]);
    }
}
