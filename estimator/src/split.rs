//! Several objects in one region: a same-class region whose points do not
//! fit inside one object holds more than one copy of it.
//!
//! A class-label plane (from the segmenter or a class-label producer) gives
//! two touching copies of one object a single region, and one pose lands
//! between them. [`RegionSplitter`] is the counterpart of
//! [`crate::parts::PartJoiner`]: where the joiner makes one instance of
//! pieces that fit inside one object, the splitter cuts a region that does
//! not fit inside one into the fewest pieces that each do.
//!
//! The test runs on up to [`SAMPLES`] valid-depth points of the region, one
//! per equal run of its pixels. Points farther than the class's extent from the
//! region's median depth are left out (flying pixels and depth spikes are not
//! a second object). A region fits when all but [`TOLERANCE`] of its point
//! pairs lie within the extent (its diameter × a slack, metres): a mask that
//! bleeds onto the table stretches only the extreme pairs, a second copy many
//! of them. One that does not fit is clustered by k-means in 3D for k = 2, 3,
//! … [`MAX_PIECES`] ([`ITERATIONS`] Lloyd steps on the samples from two
//! deterministic seedings, farthest points and slabs along the principal
//! axis, keeping the tighter result); the
//! first k whose clusters each fit and each hold at least [`MIN_SHARE`] ÷ k
//! of the points wins, and [`FULL_ITERATIONS`] Lloyd steps over its
//! pixels place the cuts. The cut is made only when the pieces share their
//! colours (copies of one object do; [`MAX_CHROMA_DISTANCE`]): a piece of
//! another colour is another object the segmenter gave this class, or what
//! the mask bled onto, and a pose of its own there would be a ghost. A region no k explains stays whole: it is not a group of this
//! object. Every pixel of the region then goes to its nearest cluster: in 3D
//! where it has depth, else by image distance to the cluster's projected
//! centre.
//!
//! A region also does not fit when its area (its valid-depth pixels at
//! their depths) exceeds [`AREA_FACTOR`] × the object's largest silhouette
//! ([`silhouette_areas`]): two boxes side by side along their narrowest
//! side nearly fit the diameter but cover twice a box's face. Each piece
//! must then cover at most that area too.
//!
//! Instance planes never come here: their instances are the producer's.
//! Buffers are sized in [`RegionSplitter::new`] and on the first frame of a
//! size; splitting then never allocates.

use crate::frame::FrameView;
use crate::instances::{InstanceFinder, InstanceLimits, MAX_PIECES};
use crate::parts::ClassExtents;
use crate::sampling::back_project;

/// Points per region used by the test and the clustering.
pub const SAMPLES: usize = 128;
/// Lloyd iterations per k on the samples.
pub const ITERATIONS: usize = 12;
/// Lloyd iterations over the region's pixels once k is chosen.
pub const FULL_ITERATIONS: usize = 3;
/// Most pixels of a region those iterations and the colour test visit.
pub const REFINE_PIXELS: usize = 4096;

/// What the cut needs of each class (index = class id − 1), worked out once
/// at start-up: the extent (the object's diameter × a factor, metres) and
/// the largest silhouette ([`silhouette_areas`], m²; empty = no area test).
/// Empty extents turn the cut off.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CutLimits {
    pub extents: Vec<f32>,
    pub areas: Vec<f32>,
}

impl CutLimits {
    /// Extents of `factor` × each object's diameter and its silhouette
    /// areas; empty (the cut off) when `factor` is not positive.
    pub fn new(objects: &fusepose_scene::ObjectSet, factor: f32) -> Self {
        let extents = crate::parts::extents(objects, factor);
        let areas = if extents.is_empty() { Vec::new() } else { silhouette_areas(objects) };
        Self { extents, areas }
    }
}

/// Cuts same-class regions that hold several objects; see the module doc.
#[derive(Debug)]
pub struct RegionSplitter {
    extents: ClassExtents,
    /// Per class (id − 1): the largest silhouette area of the object over
    /// view directions, m² ([`silhouette_areas`]); 0 = no area test.
    areas: ClassExtents,
    /// Area of the region being tested (its valid-depth pixels), m².
    area: f32,
    /// Sampled points of the region being tested, camera frame, metres.
    samples: Vec<[f32; 3]>,
    /// Depths of the region's valid pixels at the sampling stride (for the median).
    depths: Vec<f32>,
    /// Cluster of each sample.
    cluster: Vec<u8>,
    /// Valid-depth pixels of the region being tested: (index, depth in metres).
    pixels: Vec<(u32, f32)>,
    /// Samples ordered along their principal axis: (position, sample index).
    order: Vec<(f32, u8)>,
    /// Kept regions of the frame: (component id, class id).
    regions: Vec<(u32, u16)>,
}

impl RegionSplitter {
    /// A splitter for at most `max_instances` regions per frame with the
    /// per-class `limits`. Non-finite or non-positive extents never split.
    pub fn new(limits: &CutLimits, max_instances: usize) -> Self {
        Self {
            extents: ClassExtents::new(&limits.extents),
            areas: ClassExtents::new(&limits.areas),
            area: 0.0,
            samples: Vec::with_capacity(SAMPLES),
            depths: Vec::with_capacity(SAMPLES),
            cluster: vec![0; SAMPLES],
            pixels: Vec::new(),
            order: Vec::with_capacity(SAMPLES),
            regions: Vec::with_capacity(max_instances),
        }
    }

    /// Splits the regions of `finder`'s last frame that hold several objects;
    /// returns how many instances were added.
    pub fn split(&mut self, finder: &mut InstanceFinder, frame: &FrameView<'_>, limits: InstanceLimits) -> u32 {
        self.regions.clear();
        let area = frame.width() * frame.height();
        if self.pixels.capacity() < area {
            // Once per frame size: a region can be as large as the frame.
            self.pixels.reserve(area - self.pixels.len());
        }
        let cap = self.regions.capacity();
        self.regions.extend(finder.components().iter().take(cap).map(|c| (c.component_id, c.class_id)));
        let mut added = 0;
        for r in 0..self.regions.len() {
            let (id, class) = self.regions[r];
            let extent = self.extents.of(class);
            if extent <= 0.0 {
                continue;
            }
            self.sample(finder, id, frame, extent);
            let max_area = AREA_FACTOR * self.areas.of(class);
            let too_large = max_area > 0.0 && self.area > max_area;
            if self.samples.len() < 2 * MAX_PIECES || (!too_large && fits(&self.samples, extent, |_| true)) {
                continue;
            }
            let max_area = if max_area > 0.0 { max_area } else { f32::INFINITY };
            let Some((k, centres)) = self.pieces(extent, max_area) else {
                continue;
            };
            let centres = self.refine(frame, centres, k);
            let centres = &centres[..k];
            let pixels: [[f32; 2]; MAX_PIECES] = std::array::from_fn(|i| project(frame, centres.get(i)));
            let piece = |p: usize| nearest_piece(frame, centres, &pixels[..k], p);
            if !self.same_colours(frame, k, &piece) {
                continue;
            }
            added += finder.split(id, limits, |p| Some(piece(p))) as u32;
        }
        added
    }

    /// Samples up to [`SAMPLES`] valid-depth points of region `id`, one per
    /// equal run of its pixels in raster order at a quasi-random place in the
    /// run (an even stride would line up with the columns of a box-shaped
    /// region and miss its edges), leaving out those farther than `extent`
    /// from the median depth.
    fn sample(&mut self, finder: &InstanceFinder, id: u32, frame: &FrameView<'_>, extent: f32) {
        self.samples.clear();
        self.depths.clear();
        self.pixels.clear();
        let Some(c) = finder.components().iter().find(|c| c.component_id == id).copied() else {
            return;
        };
        let ids = finder.component_ids();
        let w = frame.width();
        let [u0, v0, u1, v1] = c.bbox.map(|x| x as usize);
        for v in v0..=v1 {
            for u in u0..=u1 {
                let p = v * w + u;
                if let Some(z) = frame.depth.metres(p).filter(|_| ids.get(p) == Some(&id)) {
                    self.pixels.push((p as u32, z));
                }
            }
        }
        let k = &frame.intrinsics;
        let per_m2 = 1.0 / (k.fx * k.fy) as f32;
        self.area = self.pixels.iter().map(|&(_, z)| z * z * per_m2).sum();
        let count = self.pixels.len();
        let take = count.min(SAMPLES);
        let pick = |i: usize| {
            let phase = (i as f64 * 0.618_033_988_75).fract();
            self.pixels[(((i as f64 + phase) * count as f64 / take as f64) as usize).min(count - 1)]
        };
        self.depths.extend((0..take).map(|i| pick(i).1));
        if self.depths.is_empty() {
            return;
        }
        self.depths.sort_unstable_by(f32::total_cmp);
        let median = self.depths[self.depths.len() / 2];
        for (p, z) in (0..take).map(pick).filter(|&(_, z)| (z - median).abs() <= extent) {
            let p = p as usize;
            self.samples.push(back_project(frame, p % w, p / w, z));
        }
    }

    /// Lloyd steps over the region's valid-depth pixels (up to
    /// [`REFINE_PIXELS`] of them, evenly strided) from the sample clusters'
    /// centres: the samples are few, so their clusters' centres sit off the
    /// region's by up to a sample spacing.
    fn refine(&self, frame: &FrameView<'_>, mut centres: [[f32; 3]; MAX_PIECES], k: usize) -> [[f32; 3]; MAX_PIECES] {
        let w = frame.width();
        let stride = self.pixels.len().div_ceil(REFINE_PIXELS).max(1);
        for _ in 0..FULL_ITERATIONS {
            let mut sums = [[0.0f64; 4]; MAX_PIECES];
            for &(p, z) in self.pixels.iter().step_by(stride) {
                let p = p as usize;
                let q = back_project(frame, p % w, p / w, z);
                let s = &mut sums[nearest(&centres[..k], q)];
                *s = [s[0] + q[0] as f64, s[1] + q[1] as f64, s[2] + q[2] as f64, s[3] + 1.0];
            }
            for (c, s) in centres.iter_mut().zip(&sums).take(k) {
                if s[3] > 0.0 {
                    *c = [(s[0] / s[3]) as f32, (s[1] / s[3]) as f32, (s[2] / s[3]) as f32];
                }
            }
        }
        centres
    }

    /// Whether every piece's mean chromaticity (r, g over r + g + b, of the
    /// region's valid-depth pixels, up to [`REFINE_PIXELS`] of them) lies
    /// within [`MAX_CHROMA_DISTANCE`] of the largest piece's: copies of one
    /// object share their colours (a colour cast shifts all of them alike),
    /// so a region whose pieces differ holds another object the segmenter
    /// gave this class, or one object and what its mask bled onto, and
    /// cutting it would give that piece a pose of its own.
    fn same_colours(&self, frame: &FrameView<'_>, k: usize, piece: &dyn Fn(usize) -> usize) -> bool {
        let stride = self.pixels.len().div_ceil(REFINE_PIXELS).max(1);
        let mut sums = [[0.0f64; 4]; MAX_PIECES];
        for &(p, _) in self.pixels.iter().step_by(stride) {
            let p = p as usize;
            let Some(rgb) = frame.color.get(p * 3..p * 3 + 3) else { continue };
            let s = &mut sums[piece(p)];
            *s = [s[0] + rgb[0] as f64, s[1] + rgb[1] as f64, s[2] + rgb[2] as f64, s[3] + 1.0];
        }
        shared_chroma(&sums[..k])
    }

    /// The fewest clusters (2..=MAX_PIECES) of the samples that each fit `extent`.
    fn pieces(&mut self, extent: f32, max_area: f32) -> Option<(usize, [[f32; 3]; MAX_PIECES])> {
        let n = self.samples.len();
        let area_per_sample = self.area / n.max(1) as f32;
        for k in 2..=MAX_PIECES {
            let centres = kmeans(&self.samples, k, &mut self.cluster[..n], &mut self.order);
            let min_share = (n as f32 * MIN_SHARE / k as f32).ceil() as usize;
            let ok = (0..k).all(|c| {
                let count = self.cluster[..n].iter().filter(|&&x| x as usize == c).count();
                count >= min_share
                    && count as f32 * area_per_sample <= max_area
                    && fits(&self.samples, extent, |i| self.cluster[i] as usize == c)
            });
            if ok {
                return Some((k, centres));
            }
        }
        None
    }
}

/// Per class (index = class id − 1): the largest area, m², of the convex
/// hull of the object's surface samples projected along 64 view directions
/// spread over the sphere — an upper bound of what one copy can cover.
pub fn silhouette_areas(objects: &fusepose_scene::ObjectSet) -> Vec<f32> {
    const DIRECTIONS: usize = 64;
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    objects
        .objects
        .iter()
        .map(|o| {
            let mut best = 0.0f64;
            let mut flat: Vec<[f64; 2]> = Vec::with_capacity(o.samples.len());
            for i in 0..DIRECTIONS {
                let z = 1.0 - 2.0 * (i as f64 + 0.5) / DIRECTIONS as f64;
                let r = (1.0 - z * z).sqrt();
                let d = nalgebra::Vector3::new(r * (golden * i as f64).cos(), r * (golden * i as f64).sin(), z);
                let a = if d.x.abs() < 0.9 { nalgebra::Vector3::x() } else { nalgebra::Vector3::y() };
                let e1 = d.cross(&a).normalize();
                let e2 = d.cross(&e1);
                flat.clear();
                flat.extend(o.samples.iter().map(|p| [p.coords.dot(&e1), p.coords.dot(&e2)]));
                best = best.max(hull_area(&mut flat));
            }
            best as f32
        })
        .collect()
}

/// Area of the convex hull of `points` (sorted in place; monotone chain).
fn hull_area(points: &mut [[f64; 2]]) -> f64 {
    points.sort_unstable_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]);
    let mut hull: Vec<[f64; 2]> = Vec::with_capacity(2 * points.len() + 1);
    for pass in 0..2 {
        let start = hull.len();
        let add = |p: [f64; 2], hull: &mut Vec<[f64; 2]>| {
            while hull.len() >= start + 2 && cross(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0 {
                hull.pop();
            }
            hull.push(p);
        };
        if pass == 0 {
            points.iter().for_each(|&p| add(p, &mut hull));
        } else {
            points.iter().rev().for_each(|&p| add(p, &mut hull));
        }
        hull.pop();
    }
    let n = hull.len();
    (0..n).map(|i| cross([0.0, 0.0], hull[i], hull[(i + 1) % n])).sum::<f64>().abs() / 2.0
}

/// Share of point pairs that may lie farther apart than the extent in one
/// object: the segmenter's masks bleed a cell or two onto the table, which
/// stretches a region's extreme pairs but few of its pairs (chosen on the
/// tuning splits, docs/BENCHMARKS.md).
pub const TOLERANCE: f32 = 0.05;
/// Each of k clusters must hold at least this share of 1/k of the samples.
pub const MIN_SHARE: f32 = 0.5;
/// A region covering more than this × the object's largest silhouette area
/// (`silhouette_areas`) holds more than one copy even when its points fit
/// (copies side by side along their narrowest side), and each piece must
/// cover at most that much (chosen on the tuning splits; the margin is for
/// masks that bleed).
pub const AREA_FACTOR: f32 = 1.3;
/// Most distance between two pieces' mean chromaticities (r, g over
/// r + g + b) for them to be copies of one object (chosen on the tuning
/// splits: copies side by side differ by under 0.04, most regions that took
/// in another object by over 0.1).
pub const MAX_CHROMA_DISTANCE: f64 = 0.08;

/// Whether every piece's mean chromaticity (r, g over r + g + b) lies within
/// [`MAX_CHROMA_DISTANCE`] of the largest piece's, given each piece's sums
/// of R, G, B and its pixel count.
pub fn shared_chroma(sums: &[[f64; 4]]) -> bool {
    let chroma = |s: &[f64; 4]| {
        let t = (s[0] + s[1] + s[2]).max(1.0);
        [s[0] / t, s[1] / t]
    };
    let largest = (0..sums.len()).max_by(|&a, &b| sums[a][3].total_cmp(&sums[b][3])).unwrap_or(0);
    let Some(reference) = sums.get(largest).map(chroma) else { return true };
    sums.iter().all(|s| {
        let c = chroma(s);
        ((c[0] - reference[0]).powi(2) + (c[1] - reference[1]).powi(2)).sqrt() <= MAX_CHROMA_DISTANCE
    })
}

/// Whether at most [`TOLERANCE`] of the pairs of `points` lie farther apart
/// than `extent`.
/// Only the points `i` with `member(i)` take part.
fn fits(points: &[[f32; 3]], extent: f32, member: impl Fn(usize) -> bool) -> bool {
    let e2 = extent * extent;
    let n = (0..points.len()).filter(|&i| member(i)).count();
    let far: usize = (0..points.len())
        .filter(|&i| member(i))
        .map(|i| (i + 1..points.len()).filter(|&j| member(j) && dist2(&points[i], &points[j]) > e2).count())
        .sum();
    far as f32 <= TOLERANCE * (n * n.saturating_sub(1) / 2) as f32
}

/// Where k-means starts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Seeding {
    /// The centroids of k slabs of equal point count along the points'
    /// principal axis: copies in a row (the common layout) start at their
    /// own centres, where Lloyd steps alone drift slowly across a flat run
    /// of points and can settle with slanted cuts.
    Slabs,
    /// The point farthest from the mean, then each next seed farthest from
    /// the seeds so far: copies in a cluster or a ring.
    Farthest,
}

/// k-means ([`ITERATIONS`] Lloyd steps) from each [`Seeding`], keeping the
/// one with the lower sum of squared distances; fills `cluster` and returns
/// the centres (entries past k are zero).
pub(crate) fn kmeans(
    points: &[[f32; 3]],
    k: usize,
    cluster: &mut [u8],
    order: &mut Vec<(f32, u8)>,
) -> [[f32; 3]; MAX_PIECES] {
    let n = points.len() as f32;
    let mean = points.iter().fold([0.0f32; 3], |a, p| [a[0] + p[0] / n, a[1] + p[1] / n, a[2] + p[2] / n]);
    let mut best = ([[0.0f32; 3]; MAX_PIECES], f32::INFINITY);
    for seeding in [Seeding::Farthest, Seeding::Slabs] {
        let mut seeds = [[0.0f32; 3]; MAX_PIECES];
        match seeding {
            Seeding::Farthest => {
                let farthest = |from: &dyn Fn(&[f32; 3]) -> f32| {
                    points.iter().copied().max_by(|a, b| from(a).total_cmp(&from(b))).unwrap_or(mean)
                };
                seeds[0] = farthest(&|p| dist2(p, &mean));
                for j in 1..k {
                    let chosen = &seeds[..j];
                    seeds[j] = farthest(&|p| chosen.iter().map(|c| dist2(p, c)).fold(f32::INFINITY, f32::min));
                }
            }
            Seeding::Slabs => {
                let axis = principal_axis(points, mean);
                order.clear();
                order.extend(points.iter().enumerate().map(|(i, p)| {
                    let d = [p[0] - mean[0], p[1] - mean[1], p[2] - mean[2]];
                    (d[0] * axis[0] + d[1] * axis[1] + d[2] * axis[2], i as u8)
                }));
                order.sort_unstable_by(|x, y| x.0.total_cmp(&y.0));
                let len = order.len();
                for (j, seed) in seeds.iter_mut().enumerate().take(k) {
                    let slab = &order[j * len / k..((j + 1) * len / k).max(j * len / k + 1).min(len)];
                    let m = slab.len() as f32;
                    *seed = slab.iter().fold([0.0f32; 3], |a, &(_, i)| {
                        let p = points[i as usize];
                        [a[0] + p[0] / m, a[1] + p[1] / m, a[2] + p[2] / m]
                    });
                }
            }
        }
        let centres = lloyd(points, seeds, k, cluster);
        let inertia: f32 = points.iter().map(|p| dist2(p, &centres[nearest(&centres[..k], *p)])).sum();
        if inertia < best.1 {
            best = (centres, inertia);
        }
    }
    for (p, c) in points.iter().zip(cluster.iter_mut()) {
        *c = nearest(&best.0[..k], *p) as u8;
    }
    best.0
}

/// [`ITERATIONS`] Lloyd steps from `centres`.
fn lloyd(
    points: &[[f32; 3]],
    mut centres: [[f32; 3]; MAX_PIECES],
    k: usize,
    cluster: &mut [u8],
) -> [[f32; 3]; MAX_PIECES] {
    for _ in 0..ITERATIONS {
        for (p, c) in points.iter().zip(cluster.iter_mut()) {
            *c = nearest(&centres[..k], *p) as u8;
        }
        let mut sums = [[0.0f32; 4]; MAX_PIECES];
        for (p, &c) in points.iter().zip(cluster.iter()) {
            let s = &mut sums[c as usize];
            *s = [s[0] + p[0], s[1] + p[1], s[2] + p[2], s[3] + 1.0];
        }
        for (c, s) in centres.iter_mut().zip(&sums).take(k) {
            if s[3] > 0.0 {
                *c = [s[0] / s[3], s[1] / s[3], s[2] / s[3]];
            }
        }
    }
    centres
}

/// Unit direction of largest spread of `points` about `mean` (power iteration).
fn principal_axis(points: &[[f32; 3]], mean: [f32; 3]) -> [f32; 3] {
    let mut c = [[0.0f32; 3]; 3];
    for p in points {
        let d = [p[0] - mean[0], p[1] - mean[1], p[2] - mean[2]];
        for (r, row) in c.iter_mut().enumerate() {
            for (q, x) in row.iter_mut().enumerate() {
                *x += d[r] * d[q];
            }
        }
    }
    let mut v = [0.577f32, 0.577, 0.577];
    for _ in 0..32 {
        let w = [0, 1, 2].map(|r| c[r][0] * v[0] + c[r][1] * v[1] + c[r][2] * v[2]);
        let norm = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
        if norm.is_nan() || norm <= 0.0 {
            break;
        }
        v = w.map(|x| x / norm);
    }
    v
}

fn dist2(a: &[f32; 3], b: &[f32; 3]) -> f32 {
    let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
}

/// Index of the centre nearest to `p` (0 when there are none).
pub(crate) fn nearest(centres: &[[f32; 3]], p: [f32; 3]) -> usize {
    (0..centres.len()).min_by(|&a, &b| dist2(&centres[a], &p).total_cmp(&dist2(&centres[b], &p))).unwrap_or(0)
}

/// The piece of pixel `p` in a cut between `centres` (their projections
/// `pixels`): the nearest centre in 3D where the pixel has depth, else the
/// nearest projected centre in the image.
pub(crate) fn nearest_piece(frame: &FrameView<'_>, centres: &[[f32; 3]], pixels: &[[f32; 2]], p: usize) -> usize {
    let w = frame.width();
    let (u, v) = (p % w, p / w);
    match frame.depth.metres(p) {
        Some(z) => nearest(centres, back_project(frame, u, v, z)),
        None => nearest_2d(pixels, [u as f32, v as f32]),
    }
}

/// Index of the projected centre nearest to pixel `uv`.
pub(crate) fn nearest_2d(pixels: &[[f32; 2]], uv: [f32; 2]) -> usize {
    let d = |c: &[f32; 2]| (c[0] - uv[0]).powi(2) + (c[1] - uv[1]).powi(2);
    (0..pixels.len()).min_by(|&a, &b| d(&pixels[a]).total_cmp(&d(&pixels[b]))).unwrap_or(0)
}

/// Pixel of a camera-frame point (the origin's pixel for none or z ≤ 0).
pub(crate) fn project(frame: &FrameView<'_>, p: Option<&[f32; 3]>) -> [f32; 2] {
    let k = &frame.intrinsics;
    match p {
        Some(p) if p[2] > 0.0 => {
            [(k.fx * p[0] as f64 / p[2] as f64 + k.cx) as f32, (k.fy * p[1] as f64 / p[2] as f64 + k.cy) as f32]
        }
        _ => [k.cx as f32, k.cy as f32],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{ColorFormat, DepthPlane, LabelPlane};
    use fusepose_scene::Intrinsics;

    const W: usize = 96;
    const H: usize = 32;

    fn intrinsics() -> Intrinsics {
        Intrinsics { fx: 100.0, fy: 100.0, cx: 48.0, cy: 16.0, width: W as u32, height: H as u32 }
    }

    /// Class-1 blocks [u0, u1] × rows 8..24 at 1 m; returns (kept pixel counts, added).
    fn split(extent: f32, blocks: &[(usize, usize)], spike: Option<usize>) -> (Vec<u32>, u32) {
        split_stepped(extent, blocks, spike, 0)
    }

    /// [`split`] with every second block `step` × 0.1 mm farther away.
    fn split_stepped(extent: f32, blocks: &[(usize, usize)], spike: Option<usize>, step: u16) -> (Vec<u32>, u32) {
        split_painted(extent, &[], blocks, spike, step, &[[90, 60, 30]])
    }

    /// [`split_stepped`] with block i painted `colours[i % len]`.
    fn split_painted(
        extent: f32,
        area: &[f32],
        blocks: &[(usize, usize)],
        spike: Option<usize>,
        step: u16,
        colours: &[[u8; 3]],
    ) -> (Vec<u32>, u32) {
        let (mut labels, mut depth) = (vec![0u8; W * H], vec![0u16; W * H]);
        let mut colour = vec![0u8; W * H * 3];
        for (i, &(u0, u1)) in blocks.iter().enumerate() {
            for v in 8..24 {
                for u in u0..=u1 {
                    labels[v * W + u] = 1;
                    depth[v * W + u] = 10_000 + step * (i % 2) as u16;
                    colour[(v * W + u) * 3..(v * W + u) * 3 + 3].copy_from_slice(&colours[i % colours.len()]);
                }
            }
        }
        if let Some(p) = spike {
            depth[p] = 30_000;
        }
        let frame = FrameView {
            intrinsics: intrinsics(),
            color_format: ColorFormat::Rgb8,
            color: &colour,
            depth: DepthPlane::U16 { data: &depth, scale: 1e-4 },
            labels: Some(LabelPlane::U8(&labels)),
        };
        let limits = InstanceLimits { min_pixels: 1, max_instances: 8, num_classes: 0 };
        let mut finder = InstanceFinder::with_capacity(W * H, 8);
        finder.find(&LabelPlane::U8(&labels), W, H, limits);
        let mut splitter = RegionSplitter::new(&CutLimits { extents: vec![extent], areas: area.to_vec() }, 8);
        let added = splitter.split(&mut finder, &frame, limits);
        (finder.components().iter().map(|c| c.pixels).collect(), added)
    }

    #[test]
    fn two_touching_copies_become_two_instances() {
        // Two 16 × 16-pixel blocks side by side (one region, 0.32 m × 0.16 m
        // at 1 m): 27 % of its point pairs are over 0.17 m apart, of one
        // block's 1.2 % (within TOLERANCE).
        let (pixels, added) = split(0.17, &[(20, 35), (36, 51)], None);
        assert_eq!(added, 1);
        assert_eq!(pixels, vec![256, 256]);
    }

    #[test]
    fn touching_regions_of_other_colours_are_not_copies() {
        // The pair of the test above, one block brown and one blue: another
        // object the segmenter gave this class, not a second copy.
        let (pixels, added) = split_painted(0.17, &[], &[(20, 35), (36, 51)], None, 0, &[[90, 60, 30], [30, 60, 120]]);
        assert_eq!((pixels, added), (vec![512], 0));
        // Brighter and darker (light and shadow on two copies) are still copies.
        let (pixels, added) = split_painted(0.17, &[], &[(20, 35), (36, 51)], None, 0, &[[90, 60, 30], [45, 30, 15]]);
        assert_eq!((pixels, added), (vec![256, 256], 1));
    }

    #[test]
    fn a_region_larger_than_one_copy_is_cut_even_when_its_points_fit() {
        // The pair (0.0512 m² at 1 m) fits an extent of 0.4 m, but not 1.3 ×
        // a 0.03 m² silhouette; each block (0.0256 m²) does.
        let pair = [(20, 35), (36, 51)];
        let paint = [[90, 60, 30]];
        assert_eq!(split_painted(0.4, &[0.03], &pair, None, 0, &paint), (vec![256, 256], 1));
        // A silhouette of 0.05 m² could cover it: one object.
        assert_eq!(split_painted(0.4, &[0.05], &pair, None, 0, &paint), (vec![512], 0));
    }

    #[test]
    fn silhouette_area_of_a_box_lies_between_its_largest_face_and_its_bound() {
        let objects = fusepose_scene::builtin::builtin_objects();
        let class = objects.class_of("wood_block").expect("built-in wood block");
        let area = silhouette_areas(&objects)[class as usize - 1] as f64;
        // 0.085 × 0.085 × 0.2 m: largest face 0.017 m²; a box's projection
        // never exceeds the root of the summed squared face areas.
        let faces = [0.085 * 0.2, 0.085 * 0.2, 0.085 * 0.085];
        let bound = faces.iter().map(|a: &f64| a * a).sum::<f64>().sqrt();
        assert!(area > 0.97 * faces[0] && area <= 1.001 * bound, "{area} not in [{}, {bound}]", faces[0]);
    }

    #[test]
    fn one_object_that_fits_stays_whole() {
        let (pixels, added) = split(0.17, &[(20, 35)], None);
        assert_eq!((pixels, added), (vec![256], 0));
        // A depth spike 2 m behind it is no second object.
        let (pixels, added) = split(0.17, &[(20, 35)], Some(12 * W + 25));
        assert_eq!((pixels, added), (vec![256], 0));
    }

    #[test]
    fn four_in_a_row_become_four_and_classes_without_extent_never_split() {
        // Copies in a heap stand at different depths: every second one 5 cm
        // farther. Three pieces of 21 columns would not fit (7.5 % of pairs
        // over 0.17 m even at one depth).
        let blocks = [(0, 15), (16, 31), (32, 47), (48, 63)];
        let (pixels, added) = split_stepped(0.17, &blocks, None, 500);
        assert_eq!((pixels, added), (vec![256; 4], 3));
        // At one depth too (slab seeds start at the copies' centres).
        let (pixels, added) = split(0.17, &blocks, None);
        assert_eq!((pixels, added), (vec![256; 4], 3));
        let (pixels, added) = split(0.0, &[(20, 35), (36, 51)], None);
        assert_eq!((pixels, added), (vec![512], 0));
    }

    #[test]
    fn a_region_no_number_of_copies_explains_stays_whole() {
        // A 0.96 m × 0.16 m slab cannot be cut into ≤ 8 pieces of 0.05 m.
        let (pixels, added) = split(0.05, &[(0, 95)], None);
        assert_eq!((pixels, added), (vec![1536], 0));
    }
}
