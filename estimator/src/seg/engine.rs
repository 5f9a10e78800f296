//! The segmenter's forward pass on buffers allocated once: im2col + the shared
//! GEMM ([`crate::net::gemm`]) per convolution, nearest upsampling into the
//! decoder's concatenation buffers (skip features are written there directly
//! by the encoder), a 1x1 head, per-cell argmax, removal of small label
//! fragments ([`SegEngine::set_min_component_cells`]) and the cell labels
//! brought to the frame ([`SegEngine::set_boundary`]: nearest, after a
//! one-cell erosion, or with pixel borders from interpolated logits). Mirrors `fusepose_train::seg::model` operation for
//! operation; after the first frame of a size, [`SegEngine::segment`] does not allocate.

use std::path::Path;

use fusepose_scene::ObjectSet;
use ndarray::{Array1, Array2, ArrayView2, ArrayViewMut2};

use super::boundary::{Boundary, BoundaryScratch, refine};
use super::config::{INPUT_CHANNELS, OFFSET_UNIT_CELLS, SegConfig};
use super::depth_regions::DepthRegions;
use super::file::{Certainty, SegFile};
use super::input::FrameMap;
use super::merge::InstanceMerger;
use super::voting::{Voting, VotingMode, VotingParams};
use crate::frame::{FrameError, FrameView, LabelPlane};
use crate::net::NetLoadError;
use crate::net::gemm::{cols_len, conv3x3, gemm_acc};
use crate::net::meta::ObjectEntry;

/// Why a frame could not be segmented.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SegError {
    #[error("invalid frame: {0}")]
    Frame(#[from] FrameError),
    #[error("label output has {got} values, the frame has {expected} pixels")]
    OutputLength { got: usize, expected: usize },
    #[error("network input has {got} values, expected {expected}")]
    InputLength { got: usize, expected: usize },
    #[error(
        "the partner segmenter reads {partner_input:?} px into {partner_outputs} outputs, this one \
         {input:?} px into {outputs}: averaging needs the same input size and objects"
    )]
    PartnerMismatch { input: (usize, usize), outputs: usize, partner_input: (usize, usize), partner_outputs: usize },
    #[error("partner weight {0} is outside 0..=1")]
    PartnerWeight(f32),
}

/// One layer's weights: `[O, I*k*k]` and bias `[O]`.
struct Layer {
    w: Array2<f32>,
    b: Array1<f32>,
}

/// Nearest source index of each output index, exactly as burn's `interpolate(Nearest)`:
/// `min(floor(o * (in / out)), in - 1)` in f64.
fn nearest_map(input: usize, output: usize) -> Vec<usize> {
    let ratio = input as f64 / output as f64;
    (0..output).map(|o| ((o as f64 * ratio).floor() as usize).min(input - 1)).collect()
}

/// Nearest upsampling of `[c, hi, wi]` into `[c, ys.len(), xs.len()]`.
fn upsample(src: &[f32], c: usize, wi: usize, ys: &[usize], xs: &[usize], dst: &mut [f32]) {
    let hi = src.len() / c.max(1) / wi.max(1);
    let plane = ys.len() * xs.len();
    for ch in 0..c {
        let s = &src[ch * hi * wi..(ch + 1) * hi * wi];
        let d = &mut dst[ch * plane..(ch + 1) * plane];
        for (row, &y) in d.chunks_exact_mut(xs.len()).zip(ys) {
            let srow = &s[y * wi..(y + 1) * wi];
            for (v, &x) in row.iter_mut().zip(xs) {
                *v = srow[x];
            }
        }
    }
}

/// Default of [`SegEngine::set_min_component_cells`]: 4-connected same-class
/// regions smaller than this many output cells become background. Stray
/// blocks at object borders would otherwise become instances of their own (an
/// output cell is 8x8 pixels of a 640x480 frame at the default 160x120 input).
pub const MIN_COMPONENT_CELLS: usize = 6;

/// Default [`SegEngine::set_max_elongation`]: on the held-out split, 8–16
/// removed the same 6 ghost instances (table-edge strips) and no real one.
pub const MAX_ELONGATION: f32 = 12.0;

/// Default of [`SegEngine::set_min_interior_cells`]: regions with no cell
/// whose four neighbours share its class (all border, at most two cells
/// thick) become background. [`Boundary::ErodeCells`] removed them anyway;
/// with [`Boundary::Refine`] they were most of the extra ghost poses (tuning
/// split: 78 → 54 ghosts for −0.2 ADD(S) AUC, docs/BENCHMARKS.md).
pub const MIN_INTERIOR_CELLS: usize = 1;

/// Relabels as background (0), in the `w`-wide grid `cells`, 4-connected
/// regions of one non-zero class smaller than `min_cells`, more elongated than
/// `max_elongation` (long side² / area; 0 = no limit) or with fewer than
/// `min_interior` interior cells (all existing 4-neighbours of the same class). `seen`, `stack` and
/// `members` are scratch of `cells.len()` capacity (never grown).
#[allow(clippy::too_many_arguments)] // three limits and three scratch buffers, all from the engine
fn drop_small_components(
    cells: &mut [u16],
    w: usize,
    min_cells: usize,
    max_elongation: f32,
    min_interior: usize,
    seen: &mut [bool],
    stack: &mut Vec<u32>,
    members: &mut Vec<u32>,
) {
    if (min_cells <= 1 && max_elongation <= 0.0 && min_interior == 0) || w == 0 {
        return;
    }
    let h = cells.len() / w;
    seen.fill(false);
    for start in 0..cells.len() {
        let class = cells[start];
        if class == 0 || seen[start] {
            continue;
        }
        stack.clear();
        members.clear();
        stack.push(start as u32);
        seen[start] = true;
        let (mut x0, mut x1, mut y0, mut y1) = (usize::MAX, 0, usize::MAX, 0);
        while let Some(i) = stack.pop() {
            members.push(i);
            let (x, y) = (i as usize % w, i as usize / w);
            (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
            let mut visit = |j: usize| {
                if !seen[j] && cells[j] == class {
                    seen[j] = true;
                    stack.push(j as u32);
                }
            };
            if x > 0 {
                visit(i as usize - 1);
            }
            if x + 1 < w {
                visit(i as usize + 1);
            }
            if y > 0 {
                visit(i as usize - w);
            }
            if y + 1 < h {
                visit(i as usize + w);
            }
        }
        // Elongation = long side² / area: 1 for a square, 13 for a 40×3 strip.
        let long = (x1 - x0 + 1).max(y1 - y0 + 1) as f32;
        let strip = max_elongation > 0.0 && long * long / members.len() as f32 > max_elongation;
        // Interior cells: all existing 4-neighbours of the same class.
        let interior = if min_interior == 0 {
            0
        } else {
            members
                .iter()
                .filter(|&&i| {
                    let (i, x, y) = (i as usize, i as usize % w, i as usize / w);
                    (x == 0 || cells[i - 1] == class)
                        && (x + 1 == w || cells[i + 1] == class)
                        && (y == 0 || cells[i - w] == class)
                        && (y + 1 == h || cells[i + w] == class)
                })
                .count()
        };
        if members.len() < min_cells || strip || interior < min_interior {
            for &i in members.iter() {
                cells[i as usize] = 0;
            }
        }
    }
}

/// Sets to background every labelled cell with a 4-neighbour of another label
/// (one-cell erosion of every region); `out` receives the result.
fn erode_boundaries(cells: &[u16], w: usize, out: &mut [u16]) {
    let h = cells.len() / w.max(1);
    for (i, (o, &c)) in out.iter_mut().zip(cells).enumerate() {
        let (x, y) = (i % w, i / w);
        let differs = |j: usize| cells[j] != c;
        let edge = (x > 0 && differs(i - 1))
            || (x + 1 < w && differs(i + 1))
            || (y > 0 && differs(i - w))
            || (y + 1 < h && differs(i + w));
        *o = if c != 0 && edge { 0 } else { c };
    }
}

/// Most output cells [`SegEngine::region_probability`] judges: a 160x120 grid,
/// i.e. a 320x240 network input (the shipped segmenter's is 160x120, an 80x60
/// grid); a file with a larger grid gets NaN (not judged).
const MAX_CELLS: usize = 160 * 120 + 64;

/// How the segmenter combines a frame's logits with its mirror image's ([`SegEngine::set_flip_average`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FlipAverage {
    /// The frame's own logits only.
    #[default]
    Off,
    /// The mean of both views' logits in every cell.
    All,
    /// The mean, except in cells where the two views pick two different
    /// object classes: those keep the frame's own logits, so the mirror image
    /// can move a cell between background and an object but never give it
    /// another object's class.
    NoSwap,
}

impl std::str::FromStr for FlipAverage {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "off" => Ok(Self::Off),
            "all" => Ok(Self::All),
            "no-swap" => Ok(Self::NoSwap),
            _ => Err(format!("unknown flip-average mode `{s}`: expected off, all or no-swap")),
        }
    }
}

/// The class with the largest logit in `cell` (`logits`: `[classes, cells]`; the first maximum wins).
fn argmax_at(logits: &[f32], cells: usize, classes: usize, cell: usize) -> usize {
    (1..classes).fold(0, |best, c| if logits[c * cells + cell] > logits[best * cells + cell] { c } else { best })
}

/// Swaps left and right in every row of `width` values of `plane` (all channels).
fn mirror_rows(plane: &mut [f32], width: usize) {
    plane.chunks_exact_mut(width).for_each(<[f32]>::reverse);
}

/// A cell's softmax over `classes` logits (`logit(c)`): the largest logit
/// and the sum of `exp(logit − largest)`, so that p(c) = exp(logit(c) −
/// largest) / sum.
pub(crate) fn softmax_terms(classes: usize, logit: impl Fn(usize) -> f32) -> (f32, f32) {
    let max = (0..classes).map(&logit).fold(f32::NEG_INFINITY, f32::max);
    let sum = (0..classes).map(|c| (logit(c) - max).exp()).sum();
    (max, sum)
}

/// The segmenter inference engine.
pub struct SegEngine {
    config: SegConfig,
    objects: Vec<ObjectEntry>,
    /// e1, e2, e3, e4, d3, d2, d1, head, then `o1` and `offset` when the file has them.
    layers: Vec<Layer>,
    /// `[4, H0*W0]`.
    input: Vec<f32>,
    /// `[d2 + e1, H1*W1]`: upsampled d2 then e1's output.
    cat1: Vec<f32>,
    /// `[d3 + e2, H2*W2]`.
    cat2: Vec<f32>,
    /// `[e4 + e3, H3*W3]`.
    cat3: Vec<f32>,
    e4: Vec<f32>,
    d3: Vec<f32>,
    d2: Vec<f32>,
    d1: Vec<f32>,
    /// `[K+1, H1*W1]`.
    logits: Vec<f32>,
    /// Whether and how the logits average the frame's and its mirror image's ([`SegEngine::set_flip_average`]).
    flip_average: FlipAverage,
    /// `[K+1, H1*W1]`: the mirror image's logits, mirrored back (empty while `flip_average` is off).
    mirrored_logits: Vec<f32>,
    /// A second segmenter and its share of the averaged logits ([`SegEngine::set_partner`]).
    partner: Option<(Box<SegEngine>, f32)>,
    /// `[d1, H1*W1]`: the offset branch's features when the file has it, else empty.
    o1: Vec<f32>,
    /// Whether `offsets` are not yet those of the last forward pass ([`SegEngine::compute_votes`]).
    votes_pending: bool,
    /// `[2, H1*W1]`: centre offsets (x, y) when the file has the offset head, else empty.
    offsets: Vec<f32>,
    /// Index of `b1` in `layers` (`contact` follows it) when the file has the contact branch.
    contact_layer: Option<usize>,
    /// `[d1, H1*W1]`: the contact branch's features, empty without it.
    b1: Vec<f32>,
    /// `[H1*W1]`: contact logits of the last forward pass ([`SegEngine::compute_contacts`]).
    contacts: Vec<f32>,
    /// Whether `contacts` are not yet those of the last forward pass.
    contacts_pending: bool,
    /// Instance id per cell of the last [`SegEngine::segment_instances`].
    cell_ids: Vec<u16>,
    /// Instance id → class id of the last [`SegEngine::segment_instances`] (index 0 = background).
    instance_classes: Vec<u16>,
    voting: Voting,
    /// Whether the offset head, where the file has one, is used ([`VotingMode`]).
    use_offsets: bool,
    /// Per-class distance under which two instances are one object (metres; empty = off).
    separation: Vec<f32>,
    merger: InstanceMerger,
    cols: Vec<f32>,
    cells: Vec<u16>,
    min_component_cells: usize,
    max_elongation: f32,
    min_interior_cells: usize,
    /// Subtracted from the background logit before the argmax ([`SegEngine::set_background_offset`]).
    background_offset: f32,
    boundary: Boundary,
    /// Cell labels regrouped by depth before the clean-up ([`SegEngine::set_depth_regions`]; `None` = off).
    depth_regions: Option<DepthRegions>,
    /// Cells [`DepthRegions`] changed in the last frame.
    depth_changed: usize,
    /// Eroded cell labels ([`Boundary::ErodeCells`]).
    eroded: Vec<u16>,
    /// [`Boundary::Refine`]'s per-frame scratch.
    refine_scratch: BoundaryScratch,
    /// Flood-fill scratch over the cells (capacity = cell count, never grown).
    seen: Vec<bool>,
    stack: Vec<u32>,
    members: Vec<u32>,
    /// Nearest maps (rows, columns) for the upsampling into cat3, cat2, cat1.
    up: [(Vec<usize>, Vec<usize>); 3],
    map: Option<FrameMap>,
    /// How sure this segmenter is of real objects, when its file says.
    certainty: Option<Certainty>,
}

impl SegEngine {
    /// Reads `path`, checks it against `set` (same objects in the same order) and builds the engine.
    pub fn load(path: &Path, set: &ObjectSet) -> Result<Self, NetLoadError> {
        let file = SegFile::read(path)?;
        file.check_objects(set)?;
        Self::new(&file)
    }

    /// Builds the engine from a parsed file (no object-set check; see [`SegEngine::load`]).
    pub fn new(file: &SegFile) -> Result<Self, NetLoadError> {
        let c = file.config.clone();
        let mut layers = Vec::new();
        for (name, i, o, k, _) in c.layers() {
            let w = file.tensor(&format!("{name}.weight"))?;
            let b = file.tensor(&format!("{name}.bias"))?;
            let w = Array2::from_shape_vec((o, i * k * k), w.to_vec()).map_err(|e| NetLoadError::WrongShape {
                name: format!("{name}.weight ({e})"),
                expected: vec![o, i, k, k],
                got: vec![w.len()],
            })?;
            layers.push(Layer { w, b: Array1::from_vec(b.to_vec()) });
        }
        let s = c.sizes();
        let hw = |l: usize| s[l].0 * s[l].1;
        let contact_layer = c.layers().iter().position(|l| l.0 == "b1");
        let [c1, c2, c3, c4] = c.enc;
        let [d3, d2, d1] = c.dec;
        let cols = c
            .layers()
            .into_iter()
            .zip([1, 2, 3, 4, 3, 2, 1, 1])
            .map(|((_, i, _, k, _), l)| if k == 3 { cols_len(i, hw(l)) } else { i * k * k * hw(l) })
            .max()
            .unwrap_or(0);
        let up = [(4, 3), (3, 2), (2, 1)]
            .map(|(from, to)| (nearest_map(s[from].0, s[to].0), nearest_map(s[from].1, s[to].1)));
        Ok(Self {
            input: vec![0.0; INPUT_CHANNELS * hw(0)],
            cat1: vec![0.0; (d2 + c1) * hw(1)],
            cat2: vec![0.0; (d3 + c2) * hw(2)],
            cat3: vec![0.0; (c4 + c3) * hw(3)],
            e4: vec![0.0; c4 * hw(4)],
            d3: vec![0.0; d3 * hw(3)],
            d2: vec![0.0; d2 * hw(2)],
            d1: vec![0.0; d1 * hw(1)],
            logits: vec![0.0; c.outputs() * hw(1)],
            flip_average: FlipAverage::Off,
            mirrored_logits: Vec::new(),
            partner: None,
            offsets: if c.offsets { vec![0.0; 2 * hw(1)] } else { Vec::new() },
            o1: if c.offsets && c.offset_branch { vec![0.0; d1 * hw(1)] } else { Vec::new() },
            votes_pending: false,
            contact_layer,
            b1: if contact_layer.is_some() { vec![0.0; d1 * hw(1)] } else { Vec::new() },
            contacts: if contact_layer.is_some() { vec![0.0; hw(1)] } else { Vec::new() },
            contacts_pending: false,
            cell_ids: vec![0; hw(1)],
            instance_classes: Vec::with_capacity(hw(1) + 1),
            voting: Voting::new(s[1].1, s[1].0, VotingParams::default()),
            use_offsets: false,
            separation: Vec::new(),
            merger: InstanceMerger::default(),
            cols: vec![0.0; cols],
            cells: vec![0; hw(1)],
            min_component_cells: MIN_COMPONENT_CELLS,
            max_elongation: MAX_ELONGATION,
            min_interior_cells: MIN_INTERIOR_CELLS,
            background_offset: 0.0,
            boundary: Boundary::default(),
            depth_regions: None,
            depth_changed: 0,
            eroded: vec![0; hw(1)],
            refine_scratch: BoundaryScratch::default(),
            seen: vec![false; hw(1)],
            stack: Vec::with_capacity(hw(1)),
            members: Vec::with_capacity(hw(1)),
            up,
            certainty: file.certainty.clone(),
            map: None,
            objects: file.objects.clone(),
            layers,
            config: c,
        })
    }

    pub fn config(&self) -> &SegConfig {
        &self.config
    }

    /// The objects the network was trained for, in class order.
    pub fn objects(&self) -> &[ObjectEntry] {
        &self.objects
    }

    /// Logits of the last forward pass, `[K+1, out_h * out_w]` (channel 0 = background).
    pub fn logits(&self) -> &[f32] {
        &self.logits
    }

    /// Centre offsets of the last forward pass, `[2, out_h * out_w]` (x then y,
    /// in units of [`super::config::OFFSET_UNIT_CELLS`] cells); empty without the
    /// offset head, and for the offset branch until [`SegEngine::compute_votes`].
    pub fn offsets(&self) -> &[f32] {
        if self.votes_pending { &[] } else { &self.offsets }
    }

    /// The centre vote of the cell under frame pixel `(u, v)` in the last
    /// segmentation: the cell's position plus its predicted offset, in output
    /// cells (x, y). Pixels of one object vote for one point, whichever
    /// voting mode is set. `None` without the offset head, before the first
    /// segmentation, or off the frame.
    pub fn vote_at(&self, u: usize, v: usize) -> Option<[f32; 2]> {
        let map = self.map.as_ref().filter(|_| !self.offsets().is_empty())?;
        let (w, h) = map.frame_size();
        if u >= w || v >= h {
            return None;
        }
        let (out_w, out_h) = map.grid_size();
        let (cx, cy) = map.cell_of(u, v);
        let i = cy * out_w + cx;
        let (dx, dy) = (*self.offsets.get(i)?, *self.offsets.get(out_w * out_h + i)?);
        let (dx, dy) = if dx.is_finite() && dy.is_finite() { (dx, dy) } else { (0.0, 0.0) };
        Some([cx as f32 + dx * OFFSET_UNIT_CELLS, cy as f32 + dy * OFFSET_UNIT_CELLS])
    }

    /// Contact logits of the last forward pass, `[out_h * out_w]`; empty
    /// without the contact branch or until [`SegEngine::compute_contacts`].
    pub fn contacts(&self) -> &[f32] {
        if self.contacts_pending { &[] } else { &self.contacts }
    }

    /// Whether the file has the contact branch ([`SegEngine::contact_at`]).
    pub fn has_contacts(&self) -> bool {
        self.contact_layer.is_some()
    }

    /// The probability that the cell under frame pixel `(u, v)` lies where
    /// two object instances touch, in the last segmentation. `None` without
    /// the contact branch, before [`SegEngine::compute_contacts`] after a
    /// segmentation, or off the frame.
    pub fn contact_at(&self, u: usize, v: usize) -> Option<f32> {
        let map = self.map.as_ref().filter(|_| self.contact_layer.is_some() && !self.contacts_pending)?;
        let (w, h) = map.frame_size();
        if u >= w || v >= h {
            return None;
        }
        let (out_w, _) = map.grid_size();
        let (cx, cy) = map.cell_of(u, v);
        let logit = *self.contacts.get(cy * out_w + cx)?;
        // A non-finite logit (a broken file) reads as no contact.
        Some(if logit.is_finite() { 1.0 / (1.0 + (-logit).exp()) } else { 0.0 })
    }

    /// Whether the file has the centre-offset head, i.e. [`SegEngine::segment_instances`]
    /// separates touching objects of one class.
    pub fn separates_instances(&self) -> bool {
        self.config.offsets && self.use_offsets
    }

    /// Instances of one class whose 3D centres are closer than
    /// `separation[class − 1]` metres become one ([`super::merge`]); e.g.
    /// [`crate::duplicates::separations`]. Empty (the default) = never.
    pub fn set_instance_separation(&mut self, separation: Vec<f32>) {
        self.separation = separation;
    }

    /// Peak-search tuning of the instance voting.
    pub fn set_voting(&mut self, params: VotingParams) {
        self.voting.set_params(params);
    }

    /// Votes instances with the offset head (`On`), or ignores it (`Off`,
    /// the default: class regions, as for a file without the head). Off by
    /// default since session 16: on the tuning splits the votes split single
    /// objects (108 split instances on `fp_tune` against 14) and raised the
    /// ghosts (0.04 → 0.47 per frame there), gaining on heaps only
    /// (docs/BENCHMARKS.md, session 16).
    pub fn set_voting_mode(&mut self, mode: VotingMode) {
        match mode {
            VotingMode::On(params) => {
                self.use_offsets = true;
                self.voting.set_params(params);
            }
            VotingMode::Off => self.use_offsets = false,
        }
    }

    /// Instance id per output cell of the last [`SegEngine::segment_instances`].
    pub fn cell_instances(&self) -> &[u16] {
        &self.cell_ids
    }

    /// Class id per output cell of the last [`SegEngine::segment`], `[out_h * out_w]`
    /// (argmax, then small fragments removed; before erosion).
    pub fn cell_labels(&self) -> &[u16] {
        &self.cells
    }

    /// Same-class regions smaller than `cells` output cells become background
    /// (default [`MIN_COMPONENT_CELLS`]; 0 or 1 keeps the plain argmax).
    pub fn set_min_component_cells(&mut self, cells: usize) {
        self.min_component_cells = cells;
    }

    /// Same-class regions whose long side² / area exceeds `elongation` become
    /// background (0 = off): long thin strips, such as the table's front edge
    /// that the segmenter sometimes labels as an object, are not objects.
    pub fn set_max_elongation(&mut self, elongation: f32) {
        self.max_elongation = elongation;
    }

    /// Regions with fewer interior cells than this become background
    /// (default [`MIN_INTERIOR_CELLS`]; 0 keeps them).
    pub fn set_min_interior_cells(&mut self, cells: usize) {
        self.min_interior_cells = cells;
    }

    /// Lowers the background logit by `offset` (natural-log odds) before the
    /// argmax and the pixel borders: a cell whose best class is within
    /// `offset` of background becomes that class. 0 (the default) is the
    /// plain argmax; positive values find more of partly hidden objects and
    /// leave the regions no pose explains to pose verification.
    pub fn set_background_offset(&mut self, offset: f32) {
        self.background_offset = if offset.is_finite() { offset } else { 0.0 };
    }

    /// Average the logits of the frame and of its mirror image (left and
    /// right swapped, mirrored back), at twice the network's time per frame
    /// ([`FlipAverage`]). The segmenter was trained with horizontal flips, so
    /// both are inputs it knows. The offset head's votes stay those of the
    /// frame itself. Default off.
    pub fn set_flip_average(&mut self, mode: FlipAverage) {
        self.flip_average = mode;
        self.mirrored_logits = match mode {
            FlipAverage::Off => Vec::new(),
            _ => vec![0.0; self.logits.len()],
        };
    }

    /// Averages this segmenter's logits with a second one's, `weight` its
    /// share (0..=1): two segmenters trained on different images err in
    /// different places. Everything downstream (labels, region probability,
    /// certainty floor) reads the averaged logits; the votes stay this one's.
    pub fn set_partner(&mut self, partner: SegEngine, weight: f32) -> Result<(), SegError> {
        if !(0.0..=1.0).contains(&weight) {
            return Err(SegError::PartnerWeight(weight));
        }
        let (a, b) = (&self.config, &partner.config);
        // Same input size and outputs: the same logits layout.
        if (a.input_width, a.input_height, a.outputs()) != (b.input_width, b.input_height, b.outputs()) {
            return Err(SegError::PartnerMismatch {
                input: (a.input_width, a.input_height),
                outputs: a.outputs(),
                partner_input: (b.input_width, b.input_height),
                partner_outputs: b.outputs(),
            });
        }
        self.partner = Some((Box::new(partner), weight));
        Ok(())
    }

    /// The [`SegEngine::set_flip_average`] mode.
    pub fn flip_average(&self) -> FlipAverage {
        self.flip_average
    }

    /// How cell labels become the frame's labels ([`Boundary`]; default
    /// [`Boundary::default`]). Cell-sized
    /// label steps put up to half a cell of background into an object's mask,
    /// and those points cost the pose network far more than the rim it loses
    /// ([`Boundary::ErodeCells`] vs [`Boundary::Cells`]: ADD-S AUC 68 → 81 on
    /// the held-out split with an early checkpoint, docs/BENCHMARKS.md).
    pub fn set_boundary(&mut self, boundary: Boundary) {
        self.boundary = boundary;
    }

    /// Regroups the cell labels by depth before the clean-up ([`DepthRegions`]); `None` (the default) = off.
    pub fn set_depth_regions(&mut self, regions: Option<DepthRegions>) {
        self.depth_regions = regions;
    }

    /// The depth regrouping's parameters (`None` = off).
    pub fn depth_regions(&self) -> Option<crate::seg::DepthRegionParams> {
        self.depth_regions.as_ref().map(DepthRegions::params)
    }

    /// Output cells the depth regrouping relabelled in the last frame (0 when off).
    pub fn depth_changed_cells(&self) -> usize {
        self.depth_changed
    }

    /// The current [`Boundary`] mode.
    pub fn boundary(&self) -> Boundary {
        self.boundary
    }

    /// Segments `frame` into `labels_out` (`width * height` class ids, 0 = background).
    pub fn segment(&mut self, frame: &FrameView<'_>, labels_out: &mut [u16]) -> Result<(), SegError> {
        frame.validate()?;
        let (w, h) = (frame.width(), frame.height());
        if labels_out.len() != w * h {
            return Err(SegError::OutputLength { got: labels_out.len(), expected: w * h });
        }
        if !self.map.as_ref().is_some_and(|m| m.fits(w, h, &self.config)) {
            self.map = Some(FrameMap::new(w, h, &self.config));
        }
        let Some(map) = self.map.take() else { return Ok(()) };
        map.fill_input(frame, &mut self.input);
        self.run();
        if self.background_offset != 0.0 {
            let n = self.cells.len();
            self.logits[..n].iter_mut().for_each(|v| *v -= self.background_offset);
        }
        self.argmax();
        self.depth_changed = match self.depth_regions.as_mut() {
            Some(regions) => regions.apply(frame, &map, &self.logits, &mut self.cells),
            None => 0,
        };
        let (_, out_w) = self.config.output_size();
        drop_small_components(
            &mut self.cells,
            out_w,
            self.min_component_cells,
            self.max_elongation,
            self.min_interior_cells,
            &mut self.seen,
            &mut self.stack,
            &mut self.members,
        );
        match self.boundary {
            Boundary::Cells => map.upsample(&self.cells, labels_out),
            Boundary::ErodeCells => {
                erode_boundaries(&self.cells, out_w, &mut self.eroded);
                map.upsample(&self.eroded, labels_out);
            }
            Boundary::Refine { erode_px } => {
                refine(&map, &self.cells, &self.logits, erode_px, &mut self.refine_scratch, labels_out)
            }
        }
        self.map = Some(map);
        Ok(())
    }

    /// Segments `frame` into object instances: `ids_out` (`width * height`)
    /// receives an instance id per pixel (0 = background) and the returned
    /// table gives each id's class (`table[id]`, `table[0] = 0`). With the
    /// offset head, touching objects of one class are separated by their
    /// centre votes ([`super::voting`]); without it every class is one id
    /// (id = class id), which the estimator splits into connected regions as
    /// it does a class plane. Pixel borders are those of [`SegEngine::segment`].
    pub fn segment_instances(&mut self, frame: &FrameView<'_>, ids_out: &mut [u16]) -> Result<&[u16], SegError> {
        self.segment(frame, ids_out)?;
        self.instance_classes.clear();
        if !self.separates_instances() {
            self.instance_classes.extend(0..=self.config.num_classes as u16);
            return Ok(&self.instance_classes);
        }
        let count = self.voting.assign(&self.cells, &self.offsets, &mut self.cell_ids);
        let Some(map) = self.map.as_ref() else {
            self.instance_classes.push(0);
            self.instance_classes.extend(self.voting.centres().iter().take(count).map(|c| c.class_id));
            return Ok(&self.instance_classes);
        };
        let centres = &self.voting.centres()[..count];
        self.merger.merge(frame, map, centres, &self.separation, &mut self.cell_ids, &mut self.instance_classes);
        let (out_w, out_h) = map.grid_size();
        let (w, _) = map.frame_size();
        // Each pixel takes the instance of its cell when the classes agree,
        // else of the nearest same-class cell among the 3x3 around it (pixel
        // borders may give a pixel a neighbour cell's class), else background.
        for (p, label) in ids_out.iter_mut().enumerate() {
            let class = *label;
            if class == 0 {
                continue;
            }
            let (cx, cy) = map.cell_of(p % w, p / w);
            let own = cy * out_w + cx;
            *label = if self.cells[own] == class {
                self.cell_ids[own]
            } else {
                let mut id = 0;
                'search: for y in cy.saturating_sub(1)..=(cy + 1).min(out_h - 1) {
                    for x in cx.saturating_sub(1)..=(cx + 1).min(out_w - 1) {
                        if self.cells[y * out_w + x] == class {
                            id = self.cell_ids[y * out_w + x];
                            break 'search;
                        }
                    }
                }
                id
            };
        }
        Ok(&self.instance_classes)
    }

    /// Segments `frame` into the label plane the estimator consumes: an
    /// instance plane ([`LabelPlane::Instances`], ids in `buf`, classes in the
    /// engine) when the file has the offset head, else a class plane in `buf`.
    /// `buf` is resized to the frame (allocating only when the size grows).
    pub fn segment_plane<'a>(
        &'a mut self,
        frame: &FrameView<'_>,
        buf: &'a mut Vec<u16>,
    ) -> Result<LabelPlane<'a>, SegError> {
        frame.validate()?;
        buf.resize(frame.width() * frame.height(), 0);
        if self.separates_instances() {
            let classes = self.segment_instances(frame, buf)?;
            Ok(LabelPlane::Instances { ids: buf, classes })
        } else {
            self.segment(frame, buf)?;
            Ok(LabelPlane::U16(buf))
        }
    }

    /// Instance id → class id table of the last [`SegEngine::segment_instances`] (index 0 = background).
    pub fn instance_classes(&self) -> &[u16] {
        &self.instance_classes
    }

    /// How sure this segmenter is of real objects (its file's calibration),
    /// for a threshold of [`SegEngine::region_probability`].
    pub fn certainty(&self) -> Option<&Certainty> {
        self.certainty.as_ref()
    }

    /// How sure the last segmentation was of `class` anywhere in one region:
    /// the highest softmax probability of `class` over the segmenter cells
    /// under the frame pixels with `ids[p] == id` inside `bbox` ([u_min,
    /// v_min, u_max, v_max], inclusive). A real object has cells the
    /// segmenter is sure of, at least inside it; a region it made up (a
    /// class-coloured patch, part of another object) may have none. NaN
    /// before the first segmentation, for a class the file does not have, or
    /// for a region without pixels. `ids` must be the frame's size.
    pub fn region_probability(&self, ids: &[u32], id: u32, class: u16, bbox: [u16; 4]) -> f32 {
        let classes = self.config.num_classes + 1;
        if class as usize >= classes {
            return f32::NAN;
        }
        let mut best = f32::NEG_INFINITY;
        // A maximum: the cells may come in any order.
        let cells = self.for_region_cells_by_cell(ids, id, bbox, |logit, cell| {
            // log softmax(class) = logit(class) − logsumexp(logits).
            let (max, sum) = softmax_terms(classes, |c| logit(c, cell));
            best = best.max(logit(class as usize, cell) - max - sum.ln());
        });
        if cells == 0 { f32::NAN } else { best.exp() }
    }

    /// The last segmentation's frame map and `bbox` clamped to the frame
    /// ([u0, v0, u1, v1], inclusive), when there is one and `ids` has its size.
    fn region_box(&self, ids: &[u32], bbox: [u16; 4]) -> Option<(&FrameMap, [usize; 4])> {
        let map = self.map.as_ref()?;
        let (w, h) = map.frame_size();
        if ids.len() != w * h || map.cells() > MAX_CELLS {
            return None;
        }
        let (u1, v1) = ((bbox[2] as usize).min(w - 1), (bbox[3] as usize).min(h - 1));
        let (u0, v0) = ((bbox[0] as usize).min(u1), (bbox[1] as usize).min(v1));
        Some((map, [u0, v0, u1, v1]))
    }

    /// The cells [`SegEngine::for_region_cells`] visits, in cell order: each
    /// cell of the box's cell rectangle whose pixels inside the box include
    /// one with `ids[p] == id`, found at the first such pixel (inside a region
    /// that is the cell's first pixel, where the pixel-order walk reads all
    /// of the cell's pixels). For reductions that do not depend on order.
    fn for_region_cells_by_cell(
        &self,
        ids: &[u32],
        id: u32,
        bbox: [u16; 4],
        mut visit: impl FnMut(&dyn Fn(usize, usize) -> f32, usize),
    ) -> usize {
        let Some((map, [u0, v0, u1, v1])) = self.region_box(ids, bbox) else { return 0 };
        let ((w, _), (out_w, _), cells) = (map.frame_size(), map.grid_size(), map.cells());
        let logit = |c: usize, cell: usize| self.logits[c * cells + cell];
        let ((gx0, gy0), (gx1, gy1)) = (map.cell_of(u0, v0), map.cell_of(u1, v1));
        let clip = |r: std::ops::Range<usize>, lo: usize, hi: usize| r.start.max(lo)..r.end.min(hi + 1);
        let mut visited = 0;
        for cy in gy0..=gy1 {
            let rows = clip(map.span_y(cy), v0, v1);
            for cx in gx0..=gx1 {
                let cols = clip(map.span_x(cx), u0, u1);
                if rows.clone().any(|v| ids[v * w + cols.start..v * w + cols.end.max(cols.start)].contains(&id)) {
                    visit(&logit, cy * out_w + cx);
                    visited += 1;
                }
            }
        }
        visited
    }

    /// The segmenter's mean softmax probability of each class (index 0 =
    /// background, then class ids 1..) over the cells under one region (as in
    /// [`SegEngine::region_probability`]), written to `means`, which must hold
    /// one value per class and background. Returns the cells averaged (0:
    /// no segmentation yet, no pixels, or a wrong-sized `ids` or `means`;
    /// `means` is then all zeros). No allocation.
    pub fn region_class_means(&self, ids: &[u32], id: u32, bbox: [u16; 4], means: &mut [f32]) -> usize {
        let classes = self.config.num_classes + 1;
        means.fill(0.0);
        if means.len() != classes {
            return 0;
        }
        let cells = self.for_region_cells(ids, id, bbox, |logit, cell| {
            let (max, sum) = softmax_terms(classes, |c| logit(c, cell));
            for (c, m) in means.iter_mut().enumerate() {
                *m += (logit(c, cell) - max).exp() / sum;
            }
        });
        means.iter_mut().for_each(|m| *m /= cells.max(1) as f32);
        cells
    }

    /// Calls `visit(logit, cell)` once for each segmenter cell under the frame
    /// pixels with `ids[p] == id` inside `bbox`, where `logit(class, cell)`
    /// reads the last segmentation; returns how many cells it visited (0
    /// before the first segmentation or when `ids` is not the frame's size).
    fn for_region_cells(
        &self,
        ids: &[u32],
        id: u32,
        bbox: [u16; 4],
        mut visit: impl FnMut(&dyn Fn(usize, usize) -> f32, usize),
    ) -> usize {
        let Some((map, [u0, v0, u1, v1])) = self.region_box(ids, bbox) else { return 0 };
        let ((w, _), (out_w, _), cells) = (map.frame_size(), map.grid_size(), map.cells());
        let logit = |c: usize, cell: usize| self.logits[c * cells + cell];
        // Each cell under the region once (a frame row crosses the same cells
        // as the rows above it): a bit per cell of the box's cell rectangle.
        let ((gx0, gy0), (gx1, _)) = (map.cell_of(u0, v0), map.cell_of(u1, v1));
        let span = gx1 + 1 - gx0;
        let mut seen = [0u64; MAX_CELLS / 64];
        let mut visited = 0;
        for v in v0..=v1 {
            for u in u0..=u1 {
                if ids[v * w + u] != id {
                    continue;
                }
                let (cx, cy) = map.cell_of(u, v);
                let bit = (cy - gy0) * span + (cx - gx0);
                if seen[bit / 64] & (1 << (bit % 64)) != 0 {
                    continue;
                }
                seen[bit / 64] |= 1 << (bit % 64);
                visit(&logit, cy * out_w + cx);
                visited += 1;
            }
        }
        visited
    }

    /// Runs the network on a prepared input `[4, H0, W0]` and returns the logits `[K+1, H1*W1]`.
    pub fn forward(&mut self, input: &[f32]) -> Result<&[f32], SegError> {
        if input.len() != self.input.len() {
            return Err(SegError::InputLength { got: input.len(), expected: self.input.len() });
        }
        self.input.copy_from_slice(input);
        self.run();
        Ok(&self.logits)
    }

    fn run(&mut self) {
        self.run_own();
        if let Some((partner, w)) = self.partner.as_mut() {
            partner.input.copy_from_slice(&self.input);
            partner.run();
            for (own, &other) in self.logits.iter_mut().zip(&partner.logits) {
                *own = (1.0 - *w) * *own + *w * other;
            }
        }
    }

    /// This segmenter's logits (with its mirror image's where set).
    fn run_own(&mut self) {
        if self.flip_average == FlipAverage::Off {
            return self.run_once();
        }
        let s = self.config.sizes();
        let (in_w, out_w) = (s[0].1, s[1].1);
        // The mirror image first, so that the activations left for the votes are the frame's own.
        mirror_rows(&mut self.input, in_w);
        self.run_once();
        self.mirrored_logits.copy_from_slice(&self.logits);
        mirror_rows(&mut self.mirrored_logits, out_w);
        mirror_rows(&mut self.input, in_w);
        self.run_once();
        let cells = s[1].0 * out_w;
        let classes = self.logits.len() / cells.max(1);
        for cell in 0..cells {
            if self.flip_average == FlipAverage::NoSwap {
                let own = argmax_at(&self.logits, cells, classes, cell);
                let mirrored = argmax_at(&self.mirrored_logits, cells, classes, cell);
                if own != 0 && mirrored != 0 && own != mirrored {
                    continue;
                }
            }
            for c in 0..classes {
                let i = c * cells + cell;
                self.logits[i] = 0.5 * (self.logits[i] + self.mirrored_logits[i]);
            }
        }
    }

    /// One forward pass of `input` into `logits` (and the votes when due).
    fn run_once(&mut self) {
        let s = self.config.sizes();
        let hw = |l: usize| s[l].0 * s[l].1;
        let [c1, c2, c3, c4] = self.config.enc;
        let [d3c, d2c, d1c] = self.config.dec;
        let l = &self.layers;
        let cols = &mut self.cols;
        let conv = |li: usize,
                    input: &[f32],
                    c_in: usize,
                    lvl: usize,
                    stride: usize,
                    cols: &mut [f32],
                    out: &mut [f32],
                    out_lvl: usize| {
            let o = l[li].w.nrows();
            let view = ArrayViewMut2::from_shape((o, hw(out_lvl)), &mut out[..o * hw(out_lvl)]).expect("layer buffer");
            conv3x3(input, c_in, s[lvl].0, s[lvl].1, stride, l[li].w.view(), l[li].b.view(), cols, view);
        };
        // Encoder; skip outputs land in the tail of their decoder's concat buffer.
        {
            let (_, e1) = self.cat1.split_at_mut(d2c * hw(1));
            conv(0, &self.input, INPUT_CHANNELS, 0, 2, cols, e1, 1);
        }
        {
            let e1 = &self.cat1[d2c * hw(1)..];
            let (_, e2) = self.cat2.split_at_mut(d3c * hw(2));
            conv(1, e1, c1, 1, 2, cols, e2, 2);
        }
        {
            let e2 = &self.cat2[d3c * hw(2)..];
            let (_, e3) = self.cat3.split_at_mut(c4 * hw(3));
            conv(2, e2, c2, 2, 2, cols, e3, 3);
        }
        {
            let e3 = &self.cat3[c4 * hw(3)..];
            conv(3, e3, c3, 3, 2, cols, &mut self.e4, 4);
        }
        // Decoder.
        let (ys, xs) = &self.up[0];
        upsample(&self.e4, c4, s[4].1, ys, xs, &mut self.cat3[..c4 * hw(3)]);
        conv(4, &self.cat3, c4 + c3, 3, 1, cols, &mut self.d3, 3);
        let (ys, xs) = &self.up[1];
        upsample(&self.d3, d3c, s[3].1, ys, xs, &mut self.cat2[..d3c * hw(2)]);
        conv(5, &self.cat2, d3c + c2, 2, 1, cols, &mut self.d2, 2);
        let (ys, xs) = &self.up[2];
        upsample(&self.d2, d2c, s[2].1, ys, xs, &mut self.cat1[..d2c * hw(1)]);
        conv(6, &self.cat1, d2c + c1, 1, 1, cols, &mut self.d1, 1);
        // Head: 1x1, no ReLU.
        let head = &l[7];
        let k = head.w.nrows();
        for (row, &b) in self.logits.chunks_exact_mut(hw(1)).zip(head.b.iter()) {
            row.fill(b);
        }
        let x = ArrayView2::from_shape((d1c, hw(1)), &self.d1[..]).expect("d1 buffer");
        let mut out = ArrayViewMut2::from_shape((k, hw(1)), &mut self.logits[..]).expect("logits buffer");
        gemm_acc(head.w.view(), x, &mut out);
        self.votes_pending = self.config.offsets;
        self.contacts_pending = self.contact_layer.is_some();
        // A head on `d1` costs little and is computed now; the branch (as much
        // as `d1` itself) only when voting is on or votes are asked for.
        if self.config.offsets && (!self.config.offset_branch || self.use_offsets) {
            self.compute_votes();
        }
    }

    /// Computes the centre offsets of the last forward pass where they are
    /// not yet (a file with the offset branch computes them on demand: the
    /// branch costs about as much as the last decoder layer, and the second
    /// look asks for them only in frames where it cuts). Reads `d1`, or
    /// `cat1` for the branch, which hold the last frame's values until the
    /// next forward pass.
    pub fn compute_votes(&mut self) {
        if !self.votes_pending {
            return;
        }
        self.votes_pending = false;
        let s = self.config.sizes();
        let hw = s[1].0 * s[1].1;
        let (c1, [_, d2c, d1c]) = (self.config.enc[0], self.config.dec);
        let (offset, x) = if self.config.offset_branch {
            let o1 = &self.layers[8];
            let view = ArrayViewMut2::from_shape((d1c, hw), &mut self.o1[..]).expect("o1 buffer");
            conv3x3(&self.cat1, d2c + c1, s[1].0, s[1].1, 1, o1.w.view(), o1.b.view(), &mut self.cols, view);
            (&self.layers[9], ArrayView2::from_shape((d1c, hw), &self.o1[..]).expect("o1 buffer"))
        } else {
            (&self.layers[8], ArrayView2::from_shape((d1c, hw), &self.d1[..]).expect("d1 buffer"))
        };
        for (row, &b) in self.offsets.chunks_exact_mut(hw).zip(offset.b.iter()) {
            row.fill(b);
        }
        let mut out = ArrayViewMut2::from_shape((2, hw), &mut self.offsets[..]).expect("offset buffer");
        gemm_acc(offset.w.view(), x, &mut out);
    }

    /// Computes the contact logits of the last forward pass where they are
    /// not yet (on demand, as the offset branch: the branch costs about as
    /// much as `d1`, and only the second look reads it). Reads `cat1`.
    pub fn compute_contacts(&mut self) {
        let Some(li) = self.contact_layer.filter(|_| self.contacts_pending) else { return };
        self.contacts_pending = false;
        let s = self.config.sizes();
        let hw = s[1].0 * s[1].1;
        let (c1, [_, d2c, d1c]) = (self.config.enc[0], self.config.dec);
        let (b1, head) = (&self.layers[li], &self.layers[li + 1]);
        let view = ArrayViewMut2::from_shape((d1c, hw), &mut self.b1[..]).expect("b1 buffer");
        conv3x3(&self.cat1, d2c + c1, s[1].0, s[1].1, 1, b1.w.view(), b1.b.view(), &mut self.cols, view);
        self.contacts.fill(head.b[0]);
        let x = ArrayView2::from_shape((d1c, hw), &self.b1[..]).expect("b1 buffer");
        let mut out = ArrayViewMut2::from_shape((1, hw), &mut self.contacts[..]).expect("contact buffer");
        gemm_acc(head.w.view(), x, &mut out);
    }

    /// Per-cell argmax of the logits (first maximum wins; NaN never wins).
    fn argmax(&mut self) {
        let n = self.cells.len();
        self.cells.fill(0);
        for (i, cell) in self.cells.iter_mut().enumerate() {
            let mut m = self.logits[i];
            for c in 1..self.config.outputs() {
                let v = self.logits[c * n + i];
                if v > m || m.is_nan() && !v.is_nan() {
                    m = v;
                    *cell = c as u16;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_fragments_become_background_large_regions_stay() {
        // 6x4 grid: class 1 region of 6 cells, class 2 pair (2 cells), lone class 1 cell.
        #[rustfmt::skip]
        let mut cells: Vec<u16> = vec![
            1, 1, 1, 0, 2, 2,
            1, 1, 1, 0, 0, 0,
            0, 0, 0, 0, 0, 1,
            0, 0, 0, 0, 0, 0,
        ];
        let n = cells.len();
        let (mut seen, mut stack, mut members) = (vec![false; n], Vec::with_capacity(n), Vec::with_capacity(n));
        let original = cells.clone();
        drop_small_components(&mut cells, 6, 1, 0.0, 0, &mut seen, &mut stack, &mut members);
        assert_eq!(cells, original, "min 1 keeps everything");
        drop_small_components(&mut cells, 6, 3, 0.0, 0, &mut seen, &mut stack, &mut members);
        #[rustfmt::skip]
        let expect: Vec<u16> = vec![
            1, 1, 1, 0, 0, 0,
            1, 1, 1, 0, 0, 0,
            0, 0, 0, 0, 0, 0,
            0, 0, 0, 0, 0, 0,
        ];
        assert_eq!(cells, expect);
        // Diagonal neighbours are not connected; a region of exactly min_cells stays.
        let mut diag: Vec<u16> = vec![3, 0, 0, 3, 3, 3];
        drop_small_components(&mut diag, 2, 2, 0.0, 0, &mut seen, &mut stack, &mut members);
        assert_eq!(diag, vec![0, 0, 0, 3, 3, 3]);
        assert!(stack.capacity() >= n && members.capacity() >= n);
    }

    #[test]
    fn regions_without_interior_cells_are_dropped() {
        // A 2-cell-thick bar (no cell has four class-2 neighbours) and a 3x3 block (one interior cell).
        #[rustfmt::skip]
        let mut cells: Vec<u16> = vec![
            0, 0, 0, 0, 0, 0, 0, 0,
            0, 2, 2, 2, 2, 0, 1, 1,
            0, 2, 2, 2, 2, 0, 1, 1,
            0, 0, 0, 0, 0, 0, 1, 1,
            0, 0, 0, 0, 0, 0, 0, 0,
        ];
        let n = cells.len();
        let (mut seen, mut stack, mut members) = (vec![false; n], Vec::with_capacity(n), Vec::with_capacity(n));
        let original = cells.clone();
        drop_small_components(&mut cells, 8, 1, 0.0, 0, &mut seen, &mut stack, &mut members);
        assert_eq!(cells, original);
        // The class-1 block touches the grid's right edge, which counts as
        // same-class: (7, 2) is interior.
        drop_small_components(&mut cells, 8, 1, 0.0, 1, &mut seen, &mut stack, &mut members);
        assert!(!cells.contains(&2));
        assert_eq!(cells.iter().filter(|&&c| c == 1).count(), 6);
        drop_small_components(&mut cells, 8, 1, 0.0, 2, &mut seen, &mut stack, &mut members);
        assert!(!cells.contains(&1));
    }

    #[test]
    fn long_thin_strips_are_dropped_compact_regions_kept() {
        // 40x3 strip of class 2 (elongation 13.3) and a 6x8 block of class 1 (1.3).
        let w = 48;
        let mut cells = vec![0u16; w * 12];
        for y in 0..3 {
            for x in 2..42 {
                cells[y * w + x] = 2;
            }
        }
        for y in 4..12 {
            for x in 10..16 {
                cells[y * w + x] = 1;
            }
        }
        let n = cells.len();
        let (mut seen, mut stack, mut members) = (vec![false; n], Vec::with_capacity(n), Vec::with_capacity(n));
        let mut kept = cells.clone();
        drop_small_components(&mut kept, w, 6, 14.0, 0, &mut seen, &mut stack, &mut members);
        assert_eq!(kept, cells, "below the threshold both stay");
        drop_small_components(&mut cells, w, 6, MAX_ELONGATION, 0, &mut seen, &mut stack, &mut members);
        assert_eq!(cells.iter().filter(|&&c| c == 2).count(), 0, "the strip goes");
        assert_eq!(cells.iter().filter(|&&c| c == 1).count(), 48, "the block stays");
    }

    #[test]
    fn erosion_clears_region_borders_only() {
        // A 3x3 block of class 1 in a 5x5 grid keeps its centre only; background stays.
        let mut cells = vec![0u16; 25];
        for y in 1..4 {
            for x in 1..4 {
                cells[y * 5 + x] = 1;
            }
        }
        let mut out = vec![9u16; 25];
        erode_boundaries(&cells, 5, &mut out);
        let expect: Vec<u16> = (0..25).map(|i| u16::from(i == 12)).collect();
        assert_eq!(out, expect);
        // Two classes touching: both lose the shared border.
        let (cells, mut out) = (vec![1u16, 1, 1, 2, 2, 2], vec![0u16; 6]);
        erode_boundaries(&cells, 6, &mut out);
        assert_eq!(out, vec![1, 1, 0, 0, 2, 2]);
    }
}
