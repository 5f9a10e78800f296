//! Preallocated per-frame buffers: instances, sampled points, colour crops.
//!
//! [`Workspace::prepare`] runs frame validation → instances (connected
//! components of a class plane, or one instance per instance id of an
//! instance plane; see [`crate::instances`]) → per instance:
//! N sampled valid-depth pixels back-projected to points, an S×S normalised
//! colour crop, and each point's crop cell (see [`crate::sampling`]).
//!
//! Allocation: the arrays are allocated in [`Workspace::new`]; the per-pixel
//! buffers (component ids, flood-fill stack, candidate pixels) are sized on
//! the first frame and grow only when a later frame has more pixels. Frames of
//! a fixed size never allocate after the first.

use ndarray::{Array2, Array3, Array4};
use rand::SeedableRng;
use rand_pcg::Pcg64Mcg;

use crate::frame::{FrameError, FrameView, LabelPlane};
use crate::instances::{Component, InstanceFinder, InstanceLimits, LabelStats};
use crate::parts::PartJoiner;
use crate::resident;
use crate::sampling;
use crate::split::{CutLimits, RegionSplitter};
use crate::support::{self, SupportPlane};
use crate::verify::MaskRef;
use nalgebra::Vector3;

/// Sizes fixed at start-up; buffers are allocated once from them.
///
/// Construct with `..WorkspaceConfig::default()` so added fields keep compiling.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorkspaceConfig {
    /// Most instances kept per frame (largest first).
    pub max_instances: usize,
    /// Points sampled per instance (N).
    pub num_points: usize,
    /// Side of the square colour crop (S).
    pub crop_size: usize,
    /// Smallest connected component kept, in pixels.
    pub min_pixels: usize,
    /// Largest valid class id (the object set's size); label pixels with a
    /// larger id are skipped and counted in [`PrepareStats`]. 0 accepts any id.
    pub num_classes: u16,
    /// Crop margin: the crop side is max(bbox w, h) · (1 + margin).
    pub crop_margin: f32,
    /// Instances with fewer valid-depth pixels than this are dropped (counted).
    pub min_valid_depth: usize,
    /// Pixels lying within this height (metres) of the surface the objects
    /// stand on ([`crate::support`], fitted to the background) are not an
    /// instance's points: a mask that bled onto the table, a shadow or a
    /// table texture taken for an object. 0 (the library default) = off; the
    /// daemon and `fusepose eval` use [`DEFAULT_SUPPORT_FLOOR_M`].
    pub support_floor_m: f32,
}

impl Default for WorkspaceConfig {
    fn default() -> Self {
        Self {
            max_instances: 8,
            num_points: 500,
            crop_size: 64,
            min_pixels: 50,
            num_classes: 0,
            crop_margin: 0.15,
            min_valid_depth: 10,
            support_floor_m: 0.0,
        }
    }
}

/// The support floor the daemon and `fusepose eval` use (metres): chosen on
/// the tuning splits over five sampling seeds (docs/BENCHMARKS.md, "Session
/// 25"); 6 mm added ghosts on the YCB renders.
pub const DEFAULT_SUPPORT_FLOOR_M: f32 = 0.004;

/// Why a [`WorkspaceConfig`] was refused.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum WorkspaceConfigError {
    #[error("max_instances must be in 1..=65535, got {0}")]
    MaxInstances(usize),
    #[error("num_points must be in 1..=1048576, got {0}")]
    NumPoints(usize),
    #[error("crop_size must be in 1..=1024, got {0}")]
    CropSize(usize),
    #[error("crop_margin must be finite and >= 0, got {0}")]
    CropMargin(f32),
    #[error("support_floor_m must be finite and >= 0 (metres), got {0}")]
    SupportFloor(f32),
}

/// One instance found in the label plane.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Instance {
    pub class_id: u16,
    /// Pixels in the connected component.
    pub pixels: u32,
    /// Pixels of the component with valid depth. When fewer than N, the
    /// sampled points repeat (wrap padding) and only the first
    /// `valid_depth_pixels` rows of the instance's points are distinct.
    pub valid_depth_pixels: u32,
    /// [u_min, v_min, u_max, v_max] inclusive.
    pub bbox: [u16; 4],
    /// Crop window in the frame: [u0, v0, side] (square, clamped to the image).
    pub crop_window: [u32; 3],
    /// A second class to estimate this region as (0 = none), set after
    /// [`Workspace::prepare`] by [`crate::alternates::mark`] when the
    /// segmenter was unsure; verification keeps the pose that fits.
    pub alt_class_id: u16,
}

impl Instance {
    /// Distinct points among the instance's N sampled points.
    pub fn distinct_points(&self, num_points: usize) -> usize {
        (self.valid_depth_pixels as usize).min(num_points)
    }
}

/// How far from a hint's projected centre its region may lie, pixels.
pub const HINT_REACH_PX: usize = 12;

/// Most pieces one cut carried between frames holds (and the most the
/// second look cuts a region into, [`crate::recut::RecutConfig::max_pieces`]).
pub const MAX_CUT_PIECES: usize = 6;

/// A cut to make in the next [`Workspace::prepare`]: the region of class
/// `class_id` onto which most of the centres project (camera frame, metres;
/// within [`HINT_REACH_PX`], at least two) is cut between the centres that
/// fall on it, each pixel to its nearest centre. The daemon carries a cut
/// kept in one frame to the next this way ([`crate::recut`]), so the pieces
/// enter that frame's own estimate; a centre whose copy has left the region
/// (moved apart, or out of view) drops out of the cut.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CutHint {
    pub class_id: u16,
    centres: [[f32; 3]; MAX_CUT_PIECES],
    pieces: u8,
}

impl CutHint {
    /// A cut into one piece per centre: `None` for fewer than two centres
    /// or more than [`MAX_CUT_PIECES`].
    pub fn new(class_id: u16, centres: &[[f32; 3]]) -> Option<Self> {
        if !(2..=MAX_CUT_PIECES).contains(&centres.len()) {
            return None;
        }
        let mut all = [[0.0; 3]; MAX_CUT_PIECES];
        all[..centres.len()].copy_from_slice(centres);
        Some(Self { class_id, centres: all, pieces: centres.len() as u8 })
    }

    /// The pieces' centres, camera frame, metres.
    pub fn centres(&self) -> &[[f32; 3]] {
        &self.centres[..self.pieces as usize]
    }
}

/// The pieces a hinted cut made in the last [`Workspace::prepare`]: their
/// component ids ([`Workspace::component_ids`]), the region's own first.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HintedCut {
    ids: [u32; MAX_CUT_PIECES],
    pieces: u8,
}

impl HintedCut {
    pub fn ids(&self) -> &[u32] {
        &self.ids[..self.pieces as usize]
    }
}

/// What [`Workspace::prepare`] skipped in the last frame (for the daemon's counters).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PrepareStats {
    /// Unknown class ids, small components, components beyond `max_instances`.
    pub labels: LabelStats,
    /// Instances dropped for having fewer than `min_valid_depth` valid-depth pixels.
    pub low_depth_instances: u32,
    /// Regions joined into another region of their class as pieces of one
    /// object (see [`Workspace::join_parts`]).
    pub joined_parts: u32,
    /// Instances added by cutting regions that hold several objects of their
    /// class (see [`Workspace::split_regions`]).
    pub split_regions: u32,
}

/// All per-frame buffers. Instance `i` owns row `i` of each array; rows at and
/// beyond `instances.len()` are zero.
pub struct Workspace {
    pub config: WorkspaceConfig,
    /// Instances of the current frame, `len() <= max_instances`, largest first.
    pub instances: Vec<Instance>,
    /// [max_instances, N, 3]: back-projected points, camera frame, metres.
    pub points: Array3<f32>,
    /// [max_instances, 3, S, S]: RGB crops, normalised per channel (ImageNet mean/std).
    pub crops: Array4<f32>,
    /// [max_instances, N]: index (row * S + col) in the crop of each point's pixel.
    pub choose: Array2<u32>,
    finder: InstanceFinder,
    /// Valid-depth pixel indices of the instance being prepared.
    candidates: Vec<u32>,
    /// Sampled pixel indices of the instance being prepared.
    picked: Vec<u32>,
    /// Joins same-class pieces of one object; `None` keeps every region.
    joiner: Option<PartJoiner>,
    /// Cuts same-class regions that hold several objects; `None` keeps every region.
    splitter: Option<RegionSplitter>,
    /// Cuts for the next frame ([`Workspace::set_cut_hints`]) and the
    /// component ids of the pieces they made in the last one.
    hints: Vec<CutHint>,
    hinted: Vec<HintedCut>,
    stats: PrepareStats,
    /// Background points the support plane is fitted to, and the plane of the
    /// current frame (`None`: off, or no plane found).
    support_points: Vec<Vector3<f32>>,
    support: Option<SupportPlane>,
    /// Per class (id − 1): its support floor ([`Workspace::support_floors`]);
    /// empty = `config.support_floor_m` for all.
    class_floors: Vec<f32>,
}

/// The support plane is fitted to every this-many-th background pixel in
/// each direction.
const SUPPORT_STRIDE: usize = 8;

impl Workspace {
    /// Allocates every buffer for `config`.
    pub fn new(config: WorkspaceConfig) -> Result<Self, WorkspaceConfigError> {
        if config.max_instances == 0 || config.max_instances > u16::MAX as usize {
            return Err(WorkspaceConfigError::MaxInstances(config.max_instances));
        }
        if config.num_points == 0 || config.num_points > 1 << 20 {
            return Err(WorkspaceConfigError::NumPoints(config.num_points));
        }
        if config.crop_size == 0 || config.crop_size > 1024 {
            return Err(WorkspaceConfigError::CropSize(config.crop_size));
        }
        if !(config.crop_margin.is_finite() && config.crop_margin >= 0.0) {
            return Err(WorkspaceConfigError::CropMargin(config.crop_margin));
        }
        if !(config.support_floor_m.is_finite() && config.support_floor_m >= 0.0) {
            return Err(WorkspaceConfigError::SupportFloor(config.support_floor_m));
        }
        let (m, n, s) = (config.max_instances, config.num_points, config.crop_size);
        Ok(Self {
            config,
            instances: Vec::with_capacity(m),
            // Resident now: a frame with more instances than any before
            // would otherwise fault pages in mid-run (`crate::resident`).
            points: resident::array((m, n, 3), 0.0),
            crops: resident::array((m, 3, s, s), 0.0),
            choose: resident::array((m, n), 0),
            finder: InstanceFinder::with_capacity(0, m),
            candidates: Vec::new(),
            picked: resident::vec(0, n),
            joiner: None,
            splitter: None,
            hints: Vec::with_capacity(m),
            hinted: Vec::with_capacity(m),
            stats: PrepareStats::default(),
            support_points: Vec::new(),
            support: None,
            class_floors: Vec::new(),
        })
    }

    /// Validates `frame`, finds its instances in the label plane and fills
    /// `points`, `crops` and `choose` for each; returns the instance count.
    ///
    /// `frame_seed` seeds the point sampling (same frame + seed → same
    /// points). Instances with fewer than `min_valid_depth` valid-depth pixels
    /// are dropped and counted in [`Workspace::stats`]. On error the
    /// workspace holds no instances.
    pub fn prepare(&mut self, frame: &FrameView<'_>, frame_seed: u64) -> Result<usize, FrameError> {
        self.instances.clear();
        self.stats = PrepareStats::default();
        frame.validate()?;
        let labels: LabelPlane<'_> = frame.labels.ok_or(FrameError::MissingLabels)?;
        let (w, h) = (frame.width(), frame.height());
        let limits = InstanceLimits {
            min_pixels: self.config.min_pixels.max(1),
            max_instances: self.config.max_instances,
            num_classes: self.config.num_classes,
        };
        self.finder.find(&labels, w, h, limits);
        self.stats.labels = self.finder.stats();
        // An instance plane's instances are the producer's: never joined (each
        // instance id is already whole, however its pixels are split).
        if let Some(joiner) = self.joiner.as_mut().filter(|_| !labels.is_instances()) {
            self.stats.joined_parts = joiner.join(&mut self.finder, frame);
        }
        if let Some(splitter) = self.splitter.as_mut().filter(|_| !labels.is_instances()) {
            self.stats.split_regions = splitter.split(&mut self.finder, frame, limits);
        }
        self.hinted.clear();
        if !labels.is_instances() {
            self.apply_hints(frame, limits);
        }
        self.hints.clear();
        if self.candidates.capacity() < w * h {
            let additional = w * h - self.candidates.len();
            resident::reserve(&mut self.candidates, additional);
        }
        self.fit_support(frame, &labels);
        let mut rng = Pcg64Mcg::seed_from_u64(frame_seed);
        for k in 0..self.finder.components().len() {
            let component = self.finder.components()[k];
            self.prepare_instance(frame, component, &mut rng);
        }
        self.zero_unused_rows();
        Ok(self.instances.len())
    }

    /// From the next frame on, joins regions of one class of a class plane into
    /// one instance when their points fit inside one object (see [`crate::parts`];
    /// instance planes are never joined):
    /// `extents[k]` is the largest distance in metres between two points of
    /// class id k + 1 (its diameter). An empty slice turns joining off.
    /// Allocates; call it at start-up, not per frame.
    pub fn join_parts(&mut self, extents: &[f32]) {
        self.joiner = (!extents.is_empty()).then(|| PartJoiner::new(extents, self.config.max_instances));
    }

    /// From the next frame on, cuts a region of one class of a class plane
    /// whose points do not fit inside one object into the fewest pieces that
    /// each do (see [`crate::split`]; instance planes are never cut):
    /// `limits` from [`CutLimits::new`]; empty extents turn splitting off.
    /// Allocates; call it at start-up, not per frame.
    pub fn split_regions(&mut self, limits: &CutLimits) {
        self.splitter = (!limits.extents.is_empty()).then(|| RegionSplitter::new(limits, self.config.max_instances));
    }

    /// From the next frame on, the support floor of class id k + 1 is
    /// `floors[k]` (see [`crate::support::class_floors`]: thin objects get a
    /// lower one), capped by `config.support_floor_m` (which still turns the
    /// floor off at 0). Allocates; call it at start-up, not per frame.
    pub fn support_floors(&mut self, floors: &[f32]) {
        self.class_floors = floors.to_vec();
    }

    /// Cuts instance `i`'s region in two after its estimate
    /// ([`crate::recut`]): `piece_of(pixel index)` is 0 for the pixels that
    /// stay with instance `i` and 1 for those that become a new instance,
    /// appended last. Returns the new instance's index, or `None`, changing
    /// nothing, when `i` has no region, the instance list or the region list
    /// is full, or a piece would be empty. The new instance's rows of
    /// `points`, `crops` and `choose` are not filled: it is for the steps
    /// after the estimate (verification, masks, the published box). No
    /// allocation.
    pub fn cut_instance(
        &mut self,
        frame: &FrameView<'_>,
        i: usize,
        mut piece_of: impl FnMut(usize) -> usize,
    ) -> Option<usize> {
        let id = self.component_id(i)?;
        let max = self.config.max_instances;
        if self.instances.len() >= max || self.finder.components().len() >= max {
            return None;
        }
        let inst = self.instances[i];
        let w = frame.width();
        let ids = self.finder.component_ids();
        let [u0, v0, u1, v1] = inst.bbox.map(|x| x as usize);
        let mut counts = [0usize; 2];
        for v in v0..=v1 {
            for u in u0..=u1 {
                let p = v * w + u;
                if ids.get(p) == Some(&id) {
                    counts[piece_of(p).min(1)] += 1;
                }
            }
        }
        if counts.contains(&0) {
            return None;
        }
        let new_id = self.finder.next_split_id();
        let limits = InstanceLimits { min_pixels: 1, max_instances: max, num_classes: self.config.num_classes };
        if self.finder.split(id, limits, |p| Some(piece_of(p).min(1))) != 1 {
            return None;
        }
        let h = frame.height();
        let margin = self.config.crop_margin;
        let ids = self.finder.component_ids();
        let instance = |c: Component| {
            let [u0, v0, u1, v1] = c.bbox.map(|x| x as usize);
            let valid = (v0..=v1)
                .flat_map(|v| (u0..=u1).map(move |u| v * w + u))
                .filter(|&p| ids[p] == c.component_id && frame.depth.metres(p).is_some())
                .count();
            Instance {
                class_id: c.class_id,
                pixels: c.pixels,
                valid_depth_pixels: valid as u32,
                bbox: c.bbox,
                crop_window: sampling::crop_window(c.bbox, margin, w, h),
                alt_class_id: 0,
            }
        };
        let find = |want: u32| self.finder.components().iter().copied().find(|c| c.component_id == want);
        let (Some(kept), Some(new)) = (find(id), find(new_id)) else { return None };
        let (kept, new) = (instance(kept), instance(new));
        self.instances[i] = Instance { alt_class_id: inst.alt_class_id, ..kept };
        self.instances.push(new);
        Some(self.instances.len() - 1)
    }

    /// Cuts to make in the next [`prepare`](Self::prepare) only (class
    /// planes only; see [`CutHint`]); at most `max_instances` are kept. No
    /// allocation.
    pub fn set_cut_hints(&mut self, hints: &[CutHint]) {
        self.hints.clear();
        let room = self.hints.capacity();
        self.hints.extend(hints.iter().take(room));
    }

    /// The pieces of each cut the last [`prepare`](Self::prepare) made from
    /// its hints (the pieces that kept enough pixels; at least two).
    pub fn hinted_pieces(&self) -> &[HintedCut] {
        &self.hinted
    }

    /// Makes the hinted cuts: each hint's centres project onto (or within
    /// [`HINT_REACH_PX`] of) regions of its class, a piece's centre can lie
    /// off its own pixels (the notch of an L, the hole of a mug); the region
    /// most of them fall on is cut between those, when they are two or more.
    fn apply_hints(&mut self, frame: &FrameView<'_>, limits: InstanceLimits) {
        let (w, h) = (frame.width(), frame.height());
        for k in 0..self.hints.len() {
            let hint = self.hints[k];
            let all = hint.centres();
            let ids = self.finder.component_ids();
            let components = self.finder.components();
            let of_class =
                |id: u32| id != 0 && components.iter().any(|c| c.component_id == id && c.class_id == hint.class_id);
            // The region of the hint's class nearest to a projected centre.
            let region_at = |[u, v]: [f32; 2]| {
                let (u, v) = (u.round() as i64, v.round() as i64);
                let r = HINT_REACH_PX as i64;
                let mut best: Option<(i64, u32)> = None;
                for y in (v - r).max(0)..=(v + r).min(h as i64 - 1) {
                    for x in (u - r).max(0)..=(u + r).min(w as i64 - 1) {
                        let id = ids[y as usize * w + x as usize];
                        let d = (x - u).pow(2) + (y - v).pow(2);
                        if best.is_none_or(|(bd, _)| d < bd) && of_class(id) {
                            best = Some((d, id));
                        }
                    }
                }
                best.map(|(_, id)| id)
            };
            let mut pixels = [[0.0f32; 2]; MAX_CUT_PIECES];
            let mut regions = [None; MAX_CUT_PIECES];
            for (i, c) in all.iter().enumerate() {
                pixels[i] = crate::split::project(frame, Some(c));
                regions[i] = region_at(pixels[i]);
            }
            let regions = &regions[..all.len()];
            let hits = |id: u32| regions.iter().filter(|&&r| r == Some(id)).count();
            // The region most centres fall on (the first such on a tie).
            let Some(id) = regions.iter().flatten().copied().max_by_key(|&id| (hits(id), std::cmp::Reverse(id))) else {
                continue;
            };
            if hits(id) < 2 {
                continue;
            }
            let (mut centres, mut at) = ([[0.0f32; 3]; MAX_CUT_PIECES], [[0.0f32; 2]; MAX_CUT_PIECES]);
            let mut m = 0;
            for i in (0..all.len()).filter(|&i| regions[i] == Some(id)) {
                (centres[m], at[m]) = (all[i], pixels[i]);
                m += 1;
            }
            let first_new = self.finder.next_split_id();
            let piece = |p: usize| Some(crate::split::nearest_piece(frame, &centres[..m], &at[..m], p));
            if self.finder.split(id, limits, piece) == 0 || self.hinted.len() >= self.hinted.capacity() {
                continue;
            }
            // The pieces still kept (a sliver under `min_pixels` is dropped).
            let mut cut = HintedCut { ids: [0; MAX_CUT_PIECES], pieces: 0 };
            let kept = |want: u32| self.finder.components().iter().any(|c| c.component_id == want);
            for want in std::iter::once(id).chain((0..m as u32 - 1).map(|j| first_new + j)).filter(|&c| kept(c)) {
                cut.ids[cut.pieces as usize] = want;
                cut.pieces += 1;
            }
            if cut.pieces >= 2 {
                self.hinted.push(cut);
            }
        }
    }

    /// What the last [`prepare`](Self::prepare) skipped.
    pub fn stats(&self) -> PrepareStats {
        self.stats
    }

    /// Per-pixel component ids of the last frame (row-major; 0 = none). A
    /// pixel belongs to instance `i` when it lies in `instances[i].bbox` and
    /// its id equals [`Workspace::component_id`]`(i)`.
    pub fn component_ids(&self) -> &[u32] {
        self.finder.component_ids()
    }

    /// Component id of instance `i` in [`Workspace::component_ids`].
    pub fn component_id(&self, i: usize) -> Option<u32> {
        let inst = self.instances.get(i)?;
        self.finder
            .components()
            .iter()
            .find(|c| c.bbox == inst.bbox && c.class_id == inst.class_id && c.pixels == inst.pixels)
            .map(|c| c.component_id)
    }

    /// Points of instance `i`: N rows of [x, y, z] metres, camera frame.
    pub fn instance_points(&self, i: usize) -> &[[f32; 3]] {
        let n = self.config.num_points;
        match self.points.as_slice() {
            Some(all) if i < self.config.max_instances => as_xyz(&all[i * n * 3..(i + 1) * n * 3]),
            _ => &[],
        }
    }

    /// Region `id`'s mask (a component id of [`Workspace::component_ids`])
    /// with box `bbox`, for verification.
    pub fn mask_ref(&self, id: u32, bbox: [u16; 4]) -> MaskRef<'_> {
        MaskRef { ids: self.component_ids(), id, bbox }
    }

    /// The plane the last frame's objects stand on, when the support floor
    /// is on and the background held one.
    pub fn support_plane(&self) -> Option<SupportPlane> {
        self.support
    }

    /// Height above the support plane under which a point is the table's
    /// rather than an object of `class_id`'s (metres; 0 = off).
    pub fn class_floor(&self, class_id: u16) -> f32 {
        match self.class_floors.get((class_id as usize).wrapping_sub(1)) {
            Some(&f) => f.min(self.config.support_floor_m),
            None => self.config.support_floor_m,
        }
    }

    /// Share of region `id`'s pixels with depth (within `bbox`, every
    /// second row and column) whose points lie on the support plane: lower
    /// than twice `class_id`'s floor (at the floor itself depth noise leaves
    /// table pixels scattered over the region). None when this frame has no
    /// support plane, the class no floor or the region no pixel with depth.
    pub fn share_on_support(&self, frame: &FrameView<'_>, id: u32, class_id: u16, bbox: [u16; 4]) -> Option<f32> {
        let (mut with_depth, mut on_table) = (0u32, 0u32);
        self.each_off_support(frame, id, class_id, bbox, 2, |_, on| {
            with_depth += on.is_some() as u32;
            on_table += (on == Some(true)) as u32;
        })?;
        (with_depth > 0).then(|| on_table as f32 / with_depth as f32)
    }

    /// Writes `id` into `out` (a plane of the frame's size, zero in `bbox`)
    /// at region `id`'s pixels within `bbox` that do not lie on the support
    /// plane as [`Workspace::share_on_support`] judges (pixels without depth
    /// included: no evidence either way); returns their box (u_min > u_max
    /// when none). None as for `share_on_support`. No allocation.
    pub fn write_off_support(
        &self,
        frame: &FrameView<'_>,
        id: u32,
        class_id: u16,
        bbox: [u16; 4],
        out: &mut [u32],
    ) -> Option<[u16; 4]> {
        if out.len() < frame.width() * frame.height() {
            return None;
        }
        let mut b = [u16::MAX, u16::MAX, 0, 0];
        self.each_off_support(frame, id, class_id, bbox, 1, |p, on| {
            if on != Some(true) {
                out[p] = id;
                let (u, v) = ((p % frame.width()) as u16, (p / frame.width()) as u16);
                b = [b[0].min(u), b[1].min(v), b[2].max(u), b[3].max(v)];
            }
        })?;
        Some(b)
    }

    /// Calls `f(pixel, on the table?)` (None: no depth) for region `id`'s
    /// pixels within `bbox`, every `step`-th row and column.
    fn each_off_support(
        &self,
        frame: &FrameView<'_>,
        id: u32,
        class_id: u16,
        bbox: [u16; 4],
        step: usize,
        mut f: impl FnMut(usize, Option<bool>),
    ) -> Option<()> {
        let floor = self.class_floor(class_id);
        let plane = self.support.filter(|_| floor > 0.0)?;
        let (w, h) = (frame.width(), frame.height());
        let ids = self.finder.component_ids();
        if ids.len() < w * h || w == 0 || h == 0 {
            return None;
        }
        let [u0, v0, u1, v1] = bbox.map(|x| x as usize);
        for v in (v0..=v1.min(h - 1)).step_by(step) {
            for u in (u0..=u1.min(w - 1)).step_by(step) {
                let p = v * w + u;
                if ids[p] != id {
                    continue;
                }
                let on = frame
                    .depth
                    .metres(p)
                    .map(|z| plane.height(&sampling::back_project(frame, u, v, z).into()).abs() < 2.0 * floor);
                f(p, on);
            }
        }
        Some(())
    }

    /// Fits the support plane of this frame to its background pixels (see
    /// [`WorkspaceConfig::support_floor_m`]). A plane with more than
    /// [`support::MAX_BELOW_SHARE`] of the objects' points under it is not
    /// the one they stand on: the frame then has none. (Fitting again to
    /// every pixel would find the table a segmenter gave a class, but also
    /// a box's top where no table is in view.)
    fn fit_support(&mut self, frame: &FrameView<'_>, labels: &LabelPlane<'_>) {
        self.support = None;
        if self.config.support_floor_m <= 0.0 {
            return;
        }
        let (w, h) = (frame.width(), frame.height());
        // Sized on the first frame of a size; a no-op after.
        self.support_points.clear();
        self.support_points.reserve(w.div_ceil(SUPPORT_STRIDE) * h.div_ceil(SUPPORT_STRIDE));
        // The background's points first, then the objects': they stand on the plane, not under it.
        let mut background = 0;
        for on_background in [true, false] {
            for v in (SUPPORT_STRIDE / 2..h).step_by(SUPPORT_STRIDE) {
                for u in (SUPPORT_STRIDE / 2..w).step_by(SUPPORT_STRIDE) {
                    let p = v * w + u;
                    if (labels.class_at(p) == 0) == on_background
                        && let Some(z) = frame.depth.metres(p)
                    {
                        self.support_points.push(sampling::back_project(frame, u, v, z).into());
                    }
                }
            }
            if on_background {
                background = self.support_points.len();
            }
        }
        let (bg, objects) = self.support_points.split_at(background);
        self.support =
            support::fit(bg).filter(|plane| support::share_below(plane, objects) <= support::MAX_BELOW_SHARE);
    }

    fn prepare_instance(&mut self, frame: &FrameView<'_>, component: Component, rng: &mut Pcg64Mcg) {
        let w = frame.width();
        let [u_min, v_min, u_max, v_max] = component.bbox.map(|x| x as usize);
        self.candidates.clear();
        let ids = self.finder.component_ids();
        let floor = self.class_floor(component.class_id);
        // No floor for this class: no pixel needs back-projecting.
        let support = self.support.filter(|_| floor > 0.0);
        for v in v_min..=v_max {
            for u in u_min..=u_max {
                let p = v * w + u;
                if ids[p] != component.component_id {
                    continue;
                }
                let Some(z) = frame.depth.metres(p) else { continue };
                let on_support = support
                    .is_some_and(|plane| plane.height(&sampling::back_project(frame, u, v, z).into()).abs() < floor);
                if !on_support {
                    self.candidates.push(p as u32);
                }
            }
        }
        let valid = self.candidates.len();
        if valid < self.config.min_valid_depth.max(1) {
            self.stats.low_depth_instances += 1;
            return;
        }
        let k = self.instances.len();
        let (n, s) = (self.config.num_points, self.config.crop_size);
        sampling::sample_pixels(&mut self.candidates, &mut self.picked, rng);
        let window = sampling::crop_window(component.bbox, self.config.crop_margin, w, frame.height());
        // The arrays are created in standard layout by `new`; a caller that
        // swapped in a non-contiguous array gets no instance rather than a panic.
        let (Some(points), Some(choose), Some(crops)) =
            (self.points.as_slice_mut(), self.choose.as_slice_mut(), self.crops.as_slice_mut())
        else {
            return;
        };
        let points = &mut points[k * n * 3..(k + 1) * n * 3];
        let choose = &mut choose[k * n..(k + 1) * n];
        for (i, &p) in self.picked.iter().enumerate() {
            let p = p as usize;
            let (u, v) = (p % w, p / w);
            let z = frame.depth.metres(p).unwrap_or(0.0);
            points[i * 3..i * 3 + 3].copy_from_slice(&sampling::back_project(frame, u, v, z));
            choose[i] = sampling::crop_cell(u, v, window, s);
        }
        sampling::resample_crop(frame, window, s, &mut crops[k * 3 * s * s..(k + 1) * 3 * s * s]);
        self.instances.push(Instance {
            class_id: component.class_id,
            pixels: component.pixels,
            valid_depth_pixels: valid as u32,
            bbox: component.bbox,
            crop_window: window,
            alt_class_id: 0,
        });
    }

    fn zero_unused_rows(&mut self) {
        let k = self.instances.len();
        let (n, s) = (self.config.num_points, self.config.crop_size);
        if let Some(p) = self.points.as_slice_mut() {
            p[k * n * 3..].fill(0.0);
        }
        if let Some(c) = self.choose.as_slice_mut() {
            c[k * n..].fill(0);
        }
        if let Some(c) = self.crops.as_slice_mut() {
            c[k * 3 * s * s..].fill(0.0);
        }
    }
}

/// Views a flat xyz slice (length a multiple of 3) as points.
fn as_xyz(flat: &[f32]) -> &[[f32; 3]] {
    let (chunks, _) = flat.as_chunks::<3>();
    chunks
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{ColorFormat, DepthPlane};
    use fusepose_scene::Intrinsics;

    const W: usize = 64;
    const H: usize = 48;

    struct Scene {
        color: Vec<u8>,
        depth: Vec<u16>,
        labels: Vec<u8>,
    }

    fn intrinsics() -> Intrinsics {
        Intrinsics { fx: 60.0, fy: 60.0, cx: 32.0, cy: 24.0, width: W as u32, height: H as u32 }
    }

    /// Class 1: 20x10 rect at (5, 5); class 2: 8x8 rect at (40, 30).
    /// Depth 1.0 m everywhere except a hole in the class-2 rect.
    fn scene() -> Scene {
        let mut s = Scene { color: vec![0; W * H * 3], depth: vec![1000; W * H], labels: vec![0; W * H] };
        for v in 0..H {
            for u in 0..W {
                let p = v * W + u;
                s.color[p * 3..p * 3 + 3].copy_from_slice(&[u as u8 * 3, v as u8 * 5, 77]);
                if (5..25).contains(&u) && (5..15).contains(&v) {
                    s.labels[p] = 1;
                }
                if (40..48).contains(&u) && (30..38).contains(&v) {
                    s.labels[p] = 2;
                    if u >= 44 {
                        s.depth[p] = 0;
                    }
                }
            }
        }
        s
    }

    fn frame(s: &Scene) -> FrameView<'_> {
        FrameView {
            intrinsics: intrinsics(),
            color_format: ColorFormat::Rgb8,
            color: &s.color,
            depth: DepthPlane::U16 { data: &s.depth, scale: 0.001 },
            labels: Some(LabelPlane::U8(&s.labels)),
        }
    }

    fn config() -> WorkspaceConfig {
        WorkspaceConfig { max_instances: 4, num_points: 100, crop_size: 16, min_pixels: 20, ..Default::default() }
    }

    #[test]
    fn prepare_fills_points_crops_and_choose_per_instance() {
        let s = scene();
        let mut ws = Workspace::new(config()).unwrap();
        let n = ws.prepare(&frame(&s), 7).unwrap();
        assert_eq!(n, 2);
        let a = ws.instances[0];
        assert_eq!((a.class_id, a.pixels, a.valid_depth_pixels, a.bbox), (1, 200, 200, [5, 5, 24, 14]));
        let b = ws.instances[1];
        assert_eq!((b.class_id, b.pixels, b.valid_depth_pixels), (2, 64, 32));
        // Every point of instance 0 back-projects a pixel of the rect at z = 1 m.
        for p in ws.instance_points(0) {
            assert!((p[2] - 1.0).abs() < 1e-6);
            let u = p[0] as f64 * 60.0 + 32.0;
            let v = p[1] as f64 * 60.0 + 24.0;
            assert!((5.0 - 1e-3..24.0 + 1e-3).contains(&u) && (5.0 - 1e-3..14.0 + 1e-3).contains(&v), "{u} {v}");
        }
        // Instance 1 has 32 valid pixels for 100 points: wrap padded.
        let pts = ws.instance_points(1);
        for i in 32..100 {
            assert_eq!(pts[i], pts[i % 32]);
            assert_eq!(ws.choose[[1, i]], ws.choose[[1, i % 32]]);
        }
        // Its points avoid the depth hole (u >= 44).
        assert!(pts.iter().all(|p| p[0] as f64 * 60.0 + 32.0 < 44.0 - 1e-3));
        // Unused rows are zero.
        assert!(ws.points.slice(ndarray::s![2.., .., ..]).iter().all(|&x| x == 0.0));
        assert!(ws.choose.slice(ndarray::s![2.., ..]).iter().all(|&x| x == 0));
    }

    #[test]
    fn choose_points_at_the_crop_cell_of_each_pixel() {
        let s = scene();
        let mut ws = Workspace::new(config()).unwrap();
        ws.prepare(&frame(&s), 1).unwrap();
        let inst = ws.instances[0];
        let [u0, v0, side] = inst.crop_window;
        let sz = 16usize;
        for (i, p) in ws.instance_points(0).iter().enumerate() {
            let u = (p[0] as f64 * 60.0 + 32.0).round() as usize;
            let v = (p[1] as f64 * 60.0 + 24.0).round() as usize;
            let cell = ws.choose[[0, i]] as usize;
            let (row, col) = (cell / sz, cell % sz);
            // The cell's footprint in the frame contains the pixel centre.
            let scale = side as f64 / sz as f64;
            let (cu0, cv0) = (u0 as f64 - 0.5 + col as f64 * scale, v0 as f64 - 0.5 + row as f64 * scale);
            assert!((cu0..cu0 + scale + 1e-9).contains(&(u as f64)), "u {u} col {col}");
            assert!((cv0..cv0 + scale + 1e-9).contains(&(v as f64)), "v {v} row {row}");
            // Red channel encodes u (3u/255): the crop value at the cell is
            // within one bilinear step of the pixel's own colour.
            let red = ws.crops[[0, 0, row, col]] * sampling::IMAGENET_STD[0] + sampling::IMAGENET_MEAN[0];
            let red_u = red as f64 * 255.0 / 3.0;
            assert!((red_u - u as f64).abs() <= scale / 2.0 + 0.01, "{red_u} vs {u}");
        }
    }

    #[test]
    fn same_seed_same_sample_and_errors_clear_instances() {
        let s = scene();
        let mut ws = Workspace::new(config()).unwrap();
        ws.prepare(&frame(&s), 3).unwrap();
        let first = ws.points.clone();
        ws.prepare(&frame(&s), 3).unwrap();
        assert_eq!(first, ws.points);
        ws.prepare(&frame(&s), 4).unwrap();
        assert_ne!(first, ws.points);
        let mut f = frame(&s);
        f.labels = None;
        assert_eq!(ws.prepare(&f, 0), Err(FrameError::MissingLabels));
        assert!(ws.instances.is_empty());
        let mut f = frame(&s);
        f.intrinsics.fx = 0.0;
        assert!(matches!(ws.prepare(&f, 0), Err(FrameError::BadFocalLength { .. })));
    }

    #[test]
    fn low_depth_instances_are_dropped_and_counted() {
        let mut s = scene();
        for v in 30..38 {
            for u in 40..48 {
                s.depth[v * W + u] = 0;
            }
        }
        s.depth[30 * W + 40] = 900;
        let mut ws = Workspace::new(config()).unwrap();
        assert_eq!(ws.prepare(&frame(&s), 0).unwrap(), 1);
        assert_eq!(ws.stats().low_depth_instances, 1);
        assert_eq!(ws.component_id(0), Some(ws.component_ids()[5 * W + 5]));
    }

    #[test]
    fn bad_configs_are_refused() {
        let bad = |c: WorkspaceConfig| Workspace::new(c).err();
        let base = config();
        assert_eq!(bad(WorkspaceConfig { max_instances: 0, ..base }), Some(WorkspaceConfigError::MaxInstances(0)));
        assert_eq!(bad(WorkspaceConfig { num_points: 0, ..base }), Some(WorkspaceConfigError::NumPoints(0)));
        assert_eq!(bad(WorkspaceConfig { crop_size: 0, ..base }), Some(WorkspaceConfigError::CropSize(0)));
        assert!(matches!(
            bad(WorkspaceConfig { crop_margin: f32::NAN, ..base }),
            Some(WorkspaceConfigError::CropMargin(_))
        ));
    }

    #[test]
    fn instance_planes_are_never_joined_and_keep_split_instances_whole() {
        // Two touching instances of class 1 (a 20x10 block split at u = 15),
        // and instance 3 of class 2 in two pieces left and right of them.
        let s = scene();
        let mut ids = vec![0u16; W * H];
        for v in 0..H {
            for u in 0..W {
                let p = v * W + u;
                if s.labels[p] == 1 {
                    ids[p] = if u < 15 { 1 } else { 2 };
                } else if (30..34).contains(&v) && (u < 3 || (50..54).contains(&u)) {
                    ids[p] = 3;
                }
            }
        }
        let classes = [0u16, 1, 1, 2];
        let mut f = frame(&s);
        f.labels = Some(LabelPlane::Instances { ids: &ids, classes: &classes });
        let mut ws = Workspace::new(WorkspaceConfig { min_pixels: 10, ..config() }).unwrap();
        // Extents that would join anything of one class.
        ws.join_parts(&[10.0, 10.0]);
        assert_eq!(ws.prepare(&f, 1).unwrap(), 3);
        assert_eq!(ws.stats().joined_parts, 0);
        let mut got: Vec<(u16, u32, [u16; 4])> = ws.instances.iter().map(|i| (i.class_id, i.pixels, i.bbox)).collect();
        got.sort();
        assert_eq!(got, vec![(1, 100, [5, 5, 14, 14]), (1, 100, [15, 5, 24, 14]), (2, 28, [0, 30, 53, 33])]);
        // The same frame as a class plane: the touching pair is one region.
        let classes_plane: Vec<u8> = (0..W * H).map(|p| classes[ids[p] as usize] as u8).collect();
        f.labels = Some(LabelPlane::U8(&classes_plane));
        ws.join_parts(&[]);
        let n = ws.prepare(&f, 1).unwrap();
        assert_eq!(ws.instances[0].pixels, 200);
        assert_eq!(n, 3, "class plane: the block, and the two class-2 pieces apart");
    }
}
