//! Pose verification against the depth image: does the object, placed at its
//! estimated pose, explain what the camera measured?
//!
//! The object's surface samples are projected at the estimated pose and each
//! is compared with the measured depth at its pixel: a measured surface
//! behind the sample means the camera sees through where the object should
//! be (an outlier); one in front is the object's own hidden side or an
//! occluder (no evidence either way); agreement within a tolerance that grows
//! with depth is an inlier. The coverage is the share of the instance mask
//! (on a coarse grid over the mask's and the model's boxes) with an inlier
//! nearby — a pose behind the measured surface explains nothing — and the
//! model's front surface (nearest sample per cell) must not lie behind the
//! measured surface inside the mask. A pose passes with enough of each;
//! `fit = inlier fraction × coverage × (1 − behind fraction)` is the score
//! published with it. A pose shifted off its object, or an
//! object pose made up for a patch of table, fails: the table is a plane
//! where the model has a shape, and it lies behind the model where the model
//! overhangs the patch.
//!
//! Two more terms refuse poses that depth alone explains: most of the
//! model's silhouette must have a depth reading (a pose floating over a void
//! beyond the sensor's range explains the few pixels it touches), and a flat
//! mask must not continue in its own plane past most of its border (a box
//! face "flush with" a table patch explains the patch exactly, but a real
//! box stands out of the table, so its border steps off the plane).
//! Objects thinner than [`THIN_OBJECT_M`] (scissors, a plate, a sheet) step
//! off the table by less than the depth-continuity tolerance, so that term is
//! not applied to them (still reported); the plane term still is: a thin
//! object's top lies off the table's plane by more than its tolerance. Where
//! a thin object lies on a table only the mask can say, so for them the
//! model's surface that agrees with the depth must mostly lie in the mask
//! (a thin ghost made up for a small patch of table covers table beyond it).
//!
//! That share, the mask agreement, also tells an imprecise pose from a
//! ghost: a pose 1–3 cm off its object leaves many samples off the depth,
//! but those that agree lie in its mask, where a ghost's agreeing surface
//! spills past the region it was made up for. Poses of objects at least
//! 15 cm across that agree this well pass with looser inlier and fit
//! minimums ([`VerifyConfig::agreeing_mask_agreement`]): a small rotation
//! error moves the far parts of a large object out of the depth tolerance,
//! while on a small object a pose 3 cm off can still agree inside its mask.
//!
//! Where the built-in segmenter made the region, its own certainty is a
//! last term ([`Verification::judge_region_probability`]): a region in which
//! it nowhere gave the pose's class a high probability is one it made up, a
//! class-coloured patch or a piece of another object that some pose of the
//! class may still fit. [`Verifier::explained_share`] measures how much of
//! one region another pose's model explains ([`crate::explained`]).
//!
//! Buffers are sized at construction; [`Verifier::verify`] does not allocate.

use fusepose_scene::ObjectSet;

use crate::frame::FrameView;
use crate::moments::Moments;
use crate::poses::ObjectPose;
use crate::sample_normals::{NORMAL_NEIGHBOURS, facing, sample_normals};

/// Thresholds of the check. Defaults chosen on the tuning split (`fusepose render
/// --split test --seed 7`; never the test split): they drop 1.7 % of the poses
/// under 2 cm ADD-S and 44 % of the ghost poses there (docs/BENCHMARKS.md).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VerifyConfig {
    /// Grid cells along each side of the window.
    pub grid: usize,
    /// Depth agreement tolerance `base + per_metre · z` (metres): measured and
    /// model depth within it agree.
    pub tolerance_base_m: f32,
    pub tolerance_per_m: f32,
    /// A sample that sees through to a surface behind it is an outlier only
    /// when no surface at its depth is measured within this lateral distance
    /// (metres, projected at the sample's depth): poses off by less than this
    /// are not punished at their silhouettes.
    pub lateral_slack_m: f32,
    /// Poses whose inlier fraction is below this fail.
    pub min_inlier_fraction: f32,
    /// Poses whose fit (inliers × coverage × (1 − behind)) is below this fail.
    pub min_fit: f32,
    /// Poses whose front surface lies behind the measured surface in more than
    /// this share of the mask cells they reach fail.
    pub max_behind_fraction: f32,
    /// On a flat measured patch, poses with more than this share of their
    /// visible samples off the patch's plane fail.
    pub max_off_plane: f32,
    /// Poses whose median in-mask depth residual exceeds this fail (metres).
    pub max_residual_m: f32,
    /// Poses where fewer than this share of the model's silhouette (grid
    /// cells it reaches) has a depth reading fail: a pose floating over a
    /// void (beyond the sensor's range, a window, a black hole in the depth
    /// image) is one the depth image does not support.
    pub min_depth_support: f32,
    /// A flat mask whose plane goes on past its border, on more than this
    /// share of the border, is a marking on a surface (a patch of table or
    /// wall, or a piece of a larger face), not an object standing out of it:
    /// every pose of it fails. Objects thinner than the depth tolerance
    /// cannot be told from such markings.
    pub max_plane_continuation: f32,
    /// A mask whose measured surface goes on smoothly past more than this
    /// share of its border (any shape: a table's edge, a wall's corner) has
    /// no object standing out of it: every pose of it fails. 1 = off.
    pub max_depth_continuity: f32,
    /// For objects thinner than [`THIN_OBJECT_M`] (instead of
    /// `max_depth_continuity`): poses where less than this share of the
    /// model samples agreeing with the depth lie in the mask fail. 0 = off.
    pub min_thin_mask_agreement: f32,
    /// Whether verification terms weigh each model sample by how squarely it
    /// faces the camera ([`FacingWeights`]).
    pub facing: FacingWeights,
    /// For every other object: poses where less than this share of the
    /// model samples agreeing with the depth lie in the mask fail (a pose
    /// whose agreeing surface is a neighbour's or the table's, made up for a
    /// small region beside it). 0 = off.
    pub min_mask_agreement: f32,
    /// A pose of an object at least [`Self::agreeing_min_diameter_m`] across
    /// whose depth-agreeing samples lie this much in the mask (mask
    /// agreement) is where the mask says the object is, only imprecise: it
    /// passes with the looser [`Self::agreeing_min_inlier_fraction`] and
    /// [`Self::agreeing_min_fit`] instead of `min_inlier_fraction` and
    /// `min_fit` (every other term still applies). Above 1 = off.
    pub agreeing_mask_agreement: f32,
    pub agreeing_min_inlier_fraction: f32,
    pub agreeing_min_fit: f32,
    /// Smaller objects keep the strict minimums: on them a pose 3 cm off can
    /// keep most of its agreeing samples in the mask, and a small rotation
    /// error moves few samples out of the depth tolerance (metres).
    pub agreeing_min_diameter_m: f32,
    /// Poses on a region of the built-in segmenter whose peak probability of
    /// the pose's class is below this fail
    /// ([`Verification::judge_region_probability`]; regions from other
    /// sources are not judged). 0 = off, the default: 0.8 cuts ghosts of the
    /// shipped segmenter, but a segmenter trained for minutes on a user's
    /// objects is rarely that sure of them, and there it drops many real
    /// poses (docs/BENCHMARKS.md, session 19).
    pub min_region_probability: f32,
    /// A region whose pixels with depth lie on the support plane (under the
    /// class's floor, [`crate::Workspace::class_floor`]) at least this much
    /// is judged on its other pixels ([`verify_on_region`]): the segmenter
    /// gave a patch of table the object's class around it (a green bowl on
    /// a green table), and a pose of the object cannot cover the table. A
    /// region all on the table keeps no pixel with depth and fails; a pose
    /// judged so also needs [`Self::min_thin_mask_agreement`] of its
    /// depth-agreeing surface in the trimmed region. Objects thinner than
    /// [`THIN_OBJECT_M`] are never judged so (they lie within the table's
    /// height band). Above 1 = off.
    pub trim_table_share: f32,
    /// With a fitted model ([`Verifier::set_odds`]): poses whose odds of
    /// being right ([`Verification::odds`], [`crate::pose_odds`]) are below
    /// this fail. 0 = off; without a model it does nothing.
    pub min_odds: f32,
    /// Poses with more than this share of their surface samples more than
    /// [`Self::below_support_m`] below the support plane
    /// ([`Verifier::set_support`]) fail: a solid object cannot stand inside
    /// the table. A made-up pose can hide there, its one face flush with the
    /// table and the rest "behind" the measured surface, where depth cannot
    /// refuse it. Above 1 = off.
    pub max_below_support: f32,
    /// Metres below the plane from which a sample counts as sunk: beyond the
    /// plane's fit and the depth noise of a real object resting on it.
    pub below_support_m: f32,
    /// Poses whose region covers less than this share of the object's largest
    /// face fail ([`Verification::region_area_share`]): a region of a few
    /// square centimetres cannot hold a pose, and the poses made up for such
    /// specks (a mug on a fleck of a coffee can) pass every depth term on the
    /// surface they lie on. Relative to the object, so a small part keeps its
    /// small regions. 0 = off.
    pub min_region_area_share: f32,
}

impl Default for VerifyConfig {
    fn default() -> Self {
        Self {
            grid: 24,
            tolerance_base_m: 0.008,
            tolerance_per_m: 0.006,
            lateral_slack_m: 0.012,
            min_inlier_fraction: 0.5,
            min_fit: 0.3,
            max_behind_fraction: 0.3,
            max_off_plane: 0.3,
            max_residual_m: 0.02,
            min_depth_support: 0.6,
            max_plane_continuation: 0.5,
            max_depth_continuity: 0.8,
            min_thin_mask_agreement: 0.4,
            min_mask_agreement: 0.0,
            facing: FacingWeights::None,
            agreeing_mask_agreement: 0.75,
            agreeing_min_inlier_fraction: 0.3,
            agreeing_min_fit: 0.25,
            agreeing_min_diameter_m: 0.15,
            min_region_probability: 0.0,
            trim_table_share: 0.5,
            max_below_support: 2.0,
            below_support_m: 0.03,
            min_region_area_share: 0.0,
            min_odds: 0.0,
        }
    }
}

/// Which verification terms count a model sample by the image area it
/// stands for, `|n · r̂|` (its normal against the viewing ray), instead of
/// one each. Surface samples are spread uniformly over the object's area, so
/// a face seen edge-on holds as many as one seen face-on but covers a sliver
/// of pixels: a box's side seen at 2° made half of a true pose's samples lie
/// "off" its flat front-face mask. Measured on the tuning splits, not the
/// default (docs/BENCHMARKS.md, session 46): `OffPlane` gains 0.1 ADD(S) on
/// average and lets one more stray pose through on a path-traced split,
/// `All` gains 1 point on touching pairs but passes ghosts of look-alike
/// classes on path-traced images.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FacingWeights {
    /// Every sample counts once.
    #[default]
    None,
    /// The off-plane share alone.
    OffPlane,
    /// The off-plane share and the inlier fraction.
    All,
}

/// The outcome of one pose's check.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Verification {
    /// `inlier_fraction × mask_coverage`, 0..1.
    pub fit: f32,
    /// Median |measured − model| depth over the in-mask samples not hidden behind
    /// the measured surface (metres; NaN when none).
    pub depth_residual_m: f32,
    /// Inliers / judged samples of the visible model surface.
    pub inlier_fraction: f32,
    /// Mask cells (with a depth reading) the model covers / mask cells with a depth reading.
    pub mask_coverage: f32,
    /// Mask cells where the model's front surface lies behind the measured
    /// surface / mask cells the model reaches.
    pub behind_fraction: f32,
    /// Share of the model's visible samples off the plane of a flat measured
    /// mask (0 when the mask is not flat).
    pub off_plane: f32,
    /// Grid cells of the model's silhouette with a depth reading / cells of
    /// its silhouette (any pixel, in the mask or not).
    pub depth_support: f32,
    /// Share of the border samples of a flat mask lying on the mask's plane
    /// ([`VerifyConfig::max_plane_continuation`]); 0 when the mask is not flat.
    pub plane_continuation: f32,
    /// Share of the mask's border samples where the depth goes on smoothly
    /// past it ([`VerifyConfig::max_depth_continuity`]).
    pub depth_continuity: f32,
    /// Inlier samples (model surface agreeing with the depth) that lie in the
    /// mask / inlier samples ([`VerifyConfig::min_thin_mask_agreement`]).
    pub mask_agreement: f32,
    /// The segmenter's peak probability of the pose's class in its region
    /// ([`Verification::judge_region_probability`]); NaN when not judged.
    pub region_probability: f32,
    /// Share of the model's surface samples more than
    /// [`VerifyConfig::below_support_m`] below the support plane
    /// ([`VerifyConfig::max_below_support`]); 0 without a plane.
    pub below_support: f32,
    /// The region's area back-projected at the pose's depth (pixels × z² ÷
    /// (fx · fy)) over the object's largest bounding-box face
    /// ([`VerifyConfig::min_region_area_share`]); NaN when not judged.
    pub region_area_share: f32,
    /// The fitted model's probability that the pose is right
    /// ([`crate::pose_odds`], [`VerifyConfig::min_odds`]); NaN without a
    /// model or outside [`verify_on_region`].
    pub odds: f32,
    /// Samples judged (inliers + outliers).
    pub judged_cells: u32,
    /// Whether the pose passed every threshold of [`VerifyConfig`] (depth
    /// continuity for objects at least [`THIN_OBJECT_M`] thick, mask
    /// agreement for thinner ones).
    pub passed: bool,
}

/// Which pixels belong to the instance: `ids[p] == id` (a workspace's
/// region: [`crate::Workspace::mask_ref`]).
#[derive(Clone, Copy, Debug)]
pub struct MaskRef<'a> {
    pub ids: &'a [u32],
    pub id: u32,
    /// The mask's box [u_min, v_min, u_max, v_max], inclusive.
    pub bbox: [u16; 4],
}

/// Verifies poses of one object set; one per camera (holds scratch buffers).
pub struct Verifier {
    config: VerifyConfig,
    /// Surface samples per class (id − 1), object frame, metres.
    samples: Vec<Vec<[f32; 3]>>,
    /// Per class (id − 1): each sample's surface normal (object frame, sign
    /// arbitrary; [`crate::sample_normals`]); empty when
    /// [`VerifyConfig::facing`] is `None`.
    normals: Vec<Vec<[f32; 3]>>,
    /// Per grid cell: a sample agreeing with the measured depth falls in it.
    explained: Vec<bool>,
    /// Per grid cell: the nearest sample's depth (the model's front surface; infinity = none).
    zbuf: Vec<f32>,
    /// In-mask residuals of the current pose (capacity: the most samples of a class).
    residuals: Vec<f32>,
    /// Per class (id − 1): thinner than [`THIN_OBJECT_M`], so depth continuity does not apply.
    thin: Vec<bool>,
    /// Per class (id − 1): diameter, metres.
    diameters: Vec<f32>,
    /// Per class (id − 1): area of the largest face of its samples' bounding
    /// box (object frame), m².
    faces: Vec<f32>,
    /// Per class (id − 1): farthest surface sample from the object's origin, metres.
    radii: Vec<f32>,
    /// A region's pixels off the table ([`VerifyConfig::trim_table_share`]);
    /// zero outside the call that writes it. Sized at the first frame.
    off_table: Vec<u32>,
    /// The frame's support plane ([`Verifier::set_support`]).
    support: Option<crate::support::SupportPlane>,
    /// The weight file's model of a pose's odds ([`Verifier::set_odds`]).
    odds: Option<Box<crate::pose_odds::PoseOdds>>,
}

/// Objects whose thinnest extent is below this (metres) step off a table by
/// about the depth-continuity tolerance (1 cm + 1 % of the depth), so a real
/// one lying flat looks to it like a marking on the table.
pub const THIN_OBJECT_M: f32 = 0.025;

/// The object's extent along the direction it is thinnest in (metres): the
/// spread of its surface samples along their principal axis of least variance.
pub fn thinnest_extent(samples: &[[f32; 3]]) -> f32 {
    let mut moments = Moments::default();
    samples.iter().for_each(|&p| moments.add(p));
    let Some((mean, axis, _)) = moments.least_axis(4.0) else { return 0.0 };
    let (lo, hi) = samples.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), p| {
        let d = axis[0] * (p[0] - mean[0]) + axis[1] * (p[1] - mean[1]) + axis[2] * (p[2] - mean[2]);
        (lo.min(d), hi.max(d))
    });
    hi - lo
}

/// Area of the largest face of the samples' axis-aligned bounding box (m²).
fn largest_face(samples: &[[f32; 3]]) -> f32 {
    let mut extent = [0.0f32; 3];
    for (axis, e) in extent.iter_mut().enumerate() {
        let (lo, hi) =
            samples.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), p| (lo.min(p[axis]), hi.max(p[axis])));
        *e = if hi > lo { hi - lo } else { 0.0 };
    }
    extent.sort_by(f32::total_cmp);
    extent[1] * extent[2]
}

impl Verifier {
    pub fn new(objects: &ObjectSet, config: VerifyConfig) -> Self {
        let grid = config.grid.clamp(4, 128);
        let samples: Vec<Vec<[f32; 3]>> = objects
            .objects
            .iter()
            .map(|o| o.samples.iter().map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect())
            .collect();
        let max_samples = samples.iter().map(Vec::len).max().unwrap_or(0);
        let thin = samples.iter().map(|s| thinnest_extent(s) < THIN_OBJECT_M).collect();
        // O(n²) per object: only when a term uses them.
        let normals =
            samples
                .iter()
                .map(|s| {
                    if config.facing == FacingWeights::None { Vec::new() } else { sample_normals(s, NORMAL_NEIGHBOURS) }
                })
                .collect();
        Self {
            config: VerifyConfig { grid, ..config },
            explained: vec![false; grid * grid],
            zbuf: vec![f32::INFINITY; grid * grid],
            residuals: Vec::with_capacity(max_samples),
            thin,
            diameters: objects.objects.iter().map(|o| o.diameter as f32).collect(),
            faces: samples.iter().map(|s| largest_face(s)).collect(),
            radii: samples
                .iter()
                .map(|s| s.iter().map(|p| (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt()).fold(0.0, f32::max))
                .collect(),
            samples,
            normals,
            off_table: Vec::new(),
            support: None,
            odds: None,
        }
    }

    /// The model [`verify_on_region`] computes each pose's odds with (the
    /// weight file's, [`crate::pose_odds::PoseOdds::read`]); None = no odds.
    pub fn set_odds(&mut self, odds: Option<crate::pose_odds::PoseOdds>) {
        self.odds = odds.map(Box::new);
    }

    /// Whether a model of the odds is set.
    pub fn has_odds(&self) -> bool {
        self.odds.is_some()
    }

    /// The plane the frame's objects stand on (`Workspace::support_plane`),
    /// for [`VerifyConfig::max_below_support`]; [`verify_on_region`] sets it
    /// from its workspace, so every later check of the frame (cut pieces,
    /// second masks) judges against the same plane.
    pub fn set_support(&mut self, plane: Option<crate::support::SupportPlane>) {
        self.support = plane;
    }

    pub fn config(&self) -> &VerifyConfig {
        &self.config
    }

    /// [`Verification::region_area_share`] of `pose`'s region in `frame`
    /// (NaN for an unknown class or one without an extent).
    pub fn region_area_share(&self, frame: &FrameView<'_>, pose: &ObjectPose) -> f32 {
        let Some(&face) = (pose.class_id as usize).checked_sub(1).and_then(|c| self.faces.get(c)) else {
            return f32::NAN;
        };
        let i = &frame.intrinsics;
        let z = pose.translation.z;
        let area = pose.mask_pixels as f64 * z * z / (i.fx * i.fy);
        if face > 0.0 { (area / face as f64) as f32 } else { f32::NAN }
    }

    /// Share of the pose's surface samples lying more than `depth_m` below
    /// `plane` (the surface the objects stand on): a solid object cannot
    /// stand inside the table. NaN for an unknown class.
    pub fn below_support(&self, pose: &ObjectPose, plane: &crate::support::SupportPlane, depth_m: f32) -> f32 {
        let Some(samples) = (pose.class_id as usize).checked_sub(1).and_then(|i| self.samples.get(i)) else {
            return f32::NAN;
        };
        // The plane in the object's frame: height = n · (R s + t) + d = (Rᵀ n) · s + (n · t + d).
        let m = pose.rotation.to_rotation_matrix().matrix().map(|v| v as f32);
        let n = m.transpose() * plane.normal;
        let d = plane.height(&pose.translation.map(|v| v as f32));
        let below = samples.iter().filter(|s| n[0] * s[0] + n[1] * s[1] + n[2] * s[2] + d < -depth_m).count();
        below as f32 / samples.len().max(1) as f32
    }

    /// Checks `pose` against the frame's depth and the instance mask.
    pub fn verify(&mut self, frame: &FrameView<'_>, mask: MaskRef<'_>, pose: &ObjectPose) -> Verification {
        let fail = Verification {
            depth_residual_m: f32::NAN,
            region_probability: f32::NAN,
            region_area_share: f32::NAN,
            odds: f32::NAN,
            ..Verification::default()
        };
        let Some(class) = (pose.class_id as usize).checked_sub(1).filter(|&i| i < self.samples.len()) else {
            return fail;
        };
        let samples = &self.samples[class];
        let (w, h) = (frame.width(), frame.height());
        if w == 0 || h == 0 || mask.ids.len() < w * h {
            return fail;
        }
        let k = &frame.intrinsics;
        let m = pose.rotation.to_rotation_matrix().matrix().map(|v| v as f32);
        let t = pose.translation.map(|v| v as f32);
        let (fx, fy, cx, cy) = (k.fx as f32, k.fy as f32, k.cx as f32, k.cy as f32);
        let project = projector(frame, pose);
        let rotate =
            |n: &[f32; 3]| -> [f32; 3] { [0, 1, 2].map(|r| m[(r, 0)] * n[0] + m[(r, 1)] * n[1] + m[(r, 2)] * n[2]) };
        let to_camera = |p: &[f32; 3]| -> [f32; 3] {
            let x = rotate(p);
            [x[0] + t[0], x[1] + t[1], x[2] + t[2]]
        };
        // Window: the mask's box joined with the model's projected box, inside the image.
        let [mu0, mv0, mu1, mv1] = mask.bbox.map(|v| v as f32);
        let (mut u0, mut v0, mut u1, mut v1) = (mu0, mv0, mu1, mv1);
        for p in samples {
            if let Some((u, v, _)) = project(p) {
                (u0, v0, u1, v1) = (u0.min(u), v0.min(v), u1.max(u), v1.max(v));
            }
        }
        let (u0, v0) = (u0.max(0.0), v0.max(0.0));
        let (u1, v1) = (u1.min((w - 1) as f32), v1.min((h - 1) as f32));
        if !(u1 > u0 && v1 > v0) {
            return fail;
        }
        let g = self.config.grid;
        let (cw, ch) = ((u1 - u0 + 1.0) / g as f32, (v1 - v0 + 1.0) / g as f32);
        let cfg = self.config;
        // Every sample judged at its own pixel: measured surface behind it = the
        // camera sees through where the object should be; in front = hidden side
        // or occluder, no evidence; within the tolerance = the pose explains it.
        self.explained.fill(false);
        self.zbuf.fill(f32::INFINITY);
        let (mut inliers, mut outliers, mut inliers_in_mask) = (0u32, 0u32, 0u32);
        let (mut inlier_area, mut outlier_area) = (0f32, 0f32);
        let facing_inliers = cfg.facing == FacingWeights::All;
        self.residuals.clear();
        for (i, p) in samples.iter().enumerate() {
            let Some((u, v, z)) = project(p) else { continue };
            let area = if facing_inliers { facing(rotate(&self.normals[class][i]), to_camera(p)) } else { 1.0 };
            let (gx, gy) = ((u - u0 + 0.5) / cw, (v - v0 + 0.5) / ch);
            let cell =
                (gx >= 0.0 && gy >= 0.0 && gx < g as f32 && gy < g as f32).then(|| gy as usize * g + gx as usize);
            if let Some(c) = cell {
                self.zbuf[c] = self.zbuf[c].min(z);
            }
            let (pu, pv) = (u.round(), v.round());
            if pu < 0.0 || pv < 0.0 || pu >= w as f32 || pv >= h as f32 {
                continue;
            }
            let px = pv as usize * w + pu as usize;
            let Some(z_obs) = frame.depth.metres(px) else { continue };
            let tol = cfg.tolerance_base_m + cfg.tolerance_per_m * z;
            let res = z_obs - z;
            if mask.ids[px] == mask.id && res >= -tol && self.residuals.len() < self.residuals.capacity() {
                self.residuals.push(res.abs());
            }
            if res > tol {
                // A silhouette slightly off (a pose error under
                // `lateral_slack_m`, depth edge noise) is no evidence: only a
                // measured surface behind the sample all around it is.
                let r = (cfg.lateral_slack_m * fx / z).clamp(2.0, 24.0);
                if !surface_near(frame, pu as usize, pv as usize, w, h, r, z, tol) {
                    outliers += 1;
                    outlier_area += area;
                }
            } else if res >= -tol {
                inliers += 1;
                inlier_area += area;
                inliers_in_mask += (mask.ids[px] == mask.id) as u32;
                if let Some(c) = cell {
                    self.explained[c] = true;
                }
            }
        }
        // Coverage on the grid: mask cells (centre pixel in the mask, with depth)
        // with an inlier in their 3x3 neighbourhood (samples are sparser than
        // pixels on near objects, so a cell of its own may hold none).
        // And the model's front surface behind the measured one inside the mask
        // (the whole model too far away: its samples all look hidden).
        let (mut mask_cells, mut mask_covered, mut front_cells, mut behind_cells) = (0u32, 0u32, 0u32, 0u32);
        let (mut silhouette_cells, mut supported_cells) = (0u32, 0u32);
        let mut plane = Moments::default();
        for gy in 0..g {
            let v = ((v0 + (gy as f32 + 0.5) * ch - 0.5).round() as usize).min(h - 1);
            for gx in 0..g {
                let u = ((u0 + (gx as f32 + 0.5) * cw - 0.5).round() as usize).min(w - 1);
                let px = v * w + u;
                if self.zbuf[gy * g + gx].is_finite() {
                    silhouette_cells += 1;
                    supported_cells += frame.depth.metres(px).is_some() as u32;
                }
                let Some(z_obs) = frame.depth.metres(px).filter(|_| mask.ids[px] == mask.id) else { continue };
                mask_cells += 1;
                plane.add([(u as f32 - cx) / fx * z_obs, (v as f32 - cy) / fy * z_obs, z_obs]);
                // Nearest model depth around the cell: one sample per cell may sit
                // on a far part of a sloped surface.
                let mut z_front = f32::INFINITY;
                for y in gy.saturating_sub(1)..=(gy + 1).min(g - 1) {
                    for x in gx.saturating_sub(1)..=(gx + 1).min(g - 1) {
                        z_front = z_front.min(self.zbuf[y * g + x]);
                    }
                }
                if self.zbuf[gy * g + gx].is_finite() {
                    front_cells += 1;
                    behind_cells += (z_obs < z_front - cfg.tolerance_base_m - cfg.tolerance_per_m * z_front) as u32;
                }
                mask_covered += explained_near(&self.explained, g, gx, gy) as u32;
            }
        }
        let judged = inliers + outliers;
        let inlier_fraction = if judged > 0 && inlier_area + outlier_area > 0.0 {
            inlier_area / (inlier_area + outlier_area)
        } else {
            0.0
        };
        let mask_agreement = if inliers > 0 { inliers_in_mask as f32 / inliers as f32 } else { 0.0 };
        let mask_coverage = if mask_cells > 0 { mask_covered as f32 / mask_cells as f32 } else { 0.0 };
        let behind_fraction = if front_cells > 0 { behind_cells as f32 / front_cells as f32 } else { 0.0 };
        let depth_residual_m = median(&mut self.residuals);
        let depth_support = if silhouette_cells > 0 { supported_cells as f32 / silhouette_cells as f32 } else { 0.0 };
        // A flat measured patch (a table, a wall) explained by a model whose
        // visible surface is not flat there is no object: the share of the
        // model's judged samples off the patch's plane.
        let flat = plane.flat_plane(FLAT_RMS_M);
        let (plane_continuation, depth_continuity) = border_continuation(frame, mask, flat);
        let off_plane = match flat {
            Some((n, d)) if judged > 0 => {
                let normals = &self.normals[class];
                let flat_weights = cfg.facing == FacingWeights::None;
                let (off, all) = samples
                    .iter()
                    .enumerate()
                    .filter_map(|(i, p)| project(p).map(|(u, v, z)| (u, v, z, p, i)))
                    .filter(|&(u, v, _, _, _)| u >= u0 && v >= v0 && u <= u1 && v <= v1)
                    .filter(|&(u, v, z, _, _)| {
                        let (pu, pv) = (u.round() as usize, v.round() as usize);
                        frame
                            .depth
                            .metres(pv * w + pu)
                            .is_some_and(|z_obs| z_obs - z >= -(cfg.tolerance_base_m + cfg.tolerance_per_m * z))
                    })
                    .map(|(_, _, _, p, i)| {
                        let x = to_camera(p);
                        // Each sample weighs the image area it stands for: a face
                        // seen edge-on covers a sliver of pixels, however many samples it holds.
                        let weight = if flat_weights { 1.0 } else { facing(rotate(&normals[i]), x) };
                        let is_off = (n[0] * x[0] + n[1] * x[1] + n[2] * x[2] - d).abs() > OFF_PLANE_M;
                        (if is_off { weight } else { 0.0 }, weight)
                    })
                    .fold((0f32, 0f32), |(o, a), (f, wgt)| (o + f, a + wgt));
                if all > 0.0 { off / all } else { 0.0 }
            }
            _ => 0.0,
        };
        let fit = inlier_fraction * mask_coverage * (1.0 - behind_fraction) * (1.0 - off_plane);
        let below_support =
            self.support.map_or(0.0, |plane| self.below_support(pose, &plane, self.config.below_support_m));
        let mut verdict = Verification {
            fit,
            depth_residual_m,
            inlier_fraction,
            mask_coverage,
            behind_fraction,
            off_plane,
            depth_support,
            plane_continuation,
            depth_continuity,
            mask_agreement,
            region_probability: f32::NAN,
            region_area_share: f32::NAN,
            odds: f32::NAN,
            below_support,
            judged_cells: judged,
            passed: false,
        };
        verdict.passed = self.passes(class, &verdict, fit);
        verdict
    }

    /// Whether verdict `v` of a pose of class index `class` passes every
    /// threshold of [`VerifyConfig`], its fit taken as `fit`.
    fn passes(&self, class: usize, v: &Verification, fit: f32) -> bool {
        let cfg = &self.config;
        // A pose 1-3 cm off leaves many samples off the depth; when the samples
        // that do agree lie in the mask, the pose is on the object, not on a ghost region.
        let agreeing =
            v.mask_agreement >= cfg.agreeing_mask_agreement && self.diameters[class] >= cfg.agreeing_min_diameter_m;
        let (min_inliers, min_fit) = if agreeing {
            (cfg.agreeing_min_inlier_fraction.min(cfg.min_inlier_fraction), cfg.agreeing_min_fit.min(cfg.min_fit))
        } else {
            (cfg.min_inlier_fraction, cfg.min_fit)
        };
        v.off_plane <= cfg.max_off_plane
            && v.inlier_fraction >= min_inliers
            && fit >= min_fit
            && v.behind_fraction <= cfg.max_behind_fraction
            && v.depth_residual_m.is_finite()
            && v.depth_residual_m <= cfg.max_residual_m
            && v.depth_support >= cfg.min_depth_support
            && v.plane_continuation <= cfg.max_plane_continuation
            && v.below_support <= cfg.max_below_support
            && if self.thin[class] {
                v.mask_agreement >= cfg.min_thin_mask_agreement
            } else {
                v.depth_continuity <= cfg.max_depth_continuity && v.mask_agreement >= cfg.min_mask_agreement
            }
    }

    /// Whether verdict `v` of a pose of `class_id` passes every term but the
    /// share of its mask it covers: the pose explains its part of the mask
    /// as well as a passing pose explains all of its own (its fit with the
    /// coverage taken as 1), and the segmenter's certainty, where judged,
    /// held. A region holding several copies gives one of them such a pose
    /// ([`crate::recut`]).
    pub fn passes_but_for_coverage(&self, class_id: u16, v: &Verification) -> bool {
        let Some(class) = (class_id as usize).checked_sub(1).filter(|&i| i < self.samples.len()) else {
            return false;
        };
        v.mask_coverage > 0.0 && self.region_certain(v) && self.passes(class, v, v.fit / v.mask_coverage)
    }

    /// Whether the segmenter was sure enough of the region of verdict `v`
    /// ([`VerifyConfig::min_region_probability`]); true where not judged.
    pub fn region_certain(&self, v: &Verification) -> bool {
        v.region_probability.is_nan() || v.region_probability >= self.config.min_region_probability
    }
}

impl Verification {
    /// How two poses of one region as different classes are ranked
    /// ([`crate::alternates::losers`]): passed first, then the depth fit
    /// times the segmenter's peak probability of the class in the region
    /// (the colour evidence; 1 when not judged).
    pub fn class_score(&self) -> (bool, f32) {
        let p = if self.region_probability.is_nan() { 1.0 } else { self.region_probability };
        (self.passed, self.fit * p)
    }

    /// Adds the segmenter's peak probability `p` of the pose's class in its
    /// region (`SegEngine::region_probability`): below `min` the pose fails.
    /// A region the segmenter was nowhere sure of is where it makes objects
    /// up (a class-coloured patch, part of another object), and the depth
    /// may still agree with some pose there (docs/BENCHMARKS.md, session 19).
    pub fn judge_region_probability(&mut self, p: f32, min: f32) {
        self.region_probability = p;
        if p < min {
            self.passed = false;
        }
    }
}

impl Verifier {
    /// Share of `mask`'s region that `other` explains: mask cells (on a grid
    /// over the mask's box; centre pixel in the mask, with a depth reading)
    /// with a sample of `other`'s model, at its pose, agreeing with the
    /// measured depth in their 3x3 neighbourhood. A region that lies on
    /// another object's visible surface is that object's, whatever class the
    /// segmenter gave it ([`crate::explained`]). 0 for an unknown class or
    /// an empty mask.
    pub fn explained_share(&mut self, frame: &FrameView<'_>, mask: MaskRef<'_>, other: &ObjectPose) -> f32 {
        let Some(class) = (other.class_id as usize).checked_sub(1).filter(|&i| i < self.samples.len()) else {
            return 0.0;
        };
        let (w, h) = (frame.width(), frame.height());
        if w == 0 || h == 0 || mask.ids.len() < w * h {
            return 0.0;
        }
        let k = &frame.intrinsics;
        let (fx, fy, cx, cy) = (k.fx as f32, k.fy as f32, k.cx as f32, k.cy as f32);
        let [u0, v0, u1, v1] = mask.bbox.map(|v| v as f32);
        let (u1, v1) = (u1.min((w - 1) as f32), v1.min((h - 1) as f32));
        if !(u1 >= u0 && v1 >= v0) {
            return 0.0;
        }
        // Skip the samples when the object's bounding sphere (radius r about
        // its origin) projects off the mask's box: a point dx, dz off the
        // centre c moves f·(dx·c.z − c.x·dz) / (c.z·(c.z + dz)) pixels from
        // its projection, at most f·r·(c.z + |c.x|) / (c.z·(c.z − r)).
        let (r, c) = (self.radii[class], other.translation.map(|v| v as f32));
        if c.z - r > 1e-3 {
            let reach = |f: f32, lateral: f32| f * r * (c.z + lateral.abs()) / (c.z * (c.z - r));
            let (su, sv) = (fx * c.x / c.z + cx, fy * c.y / c.z + cy);
            let (ru, rv) = (reach(fx, c.x), reach(fy, c.y));
            if su + ru < u0 || su - ru > u1 || sv + rv < v0 || sv - rv > v1 {
                return 0.0;
            }
        }
        let g = self.config.grid;
        let (cw, ch) = ((u1 - u0 + 1.0) / g as f32, (v1 - v0 + 1.0) / g as f32);
        let cfg = self.config;
        let project = projector(frame, other);
        self.explained.fill(false);
        for p in &self.samples[class] {
            let Some((u, v, z)) = project(p) else { continue };
            let (gx, gy) = ((u - u0 + 0.5) / cw, (v - v0 + 0.5) / ch);
            if !(gx >= 0.0 && gy >= 0.0 && gx < g as f32 && gy < g as f32) {
                continue;
            }
            let (pu, pv) = (u.round() as usize, v.round() as usize);
            let Some(z_obs) = frame.depth.metres(pv.min(h - 1) * w + pu.min(w - 1)) else { continue };
            if (z_obs - z).abs() <= cfg.tolerance_base_m + cfg.tolerance_per_m * z {
                self.explained[gy as usize * g + gx as usize] = true;
            }
        }
        let (mut cells, mut covered) = (0u32, 0u32);
        for gy in 0..g {
            let v = ((v0 + (gy as f32 + 0.5) * ch - 0.5).round() as usize).min(h - 1);
            for gx in 0..g {
                let u = ((u0 + (gx as f32 + 0.5) * cw - 0.5).round() as usize).min(w - 1);
                let px = v * w + u;
                if mask.ids[px] != mask.id || frame.depth.metres(px).is_none() {
                    continue;
                }
                cells += 1;
                covered += explained_near(&self.explained, g, gx, gy) as u32;
            }
        }
        if cells == 0 { 0.0 } else { covered as f32 / cells as f32 }
    }
}

/// Verifies `pose` on its region of `ws` (None: the pose has no region) with
/// every judgment a frame's poses face: the depth terms, the segmenter's
/// certainty over the region when `segmenter` is given (it made the regions;
/// pass it only when its floor is on, or to read the certainty), and the stricter fit a region's alternate class needs
/// ([`crate::alternates::fails_as_alternate`]). The daemon, `fusepose eval`
/// and the second masks ([`crate::remask`]) judge alike through it.
pub fn verify_on_region(
    verifier: &mut Verifier,
    frame: &FrameView<'_>,
    ws: &crate::Workspace,
    segmenter: Option<&crate::seg::SegEngine>,
    pose: &ObjectPose,
) -> Option<Verification> {
    verifier.set_support(ws.support_plane());
    let id = ws.component_id(pose.instance_id as usize)?;
    let mask = ws.mask_ref(id, pose.bbox);
    let mut v = match verify_off_table(verifier, frame, ws, id, pose) {
        Some(v) => v,
        None => verifier.verify(frame, mask, pose),
    };
    if let Some(seg) = segmenter {
        let min = verifier.config().min_region_probability;
        v.judge_region_probability(seg.region_probability(mask.ids, id, pose.class_id, pose.bbox), min);
    }
    if crate::alternates::fails_as_alternate(&ws.instances, pose, v.fit) {
        v.passed = false;
    }
    v.region_area_share = verifier.region_area_share(frame, pose);
    if v.region_area_share < verifier.config().min_region_area_share {
        v.passed = false;
    }
    if let Some(model) = verifier.odds.as_deref() {
        v.odds = model.probability(&v, pose);
        if v.odds < verifier.config.min_odds {
            v.passed = false;
        }
    }
    Some(v)
}

/// [`Verifier::verify`] on region `id`'s pixels off the table when at least
/// [`VerifyConfig::trim_table_share`] of them lie on it; None otherwise (or
/// with no support plane): the caller judges the whole region.
fn verify_off_table(
    verifier: &mut Verifier,
    frame: &FrameView<'_>,
    ws: &crate::Workspace,
    id: u32,
    pose: &ObjectPose,
) -> Option<Verification> {
    let share = verifier.config.trim_table_share;
    // A thin object lies within the table's height band: by height its
    // region is the table's.
    let thin = (pose.class_id as usize).checked_sub(1).and_then(|c| verifier.thin.get(c)).is_none_or(|&t| t);
    if share > 1.0 || thin {
        return None;
    }
    let mut plane = std::mem::take(&mut verifier.off_table);
    let n = frame.width() * frame.height();
    if plane.len() != n {
        plane.clear();
        plane.resize(n, 0);
    }
    // The plane is sized above on the first call, trimmed or not: no later
    // frame allocates.
    if ws.share_on_support(frame, id, pose.class_id, pose.bbox).is_none_or(|s| s < share) {
        verifier.off_table = plane;
        return None;
    }
    let verdict = ws.write_off_support(frame, id, pose.class_id, pose.bbox, &mut plane).map(|bbox| {
        // Nothing left: judged on an empty mask, the pose fails.
        let bbox = if bbox[0] > bbox[2] { pose.bbox } else { bbox };
        let mut v = verifier.verify(frame, MaskRef { ids: &plane, id, bbox }, pose);
        // A smaller mask is easier to cover: the pose's own surface must
        // lie in it too, as a thin object's must in its region (a pose
        // whose depth-agreeing surface lies on other objects is a ghost).
        if v.mask_agreement < verifier.config.min_thin_mask_agreement {
            v.passed = false;
        }
        v
    });
    let [u0, v0, u1, v1] = pose.bbox.map(|x| x as usize);
    let w = frame.width();
    for v in v0..=v1.min(frame.height().saturating_sub(1)) {
        plane[v * w + u0..=(v * w + u1).min(v * w + w - 1)].fill(0);
    }
    verifier.off_table = plane;
    verdict
}

/// Camera-frame projection of object-frame points at `pose`: pixel (u, v)
/// and depth z (metres); None behind or at the camera.
fn projector(frame: &FrameView<'_>, pose: &ObjectPose) -> impl Fn(&[f32; 3]) -> Option<(f32, f32, f32)> {
    let k = &frame.intrinsics;
    let m = pose.rotation.to_rotation_matrix().matrix().map(|v| v as f32);
    let t = pose.translation.map(|v| v as f32);
    let (fx, fy, cx, cy) = (k.fx as f32, k.fy as f32, k.cx as f32, k.cy as f32);
    move |p: &[f32; 3]| {
        let x = m[(0, 0)] * p[0] + m[(0, 1)] * p[1] + m[(0, 2)] * p[2] + t[0];
        let y = m[(1, 0)] * p[0] + m[(1, 1)] * p[1] + m[(1, 2)] * p[2] + t[1];
        let z = m[(2, 0)] * p[0] + m[(2, 1)] * p[1] + m[(2, 2)] * p[2] + t[2];
        (z > 1e-3 && z.is_finite()).then(|| (fx * x / z + cx, fy * y / z + cy, z))
    }
}

/// Whether grid cell (gx, gy) of a g×g grid or one of its 8 neighbours is
/// marked in `explained` (samples are sparser than pixels on near objects,
/// so a cell of its own may hold none).
fn explained_near(explained: &[bool], g: usize, gx: usize, gy: usize) -> bool {
    (gy.saturating_sub(1)..=(gy + 1).min(g - 1))
        .any(|y| (gx.saturating_sub(1)..=(gx + 1).min(g - 1)).any(|x| explained[y * g + x]))
}

/// Whether a surface within `tol` of depth `z` (metres) is measured within
/// `r` pixels of `(u, v)` — the object's real silhouette edge nearby: 8
/// directions at a third, two thirds and all of `r` (24 probes instead of a
/// full disc).
#[allow(clippy::too_many_arguments)] // a pixel, the frame size, a radius and a depth band
fn surface_near(frame: &FrameView<'_>, u: usize, v: usize, w: usize, h: usize, r: f32, z: f32, tol: f32) -> bool {
    const DIRS: [(f32, f32); 8] = [
        (1.0, 0.0),
        (-1.0, 0.0),
        (0.0, 1.0),
        (0.0, -1.0),
        (0.707, 0.707),
        (-0.707, 0.707),
        (0.707, -0.707),
        (-0.707, -0.707),
    ];
    let near = |x: f32, y: f32| {
        x >= 0.0
            && y >= 0.0
            && (x as usize) < w
            && (y as usize) < h
            && frame.depth.metres(y as usize * w + x as usize).is_some_and(|d| (d - z).abs() <= tol)
    };
    [r / 3.0, 2.0 * r / 3.0, r]
        .iter()
        .any(|&d| DIRS.iter().any(|&(dx, dy)| near(u as f32 + dx * d + 0.5, v as f32 + dy * d + 0.5)))
}

/// Border samples of [`border_probes`] per side of the mask's box.
const BORDER_LINES: usize = 32;
/// How far outside the mask a border sample is taken (metres, projected at its depth).
const BORDER_STEP_M: f32 = 0.012;

/// One border sample of a mask: the depth at the mask's edge, the pixel a
/// little outside it (not in the mask) and the pixel as far inside (in the
/// mask, when it is), as pixel indices.
struct BorderProbe {
    z_edge: f32,
    outside: usize,
    inside: Option<usize>,
}

/// Calls `f` for the border samples of `mask`: on `BORDER_LINES` rows and
/// columns of its box, beyond the first and last mask pixel (left / right,
/// top / bottom), `BORDER_STEP_M` (projected) away. Edges without depth and
/// samples off the image or back in the mask are left out.
fn border_probes(frame: &FrameView<'_>, mask: MaskRef<'_>, mut f: impl FnMut(BorderProbe)) {
    let (w, h) = (frame.width(), frame.height());
    let fx = frame.intrinsics.fx as f32;
    let [u0, v0, u1, v1] = mask.bbox.map(|v| v as usize);
    if u1 >= w || v1 >= h || u1 < u0 || v1 < v0 {
        return;
    }
    let inside = |u: usize, v: usize| mask.ids[v * w + u] == mask.id;
    let at = |u: isize, v: isize| {
        (u >= 0 && v >= 0 && u < w as isize && v < h as isize).then(|| v as usize * w + u as usize)
    };
    let mut probe = |u: usize, v: usize, du: isize, dv: isize| {
        let Some(z_edge) = frame.depth.metres(v * w + u) else { return };
        let step = (BORDER_STEP_M * fx / z_edge).clamp(3.0, 24.0) as isize;
        let (u, v) = (u as isize, v as isize);
        let Some(outside) = at(u + du * step, v + dv * step).filter(|&p| mask.ids[p] != mask.id) else { return };
        let inside = at(u - du * step, v - dv * step).filter(|&p| mask.ids[p] == mask.id);
        f(BorderProbe { z_edge, outside, inside });
    };
    for i in 0..BORDER_LINES {
        let v = v0 + (v1 - v0) * (2 * i + 1) / (2 * BORDER_LINES);
        if let (Some(a), Some(b)) = ((u0..=u1).find(|&u| inside(u, v)), (u0..=u1).rev().find(|&u| inside(u, v))) {
            probe(a, v, -1, 0);
            probe(b, v, 1, 0);
        }
        let u = u0 + (u1 - u0) * (2 * i + 1) / (2 * BORDER_LINES);
        if let (Some(a), Some(b)) = ((v0..=v1).find(|&v| inside(u, v)), (v0..=v1).rev().find(|&v| inside(u, v))) {
            probe(u, a, 0, -1);
            probe(u, b, 0, 1);
        }
    }
}

/// The two border terms in one pass over [`border_probes`]:
/// - plane continuation: the share of samples (outside pixels with depth)
///   that lie on `plane` (`n·x = d`), 0 without a plane;
/// - depth continuity: the share of samples where the measured surface goes
///   on smoothly past the border — the depth outside within `1 cm + 1 %` of
///   the straight continuation of the depth inside through the edge, for any
///   surface shape (a table's edge, a wall corner).
///
/// Each is 0 when it has no samples.
fn border_continuation(frame: &FrameView<'_>, mask: MaskRef<'_>, plane: Option<([f32; 3], f32)>) -> (f32, f32) {
    let w = frame.width();
    let k = &frame.intrinsics;
    let (fx, fy, cx, cy) = (k.fx as f32, k.fy as f32, k.cx as f32, k.cy as f32);
    let (mut on, mut outside) = (0u32, 0u32);
    let (mut smooth, mut through) = (0u32, 0u32);
    border_probes(frame, mask, |b| {
        let Some(z_out) = frame.depth.metres(b.outside) else { return };
        if let Some((n, d)) = plane {
            let (pu, pv) = ((b.outside % w) as f32, (b.outside / w) as f32);
            let x = [(pu - cx) / fx * z_out, (pv - cy) / fy * z_out, z_out];
            outside += 1;
            on += ((n[0] * x[0] + n[1] * x[1] + n[2] * x[2] - d).abs() <= OFF_PLANE_M / 2.0) as u32;
        }
        if let Some(z_in) = b.inside.and_then(|p| frame.depth.metres(p)) {
            let predicted = 2.0 * b.z_edge - z_in;
            through += 1;
            smooth += ((z_out - predicted).abs() <= 0.01 + 0.01 * b.z_edge) as u32;
        }
    });
    let share = |n: u32, of: u32| if of == 0 { 0.0 } else { n as f32 / of as f32 };
    (share(on, outside), share(smooth, through))
}

/// A measured patch whose points lie within this RMS distance of one plane is flat (metres).
const FLAT_RMS_M: f32 = 0.003;
/// A model sample farther than this from a flat patch's plane is off it (metres).
const OFF_PLANE_M: f32 = 0.015;

/// Median of `v` (reordered in place); NaN when empty.
fn median(v: &mut [f32]) -> f32 {
    if v.is_empty() {
        return f32::NAN;
    }
    let mid = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(mid, f32::total_cmp);
    *m
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_of_odd_even_and_empty() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), 3.0);
        assert!(median(&mut []).is_nan());
    }
}
