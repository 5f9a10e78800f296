//! A second mask for poses that failed verification: the region was the
//! segmenter's guess, the pose (roughly right) says where the object is.
//!
//! On images fusepose did not render, the segmenter's regions miss parts of
//! objects (shadows and table textures take their labels) or cut one object
//! into two; the pose from such a region is a few centimetres off and fails
//! verification, so the object is lost though its region had the right
//! class. So for each failed pose (best fit first, at most
//! [`RemaskConfig::max_regions`]), the pixels whose points lie inside its
//! posed bounding box grown by [`RemaskConfig::margin_m`], above the support
//! plane and outside every region whose pose passed, become an instance of
//! its class; it is estimated and verified again ([`RemaskConfig::rounds`]
//! times, each pose placing the next box), and the new pose replaces the
//! failed one when it passes. The region (the published mask) stays the
//! segmenter's.
//!
//! A pose that failed on its region's area
//! ([`crate::verify::VerifyConfig::min_region_area_share`]) gets none: it was
//! made up for a speck, and its posed box would make a pose of whatever lies
//! there.
//!
//! Optionally ([`RemaskConfig::max_confidence`], off by default: measured,
//! not adopted, docs/BENCHMARKS.md session 34) passed poses the network
//! doubted get a second mask too, and are replaced only by a pose it is
//! surer of.
//!
//! Class planes only: an instance plane's masks are the producer's.

use fusepose_scene::ObjectSet;
use nalgebra::{Matrix3, Vector3};

use crate::frame::{FrameView, LabelPlane};
use crate::poses::PoseSet;
use crate::seg::SegEngine;
use crate::verify::{Verification, Verifier, verify_on_region};
use crate::workspace::{Workspace, WorkspaceConfig, WorkspaceConfigError};
use crate::{EstimateError, Estimator};

/// Most failed poses per frame given a second mask ([`RemaskConfig::max_regions`]).
pub const MAX_REGIONS: usize = 16;
/// Most estimates per second mask ([`RemaskConfig::rounds`]).
pub const MAX_ROUNDS: usize = 4;

/// Fewest pixels with depth of a second mask worth estimating.
const MIN_PIXELS: usize = 64;

/// Which failed poses get a second mask, and how it is drawn.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RemaskConfig {
    /// Most failed poses per frame given a second mask (0 = off).
    pub max_regions: usize,
    /// The posed bounding box grows by this on every side (metres): room
    /// for the failed pose's error.
    pub margin_m: f32,
    /// Estimates per second mask (each pose placing the next box).
    pub rounds: usize,
    /// Only failed poses with at least this verification inlier fraction:
    /// a pose with none of its surface on the depth is no object's.
    pub min_inlier_fraction: f32,
    /// Passed poses whose network confidence is below this get a second
    /// mask too, after the failed ones, least confident first (0 = off): the
    /// network doubts a pose most often when its region held only part of
    /// the object (shadows and table texture took the rest), and a pose from
    /// part of an object's texture and shape is a few centimetres or a
    /// handle's turn off though it passes.
    pub max_confidence: f32,
    /// A passed pose is replaced only when its successor's verification
    /// inlier fraction is at least its own minus this (the depth must not
    /// say the successor is worse) ...
    pub inlier_slack: f32,
    /// ... and the network is surer of the successor: its confidence at
    /// least the old one's plus this.
    pub confidence_gain: f32,
}

impl RemaskConfig {
    pub const DEFAULT: Self = Self {
        max_regions: 4,
        margin_m: 0.01,
        rounds: 2,
        min_inlier_fraction: 0.3,
        max_confidence: 0.0,
        inlier_slack: 0.02,
        confidence_gain: 0.0,
    };

    pub fn is_on(&self) -> bool {
        self.max_regions > 0 && self.rounds > 0
    }
}

/// What [`Remask::run`] did in one frame (summed over frames by `+=`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RemaskStats {
    /// Failed poses given a second mask.
    pub tried: usize,
    /// Of them, replaced by a pose that passed.
    pub kept: usize,
    /// Passed poses the network doubted given a second mask.
    pub doubted_tried: usize,
    /// Of them, replaced.
    pub doubted_kept: usize,
    /// Piece estimates made.
    pub estimates: usize,
}

impl std::ops::AddAssign for RemaskStats {
    fn add_assign(&mut self, o: Self) {
        self.tried += o.tried;
        self.kept += o.kept;
        self.doubted_tried += o.doubted_tried;
        self.doubted_kept += o.doubted_kept;
        self.estimates += o.estimates;
    }
}

/// Second masks for failed poses; see the module doc.
pub struct Remask {
    config: RemaskConfig,
    /// Per class (id − 1): the bounding box (min, max corners), model frame, metres.
    boxes: Vec<[[f32; 3]; 2]>,
    /// Per class (id − 1): the support floor (metres above the plane).
    floors: Vec<f32>,
    /// The second masks as an instance plane (candidate j = id j + 1).
    ids: Vec<u16>,
    classes: Vec<u16>,
    /// Boxes written into `ids` this round.
    written: Vec<[u16; 4]>,
    ws: Workspace,
    poses: PoseSet,
    /// Indices (in the frame's poses) of the poses taken: failed ones first,
    /// then passed ones the network doubted.
    candidates: Vec<usize>,
    /// Passed poses the network doubted (indices), before they join `candidates`.
    doubted: Vec<usize>,
    /// Per candidate: its latest pose (the failed one, then each estimate's).
    current: Vec<Option<crate::ObjectPose>>,
    /// Per candidate: the latest estimate's pose (kept when a later round gives none).
    found: Vec<Option<crate::ObjectPose>>,
    /// Component ids of the regions whose pose passed.
    passed_regions: Vec<u32>,
    /// [`Remask::budget_next_frame`]'s estimates, for the next frame only.
    frame_budget: Option<usize>,
}

impl Remask {
    pub fn new(
        objects: &ObjectSet,
        ws_config: WorkspaceConfig,
        config: RemaskConfig,
    ) -> Result<Self, WorkspaceConfigError> {
        let regions = config.max_regions.max(1);
        let mut ws = Workspace::new(WorkspaceConfig { max_instances: regions, ..ws_config })?;
        let floors = crate::support::class_floors(objects, ws_config.support_floor_m);
        ws.support_floors(&floors);
        Ok(Self {
            config,
            boxes: objects
                .objects
                .iter()
                .map(|o| [o.bbox_min.coords.map(|x| x as f32).into(), o.bbox_max.coords.map(|x| x as f32).into()])
                .collect(),
            floors,
            ids: Vec::new(),
            classes: vec![0; regions + 1],
            written: Vec::with_capacity(regions),
            ws,
            poses: PoseSet::with_capacity(regions),
            candidates: Vec::with_capacity(2 * ws_config.max_instances.max(regions)),
            doubted: Vec::with_capacity(2 * ws_config.max_instances.max(regions)),
            current: Vec::with_capacity(regions),
            found: Vec::with_capacity(regions),
            // Room for each instance's class alternate too.
            passed_regions: Vec::with_capacity(2 * ws_config.max_instances),
            frame_budget: None,
        })
    }

    /// In the next [`Remask::run`] only: make at most `estimates` estimates
    /// (each failed pose costs one per round): what the frame's time left
    /// pays for (the daemon, at the measured cost per estimate). Fewer than a
    /// pose's rounds: none is looked at.
    pub fn budget_next_frame(&mut self, estimates: usize) {
        self.frame_budget = Some(estimates);
    }

    /// Gives the failed poses of `poses` (verdicts in `verdicts`, same order)
    /// a second mask each and replaces those whose new pose passes (pose and
    /// verdict; the pose keeps its instance and box in `ws`), judged as
    /// [`verify_on_region`] judges (`segmenter`: as the caller passes it there).
    #[allow(clippy::too_many_arguments)] // the frame's parts, borrowed one by one
    pub fn run(
        &mut self,
        frame: &FrameView<'_>,
        ws: &Workspace,
        poses: &mut PoseSet,
        verdicts: &mut [Verification],
        estimator: &mut dyn Estimator,
        verifier: &mut Verifier,
        segmenter: Option<&SegEngine>,
        seed: u64,
    ) -> Result<RemaskStats, EstimateError> {
        let mut stats = RemaskStats::default();
        let budget = self.frame_budget.take();
        let class_plane = frame.labels.is_some_and(|l| !l.is_instances());
        if !class_plane || !self.config.is_on() || verdicts.len() != poses.len() {
            return Ok(stats);
        }
        let (w, h) = (frame.width(), frame.height());
        if self.ids.len() != w * h {
            self.warm_up(frame, estimator, seed)?;
        }
        self.passed_regions.clear();
        self.candidates.clear();
        self.doubted.clear();
        // A pose that failed on its region's area was made up for a speck: a
        // mask from its posed box would make a pose of whatever lies there.
        let min_area = verifier.config().min_region_area_share;
        for (i, (p, v)) in poses.as_slice().iter().zip(verdicts.iter()).enumerate() {
            let Some(id) = ws.component_id(p.instance_id as usize) else { continue };
            if v.passed {
                self.passed_regions.push(id);
                if p.confidence < self.config.max_confidence {
                    self.doubted.push(i);
                }
            } else {
                let speck = v.region_area_share < min_area;
                if v.inlier_fraction >= self.config.min_inlier_fraction && !speck {
                    self.candidates.push(i);
                }
            }
        }
        // Best fit first: the likeliest to be an object gets the contested pixels.
        self.candidates.sort_unstable_by(|&a, &b| verdicts[b].fit.total_cmp(&verdicts[a].fit));
        // Then the least confident: a failed pose is an object lost, a doubted one imprecise.
        let all = poses.as_slice();
        self.doubted.sort_unstable_by(|&a, &b| all[a].confidence.total_cmp(&all[b].confidence));
        self.candidates.extend_from_slice(&self.doubted);
        let affordable = budget.map_or(usize::MAX, |b| b / self.config.rounds.max(1));
        self.candidates.truncate(self.config.max_regions.min(affordable));
        if self.candidates.is_empty() {
            return Ok(stats);
        }
        let doubted_tried = self.candidates.iter().filter(|&&i| verdicts[i].passed).count();
        stats.tried = self.candidates.len() - doubted_tried;
        stats.doubted_tried = doubted_tried;
        self.current.clear();
        self.current.extend(self.candidates.iter().map(|&i| Some(poses.as_slice()[i])));
        self.found.clear();
        self.found.resize(self.candidates.len(), None);
        for _ in 0..self.config.rounds {
            if self.draw(frame, ws) == 0 {
                // Boxes too thin to estimate were cleared; forget them too.
                self.clear_plane(w);
                break;
            }
            let view =
                FrameView { labels: Some(LabelPlane::Instances { ids: &self.ids, classes: &self.classes }), ..*frame };
            let estimated = self
                .ws
                .prepare(&view, seed)
                .map_err(EstimateError::Frame)
                .and_then(|_| estimator.estimate(&view, &mut self.ws, &mut self.poses));
            stats.estimates += self.poses.len();
            if let Err(e) = estimated {
                self.clear_plane(w);
                return Err(e);
            }
            self.current.iter_mut().for_each(|c| *c = None);
            for pose in self.poses.as_slice() {
                let Some(id) = self.ws.component_id(pose.instance_id as usize) else { continue };
                let j = id as usize - 1;
                if j >= self.candidates.len() {
                    continue;
                }
                self.found[j] = Some(*pose);
                self.current[j] = Some(*pose);
            }
            self.clear_plane(w);
        }
        for (j, &i) in self.candidates.iter().enumerate() {
            let Some(pose) = self.found[j] else { continue };
            let old = poses.as_slice()[i];
            // Judged on the segmenter's region as the first pose was, not on
            // the second mask: drawn from a pose, it would vouch for any pose.
            let pose = crate::ObjectPose {
                instance_id: old.instance_id,
                bbox: old.bbox,
                mask_pixels: old.mask_pixels,
                ..pose
            };
            let Some(v) = verify_on_region(verifier, frame, ws, segmenter, &pose).filter(|v| v.passed) else {
                continue;
            };
            let was = verdicts[i];
            if was.passed {
                // The depth must not say the successor is worse.
                if v.inlier_fraction < was.inlier_fraction - self.config.inlier_slack
                    || pose.confidence < old.confidence + self.config.confidence_gain
                {
                    continue;
                }
                stats.doubted_kept += 1;
            } else {
                stats.kept += 1;
            }
            poses.replace(i, pose);
            verdicts[i] = v;
        }
        Ok(stats)
    }

    /// Warms the second masks up for frames of `frame`'s size now, once per
    /// size, as [`Remask::run`] does on its first frame: for a caller that
    /// runs them only in some frames (the daemon, in frames with time to
    /// spare), so that the first such frame, minutes into a stream, does not
    /// allocate and fault in the second workspace's pages.
    pub fn warm_up_for(
        &mut self,
        frame: &FrameView<'_>,
        estimator: &mut dyn Estimator,
        seed: u64,
    ) -> Result<(), EstimateError> {
        if self.config.is_on() && self.ids.len() != frame.width() * frame.height() {
            self.warm_up(frame, estimator, seed)?;
        }
        Ok(())
    }

    /// Once per frame size: sizes the plane and estimates a square mask at
    /// the frame's centre as class 1 in every slot, so that the second
    /// workspace and the estimator have met a frame of this size and their
    /// most instances before a failed pose first comes (no later frame
    /// allocates).
    fn warm_up(
        &mut self,
        frame: &FrameView<'_>,
        estimator: &mut dyn Estimator,
        seed: u64,
    ) -> Result<(), EstimateError> {
        let (w, h) = (frame.width(), frame.height());
        self.ids.clear();
        self.ids.resize(w * h, 0);
        self.written.clear();
        let slots = self.classes.len() - 1;
        let side = (w / (2 * slots)).min(h / 4).max(1);
        let v0 = (h - side) / 2;
        for k in 0..slots {
            let u0 = (w / 4 + k * side).min(w - side);
            for v in v0..v0 + side {
                self.ids[v * w + u0..v * w + u0 + side].fill(k as u16 + 1);
            }
            self.classes[k + 1] = 1;
        }
        let view =
            FrameView { labels: Some(LabelPlane::Instances { ids: &self.ids, classes: &self.classes }), ..*frame };
        let warmed = self
            .ws
            .prepare(&view, seed)
            .map_err(EstimateError::Frame)
            .and_then(|_| estimator.estimate(&view, &mut self.ws, &mut self.poses));
        self.ids.fill(0);
        self.classes.fill(0);
        self.poses.clear();
        warmed
    }

    /// Writes each candidate's second mask from its current pose into the
    /// plane, which [`Remask::clear_plane`] left clear; returns how many
    /// were written.
    fn draw(&mut self, frame: &FrameView<'_>, ws: &Workspace) -> usize {
        let (w, h) = (frame.width(), frame.height());
        let main_ids = ws.component_ids();
        let support = ws.support_plane();
        let m = self.config.margin_m;
        let mut count = 0;
        for j in 0..self.candidates.len() {
            let Some(pose) = self.current[j] else { continue };
            let Some(class) = (pose.class_id as usize).checked_sub(1).filter(|&c| c < self.boxes.len()) else {
                continue;
            };
            let [lo, hi] = self.boxes[class];
            let (lo, hi) = ([lo[0] - m, lo[1] - m, lo[2] - m], [hi[0] + m, hi[1] + m, hi[2] + m]);
            let r: Matrix3<f32> = pose.rotation.to_rotation_matrix().matrix().map(|x| x as f32);
            let t: Vector3<f32> = pose.translation.map(|x| x as f32);
            // The grown box's corners in the image bound the window.
            let k = &frame.intrinsics;
            let (mut u0, mut v0, mut u1, mut v1) = (f32::INFINITY, f32::INFINITY, f32::NEG_INFINITY, f32::NEG_INFINITY);
            let mut behind = false;
            for c in 0..8 {
                let q = Vector3::new(
                    if c & 1 == 0 { lo[0] } else { hi[0] },
                    if c & 2 == 0 { lo[1] } else { hi[1] },
                    if c & 4 == 0 { lo[2] } else { hi[2] },
                );
                let x = r * q + t;
                if x.z < 1e-2 {
                    behind = true;
                    break;
                }
                let (u, v) = (k.fx as f32 * x.x / x.z + k.cx as f32, k.fy as f32 * x.y / x.z + k.cy as f32);
                (u0, v0, u1, v1) = (u0.min(u), v0.min(v), u1.max(u), v1.max(v));
            }
            if behind || u1 < 0.0 || v1 < 0.0 || u0 > (w - 1) as f32 || v0 > (h - 1) as f32 {
                continue;
            }
            let (u0, v0) = (u0.max(0.0) as usize, v0.max(0.0) as usize);
            let (u1, v1) = ((u1 as usize).min(w - 1), (v1 as usize).min(h - 1));
            let own = ws.component_id(pose.instance_id as usize);
            let rt = r.transpose();
            let floor = self.floors.get(class).copied().unwrap_or(0.0);
            let id = j as u16 + 1;
            let mut pixels = 0;
            for v in v0..=v1 {
                for u in u0..=u1 {
                    let p = v * w + u;
                    if self.ids[p] != 0 {
                        continue;
                    }
                    let Some(z) = frame.depth.metres(p) else { continue };
                    let region = main_ids[p];
                    if region != 0 && Some(region) != own && self.passed_regions.contains(&region) {
                        continue;
                    }
                    let x = Vector3::from(crate::sampling::back_project(frame, u, v, z));
                    if support.is_some_and(|s| s.height(&x) < floor) {
                        continue;
                    }
                    let q = rt * (x - t);
                    if (0..3).all(|a| q[a] >= lo[a] && q[a] <= hi[a]) {
                        self.ids[p] = id;
                        pixels += 1;
                    }
                }
            }
            self.written.push([u0 as u16, v0 as u16, u1 as u16, v1 as u16]);
            if pixels < MIN_PIXELS {
                self.clear_box(w, self.written.len() - 1, id);
                continue;
            }
            self.classes[id as usize] = pose.class_id;
            count += 1;
        }
        count
    }

    fn clear_box(&mut self, w: usize, k: usize, id: u16) {
        let [u0, v0, u1, v1] = self.written[k].map(|x| x as usize);
        for v in v0..=v1 {
            for x in &mut self.ids[v * w + u0..=v * w + u1] {
                if *x == id {
                    *x = 0;
                }
            }
        }
    }

    fn clear_plane(&mut self, w: usize) {
        for k in 0..self.written.len() {
            let [u0, v0, u1, v1] = self.written[k].map(|x| x as usize);
            for v in v0..=v1 {
                self.ids[v * w + u0..=v * w + u1].fill(0);
            }
        }
        self.written.clear();
        self.classes.fill(0);
    }
}
