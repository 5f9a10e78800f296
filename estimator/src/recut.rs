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
//! [`RecutConfig::max_coverage`] of it is cut ([`pieces_for`]: about one
//! piece per share of it the pose covers, 2 to [`RecutConfig::max_pieces`];
//! k-means on its 3D points), each piece is estimated on its own as an
//! instance, and the depth image decides: a piece is a copy when its pose
//! passes verification and lies apart from the copies found before it
//! ([`RecutConfig::min_separation`] × the object's smallest side, neither
//! explaining the other, solids apart); the cut stays with two copies or
//! more, and a piece that is no copy joins the nearest one. The parts of
//! one object, cut, are posed as one object twice; two copies as two. With
//! [`RecutConfig::refit`] the pixels then go to the piece whose posed box
//! holds them and the pieces are estimated again: k-means cuts between
//! point clusters, which misses the contact of copies whose mass lies off
//! their centre. In a heap the one pose of a region of several copies lies
//! between them and fails verification, so [`RecutConfig::poses`] also
//! takes failed poses' regions (docs/BENCHMARKS.md, session 30).
//!
//! The network's own per-point translations do not propose cuts: in a
//! region of several copies they point at one centre (their k-means centres
//! 2–16 mm apart where copies lie 20–50 mm apart; session 30).
//!
//! In a live stream the second look rarely has the time: the pieces'
//! estimates and checks cost more than a busy frame leaves. So a cut that
//! stood is carried to the next frame with a centre per copy
//! ([`Recut::hints`] → [`Workspace::set_cut_hints`]): the region is cut
//! before the estimate and its pieces are posed with the frame's other
//! objects, then judged by the same terms ([`RecutStats::carried`]); a
//! frame without the time for the pieces defers its cuts to the next frame
//! that way ([`Recut::defer_next_frame`]), and a deferred cut the next frame
//! refuses keeps that place whole for [`REFUSED_FRAMES`] frames.
//!
//! Class planes only: an instance plane's instances are the producer's.
//! Buffers are sized in [`Recut::new`] and on the first frame of a size;
//! a frame then allocates nothing.

use fusepose_scene::ObjectSet;

use crate::contact_cut::{ContactCut, ContactMap};
use crate::frame::{FrameView, LabelPlane};
use crate::poses::{ObjectPose, PoseSet};
use crate::seg::SegEngine;
use crate::split::{kmeans, nearest_2d, nearest_piece, project};
use crate::verify::{MaskRef, Verification, Verifier};
pub use crate::workspace::MAX_CUT_PIECES;
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

/// Rounds of [`Recut::refit`] and estimate: each pose places the next cut.
const REFIT_ROUNDS: usize = 2;
/// A posed box holds a point this far outside its faces
/// ([`RecutConfig::refit_by_verdict`]): a copy's surface points lie on its
/// box's faces, and depth noise puts half of them just outside (with no
/// margin the order never applies: tune_pairs as without it, session 35).
const REFIT_HOLD_M: f32 = 0.005;
/// [`RecutConfig::best_piece`]: a piece's pose replaces a passed region
/// pose when its fit is at least this much higher ...
pub const BEST_PIECE_MARGIN: f32 = 0.1;
/// ... and at least this: pieces fitting 0.6–0.75 were as often posed
/// further from their object than the region's pose (path-traced stray
/// poses up 0.03–0.04 per frame without it; docs/BENCHMARKS.md, session 45).
pub const BEST_PIECE_MIN_FIT: f32 = 0.8;
/// [`RecutConfig::best_piece`]: the fit a piece's pose needs to take over a
/// region whose own pose failed. At 0.9 or below, regions no object explains
/// (a table patch, a shadow) got a pose from a piece that fits its small
/// patch (path-traced ghosts and strays up to 0.08 per frame; session 45).
pub const REVIVE_MIN_FIT: f32 = 0.95;
/// Fewest valid-depth pixels of a region worth cutting.
const MIN_POINTS: usize = 64;
/// Each piece of a cut in two must hold at least this share of the region's
/// samples (a cut in k pieces: this × 2 ÷ k): a sliver is what the mask bled
/// onto, not a copy.
const MIN_PIECE_SHARE: f32 = 0.2;
/// Centre votes of two copies lie at least this far apart (segmenter output
/// cells; the votes of one object scatter by a cell or two, and copies that
/// touch have centres a body width apart, several cells at working range).
const MIN_VOTE_GAP_CELLS: f32 = 3.0;
/// A sample seeds its k-means piece's flood along the contacts when it lies
/// at most this share of the distance to any other centre from its own.
const SEED_RATIO: f32 = 0.6;

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
    /// they fall into two groups apart; else as `Creases`.
    Votes,
    /// The votes only: a region whose votes point at one centre is not cut.
    VotesOnly,
    /// The segmenter's contact band where its file has the contact branch
    /// ([`crate::contact_cut`]): along the band where it parts the region,
    /// else k-means pieces grown from their centres over it; without the
    /// branch, the 3D points.
    Contacts,
    /// The depth image's concave creases and steps ([`crate::creases`]):
    /// along them where they part the region into even pieces of one colour,
    /// else the 3D points (not grown over them as `Contacts` are).
    Creases,
}

impl std::fmt::Display for CutProposal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Points => "points",
            Self::Votes => "votes",
            Self::VotesOnly => "votes-only",
            Self::Contacts => "contacts",
            Self::Creases => "creases",
        })
    }
}

/// `points`, `votes`, `votes-only`, `contacts` or `creases`.
impl std::str::FromStr for CutProposal {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "points" => Ok(Self::Points),
            "votes" => Ok(Self::Votes),
            "votes-only" => Ok(Self::VotesOnly),
            "contacts" => Ok(Self::Contacts),
            "creases" => Ok(Self::Creases),
            _ => Err(format!("cut proposal {s:?}: expected points, votes, votes-only, contacts or creases")),
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
    /// Most pieces a region is cut into (2 to [`MAX_CUT_PIECES`]): one whose
    /// pose covers a share c of it holds up to 1 ÷ c copies, so it is cut
    /// into that many, rounded up, at least 2 and at most this ([`pieces_for`]).
    pub max_pieces: usize,
    /// Which regions' poses qualify for a second look besides their
    /// coverage.
    pub poses: RecutPoses,
    /// Once the pieces have poses, give each pixel of the region to the
    /// piece whose posed bounding box holds its point (the nearest box
    /// where none or several do) and estimate the pieces again
    /// ([`Recut::refit`]): a cut between point clusters misses the contact
    /// between copies whose mass lies off their centre (an L, a mug).
    pub refit: bool,
    /// With [`RecutConfig::refit`]: a pixel goes first to the best-verified
    /// piece (passed before failed, then by fit) whose posed box holds its
    /// point within [`REFIT_HOLD_M`], and to the nearest box only where none
    /// does. A piece holding parts of two copies is posed between them; by
    /// nearest box centre it keeps the part of the copy its neighbour posed
    /// exactly, and is never posed clean. Off: on the tuning splits it gains
    /// on pairs and heaps but adds stray poses on heaps, wood blocks posed
    /// between two whose coplanar tops the depth cannot tell apart
    /// (docs/BENCHMARKS.md, session 35).
    pub refit_by_verdict: bool,
    /// A piece counts as a copy only when its pose's verification fit is at
    /// least this (besides passing): a piece that still holds parts of two
    /// copies gets a pose between them that passes on its neighbours'
    /// surfaces with a low fit. 0 = any passing pose.
    pub min_piece_fit: f32,
    /// A refused cut still tells which pose fits: where a piece's pose
    /// passed and fits its piece by [`BEST_PIECE_MARGIN`] better than the
    /// region's pose fits the region, and at least [`BEST_PIECE_MIN_FIT`],
    /// it replaces the region's pose (the region stays one instance). A
    /// region whose pose failed takes it only at a fit of
    /// [`REVIVE_MIN_FIT`] or more ([`Recut::take_best_piece`]).
    pub best_piece: bool,
}

/// Which poses' regions the second look takes ([`RecutConfig::poses`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RecutPoses {
    /// Poses that passed verification: a region whose pose failed is more
    /// often another object taken for this class, and its pieces' poses fit
    /// a small model anywhere.
    Passed,
    /// Also poses that failed on their coverage alone
    /// ([`Verifier::passes_but_for_coverage`]): the pose of one copy in a
    /// region of three or more covers too little of it to pass.
    Coverage,
    /// Any pose of a region the segmenter was sure of (its certainty floor,
    /// where judged), except a region's alternate class: in a heap the one
    /// pose of a region of several copies lies between them and fails, and
    /// the region would otherwise lose every pose.
    Any,
}

impl std::fmt::Display for RecutPoses {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Passed => "passed",
            Self::Coverage => "coverage",
            Self::Any => "any",
        })
    }
}

/// `passed`, `coverage` or `any`.
impl std::str::FromStr for RecutPoses {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "passed" => Ok(Self::Passed),
            "coverage" => Ok(Self::Coverage),
            "any" => Ok(Self::Any),
            _ => Err(format!("recut poses {s:?}: expected passed, coverage or any")),
        }
    }
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
        max_pieces: MAX_CUT_PIECES,
        poses: RecutPoses::Any,
        refit: true,
        refit_by_verdict: false,
        min_piece_fit: 0.0,
        best_piece: true,
    };

    pub fn is_on(&self) -> bool {
        self.max_coverage > 0.0 && self.max_regions > 0
    }

    /// Whether a piece whose pose got verdict `v` may be a copy: it passed,
    /// with at least [`RecutConfig::min_piece_fit`].
    fn piece_may_be_copy(&self, v: &Verification) -> bool {
        v.passed && v.fit >= self.min_piece_fit
    }

    /// [`RecutConfig::max_pieces`] within 2 ..= [`MAX_CUT_PIECES`].
    fn pieces(&self) -> usize {
        self.max_pieces.clamp(2, MAX_CUT_PIECES)
    }
}

/// Pieces for a region whose pose covers `coverage` of it: the pose explains
/// at least one copy, so up to 1 ÷ `coverage` copies, rounded up, within
/// 2 ..= `max`. Rounded up because a pose between copies covers more than
/// one, and a piece too many costs little: pieces of one copy fail the
/// two-copy terms and join it ([`Recut::copies`]).
pub fn pieces_for(coverage: f32, max: usize) -> usize {
    let copies = 1.0 / coverage.max(1e-3);
    ((copies - 1e-3).ceil() as usize).clamp(2, max.max(2))
}

/// What one frame's second look did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RecutStats {
    /// Regions cut and estimated again.
    pub tried: usize,
    /// Of them, regions whose cut stayed (each now two instances or more).
    pub kept: usize,
    /// Cuts carried from the last frame ([`Recut::hints`]) that held again.
    pub carried: usize,
    /// Regions cut but not estimated ([`Recut::defer_next_frame`], or a
    /// budget too small for the first: [`Recut::budget_next_frame`]):
    /// their cuts are carried to the next frame untried.
    pub deferred: usize,
    /// Pieces estimated, counting each refit round again (what the second
    /// look's time goes by).
    pub estimates: usize,
    /// Of the regions cut, those cut along the segmenter's centre votes.
    pub by_votes: usize,
    /// Of the regions cut, those cut along the segmenter's contact band.
    pub by_contacts: usize,
    /// Cuts estimated and refused, by the first term that refused them:
    /// a piece without a pose or whose pose failed verification, poses too
    /// close, one pose explaining the other's piece, solids overlapping.
    pub refused: [usize; 4],
    /// Refused cuts whose best piece's pose replaced the region's.
    pub replaced: usize,
}

/// Totals over frames (an evaluation's counts).
impl std::ops::AddAssign for RecutStats {
    fn add_assign(&mut self, o: Self) {
        self.tried += o.tried;
        self.kept += o.kept;
        self.carried += o.carried;
        self.deferred += o.deferred;
        self.estimates += o.estimates;
        self.by_votes += o.by_votes;
        self.by_contacts += o.by_contacts;
        self.replaced += o.replaced;
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
    /// Pieces it was cut into, and the piece plane's id before its first.
    pieces: u8,
    base: u16,
}

/// Cuts, estimates and judges regions again; see the module doc.
pub struct Recut {
    config: RecutConfig,
    /// Two copies cannot share space: the pieces' poses must not overlap.
    solids: std::sync::Arc<crate::interpenetration::Solids>,
    /// Per class (id − 1): the smallest bounding-box side, metres.
    sides: Vec<f32>,
    /// Per class (id − 1): the bounding box (min, max corners), model frame, metres.
    boxes: Vec<[[f32; 3]; 2]>,
    /// The pieces as an instance plane: piece ids base + 1 ..= base + k for
    /// a candidate cut into k pieces ([`Candidate`]), 0 elsewhere.
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
    /// [`Recut::set_contacts`].
    contacts: Option<Box<dyn ContactMap + Send>>,
    contact_cut: ContactCut,
    /// The depth image's band for [`CutProposal::Creases`].
    crease_band: crate::creases::CreaseBand,
    cluster: Vec<u8>,
    order: Vec<(f32, u8)>,
    /// Per candidate: its pieces' centres (k-means), camera frame.
    centres: Vec<[[f32; 3]; MAX_CUT_PIECES]>,
    marks: Vec<bool>,
    /// [`Recut::budget_next_frame`]'s piece estimates, for the next frame only.
    frame_budget: Option<usize>,
    /// [`Recut::defer_next_frame`], for the next frame only.
    defer: Option<()>,
    /// Cuts refused in this frame's [`Recut::run`], by [`Refusal`].
    refusals: [usize; 4],
    /// Refused cuts of this frame whose region took a piece's pose.
    replaced: usize,
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
        let pieces = config.pieces() * regions;
        let mut ws = Workspace::new(WorkspaceConfig { max_instances: pieces, ..ws_config })?;
        ws.support_floors(&crate::support::class_floors(objects, ws_config.support_floor_m));
        Ok(Self {
            config,
            solids,
            sides: objects.objects.iter().map(|o| (o.bbox_max - o.bbox_min).min() as f32).collect(),
            boxes: objects
                .objects
                .iter()
                .map(|o| [o.bbox_min.coords.map(|x| x as f32).into(), o.bbox_max.coords.map(|x| x as f32).into()])
                .collect(),
            ids: Vec::new(),
            classes: vec![0; pieces + 1],
            written: Vec::with_capacity(regions),
            ws,
            poses: PoseSet::with_capacity(2 * pieces),
            verdicts: Vec::with_capacity(2 * pieces),
            candidates: Vec::with_capacity(ws_config.max_instances.max(regions)),
            samples: Vec::with_capacity(SAMPLES),
            sample_pixels: Vec::with_capacity(SAMPLES),
            sample_votes: Vec::with_capacity(SAMPLES),
            votes: None,
            contacts: None,
            contact_cut: ContactCut::default(),
            crease_band: Default::default(),
            cluster: vec![0; SAMPLES],
            order: Vec::with_capacity(SAMPLES),
            centres: Vec::with_capacity(regions),
            marks: Vec::with_capacity(4 * ws_config.max_instances),
            frame_budget: None,
            defer: None,
            refusals: [0; 4],
            replaced: 0,
            refused: Vec::with_capacity(ws_config.max_instances),
            carried: Vec::with_capacity(ws_config.max_instances),
        })
    }

    /// The cuts that stood in the last [`Recut::run`]: the second look's
    /// kept cuts and the carried cuts that held again. A live stream passes
    /// them to [`Workspace::set_cut_hints`] before its next frame's prepare,
    /// so that copies cut apart once are estimated as an instance each in the
    /// frame's own estimate from then on (the second look itself needs time a busy
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

    /// Contacts for the cuts from a source other than the segmenter (tests,
    /// or a producer's own); they replace the segmenter's.
    pub fn set_contacts(&mut self, contacts: Box<dyn ContactMap + Send>) {
        self.contacts = Some(contacts);
    }

    /// In the next [`Recut::run`] only: estimate at most `estimates` pieces
    /// in all, each refit round counting its pieces again: what the frame's
    /// time left pays for (the daemon, at the measured cost per piece). A
    /// region is looked at in this frame only when its pieces and their
    /// refit rounds fit (lowest coverage first); when the first region's do
    /// not, the cuts are deferred to the next frame's estimate
    /// ([`Recut::defer_next_frame`]). A region of a heap cut into six and
    /// refitted twice is 18 estimates, a pair's 6.
    pub fn budget_next_frame(&mut self, estimates: usize) {
        self.frame_budget = Some(estimates);
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
        self.choose(poses.as_slice(), verdicts, verifier, &ws.instances);
        if self.candidates.is_empty() {
            return Ok(stats);
        }
        // Votes set from elsewhere, else the segmenter's where its file has the
        // head (computed now: a file with the offset branch leaves them to here).
        let own = self.votes.take();
        let own_contacts = self.contacts.take();
        let by_contacts = self.config.proposal == CutProposal::Contacts;
        // The depth image's creases need nothing from the segmenter.
        let by_creases = self.config.proposal == CutProposal::Creases;
        if let Some(seg) = segmenter.as_deref_mut().filter(|_| !by_creases) {
            if by_contacts && own_contacts.is_none() {
                seg.compute_contacts();
            } else if !by_contacts && own.is_none() && self.config.proposal != CutProposal::Points {
                seg.compute_votes();
            }
        }
        let segmenter = segmenter.as_deref();
        let from_segmenter = segmenter.filter(|s| !s.offsets().is_empty()).map(|s| s as &dyn CentreVotes);
        let votes =
            own.as_deref().map(|v| v as &dyn CentreVotes).or(from_segmenter).filter(|_| !by_contacts && !by_creases);
        let contacts = own_contacts
            .as_deref()
            .map(|c| c as &dyn ContactMap)
            .or(segmenter.filter(|s| s.has_contacts()).map(|s| s as &dyn ContactMap))
            .filter(|_| by_contacts);
        (stats.by_votes, stats.by_contacts) = self.cut(frame, ws, poses.as_slice(), votes, contacts);
        self.votes = own;
        self.contacts = own_contacts;
        let budget = self.frame_budget.take();
        let rounds = if self.config.refit { REFIT_ROUNDS } else { 0 };
        let first = self.candidates.first().map_or(0, |c| c.pieces as usize * (1 + rounds));
        if self.centres.is_empty() {
            return Ok(stats);
        }
        if self.defer.take().is_some() || budget.is_some_and(|b| b < first) {
            // No time for the pieces now: the next frame's own estimate
            // poses them, and `check_hinted` judges the cut there.
            stats.tried = self.centres.len();
            stats.deferred = self.defer_cuts(poses.as_slice());
            return Ok(stats);
        }
        let cost = self.fit_budget(frame.width(), budget.unwrap_or(usize::MAX) / (1 + rounds));
        stats.tried = self.centres.len();
        self.estimate_pieces(frame, estimator, seed, |this, view, _| this.verify(view, verifier, segmenter))?;
        stats.estimates = cost;
        for _ in 0..rounds {
            if self.refit(frame) == 0 {
                break;
            }
            self.estimate_pieces(frame, estimator, seed, |this, view, _| this.verify(view, verifier, segmenter))?;
            stats.estimates += cost;
        }
        stats.kept =
            self.with_pieces(frame, |this, view, ids| this.apply(frame, view, verifier, ids, ws, poses, verdicts));
        stats.refused = self.refusals;
        stats.replaced = std::mem::take(&mut self.replaced);
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
        self.with_pieces(frame, |this, view, ids| {
            this.ws
                .prepare(view, seed)
                .map_err(EstimateError::Frame)
                .and_then(|_| estimator.estimate(view, &mut this.ws, &mut this.poses))
                .map(|()| then(this, view, ids))
        })
    }

    /// Runs `f` with the piece plane's view and ids (taken out of `self`
    /// while the view borrows them; no allocation).
    fn with_pieces<R>(&mut self, frame: &FrameView<'_>, f: impl FnOnce(&mut Self, &FrameView<'_>, &[u16]) -> R) -> R {
        let (ids, classes) = (std::mem::take(&mut self.ids), std::mem::take(&mut self.classes));
        let view = FrameView { labels: Some(LabelPlane::Instances { ids: &ids, classes: &classes }), ..*frame };
        let out = f(self, &view, &ids);
        (self.ids, self.classes) = (ids, classes);
        out
    }

    /// Gives each pixel with depth of each cut region to the piece whose
    /// posed bounding box holds its point, or lies nearest to it (inside
    /// several: the one whose box centre is nearest, in box half-sizes; with
    /// [`RecutConfig::refit_by_verdict`], the best-verified one that holds
    /// it within [`REFIT_HOLD_M`]). Pieces without a pose take no pixels; a
    /// region with fewer than two posed pieces is left as cut. Returns how
    /// many pixels changed piece.
    fn refit(&mut self, frame: &FrameView<'_>) -> usize {
        let w = frame.width();
        let mut changed = 0;
        for j in 0..self.candidates.len() {
            let c = self.candidates[j];
            // Per piece: rotation (rows = model axes in the camera frame), translation, box.
            let mut placed = [None; MAX_CUT_PIECES];
            for (k, slot) in placed.iter_mut().enumerate().take(c.pieces as usize) {
                *slot = self.piece_pose(j, k).and_then(|a| {
                    let p = self.poses.as_slice()[a];
                    let b = *self.boxes.get((p.class_id as usize).checked_sub(1)?)?;
                    let r = p.rotation.to_rotation_matrix().matrix().transpose().map(|x| x as f32);
                    Some((r, p.translation.map(|x| x as f32), b))
                });
            }
            if placed.iter().flatten().count() < 2 {
                continue;
            }
            // The posed pieces, best verdict first (for `refit_by_verdict`).
            let mut order = [0usize; MAX_CUT_PIECES];
            let mut posed = 0;
            for (k, slot) in placed.iter().enumerate() {
                if slot.is_some() {
                    order[posed] = k;
                    posed += 1;
                }
            }
            let by_verdict = self.config.refit_by_verdict;
            if by_verdict {
                let verdict = |k: usize| {
                    self.piece_pose(j, k).map_or((false, 0.0), |a| (self.verdicts[a].passed, self.verdicts[a].fit))
                };
                order[..posed].sort_unstable_by(|&a, &b| {
                    let (va, vb) = (verdict(a), verdict(b));
                    vb.0.cmp(&va.0).then(vb.1.total_cmp(&va.1))
                });
            }
            let [u0, v0, u1, v1] = self.written[j].map(|x| x as usize);
            let first = c.base + 1;
            let last = c.base + c.pieces as u16;
            for v in v0..=v1 {
                for u in u0..=u1 {
                    let p = v * w + u;
                    let Some(&id) = self.ids.get(p).filter(|&&id| (first..=last).contains(&id)) else { continue };
                    let Some(z) = frame.depth.metres(p) else { continue };
                    let x = nalgebra::Vector3::from(crate::sampling::back_project(frame, u, v, z));
                    let score = |(r, t, [lo, hi]): &(nalgebra::Matrix3<f32>, nalgebra::Vector3<f32>, [[f32; 3]; 2])| {
                        let q = r * (x - t);
                        let (mut outside, mut centre) = (0.0f32, 0.0f32);
                        for a in 0..3 {
                            outside += (lo[a] - q[a]).max(q[a] - hi[a]).max(0.0).powi(2);
                            let half = ((hi[a] - lo[a]) / 2.0).max(1e-4);
                            centre += ((q[a] - (lo[a] + hi[a]) / 2.0) / half).powi(2);
                        }
                        (outside, centre)
                    };
                    let holds =
                        |k: &usize| placed[*k].as_ref().is_some_and(|s| score(s).0 <= REFIT_HOLD_M * REFIT_HOLD_M);
                    let held = if by_verdict { order[..posed].iter().copied().find(holds) } else { None };
                    let best = held.or_else(|| {
                        placed
                            .iter()
                            .enumerate()
                            .filter_map(|(k, slot)| slot.as_ref().map(|s| (k, score(s))))
                            .min_by(|a, b| a.1.0.total_cmp(&b.1.0).then(a.1.1.total_cmp(&b.1.1)))
                            .map(|(k, _)| k)
                    });
                    if let Some(k) = best {
                        let new = first + k as u16;
                        if new != id {
                            self.ids[p] = new;
                            changed += 1;
                        }
                    }
                }
            }
        }
        changed
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
        if self.config.proposal == CutProposal::Contacts {
            self.contact_cut.resize(w, h);
        } else if matches!(self.config.proposal, CutProposal::Creases | CutProposal::Votes) {
            // The creases' band is marked on 2 × 2 cells, and cut on them.
            self.contact_cut.resize_scaled(w, h, 2);
            self.crease_band.resize(w, h);
        }
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
    /// second look judges its own ([`Recut::copies`]): best fit first, a
    /// piece is a copy when its pose passed and it is two copies with each
    /// copy taken before it. A cut with two copies or more holds and is
    /// carried on with their centres; the poses of its other pieces go (each
    /// is one of the copies seen again, or failed). Of a cut that does not
    /// hold, only its best pose stays (the pieces are one object seen
    /// several times) and the cut is forgotten. Returns how many held.
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
        for cut in ws.hinted_pieces() {
            // Each piece's pose, best fit first.
            let mut found = [(0.0f32, 0usize); MAX_CUT_PIECES];
            let mut n = 0;
            for &id in cut.ids() {
                let at = poses.as_slice().iter().position(|p| ws.component_id(p.instance_id as usize) == Some(id));
                if let Some(a) = at {
                    found[n] = (verdicts[a].fit, a);
                    n += 1;
                }
            }
            if n < 2 {
                continue;
            }
            let found = &mut found[..n];
            found.sort_unstable_by(|x, y| y.0.total_cmp(&x.0));
            let pose_mask = |a: usize| {
                let p = poses.as_slice()[a];
                (p, ws.component_id(p.instance_id as usize).map(|id| ws.mask_ref(id, p.bbox)))
            };
            let mut taken = [0usize; MAX_CUT_PIECES];
            let mut count = 0;
            for &(_, a) in found.iter().filter(|&&(_, a)| self.config.piece_may_be_copy(&verdicts[a])) {
                let (pa, Some(ma)) = pose_mask(a) else { continue };
                let copy = taken[..count].iter().all(|&t| {
                    let (pt, Some(mt)) = pose_mask(t) else { return false };
                    terms.two_copies(view, verifier, (&pa, &verdicts[a], ma), (&pt, &verdicts[t], mt)).is_ok()
                });
                if copy {
                    taken[count] = a;
                    count += 1;
                }
            }
            let stays = |a: usize| match count >= 2 {
                true => taken[..count].contains(&a),
                // Refused: the first copy taken, else the best fit.
                false => a == if count == 1 { taken[0] } else { found[0].1 },
            };
            for &(_, a) in found.iter() {
                self.marks[a] = !stays(a);
            }
            if count >= 2 {
                let centre = |a: usize| {
                    let i = poses.as_slice()[a].instance_id as usize;
                    let inst = ws.instances[i];
                    mean(ws.instance_points(i)[..inst.distinct_points(ws.config.num_points)].iter().copied())
                };
                let mut centres = [[0.0f32; 3]; MAX_CUT_PIECES];
                for (c, &a) in centres.iter_mut().zip(&taken[..count]) {
                    *c = centre(a);
                }
                if self.carried.len() < self.carried.capacity()
                    && let Some(hint) = CutHint::new(poses.as_slice()[taken[0]].class_id, &centres[..count])
                {
                    self.carried.push(hint);
                }
                held += 1;
            } else if self.refused.len() < self.refused.capacity() {
                let mid = mean(found.iter().map(|&(_, a)| poses.as_slice()[a].translation.map(|x| x as f32).into()));
                let class_id = poses.as_slice()[found[0].1].class_id;
                self.refused.push(Refused { class_id, midpoint: mid, frames: REFUSED_FRAMES });
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
            let (centres, class_id) = (&self.centres[j][..c.pieces as usize], poses[c.pose].class_id);
            let mid = mean(centres.iter().copied());
            // The same place: within the object's smallest side.
            let reach = self.sides.get(class_id as usize - 1).copied().unwrap_or(0.0);
            let near = |r: &Refused| {
                r.class_id == class_id && (0..3).map(|k| (r.midpoint[k] - mid[k]).powi(2)).sum::<f32>() < reach * reach
            };
            if self.refused.iter().any(near) || self.carried.len() >= self.carried.capacity() {
                continue;
            }
            if let Some(hint) = CutHint::new(class_id, centres) {
                self.carried.push(hint);
                deferred += 1;
            }
        }
        deferred
    }

    /// Keeps the candidates (lowest coverage first) whose pieces fit in
    /// `budget` (pieces estimated once each), at least the first, and takes
    /// the others' pieces off the piece plane; returns the pieces kept.
    fn fit_budget(&mut self, width: usize, budget: usize) -> usize {
        let mut total = 0;
        let mut keep = 0;
        for c in &self.candidates {
            if keep > 0 && total + c.pieces as usize > budget {
                break;
            }
            total += c.pieces as usize;
            keep += 1;
        }
        for j in keep..self.candidates.len() {
            let c = self.candidates[j];
            let pieces = c.base + 1..=c.base + c.pieces as u16;
            let [u0, v0, u1, v1] = self.written[j].map(|x| x as usize);
            for v in v0..=v1 {
                for id in &mut self.ids[v * width + u0..=v * width + u1] {
                    if pieces.contains(id) {
                        *id = 0;
                    }
                }
            }
            self.classes[c.base as usize + 1..=c.base as usize + c.pieces as usize].fill(0);
        }
        self.candidates.truncate(keep);
        self.centres.truncate(keep);
        self.written.truncate(keep);
        total
    }

    /// The regions to look at, lowest coverage first.
    fn choose(
        &mut self,
        poses: &[ObjectPose],
        verdicts: &[Verification],
        verifier: &Verifier,
        instances: &[crate::Instance],
    ) {
        self.candidates.clear();
        for (k, v) in verdicts.iter().enumerate() {
            let (coverage, pose) = (v.mask_coverage, &poses[k]);
            let supported = v.passed
                || (!crate::alternates::is_alternate(instances, pose)
                    && match self.config.poses {
                        RecutPoses::Passed => false,
                        RecutPoses::Coverage => verifier.passes_but_for_coverage(pose.class_id, v),
                        RecutPoses::Any => verifier.region_certain(v),
                    });
            if supported && coverage < self.config.max_coverage && pose.class_id as usize <= self.sides.len() {
                self.candidates.push(Candidate { pose: k, coverage, pieces: 0, base: 0 });
            }
        }
        self.candidates.sort_unstable_by(|a, b| a.coverage.total_cmp(&b.coverage));
        self.candidates.truncate(self.config.max_regions);
    }

    /// Writes the candidates' pieces into the instance plane, from up to
    /// [`SAMPLES`] of the region's valid-depth points. A region is cut into
    /// [`pieces_for`] its coverage pieces or, failing that, fewer, down to
    /// two: by their centre votes where [`RecutConfig::proposal`] asks for
    /// them and they fall into groups at least [`MIN_VOTE_GAP_CELLS`] apart
    /// (every pixel to the group nearest its cell's vote), else by k-means
    /// in 3D (every pixel to its nearest centre, by image distance to the
    /// projected centres where it has no depth). Pieces must be even enough
    /// ([`MIN_PIECE_SHARE`]); a candidate no count cuts evenly is dropped.
    /// With `contacts`, a region the contact band parts into two or more
    /// even pieces is cut along it instead, and k-means pieces are grown
    /// from their centres over the band ([`ContactCut::grow`]).
    /// Returns how many were cut along votes, and along contacts.
    fn cut(
        &mut self,
        frame: &FrameView<'_>,
        ws: &Workspace,
        poses: &[ObjectPose],
        votes: Option<&dyn CentreVotes>,
        contacts: Option<&dyn ContactMap>,
    ) -> (usize, usize) {
        let voter = votes.filter(|_| self.config.proposal != CutProposal::Points);
        let max_pieces = self.config.pieces();
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
        // `contact_cut` was sized with `ids` (`warm_up`): contacts come with the proposal only.
        let (mut kept, mut by_votes, mut by_contacts, mut base) = (0, 0, 0, 0u16);
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
            let even = |cluster: &[u8], k: usize| {
                let min = (MIN_PIECE_SHARE * 2.0 / k as f32 * n as f32).ceil() as usize;
                (0..k).all(|m| cluster.iter().filter(|&&x| x as usize == m).count() >= min)
            };
            let most = pieces_for(self.candidates[c].coverage, max_pieces);
            // The votes of every sample, when there are votes for all.
            let voted = voter.filter(|seg| {
                self.sample_votes.clear();
                for &[u, v] in &self.sample_pixels {
                    match seg.vote_at(u as usize, v as usize) {
                        Some([x, y]) => self.sample_votes.push([x, y, 0.0]),
                        None => return false,
                    }
                }
                true
            });
            // The most pieces whose vote groups lie apart and are even.
            let vote_cut = voted.and_then(|seg| {
                (2..=most).rev().find_map(|k| {
                    let c = kmeans(&self.sample_votes, k, &mut self.cluster[..n], &mut self.order);
                    let gap = (0..k)
                        .flat_map(|a| (a + 1..k).map(move |b| (a, b)))
                        .map(|(a, b)| ((c[a][0] - c[b][0]).powi(2) + (c[a][1] - c[b][1]).powi(2)).sqrt())
                        .fold(f32::INFINITY, f32::min);
                    (gap >= MIN_VOTE_GAP_CELLS && even(&self.cluster[..n], k)).then(|| {
                        let cells: [[f32; 2]; MAX_CUT_PIECES] = std::array::from_fn(|i| [c[i][0], c[i][1]]);
                        (seg, cells, k)
                    })
                })
            });
            // The contact band's pieces, when it parts the region evenly; with
            // votes, the depth image's creases where the votes do not cut.
            let creases = match self.config.proposal {
                CutProposal::Creases => true,
                CutProposal::Votes => vote_cut.is_none(),
                _ => false,
            };
            if creases {
                self.crease_band.mark(frame, [u0, v0, u1, v1], in_region);
            }
            let map = if creases { Some(&self.crease_band as &dyn ContactMap) } else { contacts };
            let contact_pieces = map.and_then(|map| {
                let k = self.contact_cut.cut([u0, v0, u1, v1], in_region, map, most)?;
                self.contact_cut.pieces_of(&self.sample_pixels, &mut self.cluster);
                even(&self.cluster[..n], k).then_some(k)
            });
            // A fold between pieces of two colours is where another object
            // the segmenter gave this class meets it: no copy (the points decide).
            let contact_pieces = contact_pieces.filter(|&k| {
                !creases || {
                    let mut sums = [[0.0f64; 4]; MAX_CUT_PIECES];
                    // `cluster` holds each sample's piece (`pieces_of` above).
                    for (&[u, v], &piece) in self.sample_pixels.iter().zip(&self.cluster[..n]) {
                        let p = v as usize * w + u as usize;
                        let Some(rgb) = frame.color.get(p * 3..p * 3 + 3) else { continue };
                        let s = &mut sums[(piece as usize).min(k - 1)];
                        *s = [s[0] + rgb[0] as f64, s[1] + rgb[1] as f64, s[2] + rgb[2] as f64, s[3] + 1.0];
                    }
                    crate::split::shared_chroma(&sums[..k])
                }
            });
            let ids = &mut self.ids;
            let mut fill = |piece_of: &dyn Fn(usize, usize, usize) -> usize| {
                for v in v0..=v1 {
                    for u in u0..=u1 {
                        let p = v * w + u;
                        if in_region(p) {
                            ids[p] = base + 1 + piece_of(u, v, p) as u16;
                        }
                    }
                }
            };
            let mut centres = [[0.0f32; 3]; MAX_CUT_PIECES];
            let piece_centres = |cluster: &[u8], k: usize, centres: &mut [[f32; 3]; MAX_CUT_PIECES]| {
                let mut sums = [[0.0f32; 4]; MAX_CUT_PIECES];
                for (p, &m) in self.samples.iter().zip(cluster) {
                    let s = &mut sums[(m as usize).min(k - 1)];
                    *s = [s[0] + p[0], s[1] + p[1], s[2] + p[2], s[3] + 1.0];
                }
                for (centre, s) in centres.iter_mut().zip(&sums).take(k) {
                    *centre = [s[0], s[1], s[2]].map(|x| x / s[3].max(1.0));
                }
            };
            let pieces = if let Some(k) = contact_pieces {
                let cut = &self.contact_cut;
                fill(&|_, _, p| cut.piece_at(p));
                by_contacts += 1;
                piece_centres(&self.cluster[..n], k, &mut centres);
                k
            } else if let Some((seg, cells, k)) = vote_cut {
                fill(&|u, v, _| seg.vote_at(u, v).map_or(0, |vote| nearest_2d(&cells[..k], vote)));
                by_votes += 1;
                // The pieces' 3D centres (for the cut carried to the next frame).
                piece_centres(&self.cluster[..n], k, &mut centres);
                k
            } else {
                if voter.is_some() && self.config.proposal == CutProposal::VotesOnly {
                    continue;
                }
                let Some(k) = (2..=most).rev().find(|&k| {
                    let c = kmeans(&self.samples, k, &mut self.cluster[..n], &mut self.order);
                    centres[..k].copy_from_slice(&c[..k]);
                    even(&self.cluster[..n], k)
                }) else {
                    continue;
                };
                let mut pixels = [[0.0f32; 2]; MAX_CUT_PIECES];
                for (pixel, centre) in pixels.iter_mut().zip(&centres).take(k) {
                    *pixel = project(frame, Some(centre));
                }
                // With contacts, the samples near their centre seed a flood
                // that meets where the copies touch, not halfway between centres.
                // Only the segmenter's contacts (never the depth image's
                // creases: grown over them, pieces pass on regions that are
                // no copies; docs/BENCHMARKS.md, session 44).
                let grown = contacts.is_some_and(|map| {
                    let near = |i: usize| {
                        let s = self.samples[i];
                        let d = |c: &[f32; 3]| (0..3).map(|j| (s[j] - c[j]).powi(2)).sum::<f32>();
                        let own = d(&centres[self.cluster[i] as usize]);
                        (0..k)
                            .filter(|&m| m != self.cluster[i] as usize)
                            .all(|m| own < SEED_RATIO * SEED_RATIO * d(&centres[m]))
                    };
                    let seeds = (0..n).filter(|&i| near(i)).map(|i| {
                        let [u, v] = self.sample_pixels[i];
                        (v as usize * w + u as usize, self.cluster[i] as u16)
                    });
                    self.contact_cut.grow([u0, v0, u1, v1], in_region, map, seeds);
                    let mut moved = [0u8; SAMPLES];
                    self.contact_cut.pieces_of(&self.sample_pixels, &mut moved);
                    even(&moved[..n], k)
                });
                if grown {
                    let cut = &self.contact_cut;
                    fill(&|_, _, p| cut.piece_at(p));
                    by_contacts += 1;
                } else {
                    fill(&|_, _, p| nearest_piece(frame, &centres[..k], &pixels[..k], p));
                }
                k
            };
            self.classes[base as usize + 1..=base as usize + pieces].fill(pose.class_id);
            self.written.push(bbox);
            self.candidates[kept] = Candidate { pieces: pieces as u8, base, ..self.candidates[c] };
            self.centres.push(centres);
            base += pieces as u16;
            kept += 1;
        }
        self.candidates.truncate(kept);
        (by_votes, by_contacts)
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
        let want = (self.candidates[j].base as usize + 1 + k) as u32;
        self.poses.as_slice().iter().position(|p| self.ws.component_id(p.instance_id as usize) == Some(want))
    }

    /// The pieces of candidate `j` that are copies of the object, each with
    /// its pose (index in `self.poses`): best fit first, a piece is taken
    /// when its pose passed verification and it is two copies
    /// ([`Terms::two_copies`]) with each piece taken before it. Returns how
    /// many (in piece order), or why fewer than two: the first refusal met,
    /// else [`Refusal::Unverified`].
    fn copies(
        &self,
        j: usize,
        view: &FrameView<'_>,
        verifier: &mut Verifier,
        taken: &mut [(usize, usize); MAX_CUT_PIECES],
    ) -> Result<usize, Refusal> {
        let c = self.candidates[j];
        let mut passed = [(0.0f32, 0usize, 0usize); MAX_CUT_PIECES];
        let mut n = 0;
        for k in 0..c.pieces as usize {
            if let Some(a) = self.piece_pose(j, k).filter(|&a| self.config.piece_may_be_copy(&self.verdicts[a])) {
                passed[n] = (self.verdicts[a].fit, k, a);
                n += 1;
            }
        }
        passed[..n].sort_unstable_by(|x, y| y.0.total_cmp(&x.0));
        let terms = Terms { config: &self.config, sides: &self.sides, solids: &self.solids };
        let mask = |k: usize, a: usize| {
            (
                &self.poses.as_slice()[a],
                &self.verdicts[a],
                self.ws.mask_ref(c.base as u32 + 1 + k as u32, self.poses.as_slice()[a].bbox),
            )
        };
        let (mut count, mut first) = (0, None);
        for &(_, k, a) in &passed[..n] {
            let refusal = taken[..count]
                .iter()
                .find_map(|&(tk, ta)| terms.two_copies(view, verifier, mask(k, a), mask(tk, ta)).err());
            match refusal {
                None => {
                    taken[count] = (k, a);
                    count += 1;
                }
                Some(why) => {
                    first.get_or_insert(why);
                }
            }
        }
        // In piece order: the first piece's copy keeps the region's instance.
        taken[..count].sort_unstable_by_key(|t| t.0);
        if count >= 2 { Ok(count) } else { Err(first.unwrap_or(Refusal::Unverified)) }
    }

    /// A refused cut of candidate `j`: its best-fitting passed piece's pose
    /// replaces the region's pose `whole` when it fits better
    /// ([`RecutConfig::best_piece`]). Where the cut found one copy and a piece
    /// it could not pose, the region's one pose lay between them; the piece's
    /// pose lies on its copy. The pose keeps the region's instance, box and
    /// pixel count; its verdict (fit, coverage) is the piece's.
    fn take_best_piece(&mut self, j: usize, whole: usize, poses: &mut PoseSet, verdicts: &mut [Verification]) {
        let best = (0..self.candidates[j].pieces as usize)
            .filter_map(|k| self.piece_pose(j, k))
            .filter(|&a| self.verdicts[a].passed)
            .max_by(|&a, &b| self.verdicts[a].fit.total_cmp(&self.verdicts[b].fit));
        let (Some(a), Some(region)) = (best, verdicts.get(whole).copied()) else { return };
        let fit = self.verdicts[a].fit;
        let better = match region.passed {
            true => fit >= (region.fit + BEST_PIECE_MARGIN).max(BEST_PIECE_MIN_FIT),
            false => fit >= REVIVE_MIN_FIT,
        };
        if better {
            let own = poses.as_slice()[whole];
            let piece = self.poses.as_slice()[a];
            poses.replace(
                whole,
                ObjectPose { instance_id: own.instance_id, bbox: own.bbox, mask_pixels: own.mask_pixels, ..piece },
            );
            verdicts[whole] = self.verdicts[a];
            self.replaced += 1;
        }
    }

    /// Keeps the cuts the depth image supports; returns how many. The
    /// region becomes one instance per copy taken ([`Recut::copies`]); a
    /// piece not taken joins the copy whose piece centre lies nearest (it is
    /// more of that copy, or a part no pose explains).
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
            let c = self.candidates[j];
            let whole = c.pose;
            let mut taken = [(0usize, 0usize); MAX_CUT_PIECES];
            let count = match self.copies(j, view, verifier, &mut taken) {
                Ok(count) => count,
                Err(why) => {
                    self.refusals[why as usize] += 1;
                    if self.config.best_piece {
                        self.take_best_piece(j, whole, poses, verdicts);
                    }
                    continue;
                }
            };
            // Room for the copies' poses (the region's goes after the loop).
            if poses.len() + count > poses.capacity() || ws.instances.len() + count - 1 > ws.config.max_instances {
                continue;
            }
            // Each piece's copy: its own if taken, else the nearest taken.
            let centres = self.centres[j];
            let mut copy_of = [0usize; MAX_CUT_PIECES];
            for (k, copy) in copy_of.iter_mut().enumerate().take(c.pieces as usize) {
                let d = |t: usize| {
                    let (a, b) = (centres[k], centres[taken[t].0]);
                    (0..3).map(|x| (a[x] - b[x]).powi(2)).sum::<f32>()
                };
                *copy = (0..count).min_by(|&x, &y| d(x).total_cmp(&d(y))).unwrap_or(0);
            }
            let i = poses.as_slice()[whole].instance_id as usize;
            let piece = |p: usize| ids.get(p).map_or(0, |&id| id.saturating_sub(c.base + 1) as usize);
            // Copy 0 keeps the region's instance index; each other is cut off it.
            let mut at = [i; MAX_CUT_PIECES];
            let mut made = 1;
            while made < count {
                let Some(new) =
                    ws.cut_instance(frame, i, |p| usize::from(copy_of[piece(p).min(MAX_CUT_PIECES - 1)] == made))
                else {
                    break;
                };
                at[made] = new;
                made += 1;
            }
            if made < 2 {
                continue;
            }
            self.marks[whole] = true;
            for t in (0..made).rev() {
                let inst = ws.instances[at[t]];
                let pose = self.poses.as_slice()[taken[t].1];
                poses.push(ObjectPose { instance_id: at[t] as u16, bbox: inst.bbox, mask_pixels: inst.pixels, ..pose });
                verdicts.push(self.verdicts[taken[t].1]);
                self.marks.push(false);
            }
            // A stream carries the cut with a centre per copy ([`CutHint`]).
            // A refitted cut follows the copies' poses: their centres place it.
            let pose = |t: usize| self.poses.as_slice()[taken[t].1];
            let mut at = [[0.0f32; 3]; MAX_CUT_PIECES];
            for (t, c) in at.iter_mut().enumerate().take(made) {
                *c = match self.config.refit {
                    true => pose(t).translation.map(|x| x as f32).into(),
                    false => centres[taken[t].0],
                };
            }
            if self.carried.len() < self.carried.capacity()
                && let Some(hint) = CutHint::new(pose(0).class_id, &at[..made])
            {
                self.carried.push(hint);
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

/// The mean of `points` (the origin for none).
fn mean(points: impl ExactSizeIterator<Item = [f32; 3]>) -> [f32; 3] {
    let n = points.len().max(1) as f32;
    points.fold([0.0; 3], |c, p| [c[0] + p[0] / n, c[1] + p[1] / n, c[2] + p[2] / n])
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
