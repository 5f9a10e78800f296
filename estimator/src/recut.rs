//! A second look at regions their pose leaves unexplained: two copies side
//! by side that passed as one object.
//!
//! The cut in [`crate::split`] runs before any pose and judges a region by
//! its size alone, so two cans or two boxes side by side along their thin
//! side pass as one object (they fit inside one copy's diameter and largest
//! silhouette) and get one pose between them. That pose then covers only
//! part of its region: on the tuning splits a region of one copy has its
//! verification coverage ([`Verification::mask_coverage`]) at 0.94 or more
//! in 9 cases of 10, one of two or more copies at a median of 0.76
//! (docs/BENCHMARKS.md, session 24).
//!
//! So after verification, each region whose pose covers less than
//! [`RecutConfig::max_coverage`] of it is cut in two (k-means on its 3D
//! points), each piece is estimated on its own as an instance, and the depth
//! image decides: the cut stays when both pieces' poses pass verification
//! and lie apart as two copies must ([`RecutConfig::min_separation`] × the
//! object's smallest side). The parts of one object, cut, vote for one
//! centre (the network's per-point translations point at the object's
//! centre from any part of it); two copies vote for two.
//!
//! In a live stream the second look rarely has the time: two pieces'
//! estimates and checks cost more than a busy frame leaves. So a cut that
//! stood is carried to the next frame ([`Recut::hints`] →
//! [`Workspace::set_cut_hints`]): the region is cut before the estimate and
//! its pieces are posed with the frame's other objects, then judged by the
//! same terms ([`RecutStats::carried`]); a frame without the time for the
//! pieces defers its cuts to the next frame that way
//! ([`Recut::defer_next_frame`]), and a deferred cut the next frame refuses
//! keeps that place whole for [`REFUSED_FRAMES`] frames.
//!
//! Class planes only: an instance plane's instances are the producer's.
//! Buffers are sized in [`Recut::new`] and on the first frame of a size;
//! a frame then allocates nothing.

use fusepose_scene::ObjectSet;

use crate::frame::{FrameView, LabelPlane};
use crate::poses::{ObjectPose, PoseSet};
use crate::seg::SegEngine;
use crate::split::{kmeans, nearest_2d, nearest_piece, project};
use crate::verify::{MaskRef, Verification, Verifier};
use crate::workspace::{CutHint, Workspace, WorkspaceConfig, WorkspaceConfigError};
use crate::{EstimateError, Estimator};

/// Points per region the cut clusters.
const SAMPLES: usize = 128;
/// Frames for which a deferred cut that the next frame refused is not
/// deferred again near the same place (one second at 24 FPS).
pub const REFUSED_FRAMES: u32 = 24;

/// A refused cut: where, of which class, and for how many more frames.
#[derive(Clone, Copy, Debug)]
struct Refused {
    class_id: u16,
    midpoint: [f32; 3],
    frames: u32,
}

/// Fewest valid-depth pixels of a region worth cutting.
const MIN_POINTS: usize = 64;
/// Each piece must hold at least this share of the region's samples: a
/// sliver is what the mask bled onto, not a copy.
const MIN_PIECE_SHARE: f32 = 0.2;
/// Centre votes of two copies lie at least this far apart (segmenter output
/// cells; the votes of one object scatter by a cell or two, and copies that
/// touch have centres a body width apart, several cells at working range).
const MIN_VOTE_GAP_CELLS: f32 = 3.0;

/// Where each pixel's object centre lies: a segmenter's centre-offset votes
/// ([`SegEngine::vote_at`]). The pixels of one object vote for one point,
/// those of two touching copies for two.
pub trait CentreVotes {
    /// The vote of frame pixel `(u, v)`, in segmenter output cells (x, y);
    /// `None` where there is none.
    fn vote_at(&self, u: usize, v: usize) -> Option<[f32; 2]>;
}

impl CentreVotes for SegEngine {
    fn vote_at(&self, u: usize, v: usize) -> Option<[f32; 2]> {
        SegEngine::vote_at(self, u, v)
    }
}

/// Where a region's cut in two comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CutProposal {
    /// k-means on the region's 3D points.
    Points,
    /// The segmenter's centre-offset votes where its file has the head and
    /// they fall into two groups apart; else the 3D points.
    Votes,
    /// The votes only: a region whose votes point at one centre is not cut.
    VotesOnly,
}

impl std::fmt::Display for CutProposal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Points => "points",
            Self::Votes => "votes",
            Self::VotesOnly => "votes-only",
        })
    }
}

/// `points`, `votes` or `votes-only`.
impl std::str::FromStr for CutProposal {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "points" => Ok(Self::Points),
            "votes" => Ok(Self::Votes),
            "votes-only" => Ok(Self::VotesOnly),
            _ => Err(format!("cut proposal {s:?}: expected points, votes or votes-only")),
        }
    }
}

/// When a region is looked at again, and what its cut must show.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RecutConfig {
    /// Regions whose pose's verification coverage is below this are cut and
    /// estimated again (0 = off).
    pub max_coverage: f32,
    /// The pieces' poses must be at least this × the object's smallest
    /// bounding-box side apart to be two copies.
    pub min_separation: f32,
    /// Neither piece's pose may explain this share or more of the other
    /// piece's mask ([`Verifier::explained_share`]): the pose of one half of
    /// a single object covers its other half too.
    pub max_cross_explained: f32,
    /// The pieces' solids may overlap by at most this share of either
    /// ([`crate::interpenetration::Solids::share_inside`]): two copies cannot
    /// share space, where the two poses of one object cut in two do.
    pub max_overlap: f32,
    /// Most regions looked at per frame (the lowest coverage first).
    pub max_regions: usize,
    /// Where the cut comes from.
    pub proposal: CutProposal,
}

impl RecutConfig {
    /// The daemon's and `fusepose eval`'s default.
    pub const DEFAULT: Self = Self {
        max_coverage: 0.85,
        min_separation: 0.5,
        max_cross_explained: 0.5,
        max_overlap: 0.15,
        max_regions: 2,
        proposal: CutProposal::Votes,
    };

    pub fn is_on(&self) -> bool {
        self.max_coverage > 0.0 && self.max_regions > 0
    }
}

/// What one frame's second look did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RecutStats {
    /// Regions cut and estimated again.
    pub tried: usize,
    /// Of them, regions whose cut stayed (each now two instances).
    pub kept: usize,
    /// Cuts carried from the last frame ([`Recut::hints`]) that held again.
    pub carried: usize,
    /// Regions cut but not estimated ([`Recut::defer_next_frame`]): their
    /// cuts are carried to the next frame untried.
    pub deferred: usize,
    /// Of the regions cut, those cut along the segmenter's centre votes.
    pub by_votes: usize,
    /// Cuts estimated and refused, by the first term that refused them:
    /// a piece without a pose or whose pose failed verification, poses too
    /// close, one pose explaining the other's piece, solids overlapping.
    pub refused: [usize; 4],
}

/// Totals over frames (an evaluation's counts).
impl std::ops::AddAssign for RecutStats {
    fn add_assign(&mut self, o: Self) {
        self.tried += o.tried;
        self.kept += o.kept;
        self.carried += o.carried;
        self.deferred += o.deferred;
        self.by_votes += o.by_votes;
        for (r, n) in self.refused.iter_mut().zip(o.refused) {
            *r += n;
        }
    }
}

/// Why a cut's pieces are not two copies (index into [`RecutStats::refused`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Refusal {
    Unverified = 0,
    Close = 1,
    Explained = 2,
    Overlap = 3,
}

/// A region chosen for a second look.
#[derive(Clone, Copy, Debug)]
struct Candidate {
    /// Index of the region's pose in the frame's poses.
    pose: usize,
    coverage: f32,
}

/// Cuts, estimates and judges regions again; see the module doc.
pub struct Recut {
    config: RecutConfig,
    /// Two copies cannot share space: the pieces' poses must not overlap.
    solids: std::sync::Arc<crate::interpenetration::Solids>,
    /// Per class (id − 1): the smallest bounding-box side, metres.
    sides: Vec<f32>,
    /// The pieces as an instance plane: piece ids 2j + 1 and 2j + 2 for
    /// candidate j, 0 elsewhere.
    ids: Vec<u16>,
    classes: Vec<u16>,
    /// Boxes written into `ids` this frame (cleared on the next).
    written: Vec<[u16; 4]>,
    ws: Workspace,
    poses: PoseSet,
    verdicts: Vec<Verification>,
    candidates: Vec<Candidate>,
    samples: Vec<[f32; 3]>,
    /// Frame pixel of each sample.
    sample_pixels: Vec<[u16; 2]>,
    /// Each sample's centre vote (cells, z = 0) when the cut follows votes.
    sample_votes: Vec<[f32; 3]>,
    /// [`Recut::set_votes`].
    votes: Option<Box<dyn CentreVotes + Send>>,
    cluster: Vec<u8>,
    order: Vec<(f32, u8)>,
    /// Per candidate: its two centres (k-means), camera frame.
    centres: Vec<[[f32; 3]; 2]>,
    marks: Vec<bool>,
    /// [`Recut::limit_next_frame`]'s cap, for the next frame only.
    frame_limit: Option<usize>,
    /// [`Recut::defer_next_frame`], for the next frame only.
    defer: Option<()>,
    /// Cuts refused in this frame's [`Recut::run`], by [`Refusal`].
    refusals: [usize; 4],
    /// Cuts the next frame refused, per class and midpoint, with the frames
    /// for which no region there is cut again without its pieces' poses.
    refused: Vec<Refused>,
    /// The cuts that stood in the last frame, to make again in the next
    /// ([`Recut::hints`]).
    carried: Vec<CutHint>,
}

impl Recut {
    /// For the estimator's workspace sizes `ws_config` (the pieces are
    /// prepared as its instances).
    pub fn new(
        objects: &ObjectSet,
        solids: std::sync::Arc<crate::interpenetration::Solids>,
        ws_config: WorkspaceConfig,
        config: RecutConfig,
    ) -> Result<Self, WorkspaceConfigError> {
        let regions = config.max_regions.max(1);
        let mut ws = Workspace::new(WorkspaceConfig { max_instances: 2 * regions, ..ws_config })?;
        ws.support_floors(&crate::support::class_floors(objects, ws_config.support_floor_m));
        Ok(Self {
            config,
            solids,
            sides: objects.objects.iter().map(|o| (o.bbox_max - o.bbox_min).min() as f32).collect(),
            ids: Vec::new(),
            classes: vec![0; 2 * regions + 1],
            written: Vec::with_capacity(regions),
            ws,
            poses: PoseSet::with_capacity(4 * regions),
            verdicts: Vec::with_capacity(4 * regions),
            candidates: Vec::with_capacity(ws_config.max_instances.max(regions)),
            samples: Vec::with_capacity(SAMPLES),
            sample_pixels: Vec::with_capacity(SAMPLES),
            sample_votes: Vec::with_capacity(SAMPLES),
            votes: None,
            cluster: vec![0; SAMPLES],
            order: Vec::with_capacity(SAMPLES),
            centres: Vec::with_capacity(regions),
            marks: Vec::with_capacity(4 * ws_config.max_instances),
            frame_limit: None,
            defer: None,
            refusals: [0; 4],
            refused: Vec::with_capacity(ws_config.max_instances),
            carried: Vec::with_capacity(ws_config.max_instances),
        })
    }

    /// The cuts that stood in the last [`Recut::run`]: the second look's
    /// kept cuts and the carried cuts that held again. A live stream passes
    /// them to [`Workspace::set_cut_hints`] before its next frame's prepare,
    /// so that a pair cut once is estimated as two instances in the frame's
    /// own estimate from then on (the second look itself needs time a busy
    /// frame does not have). Frames that are not a stream (an evaluation's
    /// independent views) must not.
    pub fn hints(&self) -> &[CutHint] {
        &self.carried
    }

    /// In the next [`Recut::run`] only: cut the regions that qualify but do
    /// not estimate their pieces; carry the cuts to the next frame instead
    /// ([`Recut::hints`]), whose own estimate poses the pieces and where
    /// they are judged by the same terms. For a frame without the time for
    /// the pieces (the daemon). A cut refused there is not deferred again
    /// for [`REFUSED_FRAMES`] frames, so one object does not alternate
    /// between whole and halved.
    pub fn defer_next_frame(&mut self) {
        self.defer = Some(());
    }

    /// Centre votes for the cuts from a source other than the segmenter
    /// (tests, or a producer's own votes); they replace the segmenter's.
    pub fn set_votes(&mut self, votes: Box<dyn CentreVotes + Send>) {
        self.votes = Some(votes);
    }

    /// Looks at no more than `regions` regions in the next [`Recut::run`]
    /// only: what the frame's time left pays for (the daemon).
    pub fn limit_next_frame(&mut self, regions: usize) {
        self.frame_limit = Some(regions);
    }

    /// Looks again at the regions of `ws` whose pose in `poses` covers less
    /// than `max_coverage` of them; `verdicts` is the verification of each
    /// pose (same order, at most one pose per instance: after class
    /// alternates are settled). Where a cut stays, the region's pose is
    /// replaced by its pieces' poses (with their verdicts, appended) and
    /// `ws` holds the pieces as two instances. `segmenter`: the built-in
    /// segmenter when it made the regions (its certainty is judged on the
    /// pieces as on any region, and its centre votes, computed here where a
    /// region is to be cut, propose the cuts unless
    /// [`Recut::set_votes`] gave others). `estimator` estimates the pieces; it should
    /// not be one that tracks objects across frames (its tracks would see
    /// only the pieces).
    #[allow(clippy::too_many_arguments)] // the frame's parts, borrowed one by one
    pub fn run(
        &mut self,
        frame: &FrameView<'_>,
        ws: &mut Workspace,
        poses: &mut PoseSet,
        verdicts: &mut Vec<Verification>,
        estimator: &mut dyn Estimator,
        verifier: &mut Verifier,
        mut segmenter: Option<&mut SegEngine>,
        seed: u64,
    ) -> Result<RecutStats, EstimateError> {
        let mut stats = RecutStats::default();
        self.refusals = [0; 4];
        // What stood in the last frame is carried only into the next.
        self.carried.clear();
        for r in &mut self.refused {
            r.frames = r.frames.saturating_sub(1);
        }
        self.refused.retain(|r| r.frames > 0);
        let class_plane = frame.labels.is_some_and(|l| !l.is_instances());
        if !class_plane || !self.config.is_on() || verdicts.len() != poses.len() {
            return Ok(stats);
        }
        stats.carried = self.check_hinted(frame, ws, poses, verdicts, verifier);
        if self.ids.len() != frame.width() * frame.height() {
            self.warm_up(frame, estimator, seed)?;
        }
        self.choose(poses.as_slice(), verdicts);
        if self.candidates.is_empty() {
            return Ok(stats);
        }
        // Votes set from elsewhere, else the segmenter's where its file has the
        // head (computed now: a file with the offset branch leaves them to here).
        let own = self.votes.take();
        if let Some(seg) =
            segmenter.as_deref_mut().filter(|_| own.is_none() && self.config.proposal != CutProposal::Points)
        {
            seg.compute_votes();
        }
        let segmenter = segmenter.as_deref();
        let from_segmenter = segmenter.filter(|s| !s.offsets().is_empty()).map(|s| s as &dyn CentreVotes);
        let votes = own.as_deref().map(|v| v as &dyn CentreVotes).or(from_segmenter);
        stats.by_votes = self.cut(frame, ws, poses.as_slice(), votes);
        self.votes = own;
        stats.tried = self.centres.len();
        if stats.tried == 0 {
            return Ok(stats);
        }
        if self.defer.take().is_some() {
            // No time for the pieces now: the next frame's own estimate
            // poses them, and `check_hinted` judges the cut there.
            stats.deferred = self.defer_cuts(poses.as_slice());
            return Ok(stats);
        }
        stats.kept = self.estimate_pieces(frame, estimator, seed, |this, view, ids| {
            this.verify(view, verifier, segmenter);
            this.apply(frame, view, verifier, ids, ws, poses, verdicts)
        })?;
        stats.refused = self.refusals;
        Ok(stats)
    }

    /// Prepares the piece plane's instances in the second workspace and
    /// estimates them into `self.poses`, then runs `then` with the plane's
    /// view and ids (taken out of `self` while the view borrows them; no
    /// allocation).
    fn estimate_pieces<R>(
        &mut self,
        frame: &FrameView<'_>,
        estimator: &mut dyn Estimator,
        seed: u64,
        then: impl FnOnce(&mut Self, &FrameView<'_>, &[u16]) -> R,
    ) -> Result<R, EstimateError> {
        let (ids, classes) = (std::mem::take(&mut self.ids), std::mem::take(&mut self.classes));
        let view = FrameView { labels: Some(LabelPlane::Instances { ids: &ids, classes: &classes }), ..*frame };
        let estimated = self
            .ws
            .prepare(&view, seed)
            .map_err(EstimateError::Frame)
            .and_then(|_| estimator.estimate(&view, &mut self.ws, &mut self.poses))
            .map(|()| then(self, &view, &ids));
        (self.ids, self.classes) = (ids, classes);
        estimated
    }

    /// Once per frame size: sizes the piece plane, and estimates a square
    /// piece at the frame's centre as class 1, so that the second workspace
    /// and the piece estimator have met a frame of this size and an instance
    /// before a region first qualifies (no later frame allocates).
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
        self.classes.fill(0);
        let side = (w.min(h) / 8).max(1);
        let (u0, v0) = ((w - side) / 2, (h - side) / 2);
        for v in v0..v0 + side {
            self.ids[v * w + u0..v * w + u0 + side].fill(1);
        }
        self.classes[1] = 1;
        let warmed = self.estimate_pieces(frame, estimator, seed, |_, _, _| ());
        for v in v0..v0 + side {
            self.ids[v * w + u0..v * w + u0 + side].fill(0);
        }
        self.classes.fill(0);
        self.poses.clear();
        warmed
    }

    /// Judges the pieces of the cuts `ws` made from carried hints as the
    /// second look judges its own: a cut that holds is carried on; of one
    /// that does not, the piece pose that fits worse is dropped (the two are
    /// one object seen twice) and the cut is forgotten. Returns how many held.
    fn check_hinted(
        &mut self,
        view: &FrameView<'_>,
        ws: &Workspace,
        poses: &mut PoseSet,
        verdicts: &mut Vec<Verification>,
        verifier: &mut Verifier,
    ) -> usize {
        self.marks.clear();
        self.marks.resize(poses.len(), false);
        let terms = Terms { config: &self.config, sides: &self.sides, solids: &self.solids };
        let mut held = 0;
        for &[ida, idb] in ws.hinted_pieces() {
            let find =
                |id: u32| poses.as_slice().iter().position(|p| ws.component_id(p.instance_id as usize) == Some(id));
            let (Some(a), Some(b)) = (find(ida), find(idb)) else { continue };
            let (pa, pb) = (poses.as_slice()[a], poses.as_slice()[b]);
            let (ma, mb) = (ws.mask_ref(ida, pa.bbox), ws.mask_ref(idb, pb.bbox));
            if terms.two_copies(view, verifier, (&pa, &verdicts[a], ma), (&pb, &verdicts[b], mb)).is_ok() {
                let centre = |i: usize| {
                    let inst = ws.instances[i];
                    let points = &ws.instance_points(i)[..inst.distinct_points(ws.config.num_points)];
                    let n = points.len().max(1) as f32;
                    points.iter().fold([0.0f32; 3], |c, p| [c[0] + p[0] / n, c[1] + p[1] / n, c[2] + p[2] / n])
                };
                if self.carried.len() < self.carried.capacity() {
                    let centres = [centre(pa.instance_id as usize), centre(pb.instance_id as usize)];
                    self.carried.push(CutHint { class_id: pa.class_id, centres });
                }
                held += 1;
            } else {
                let worse = if verdicts[a].fit >= verdicts[b].fit { b } else { a };
                self.marks[worse] = true;
                if self.refused.len() < self.refused.capacity() {
                    let (ta, tb) = (pa.translation, pb.translation);
                    let midpoint = [(ta.x + tb.x) as f32 / 2.0, (ta.y + tb.y) as f32 / 2.0, (ta.z + tb.z) as f32 / 2.0];
                    self.refused.push(Refused { class_id: pa.class_id, midpoint, frames: REFUSED_FRAMES });
                }
            }
        }
        if self.marks.iter().any(|&m| m) {
            poses.remove_marked(&self.marks);
            crate::poses::remove_marked(verdicts, &self.marks);
        }
        held
    }

    /// Carries this frame's cuts to the next untried, except near a cut
    /// refused lately; returns how many.
    fn defer_cuts(&mut self, poses: &[ObjectPose]) -> usize {
        let mut deferred = 0;
        for (j, c) in self.candidates.iter().enumerate() {
            let (centres, class_id) = (self.centres[j], poses[c.pose].class_id);
            let mid = [0, 1, 2].map(|k| (centres[0][k] + centres[1][k]) / 2.0);
            // The same place: within the object's smallest side.
            let reach = self.sides.get(class_id as usize - 1).copied().unwrap_or(0.0);
            let near = |r: &Refused| {
                r.class_id == class_id && (0..3).map(|k| (r.midpoint[k] - mid[k]).powi(2)).sum::<f32>() < reach * reach
            };
            if self.refused.iter().any(near) || self.carried.len() >= self.carried.capacity() {
                continue;
            }
            self.carried.push(CutHint { class_id, centres });
            deferred += 1;
        }
        deferred
    }

    /// The regions to look at, lowest coverage first.
    fn choose(&mut self, poses: &[ObjectPose], verdicts: &[Verification]) {
        self.candidates.clear();
        for (k, v) in verdicts.iter().enumerate() {
            let coverage = v.mask_coverage;
            // Only a pose the depth supports is worth a second look: a region
            // whose pose failed is more often another object taken for this
            // class, and its pieces' poses fit a small model anywhere.
            if v.passed && coverage < self.config.max_coverage && poses[k].class_id as usize <= self.sides.len() {
                self.candidates.push(Candidate { pose: k, coverage });
            }
        }
        self.candidates.sort_unstable_by(|a, b| a.coverage.total_cmp(&b.coverage));
        self.candidates.truncate(self.config.max_regions.min(self.frame_limit.take().unwrap_or(usize::MAX)));
    }

    /// Writes the candidates' pieces into the instance plane, from up to
    /// [`SAMPLES`] of the region's valid-depth points: by their centre votes
    /// where [`RecutConfig::proposal`] asks for them and they fall into two
    /// groups [`MIN_VOTE_GAP_CELLS`] apart (every pixel to the group nearest
    /// its cell's vote), else by k-means in 3D (every pixel to its nearest
    /// centre, by image distance to the projected centres where it has no
    /// depth). Candidates whose pieces are too uneven are dropped. Returns
    /// how many were cut along votes.
    fn cut(
        &mut self,
        frame: &FrameView<'_>,
        ws: &Workspace,
        poses: &[ObjectPose],
        votes: Option<&dyn CentreVotes>,
    ) -> usize {
        let voter = votes.filter(|_| self.config.proposal != CutProposal::Points);
        let (w, h) = (frame.width(), frame.height());
        for b in self.written.drain(..) {
            let [u0, v0, u1, v1] = b.map(|x| x as usize);
            for v in v0..=v1.min(h.saturating_sub(1)) {
                self.ids[v * w + u0.min(w)..v * w + (u1 + 1).min(w)].fill(0);
            }
        }
        self.classes.fill(0);
        self.centres.clear();
        let all = ws.component_ids();
        let (mut kept, mut by_votes) = (0, 0);
        for c in 0..self.candidates.len() {
            let pose = poses[self.candidates[c].pose];
            let Some(id) = ws.component_id(pose.instance_id as usize) else { continue };
            let bbox = ws.instances[pose.instance_id as usize].bbox;
            let [u0, v0, u1, v1] = bbox.map(|x| x as usize);
            let in_region = |p: usize| all.get(p) == Some(&id);
            let valid = (v0..=v1)
                .flat_map(|v| (u0..=u1).map(move |u| v * w + u))
                .filter(|&p| in_region(p) && frame.depth.metres(p).is_some())
                .count();
            if valid < MIN_POINTS {
                continue;
            }
            let stride = valid.div_ceil(SAMPLES).max(1);
            self.samples.clear();
            self.sample_pixels.clear();
            let points = (v0..=v1)
                .flat_map(|v| (u0..=u1).map(move |u| (u, v)))
                .filter_map(|(u, v)| {
                    let p = v * w + u;
                    frame.depth.metres(p).filter(|_| in_region(p)).map(|z| (u, v, z))
                })
                .step_by(stride)
                .take(SAMPLES);
            for (u, v, z) in points {
                self.samples.push(crate::sampling::back_project(frame, u, v, z));
                self.sample_pixels.push([u as u16, v as u16]);
            }
            let n = self.samples.len();
            let min = (MIN_PIECE_SHARE * n as f32).ceil() as usize;
            let even = |cluster: &[u8]| {
                let ones = cluster.iter().filter(|&&x| x == 1).count();
                ones >= min && n - ones >= min
            };
            let vote_cut = voter.and_then(|seg| {
                self.sample_votes.clear();
                for &[u, v] in &self.sample_pixels {
                    let [x, y] = seg.vote_at(u as usize, v as usize)?;
                    self.sample_votes.push([x, y, 0.0]);
                }
                let c = kmeans(&self.sample_votes, 2, &mut self.cluster[..n], &mut self.order);
                let gap = ((c[0][0] - c[1][0]).powi(2) + (c[0][1] - c[1][1]).powi(2)).sqrt();
                (gap >= MIN_VOTE_GAP_CELLS && even(&self.cluster[..n]))
                    .then_some((seg, [[c[0][0], c[0][1]], [c[1][0], c[1][1]]]))
            });
            let base = 2 * kept as u16;
            let mut fill = |piece_of: &dyn Fn(usize, usize, usize) -> usize| {
                for v in v0..=v1 {
                    for u in u0..=u1 {
                        let p = v * w + u;
                        if in_region(p) {
                            self.ids[p] = base + 1 + piece_of(u, v, p) as u16;
                        }
                    }
                }
            };
            let centres = if let Some((seg, votes)) = vote_cut {
                fill(&|u, v, _| seg.vote_at(u, v).map_or(0, |vote| nearest_2d(&votes, vote)));
                by_votes += 1;
                // The pieces' 3D centres (for the cut carried to the next frame).
                let mut sums = [[0.0f32; 4]; 2];
                for (p, &k) in self.samples.iter().zip(&self.cluster[..n]) {
                    let s = &mut sums[k.min(1) as usize];
                    *s = [s[0] + p[0], s[1] + p[1], s[2] + p[2], s[3] + 1.0];
                }
                sums.map(|s| [s[0] / s[3], s[1] / s[3], s[2] / s[3]])
            } else {
                if voter.is_some() && self.config.proposal == CutProposal::VotesOnly {
                    continue;
                }
                let centres = kmeans(&self.samples, 2, &mut self.cluster[..n], &mut self.order);
                if !even(&self.cluster[..n]) {
                    continue;
                }
                let centres = [centres[0], centres[1]];
                let pixels = [project(frame, Some(&centres[0])), project(frame, Some(&centres[1]))];
                fill(&|_, _, p| nearest_piece(frame, &centres, &pixels, p));
                centres
            };
            self.classes[base as usize + 1] = pose.class_id;
            self.classes[base as usize + 2] = pose.class_id;
            self.written.push(bbox);
            self.candidates[kept] = self.candidates[c];
            self.centres.push(centres);
            kept += 1;
        }
        self.candidates.truncate(kept);
        by_votes
    }

    /// Verifies each piece's pose on its piece's mask.
    fn verify(&mut self, view: &FrameView<'_>, verifier: &mut Verifier, segmenter: Option<&SegEngine>) {
        self.verdicts.clear();
        let min_region_probability = verifier.config().min_region_probability;
        for pose in self.poses.as_slice() {
            let v = match self.ws.component_id(pose.instance_id as usize) {
                Some(id) => {
                    let mask = self.ws.mask_ref(id, pose.bbox);
                    let mut v = verifier.verify(view, mask, pose);
                    if let Some(seg) = segmenter.filter(|_| min_region_probability > 0.0) {
                        v.judge_region_probability(
                            seg.region_probability(mask.ids, id, pose.class_id, pose.bbox),
                            min_region_probability,
                        );
                    }
                    v
                }
                None => Verification { passed: false, ..Verification::default() },
            };
            self.verdicts.push(v);
        }
    }

    /// The pose (index in `self.poses`) of candidate `j`'s piece `k`.
    fn piece_pose(&self, j: usize, k: usize) -> Option<usize> {
        let want = (2 * j + 1 + k) as u32;
        self.poses.as_slice().iter().position(|p| self.ws.component_id(p.instance_id as usize) == Some(want))
    }

    /// Whether candidate `j`'s pieces are two copies ([`Terms::two_copies`]).
    fn pieces_are_two_copies(
        &mut self,
        j: usize,
        view: &FrameView<'_>,
        verifier: &mut Verifier,
    ) -> Result<(), Refusal> {
        let (Some(a), Some(b)) = (self.piece_pose(j, 0), self.piece_pose(j, 1)) else {
            return Err(Refusal::Unverified);
        };
        let (pa, pb) = (self.poses.as_slice()[a], self.poses.as_slice()[b]);
        let ma = self.ws.mask_ref((2 * j + 1) as u32, pa.bbox);
        let mb = self.ws.mask_ref((2 * j + 2) as u32, pb.bbox);
        let terms = Terms { config: &self.config, sides: &self.sides, solids: &self.solids };
        terms.two_copies(view, verifier, (&pa, &self.verdicts[a], ma), (&pb, &self.verdicts[b], mb))
    }

    /// Keeps the cuts the depth image supports; returns how many.
    #[allow(clippy::too_many_arguments)]
    fn apply(
        &mut self,
        frame: &FrameView<'_>,
        view: &FrameView<'_>,
        verifier: &mut Verifier,
        ids: &[u16],
        ws: &mut Workspace,
        poses: &mut PoseSet,
        verdicts: &mut Vec<Verification>,
    ) -> usize {
        self.marks.clear();
        self.marks.resize(poses.len(), false);
        let mut kept = 0;
        for j in 0..self.candidates.len() {
            let whole = self.candidates[j].pose;
            if let Err(why) = self.pieces_are_two_copies(j, view, verifier) {
                self.refusals[why as usize] += 1;
                continue;
            }
            let (Some(a), Some(b)) = (self.piece_pose(j, 0), self.piece_pose(j, 1)) else { continue };
            let (pa, pb) = (self.poses.as_slice()[a], self.poses.as_slice()[b]);
            let (va, vb) = (self.verdicts[a], self.verdicts[b]);
            // Room for both pieces' poses (the region's goes after the loop).
            if poses.len() + 2 > poses.capacity() {
                continue;
            }
            let i = poses.as_slice()[whole].instance_id as usize;
            let base = 2 * j as u16 + 1;
            let Some(new) = ws.cut_instance(frame, i, |p| ids[p].saturating_sub(base) as usize) else { continue };
            let placed = |pose: ObjectPose, at: usize| {
                let inst = ws.instances[at];
                ObjectPose { instance_id: at as u16, bbox: inst.bbox, mask_pixels: inst.pixels, ..pose }
            };
            // Piece 0 keeps the region's instance index, piece 1 is the new one.
            poses.push(placed(pb, new));
            verdicts.push(vb);
            self.marks.push(false);
            self.marks[whole] = true;
            poses.push(placed(pa, i));
            verdicts.push(va);
            self.marks.push(false);
            if self.carried.len() < self.carried.capacity() {
                self.carried.push(CutHint { class_id: pa.class_id, centres: self.centres[j] });
            }
            kept += 1;
        }
        if kept > 0 {
            poses.remove_marked(&self.marks);
            crate::poses::remove_marked(verdicts, &self.marks);
        }
        kept
    }
}

/// The terms that tell two copies from one object cut in two.
struct Terms<'a> {
    config: &'a RecutConfig,
    sides: &'a [f32],
    solids: &'a crate::interpenetration::Solids,
}

impl Terms<'_> {
    /// Whether poses `a` and `b`, each with its verification and mask, are
    /// two copies: both passed, they lie apart, neither explains the other's
    /// mask, and their solids do not overlap ([`RecutConfig`]).
    fn two_copies(
        &self,
        view: &FrameView<'_>,
        verifier: &mut Verifier,
        (pa, va, ma): (&ObjectPose, &Verification, MaskRef<'_>),
        (pb, vb, mb): (&ObjectPose, &Verification, MaskRef<'_>),
    ) -> Result<(), Refusal> {
        if !(va.passed && vb.passed) {
            return Err(Refusal::Unverified);
        }
        let side = self.sides.get(pa.class_id as usize - 1).copied().unwrap_or(0.0);
        if (pa.translation - pb.translation).norm() < (self.config.min_separation * side) as f64 {
            return Err(Refusal::Close);
        }
        let explained = verifier.explained_share(view, mb, pa).max(verifier.explained_share(view, ma, pb));
        if explained >= self.config.max_cross_explained {
            return Err(Refusal::Explained);
        }
        let iso =
            |p: &ObjectPose| nalgebra::Isometry3::from_parts(nalgebra::Translation3::from(p.translation), p.rotation);
        let (ia, ib) = (iso(pa), iso(pb));
        let overlap = self.solids.share_inside(pa.class_id, &ia, pb.class_id, &ib).max(self.solids.share_inside(
            pb.class_id,
            &ib,
            pa.class_id,
            &ia,
        ));
        if overlap > self.config.max_overlap {
            return Err(Refusal::Overlap);
        }
        Ok(())
    }
}
