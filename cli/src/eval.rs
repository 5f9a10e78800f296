//! `fusepose eval`: run an estimator frame by frame over a BOP or YCB-Video
//! dataset and score it (ADD-S AUC, ADD(S) AUC, ADD-S < 2 cm, per object and
//! overall), with timing, a BOP results CSV, a JSON summary and a PNG of the
//! accuracy–threshold curves.
//!
//! Scoring: every ground-truth object of the evaluated set counts once; an
//! object with no estimate of its class (instance not found, dropped, or the
//! frame refused) is a failure (infinite error). With several instances of a
//! class in a frame, estimates are matched greedily by translation distance.
//! Ghosts are estimates matched to no object; stray poses are those at ADD-S
//! ≥ 0.1 × diameter from every true object of their class (ghosts, and poses
//! matched to a copy they miss, e.g. between two copies in a heap): a grasp
//! at nothing either way.
//! Timing covers `Workspace::prepare` + `Estimator::estimate` per frame (not
//! image decoding); time per object is the frame time divided by the
//! instances estimated in it.
//!
//! Masks: `--masks gt` uses the dataset's ground-truth class labels, `--masks
//! net` the built-in segmenter's ([`masks`]); `--masks gt,net` evaluates
//! every estimator with both on the same frames. `--overlay DIR` writes one
//! PNG per frame: the instances the last estimator posed tinted, each copy of
//! a class in its own shade with a white line where two meet, and each pose
//! drawn in its instance's shade.
//!
//! Verification (`--verify drop|flag|off`, default `drop` as in the daemon)
//! checks each pose against the depth image and counts what fails, ghosts
//! apart from poses of real objects; `FUSEPOSE_VERIFY_TRACE=1` prints each
//! pose's verification terms to stderr (how the thresholds were chosen on the
//! tuning split, docs/BENCHMARKS.md). `--masks gt-instances` sends the true
//! masks as an instance plane, and every run with true instance masks in the
//! dataset reports instance precision / recall and merged / split regions.
//! `FUSEPOSE_MISS_TRACE=1` prints, for each true object left without a pose
//! within 0.1 d, where its pixels went: background, a region of its class or
//! of another, with or without a published pose.

mod dataset;
mod instances;
mod masks;
mod per_object;
mod pseudo;
mod variants;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use fusepose_estimator::alternates;
use fusepose_estimator::net::{NetEstimator, NetOptions};
use fusepose_estimator::pose_odds::PoseOdds;
use fusepose_estimator::seg::SegEngine;
use fusepose_estimator::verify::{FacingWeights, Verifier, VerifyConfig};
use fusepose_estimator::{
    ColorFormat, DepthPlane, Estimator, FrameView, IcpConfig, IcpEstimator, LabelPlane, ObjectPose, PoseSet, Workspace,
    WorkspaceConfig,
};
use fusepose_scene::metrics::{
    BopResult, BopResultsWriter, MetricsRow, MetricsTable, ObjectMetric, plot_accuracy_curves,
};
use fusepose_scene::render::cast::Cast;
use fusepose_scene::{ObjectSet, Pose};
use indicatif::{ProgressBar, ProgressStyle};

use crate::pose_overlay::{DrawnPose, Tint};

use dataset::{EvalDataset, EvalFrame, GtObject};
use masks::NetMasks;
use per_object::PerObjectWriter;

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum EstimatorKind {
    Icp,
    Net,
}

impl EstimatorKind {
    fn name(self) -> &'static str {
        match self {
            EstimatorKind::Icp => "icp",
            EstimatorKind::Net => "net",
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum MaskSource {
    /// Ground-truth visible masks from the dataset, flattened to class ids
    /// (touching copies of a class become one region, as on a class-label wire).
    Gt,
    /// Ground-truth visible masks as an instance plane (each object its own instance).
    GtInstances,
    /// The segmentation network's masks (an instance plane when the segmenter
    /// has the centre-offset head).
    Net,
}

impl MaskSource {
    fn name(self) -> &'static str {
        match self {
            MaskSource::Gt => "gt",
            MaskSource::GtInstances => "gt-instances",
            MaskSource::Net => "net",
        }
    }
}

#[derive(clap::Args, Clone, Debug)]
pub struct Args {
    /// Dataset: a BOP dataset root (its --split folder is used) or a split
    /// folder itself, or a YCB-Video root.
    #[arg(long)]
    pub dataset: PathBuf,
    /// BOP split under the dataset root (ignored when --dataset is a split folder).
    #[arg(long, default_value = "test")]
    pub split: String,
    /// Estimator to evaluate.
    #[arg(long, value_enum, default_value_t = EstimatorKind::Icp)]
    pub estimator: EstimatorKind,
    /// Evaluate several estimators on the same frames (e.g. `icp,net`); overrides --estimator.
    #[arg(long, value_enum, value_delimiter = ',')]
    pub compare: Vec<EstimatorKind>,
    /// Where instance masks come from; `gt,net` evaluates with both.
    #[arg(long, value_enum, value_delimiter = ',', default_value = "gt")]
    pub masks: Vec<MaskSource>,
    /// Segmenter for `--masks net` (default: the one embedded in --weights).
    #[arg(long)]
    pub seg_weights: Option<PathBuf>,
    /// `--masks net`: same-class regions smaller than this many segmenter output cells
    /// become background (default: the engine's, 6).
    #[arg(long)]
    pub seg_min_cells: Option<usize>,
    /// `--masks net`: regions whose long side² / area exceeds this become
    /// background (strips; 0 = keep all; default: the engine's).
    #[arg(long)]
    pub seg_max_elongation: Option<f32>,
    /// `--masks net`: regions with fewer interior cells (all four neighbours
    /// of their class) become background (default: the engine's, 1).
    #[arg(long)]
    pub seg_min_interior: Option<usize>,
    /// `--masks net` with the offset head: the instance vote's peak search,
    /// MIN_VOTES,MERGE_RADIUS_CELLS,MIN_CELLS (default: the engine's), or
    /// `off` (the head ignored: class regions, as without it).
    #[arg(long)]
    pub seg_voting: Option<fusepose_estimator::seg::voting::VotingMode>,
    /// `--masks net`: lower the background logit by this much before the
    /// argmax (log odds; more of partly hidden objects found, more regions
    /// for verification to refuse). Default: the engine's, 0.
    #[arg(long)]
    pub seg_background_offset: Option<f32>,
    /// `--masks net`: average the segmenter's logits over the frame and its
    /// mirror image (twice its network's time): `off`, `all` (every cell) or
    /// `no-swap` (not where the two views pick two different objects).
    /// Default: the engine's, off.
    #[arg(long)]
    pub seg_flip_average: Option<fusepose_estimator::seg::FlipAverage>,
    /// `--masks net`: a second segmenter (a network file with one embedded, or
    /// a segmenter file) whose logits are averaged with the first one's.
    #[arg(long)]
    pub seg_partner: Option<PathBuf>,
    /// `--seg-partner`'s share of the averaged logits (0..=1).
    #[arg(long, default_value_t = 0.5)]
    pub seg_partner_weight: f32,
    /// `--masks net`: regroup the segmenter's cells by the depth image before
    /// its clean-up: cells standing on the table together that fit inside one
    /// object of their majority class take that class. `off`, `on`,
    /// or KEY=VALUE,… over the defaults (height, step, step-per-m, share,
    /// absorb, absorb-p, slack); default `on`, as the daemon's
    /// `estimator.seg_depth_regions`.
    #[arg(long, default_value = "on")]
    pub seg_depth_regions: DepthRegionsArg,
    /// `--masks net`: how cell labels become frame labels: `cells`,
    /// `erode-cells` or `refine:N` (pixel borders from interpolated logits, N
    /// pixels eroded); default: the engine's.
    #[arg(long)]
    pub seg_boundary: Option<fusepose_estimator::seg::Boundary>,
    /// Write one PNG per frame here: the last estimator's instances tinted (the
    /// segmenter's regions after any cut with `--masks net`; each copy of a
    /// class its own shade, a white line where two meet), its poses drawn in
    /// their instance's shade.
    #[arg(long)]
    pub overlay: Option<PathBuf>,
    /// Write pseudo-labels for the segmenter's adaptation to this folder: each
    /// frame's published poses rendered and confirmed by its depth, the table
    /// as background, the rest unknown (no ground truth is read). Needs
    /// `--masks net` (last), one seed and no cast; train on them with `fusepose
    /// train --stage seg --adapt-labels DIR`.
    #[arg(long)]
    pub pseudo_labels: Option<PathBuf>,
    /// With --pseudo-labels: label as background the table pixels the segmenter gave a class that no pose
    /// explains (ghosts to unlearn). Off by default, as session 48's round 1 labelled; the one command adapted
    /// alike with and without it (docs/BENCHMARKS.md, session 49).
    #[arg(long)]
    pub pseudo_table_patches: bool,
    /// Object set: `builtin` or a mesh folder (default: the one the dataset names, else builtin).
    #[arg(long)]
    pub objects: Option<String>,
    /// Metres per mesh-file unit for a mesh folder (0.001 for millimetre meshes).
    #[arg(long, alias = "mesh-scale", default_value_t = 1.0)]
    pub scale: f64,
    /// Declare an object's symmetry for ADD(S), as `train --symmetry` (NAME=KIND or a bare
    /// `suggested`). Objects still without one take the symmetry the network's weight
    /// file was trained with.
    #[arg(long = "symmetry", value_name = "NAME=KIND")]
    pub symmetry: Vec<fusepose_scene::symmetry_spec::SymmetrySpec>,
    #[arg(long, help = crate::weights::WEIGHTS_HELP)]
    pub weights: Option<PathBuf>,
    /// Base seed of each frame's randomness, e.g. point sampling (frame i uses seed + i).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Evaluate with this many sampling seeds (`--seed`, `--seed` + 1, …) and
    /// end with each run's mean ± standard deviation over them: one seed is
    /// one draw of the point sampling, and single runs differ by up to a few
    /// points of ADD(S) between seeds. Judge changes on several.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub seeds: u32,
    /// Evaluate only the first N frames.
    #[arg(long)]
    pub limit: Option<usize>,
    /// Most instances estimated per frame (largest masks first).
    #[arg(long, default_value_t = 16)]
    pub max_instances: usize,
    /// `net`: refiner iterations per object (default: the weight file's, 2).
    #[arg(long)]
    pub refine_iterations: Option<usize>,
    /// Drop estimates less confident than this (0..1), as the daemon's
    /// `estimator.min_confidence` does.
    #[arg(long, default_value_t = 0.0)]
    pub min_confidence: f32,
    /// `net`: points per object (default: the weight file's N).
    #[arg(long)]
    pub points: Option<usize>,
    /// Join regions of one class into one instance when their points fit
    /// inside one object: within FACTOR × its diameter (0 = keep every region),
    /// as the daemon's `estimator.join_parts`.
    #[arg(long, default_value_t = 1.0)]
    pub join_parts: f32,
    /// Cut a region of one class whose points do not fit inside one object
    /// (FACTOR × its diameter) into the fewest pieces that each do: touching
    /// copies of one object (0 = off), as the daemon's `estimator.split_regions`.
    #[arg(long, default_value_t = 1.0)]
    pub split_regions: f32,
    /// One object, not two: segmenter instances of a class whose centres are
    /// within FACTOR × the object's smallest side become one, and a pose that
    /// close to a better pose of its class is dropped (0 = off), as the
    /// daemon's `estimator.duplicates`.
    #[arg(long, default_value_t = 0.0)]
    pub duplicates: f32,
    /// Of two poses whose solids overlap by more than this share, the one
    /// more inside the other is dropped, as the daemon's
    /// `estimator.max_interpenetration` (1 = off).
    #[arg(long, default_value_t = fusepose_estimator::interpenetration::DEFAULT_MAX_SHARE)]
    pub max_interpenetration: f32,
    /// Of two verified poses where one's model explains more than this share
    /// of the other's region, the one more explained by the other is
    /// dropped, as the daemon's `estimator.max_explained_share` (1 = off;
    /// needs verification).
    #[arg(long, default_value_t = fusepose_estimator::explained::DEFAULT_MAX_SHARE)]
    pub max_explained: f32,
    /// `--masks net` with verification: a region whose runner-up class has at
    /// least this mean segmenter probability is estimated as that class too
    /// and the better-verified pose kept, as the daemon's
    /// `estimator.class_alternates` (0 = off).
    #[arg(long, default_value_t = fusepose_estimator::alternates::DEFAULT_MIN_PROBABILITY)]
    pub class_alternates: f32,
    /// With verification, class-label masks and the network: a region whose
    /// verified pose covers less than this share of it is cut in two and
    /// each piece estimated; the cut stays when both poses pass and lie
    /// apart as two copies (0 = off), as the daemon's `estimator.recut`.
    #[arg(long, default_value_t = fusepose_estimator::recut::RecutConfig::DEFAULT.max_coverage)]
    pub recut: f32,
    /// Metres: an instance's pixels within this height of the plane the
    /// objects stand on (fitted to the background) are left out of its
    /// points (0 = off), as the daemon's `estimator.support_floor`.
    #[arg(long, default_value_t = fusepose_estimator::workspace::DEFAULT_SUPPORT_FLOOR_M)]
    pub support_floor: f32,
    /// `--recut`: how far apart the pieces' poses must be, × the object's smallest side.
    #[arg(long, default_value_t = fusepose_estimator::recut::RecutConfig::DEFAULT.min_separation)]
    pub recut_separation: f32,
    /// `--recut`: where a region's cut comes from: `points` (k-means on its
    /// 3D points), `votes` (the segmenter's centre-offset votes where its
    /// file has the head and they point at two centres, else as `creases`),
    /// `votes-only`, `contacts` (the segmenter's contact band where its
    /// file has the branch and the band parts the region, else the points),
    /// or `creases` (as `contacts`, the band from the depth image's concave
    /// folds and steps), as the daemon's `estimator.recut_proposal`.
    #[arg(long, default_value_t = fusepose_estimator::recut::RecutConfig::DEFAULT.proposal)]
    pub recut_proposal: fusepose_estimator::recut::CutProposal,
    /// `--recut`: most pieces a region is cut into (2 to 6): a region whose
    /// pose covers a share c of it is cut into 1 ÷ c pieces, rounded, as the
    /// daemon's `estimator.recut_pieces`.
    #[arg(long, default_value_t = fusepose_estimator::recut::RecutConfig::DEFAULT.max_pieces,
          value_parser = clap::builder::RangedI64ValueParser::<usize>::new().range(2..=fusepose_estimator::recut::MAX_CUT_PIECES as i64))]
    pub recut_pieces: usize,
    /// `--recut`: which regions' poses qualify besides their coverage:
    /// `passed` (verified poses), `coverage` (also poses that failed on
    /// their coverage alone) or `any` (any pose of a region the segmenter
    /// was sure of), as the daemon's `estimator.recut_poses`.
    #[arg(long, default_value_t = fusepose_estimator::recut::RecutConfig::DEFAULT.poses)]
    pub recut_poses: fusepose_estimator::recut::RecutPoses,
    /// `--recut`: once the pieces have poses, give each pixel to the piece
    /// whose posed box holds it and estimate the pieces again, as the
    /// daemon's `estimator.recut_refit`.
    #[arg(long, default_value_t = fusepose_estimator::recut::RecutConfig::DEFAULT.refit, action = clap::ArgAction::Set)]
    pub recut_refit: bool,
    /// `--recut-refit`: a pixel goes first to the best-verified piece whose
    /// posed box holds it (within 5 mm), not to the nearest box centre. Off:
    /// measured, not adopted (docs/BENCHMARKS.md, session 35).
    #[arg(long)]
    pub recut_refit_by_verdict: bool,
    /// `--recut`: a piece is a copy only when its pose's verification fit is
    /// at least this (0 = any passing pose).
    #[arg(long, default_value_t = fusepose_estimator::recut::RecutConfig::DEFAULT.min_piece_fit)]
    pub recut_min_piece_fit: f32,
    /// `--recut`: a refused cut's best passed piece pose replaces the
    /// region's pose where it fits better (by 0.1 and at least 0.8; a failed
    /// region's pose at a piece fit of 0.95 or more), as the daemon's
    /// `estimator.recut_best_piece`.
    #[arg(long, default_value_t = fusepose_estimator::recut::RecutConfig::DEFAULT.best_piece, action = clap::ArgAction::Set)]
    pub recut_best_piece: bool,
    /// Second masks for failed poses: at most this many per frame get the
    /// pixels inside their posed box (grown by `--remask-margin`) as a new
    /// mask and are estimated again, kept when the new pose passes (0 =
    /// off), as the daemon's `estimator.remask`.
    #[arg(long, default_value_t = fusepose_estimator::remask::RemaskConfig::DEFAULT.max_regions,
          value_parser = clap::builder::RangedI64ValueParser::<usize>::new().range(0..=fusepose_estimator::remask::MAX_REGIONS as i64))]
    pub remask: usize,
    /// `--remask`: metres the posed box grows by on every side, as the
    /// daemon's `estimator.remask_margin_m`.
    #[arg(long, default_value_t = fusepose_estimator::remask::RemaskConfig::DEFAULT.margin_m)]
    pub remask_margin: f32,
    /// `--remask`: estimates per second mask (each pose placing the next
    /// box), as the daemon's `estimator.remask_rounds`.
    #[arg(long, default_value_t = fusepose_estimator::remask::RemaskConfig::DEFAULT.rounds,
          value_parser = clap::builder::RangedI64ValueParser::<usize>::new().range(1..=fusepose_estimator::remask::MAX_ROUNDS as i64))]
    pub remask_rounds: usize,
    /// `--remask`: only failed poses with at least this inlier fraction.
    #[arg(long, default_value_t = fusepose_estimator::remask::RemaskConfig::DEFAULT.min_inlier_fraction)]
    pub remask_min_inliers: f32,
    /// `--remask`: passed poses whose confidence is below this get a second
    /// mask too (0 = off).
    #[arg(long, default_value_t = fusepose_estimator::remask::RemaskConfig::DEFAULT.max_confidence)]
    pub remask_doubted_below: f32,
    /// `--remask-doubted-below`: a passed pose is replaced only when the new
    /// pose's inlier fraction is at least the old one's minus this ...
    #[arg(long, default_value_t = fusepose_estimator::remask::RemaskConfig::DEFAULT.inlier_slack)]
    pub remask_inlier_slack: f32,
    /// ... and its confidence at least the old one's plus this.
    #[arg(long, default_value_t = fusepose_estimator::remask::RemaskConfig::DEFAULT.confidence_gain, allow_negative_numbers = true)]
    pub remask_confidence_gain: f32,
    /// Pose verification against the depth image, as the daemon's
    /// `estimator.verify`: `drop` (poses that fail are removed, the daemon's
    /// default), `flag` (kept, counted) or `off`.
    #[arg(long, default_value = "drop", value_parser = ["drop", "flag", "off"])]
    pub verify: String,
    /// Verification thresholds (default: the daemon's).
    #[arg(long)]
    pub verify_min_fit: Option<f32>,
    #[arg(long)]
    pub verify_min_inliers: Option<f32>,
    #[arg(long)]
    pub verify_min_depth_support: Option<f32>,
    #[arg(long)]
    pub verify_max_plane_continuation: Option<f32>,
    #[arg(long)]
    pub verify_max_depth_continuity: Option<f32>,
    #[arg(long)]
    pub verify_min_thin_mask_agreement: Option<f32>,
    /// Least share of a pose's depth-agreeing model surface inside its mask,
    /// for objects 2.5 cm thick or more (0 = off, the default; thin ones have
    /// their own)
    #[arg(long)]
    pub verify_min_mask_agreement: Option<f32>,
    /// Which verification terms weigh each model sample by how squarely it
    /// faces the camera: `none` (the default), `off-plane` or `all` (also the
    /// inlier fraction); `VerifyConfig::facing`
    #[arg(long, default_value = "none", value_parser = ["none", "off-plane", "all"])]
    pub verify_facing: String,
    /// Mask agreement from which a pose passes with the looser inlier and fit
    /// minimums below (above 1 = off).
    #[arg(long)]
    pub verify_agreeing_mask_agreement: Option<f32>,
    #[arg(long)]
    pub verify_agreeing_min_inliers: Option<f32>,
    #[arg(long)]
    pub verify_agreeing_min_fit: Option<f32>,
    /// Regions with at least this share of their depth pixels on the table
    /// are judged on the rest, as the daemon's
    /// `estimator.verify_trim_table_share` (above 1 = off).
    #[arg(long)]
    pub verify_trim_table_share: Option<f32>,
    /// Poses with more than this share of their surface samples 3 cm (see
    /// the next flag) or more below the support plane fail (above 1 = off).
    #[arg(long)]
    pub verify_max_below_support: Option<f32>,
    /// Poses whose region covers less than this share of the object's largest
    /// face (back-projected at the pose's depth) fail, as the daemon's
    /// `estimator.verify_min_region_area_share` (0 = off).
    #[arg(long)]
    pub verify_min_area_share: Option<f32>,
    /// Metres below the support plane from which a surface sample counts as
    /// sunk, as `VerifyConfig::below_support_m` (default 0.03).
    #[arg(long)]
    pub verify_below_support_depth: Option<f32>,
    /// `--masks net`: poses whose region the segmenter nowhere gave their
    /// class a probability of at least this fail (0 = off).
    #[arg(long)]
    pub verify_min_region_probability: Option<f32>,
    /// `--masks net`: as the daemon's `estimator.verify_region_certainty_quantile`,
    /// the segmenter's recorded certainty of real objects at this quantile
    /// (0.01..=0.5; 0 = off) as the region-probability floor (the higher of
    /// the two applies). Default: the daemon's (0.05) where the weight file
    /// records the certainty, else off.
    #[arg(long, value_name = "Q")]
    pub verify_region_quantile: Option<f32>,
    /// Poses whose odds of being right (the weight file's fitted model,
    /// `fusepose train --stage odds`) are below this fail, as the daemon's
    /// `estimator.verify_min_odds` (0 = off, the default).
    #[arg(long, value_name = "P")]
    pub verify_min_odds: Option<f32>,
    /// Write each verified pose's odds terms and whether it is right (wrong:
    /// matched to no object, or 0.1 diameters ADD-S or more from every object
    /// of its class; right: else within 2 cm ADD-S; others left out) to this file,
    /// the samples of `fusepose train --stage odds`. Fit it on frames that
    /// are neither tuning nor test frames.
    #[arg(long, value_name = "CSV")]
    pub odds_samples: Option<PathBuf>,
    /// Write the summary as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write BOP results CSV (with --compare: one file per estimator, `<stem>_<name>.csv`).
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// Write one row per ground-truth object (its visible fraction, whether an
    /// estimate was matched, ADD / ADD-S / ADD(S) in metres, the estimate's
    /// confidence and mask size) and one per estimate matched to no object
    /// (`ghost` = 1), to find where the accuracy goes (with several runs:
    /// `<stem>_<name>.csv`).
    #[arg(long)]
    pub per_object_csv: Option<PathBuf>,
    /// Write a PNG of the ADD-S accuracy–threshold curves.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Colour cast applied to each frame's RGB in linear light
    /// (`fusepose_scene::render::cast`); a list (`none,warm,cool,dim`)
    /// evaluates each and prints a row per cast.
    #[arg(long, value_delimiter = ',', default_value = "none", value_parser = cast_arg())]
    pub cast: Vec<Cast>,
    /// Dim frames brightened by one gain in linear light before the networks
    /// (`fusepose_estimator::exposure`, after any `--cast`): `off`, `on` or
    /// KEY=VALUE,… over the defaults (target, quantile, max-gain); default
    /// as the daemon's `estimator.auto_exposure`.
    #[arg(long, default_value = "on")]
    pub auto_exposure: ExposureArg,
    /// A strongly tinted frame's light undone by one gain per channel before
    /// the networks, after auto exposure (`fusepose_estimator::white_balance`):
    /// `off`, `on` or KEY=VALUE,… over the defaults (band, quantile); default
    /// as the daemon's `estimator.white_balance`.
    #[arg(long, default_value = "off")]
    pub white_balance: WhiteBalanceArg,
}

/// `--cast`'s parser: the casts' names as clap's possible values (shown in `--help`).
fn cast_arg() -> impl clap::builder::TypedValueParser<Value = Cast> {
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(Cast::ALL.map(Cast::name))
        .map(|s| s.parse::<Cast>().expect("a possible value names a cast"))
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if args.pseudo_labels.is_some() {
        let casts = args.cast.iter().filter(|&&c| c != Cast::None).count();
        if args.seeds > 1 || casts > 0 || args.masks.last() != Some(&MaskSource::Net) {
            anyhow::bail!(
                "--pseudo-labels labels the frames as they came: give `--masks net` (last), one seed and no --cast"
            );
        }
    }
    if let Some(path) = &args.odds_samples {
        // Once for every seed and cast: each run appends its samples.
        let header = fusepose_estimator::pose_odds::samples_header() + "\n";
        std::fs::write(path, header).with_context(|| format!("--odds-samples {}", path.display()))?;
    }
    variants::run_each(args, run_cast)
}

/// Applies `--symmetry`, then (for the network) the weight file's symmetries
/// to objects that still declare none, so ADD(S) treats an object as training did.
fn declare_symmetries(objects: &mut ObjectSet, args: &Args, net: bool) -> anyhow::Result<()> {
    use fusepose_scene::symmetry_spec::{Describe, apply_symmetry_specs};
    for (name, symmetry) in apply_symmetry_specs(objects, &args.symmetry)? {
        tracing::info!("{name}: symmetry {} (--symmetry)", Describe(&symmetry));
    }
    if net {
        let weights = crate::weights::resolve_weights(args.weights.as_deref())?;
        let file = fusepose_estimator::net::WeightFile::read(&weights)
            .with_context(|| format!("loading {}", weights.display()))?;
        for name in file.adopt_symmetries(objects) {
            tracing::info!("{name}: symmetry from {}", weights.display());
        }
    }
    Ok(())
}

/// One evaluation under `args.cast[0]`; returns the summaries `--json` writes.
fn run_cast(args: Args) -> anyhow::Result<serde_json::Map<String, serde_json::Value>> {
    let mut data = EvalDataset::open(&args.dataset, &args.split)?;
    let source = args.objects.clone().or_else(|| data.object_source()).unwrap_or_else(|| "builtin".into());
    let mut objects = fusepose_scene::mesh_io::load_object_set(&source, args.scale)
        .with_context(|| format!("loading object set `{source}`"))?;
    let kinds = if args.compare.is_empty() { vec![args.estimator] } else { args.compare.clone() };
    declare_symmetries(&mut objects, &args, kinds.contains(&EstimatorKind::Net))?;
    data.bind(&objects)?;
    let mut mask_sources = args.masks.clone();
    mask_sources.dedup();
    let solids = std::sync::Arc::new(fusepose_estimator::interpenetration::Solids::new(&objects));
    let cut_limits = fusepose_estimator::split::CutLimits::new(&objects, args.split_regions);
    // Read from the weight file once, for every runner on segmenter masks.
    let floor = if mask_sources.contains(&MaskSource::Net) { region_floor(&args)? } else { 0.0 };
    let odds = if kinds.contains(&EstimatorKind::Net) { pose_odds(&args)? } else { None };
    let samples = match &args.odds_samples {
        None => None,
        Some(path) => {
            let file = std::fs::OpenOptions::new()
                .append(true)
                .open(path)
                .with_context(|| format!("--odds-samples {}", path.display()))?;
            Some(std::sync::Arc::new(std::sync::Mutex::new(std::io::BufWriter::new(file))))
        }
    };
    let mut runners = kinds
        .iter()
        .flat_map(|&k| mask_sources.iter().map(move |&m| (k, m)))
        .map(|(k, m)| {
            let odds = (odds.as_ref(), samples.as_ref());
            Runner::new(k, m, mask_sources.len() > 1, &objects, &solids, &cut_limits, floor, odds, &args)
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let mut net_masks = match mask_sources.contains(&MaskSource::Net) {
        false => None,
        true => {
            let weights = match &args.seg_weights {
                Some(path) => path.clone(),
                None => crate::weights::resolve_weights(args.weights.as_deref())?,
            };
            let settings = masks::SegSettings {
                min_cells: args.seg_min_cells,
                max_elongation: args.seg_max_elongation,
                boundary: args.seg_boundary,
                min_interior: args.seg_min_interior,
                voting: args.seg_voting,
                background_offset: args.seg_background_offset,
                flip_average: args.seg_flip_average,
                depth_regions: args.seg_depth_regions.0,
            };
            Some(NetMasks::load(&weights, &objects, &settings)?)
        }
    };
    if let (Some(m), Some(partner)) = (net_masks.as_mut(), &args.seg_partner) {
        m.set_partner(partner, args.seg_partner_weight, &objects)?;
    }
    if let Some(m) = net_masks.as_mut() {
        m.set_instance_separation(fusepose_estimator::duplicates::separations(&objects, args.duplicates));
    }
    let metrics = objects
        .objects
        .iter()
        .map(ObjectMetric::for_model)
        .collect::<Result<Vec<_>, _>>()
        .context("preparing ADD/ADD-S points")?;

    let frames = args.limit.map_or(data.len(), |l| l.min(data.len()));
    let bar = ProgressBar::new(frames as u64);
    bar.set_style(
        ProgressStyle::with_template("{prefix} [{bar:40}] {pos}/{len} frames {elapsed_precise} eta {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    bar.set_prefix(runners.iter().map(|r| r.name.clone()).collect::<Vec<_>>().join(","));
    let mut auto_exposure = args.auto_exposure.0.map(fusepose_estimator::exposure::AutoExposure::new);
    let mut white_balance = args.white_balance.0.map(fusepose_estimator::white_balance::WhiteBalance::new);
    let mut pseudo = match &args.pseudo_labels {
        Some(dir) => {
            Some(pseudo::PseudoLabeller::create(dir, &data.split_dir()?, &objects, args.pseudo_table_patches)?)
        }
        None => None,
    };
    for index in 0..frames {
        let mut frame = data.load(index, objects.len() as u16).with_context(|| format!("loading frame {index}"))?;
        let colour_cast = args.cast.first().copied().unwrap_or(Cast::None);
        colour_cast.apply(&mut frame.rgb, args.seed.wrapping_add(index as u64));
        if let Some(ae) = auto_exposure.as_mut() {
            ae.apply_in_place(&mut frame.rgb);
        }
        if let Some(wb) = white_balance.as_mut() {
            wb.apply_in_place(&mut frame.rgb);
        }
        if let Some(seg) = &mut net_masks {
            seg.segment(&frame).with_context(|| format!("segmenting frame {index}"))?;
        }
        for runner in &mut runners {
            let (labels, seg_engine) = match (runner.masks, net_masks.as_mut()) {
                (MaskSource::Net, Some(seg)) => {
                    let (plane, engine) = seg.plane_and_engine();
                    (plane, Some(engine))
                }
                (MaskSource::GtInstances, _) => {
                    (LabelPlane::Instances { ids: &frame.instances, classes: &frame.instance_classes }, None)
                }
                _ => (LabelPlane::U16(&frame.labels), None),
            };
            runner.evaluate(&frame, labels, seg_engine, args.seed.wrapping_add(index as u64), &metrics)?;
        }
        if let (Some(dir), Some(last)) = (&args.overlay, runners.last()) {
            // The instances the estimator posed, after the second look's cuts.
            let ws = &last.workspace;
            let instances: Vec<(u32, u16)> =
                (0..ws.instances.len()).filter_map(|i| Some((ws.component_id(i)?, ws.instances[i].class_id))).collect();
            let poses: Vec<DrawnPose> = last
                .poses
                .as_slice()
                .iter()
                .map(|p| DrawnPose {
                    class_id: p.class_id,
                    pose: pose_of(p),
                    instance: ws.component_id(p.instance_id as usize),
                })
                .collect();
            // A frame the workspace could not prepare has no regions: its labels then.
            let tint = if ws.component_ids().len() == frame.labels.len() {
                Tint::Instances { ids: ws.component_ids(), instances: &instances }
            } else {
                Tint::Classes(&frame.labels)
            };
            let path = dir.join(format!("{:06}_{:06}.png", frame.scene_id, frame.im_id));
            crate::pose_overlay::write(&path, &frame.intrinsics, &frame.rgb, tint, &poses, &objects)?;
        }
        if let (Some(labeller), Some(seg), Some(last)) = (pseudo.as_mut(), net_masks.as_ref(), runners.last()) {
            labeller.add(&frame, &seg.class_labels, last.poses.as_slice(), &objects)?;
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    if let Some(labeller) = pseudo {
        let dir = labeller.finish()?;
        println!("wrote pseudo-labels to {}", dir.display());
    }
    if let Some(dir) = &args.overlay {
        println!("wrote {frames} overlays to {}", dir.display());
    }

    let name = args.dataset.display().to_string();
    let mut summaries = serde_json::Map::new();
    if let Some(seg) = &net_masks {
        let (median, p99) = (percentile(&seg.ms, 0.5), percentile(&seg.ms, 0.99));
        seg.print(median, p99);
        summaries.insert("segmenter".to_string(), seg.summary(median, p99));
    }
    for runner in &mut runners {
        runner.print(&name, frames);
        summaries.insert(runner.name.clone(), runner.summary());
        if let Some(csv) = runner.csv.take() {
            csv.finish().context("writing BOP results CSV")?;
        }
        if let Some(out) = runner.per_object.take() {
            out.finish().context("writing the per-object CSV")?;
        }
    }
    if let Some(path) = &args.json {
        let json = if summaries.len() == 1 {
            summaries.values().next().cloned().unwrap_or_default()
        } else {
            serde_json::Value::Object(summaries.clone())
        };
        std::fs::write(path, serde_json::to_string_pretty(&json)?)
            .with_context(|| format!("writing {}", path.display()))?;
        println!("wrote {}", path.display());
    }
    if let Some(path) = &args.plot {
        write_plot(&runners, path)?;
        println!("wrote {}", path.display());
    }
    Ok(summaries)
}

/// Visible-fraction buckets of the breakdown: (upper bound, name). BOP's
/// own evaluation leaves objects under 10 % visible out; here they count in
/// every headline number and the breakdown shows what they cost.
const VISIBILITY_BUCKETS: [(f64, &str); 4] =
    [(0.1, "visible < 10 %"), (0.3, "10-30 %"), (0.6, "30-60 %"), (f64::INFINITY, ">= 60 %")];

/// Index in [`VISIBILITY_BUCKETS`] of a visible fraction (NaN counts as fully visible).
fn visibility_bucket(visible: f64) -> usize {
    VISIBILITY_BUCKETS.iter().position(|(below, _)| visible < *below).unwrap_or(VISIBILITY_BUCKETS.len() - 1)
}

/// One estimator under evaluation with its buffers and accumulated results.
struct Runner {
    kind: EstimatorKind,
    masks: MaskSource,
    /// `icp`, or `icp/net-masks` when several mask sources are evaluated.
    name: String,
    estimator: Box<dyn Estimator>,
    workspace: Workspace,
    poses: PoseSet,
    table: MetricsTable,
    /// The same errors by visible fraction of the object ([`VISIBILITY_BUCKETS`]).
    by_visibility: MetricsTable,
    frame_ms: Vec<f64>,
    object_ms: Vec<f64>,
    /// Frames refused by validation, by reason.
    refused: BTreeMap<&'static str, usize>,
    /// Estimates matched to no ground-truth object (ghost objects: a false
    /// instance of the masks, or a second instance of an object).
    unmatched: usize,
    /// Published poses at ADD-S ≥ 0.1 d from every true object of their class
    /// (a grasp at nothing), and how many of them the matching paired with an
    /// object (a pose between two copies) rather than counting as a ghost.
    stray: usize,
    stray_matched: usize,
    /// Each class's diameter (metres), index class − 1.
    diameters: Vec<f64>,
    /// Regions joined into another of their class (`--join-parts`).
    joined: usize,
    /// Instances added by cutting regions (`--split-regions`).
    split: usize,
    /// Instance regions against the ground-truth instance masks.
    instance_counts: instances::InstanceCounts,
    /// Pose verification (`--verify`): the checker, whether failures are dropped,
    /// and what it judged: (ghost poses failing, matched poses failing,
    /// matched poses under 2 cm ADD-S failing, poses checked).
    verifier: Option<Verifier>,
    /// Rank of each pose for duplicate suppression (verification fit, else confidence).
    scores: Vec<f32>,
    /// Per-class minimum centre distance of two poses (`--duplicates`).
    separations: Vec<f32>,
    /// Poses dropped as duplicates.
    duplicates: usize,
    /// `--max-interpenetration`, the object solids, and the poses it dropped.
    max_interpenetration: f32,
    solids: std::sync::Arc<fusepose_estimator::interpenetration::Solids>,
    interpenetrating: usize,
    /// `--max-explained` and the poses it dropped.
    max_explained: f32,
    explained: usize,
    /// `--class-alternates`, the regions that got an alternate class, the
    /// alternates kept, and scratch.
    class_alternates: f32,
    alternates_tried: usize,
    alternates_kept: usize,
    class_means: Vec<f32>,
    /// `--recut`: the second look and the network sibling that estimates its
    /// pieces; regions cut again and cuts kept.
    recut: Option<(fusepose_estimator::recut::Recut, Box<dyn Estimator>)>,
    recut_stats: fusepose_estimator::recut::RecutStats,
    /// `--remask`: second masks for failed poses, with their own network sibling.
    remask: Option<(fusepose_estimator::remask::Remask, Box<dyn Estimator>)>,
    remask_stats: fusepose_estimator::remask::RemaskStats,
    verify_drop: bool,
    verify_counts: [usize; 4],
    /// `--odds-samples`: where each verified pose's terms and label go.
    odds_samples: Option<SampleWriter>,
    verify_ms: Vec<f64>,
    min_confidence: f32,
    csv: Option<BopResultsWriter>,
    per_object: Option<PerObjectWriter<std::io::BufWriter<std::fs::File>>>,
}

/// `--verify-region-quantile`: the segmenter's recorded certainty of real
/// objects at that quantile (without the flag: at the daemon's default
/// quantile, 0 when the file records none); an error when the flag is given
/// and the file records none or the quantile is out of range.
fn region_floor(args: &Args) -> anyhow::Result<f32> {
    if args.verify_region_quantile == Some(0.0) || args.verify == "off" {
        return Ok(0.0);
    }
    let weights = match &args.seg_weights {
        Some(path) => path.clone(),
        None => crate::weights::resolve_weights(args.weights.as_deref())?,
    };
    let file = fusepose_estimator::seg::SegFile::read(&weights)
        .with_context(|| format!("--verify-region-quantile: reading the segmenter in {}", weights.display()))?;
    let Some(q) = args.verify_region_quantile else {
        // The daemon's default: on where the file records the certainty.
        let q = fusepose_estimator::seg::file::DEFAULT_CERTAINTY_QUANTILE;
        return Ok(file.certainty.and_then(|c| c.quantile(q)).unwrap_or(0.0));
    };
    let certainty = file.certainty.with_context(|| {
        format!(
            "--verify-region-quantile: {} records no segmenter certainty; record it with \
             `fusepose train --stage calibrate --objects ... --out {}`",
            weights.display(),
            weights.display()
        )
    })?;
    certainty.quantile(q).with_context(|| format!("--verify-region-quantile {q}: must be in 0.01..=0.5"))
}

/// The weight file's model of a pose's odds (none with verification off);
/// an error when `--verify-min-odds` asks for it and the file has none.
fn pose_odds(args: &Args) -> anyhow::Result<Option<PoseOdds>> {
    if args.verify == "off" {
        return Ok(None);
    }
    let weights = crate::weights::resolve_weights(args.weights.as_deref())?;
    let odds = PoseOdds::read(&weights)?;
    if odds.is_none() && args.verify_min_odds.is_some_and(|p| p > 0.0) {
        anyhow::bail!(
            "--verify-min-odds: {} records no pose odds model; fit one with `fusepose eval --odds-samples S.csv ...` on frames that are neither tuning nor test \
             frames, then `fusepose train --stage odds --odds-samples S.csv --out {}`",
            weights.display(),
            weights.display()
        );
    }
    Ok(odds)
}

/// `--odds-samples`: the file, its header written, shared by every runner.
type SampleWriter = std::sync::Arc<std::sync::Mutex<std::io::BufWriter<std::fs::File>>>;

impl Runner {
    /// `region_floor`: [`region_floor`]'s value, applied when `masks` is the segmenter's.
    #[allow(clippy::too_many_arguments)] // the run's shared parts, borrowed one by one
    fn new(
        kind: EstimatorKind,
        masks: MaskSource,
        several_masks: bool,
        objects: &ObjectSet,
        solids: &std::sync::Arc<fusepose_estimator::interpenetration::Solids>,
        cut_limits: &fusepose_estimator::split::CutLimits,
        region_floor: f32,
        odds: (Option<&PoseOdds>, Option<&SampleWriter>),
        args: &Args,
    ) -> anyhow::Result<Self> {
        let name =
            if several_masks { format!("{}/{}-masks", kind.name(), masks.name()) } else { kind.name().to_string() };
        let num_classes = u16::try_from(objects.len()).context("more than 65535 objects")?;
        // Only the segmenter's own regions are judged on its certainty.
        let region_floor = if masks == MaskSource::Net { region_floor } else { 0.0 };
        let mut recut_parts = None;
        let mut remask_parts = None;
        let (estimator, config): (Box<dyn Estimator>, WorkspaceConfig) = match kind {
            EstimatorKind::Icp => (
                Box::new(IcpEstimator::new(objects, IcpConfig::default())?),
                WorkspaceConfig {
                    max_instances: args.max_instances,
                    support_floor_m: args.support_floor,
                    ..WorkspaceConfig::default()
                },
            ),
            EstimatorKind::Net => {
                let weights = crate::weights::resolve_weights(args.weights.as_deref())?;
                let options = NetOptions { refine_iterations: args.refine_iterations, ..NetOptions::default() };
                let net = NetEstimator::load(&weights, objects, options)
                    .with_context(|| format!("loading {}", weights.display()))?;
                let mut config = net.workspace_config(args.max_instances);
                config.num_points = args.points.unwrap_or(config.num_points);
                config.support_floor_m = args.support_floor;
                let recut_config = fusepose_estimator::recut::RecutConfig {
                    max_coverage: args.recut,
                    min_separation: args.recut_separation,
                    proposal: args.recut_proposal,
                    max_pieces: args.recut_pieces,
                    poses: args.recut_poses,
                    refit: args.recut_refit,
                    refit_by_verdict: args.recut_refit_by_verdict,
                    min_piece_fit: args.recut_min_piece_fit,
                    best_piece: args.recut_best_piece,
                    ..fusepose_estimator::recut::RecutConfig::DEFAULT
                };
                if recut_config.is_on() && args.verify != "off" {
                    let ws_config = WorkspaceConfig { num_classes, ..config };
                    let recut =
                        fusepose_estimator::recut::Recut::new(objects, solids.clone(), ws_config, recut_config)?;
                    recut_parts = Some((recut, Box::new(net.untracked_sibling()) as Box<dyn Estimator>));
                }
                let remask_config = fusepose_estimator::remask::RemaskConfig {
                    max_regions: args.remask,
                    margin_m: args.remask_margin,
                    rounds: args.remask_rounds,
                    min_inlier_fraction: args.remask_min_inliers,
                    max_confidence: args.remask_doubted_below,
                    inlier_slack: args.remask_inlier_slack,
                    confidence_gain: args.remask_confidence_gain,
                };
                anyhow::ensure!(
                    (0.0..=0.1).contains(&args.remask_margin) && (0.0..=1.0).contains(&args.remask_min_inliers),
                    "--remask-margin must be in 0..=0.1 metres and --remask-min-inliers in 0..=1"
                );
                if remask_config.is_on() && args.verify != "off" {
                    let ws_config = WorkspaceConfig { num_classes, ..config };
                    let remask = fusepose_estimator::remask::Remask::new(objects, ws_config, remask_config)?;
                    remask_parts = Some((remask, Box::new(net.untracked_sibling()) as Box<dyn Estimator>));
                }
                (Box::new(net), config)
            }
        };
        let mut workspace = Workspace::new(WorkspaceConfig { num_classes, ..config })?;
        workspace.join_parts(&fusepose_estimator::parts::extents(objects, args.join_parts));
        workspace.support_floors(&fusepose_estimator::support::class_floors(objects, args.support_floor));
        workspace.split_regions(cut_limits);
        let csv = match &args.csv {
            None => None,
            Some(path) => {
                let several = args.compare.len() > 1 || several_masks;
                let path = if several { suffixed(path, &name.replace('/', "_")) } else { path.clone() };
                Some(BopResultsWriter::create(&path).with_context(|| format!("creating {}", path.display()))?)
            }
        };
        let per_object = match &args.per_object_csv {
            None => None,
            Some(path) => {
                let several = args.compare.len() > 1 || several_masks;
                let path = if several { suffixed(path, &name.replace('/', "_")) } else { path.clone() };
                Some(PerObjectWriter::create(&path).with_context(|| format!("creating {}", path.display()))?)
            }
        };
        Ok(Self {
            kind,
            masks,
            name,
            estimator,
            // Room for each instance's class alternate.
            poses: PoseSet::with_capacity(2 * config.max_instances),
            workspace,
            table: MetricsTable::for_objects(objects),
            by_visibility: MetricsTable::new(
                VISIBILITY_BUCKETS.iter().enumerate().map(|(i, (_, name))| (i as u16 + 1, (*name).to_owned())),
            ),
            frame_ms: Vec::new(),
            object_ms: Vec::new(),
            refused: BTreeMap::new(),
            unmatched: 0,
            stray: 0,
            stray_matched: 0,
            diameters: objects.objects.iter().map(|o| o.diameter).collect(),
            joined: 0,
            split: 0,
            instance_counts: instances::InstanceCounts::default(),
            verifier: (args.verify != "off").then(|| {
                let d = VerifyConfig::default();
                let min_region = args.verify_min_region_probability.unwrap_or(d.min_region_probability);
                let mut verifier = Verifier::new(
                    objects,
                    VerifyConfig {
                        min_fit: args.verify_min_fit.unwrap_or(d.min_fit),
                        min_inlier_fraction: args.verify_min_inliers.unwrap_or(d.min_inlier_fraction),
                        min_depth_support: args.verify_min_depth_support.unwrap_or(d.min_depth_support),
                        max_plane_continuation: args.verify_max_plane_continuation.unwrap_or(d.max_plane_continuation),
                        max_depth_continuity: args.verify_max_depth_continuity.unwrap_or(d.max_depth_continuity),
                        min_thin_mask_agreement: args
                            .verify_min_thin_mask_agreement
                            .unwrap_or(d.min_thin_mask_agreement),
                        min_mask_agreement: args.verify_min_mask_agreement.unwrap_or(d.min_mask_agreement),
                        facing: match args.verify_facing.as_str() {
                            "off-plane" => FacingWeights::OffPlane,
                            "all" => FacingWeights::All,
                            _ => FacingWeights::None,
                        },
                        agreeing_mask_agreement: args
                            .verify_agreeing_mask_agreement
                            .unwrap_or(d.agreeing_mask_agreement),
                        agreeing_min_inlier_fraction: args
                            .verify_agreeing_min_inliers
                            .unwrap_or(d.agreeing_min_inlier_fraction),
                        agreeing_min_fit: args.verify_agreeing_min_fit.unwrap_or(d.agreeing_min_fit),
                        min_region_probability: min_region.max(region_floor),
                        trim_table_share: args.verify_trim_table_share.unwrap_or(d.trim_table_share),
                        max_below_support: args.verify_max_below_support.unwrap_or(d.max_below_support),
                        below_support_m: args.verify_below_support_depth.unwrap_or(d.below_support_m),
                        min_region_area_share: args.verify_min_area_share.unwrap_or(d.min_region_area_share),
                        min_odds: args.verify_min_odds.unwrap_or(d.min_odds),
                        ..d
                    },
                );
                verifier.set_odds(odds.0.cloned());
                verifier
            }),
            odds_samples: odds.1.cloned(),
            verify_drop: args.verify == "drop",
            scores: Vec::new(),
            separations: fusepose_estimator::duplicates::separations(objects, args.duplicates),
            duplicates: 0,
            max_interpenetration: args.max_interpenetration,
            solids: solids.clone(),
            interpenetrating: 0,
            max_explained: args.max_explained,
            explained: 0,
            class_alternates: args.class_alternates,
            alternates_tried: 0,
            alternates_kept: 0,
            class_means: Vec::new(),
            recut: recut_parts,
            recut_stats: Default::default(),
            remask: remask_parts,
            remask_stats: Default::default(),
            verify_counts: [0; 4],
            verify_ms: Vec::new(),
            min_confidence: args.min_confidence,
            csv,
            per_object,
        })
    }

    /// Estimates `frame` with instance masks from `labels` and scores it.
    fn evaluate(
        &mut self,
        frame: &EvalFrame,
        labels: LabelPlane<'_>,
        seg: Option<&mut SegEngine>,
        seed: u64,
        metrics: &[ObjectMetric],
    ) -> anyhow::Result<()> {
        let view = FrameView {
            intrinsics: frame.intrinsics,
            color_format: ColorFormat::Rgb8,
            color: &frame.rgb,
            depth: DepthPlane::U16 { data: &frame.depth, scale: frame.depth_unit_m as f32 },
            labels: Some(labels),
        };
        let start = Instant::now();
        let prepared = self.workspace.prepare(&view, seed);
        let prepared_ok = prepared.is_ok();
        self.joined += self.workspace.stats().joined_parts as usize;
        self.split += self.workspace.stats().split_regions as usize;
        if let (true, Some(seg), Some(_)) = (prepared_ok && self.class_alternates > 0.0, seg.as_deref(), &self.verifier)
        {
            self.alternates_tried +=
                alternates::mark(&mut self.workspace, seg, self.class_alternates, &mut self.class_means);
        }
        let estimated = match prepared {
            Ok(_) => self.estimator.estimate(&view, &mut self.workspace, &mut self.poses).map(|_| ()),
            Err(e) => Err(e.into()),
        };
        self.poses.retain_confident(self.min_confidence);
        let seconds = start.elapsed().as_secs_f64();
        if estimated.is_ok() {
            self.verify(&view, frame, seg, metrics, seed);
            self.suppress_explained(&view);
            self.suppress_duplicates();
            self.suppress_interpenetrating();
        }
        // After the second look, which may cut a region in two.
        if prepared_ok && frame.instances.iter().any(|&i| i != 0) {
            let ids: Vec<u32> =
                (0..self.workspace.instances.len()).filter_map(|i| self.workspace.component_id(i)).collect();
            self.instance_counts.add_frame(&frame.instances, self.workspace.component_ids(), &ids);
        }
        if let Err(e) = estimated {
            let reason = match &e {
                fusepose_estimator::EstimateError::Frame(f) => f.reason(),
                _ => "estimate_error",
            };
            *self.refused.entry(reason).or_default() += 1;
            tracing::warn!("frame {}/{}: {e}", frame.scene_id, frame.im_id);
            self.poses.clear();
        }
        self.frame_ms.push(seconds * 1e3);
        if !self.poses.is_empty() {
            let per_object = seconds * 1e3 / self.poses.len() as f64;
            self.object_ms.extend(std::iter::repeat_n(per_object, self.poses.len()));
        }
        let pairs = match_estimates(&frame.gt, self.poses.as_slice());
        self.unmatched += self.poses.len() - pairs.iter().filter(|(_, e)| e.is_some()).count();
        for p in self.poses.as_slice() {
            if nearest_error(&frame.gt, p, metrics, &self.diameters) >= STRAY_ERROR {
                self.stray += 1;
                self.stray_matched += pairs.iter().any(|(_, e)| e.is_some_and(|e| std::ptr::eq(e, p))) as usize;
            }
        }
        if std::env::var_os("FUSEPOSE_MISS_TRACE").is_some() {
            let ws = &self.workspace;
            let comp_of: Vec<(u32, usize)> =
                (0..ws.instances.len()).filter_map(|i| ws.component_id(i).map(|c| (c, i))).collect();
            for (k, g) in frame.gt.iter().enumerate() {
                let est = pairs.iter().find(|(t, _)| std::ptr::eq(*t, g)).and_then(|(_, e)| *e);
                let add_s = est
                    .zip(metrics.get(g.class_id as usize - 1))
                    .map(|(e, m)| m.errors(&pose_of(e), &g.pose).add_s)
                    .unwrap_or(-1.0);
                let d = self.diameters.get(g.class_id as usize - 1).copied().unwrap_or(0.1);
                if est.is_some() && add_s < 0.1 * d {
                    continue;
                }
                // Pixels of this true instance: background / region with a posed instance (same, other class) / region unposed.
                let (mut px, mut bg, mut same_posed, mut other_posed, mut same_unposed, mut other_unposed) =
                    (0, 0, 0, 0, 0, 0);
                for (&t, &c) in frame.instances.iter().zip(ws.component_ids()) {
                    if t as usize != k + 1 {
                        continue;
                    }
                    px += 1;
                    let Some(&(_, i)) = comp_of.iter().find(|(cc, _)| *cc == c && c != 0) else {
                        bg += 1;
                        continue;
                    };
                    let class = ws.instances[i].class_id;
                    let posed = self.poses.as_slice().iter().any(|p| p.instance_id as usize == i);
                    match (class == g.class_id, posed) {
                        (true, true) => same_posed += 1,
                        (false, true) => other_posed += 1,
                        (true, false) => same_unposed += 1,
                        (false, false) => other_unposed += 1,
                    }
                }
                eprintln!(
                    "MTRACE frame {}/{} class {} vis {:.2} px {px} est {} add_s {add_s:.4} bg {bg} same_posed {same_posed} other_posed {other_posed} same_unposed {same_unposed} other_unposed {other_unposed}",
                    frame.scene_id,
                    frame.im_id,
                    g.class_id,
                    g.visible.unwrap_or(-1.0),
                    est.is_some() as u8
                );
            }
        }
        for &(gt, est) in &pairs {
            let errors = est.zip(metrics.get(gt.class_id as usize - 1)).map(|(e, m)| m.errors(&pose_of(e), &gt.pose));
            self.table.record(gt.class_id, errors);
            if let Some(v) = gt.visible {
                self.by_visibility.record(visibility_bucket(v) as u16 + 1, errors);
            }
            if let Some(out) = &mut self.per_object {
                out.write((frame.scene_id, frame.im_id), Some(gt), est, errors)?;
            }
        }
        if let Some(out) = &mut self.per_object {
            let poses = self.poses.as_slice();
            for (i, p) in poses.iter().enumerate() {
                if !pairs.iter().any(|(_, e)| e.is_some_and(|e| std::ptr::eq(e, &poses[i]))) {
                    out.write((frame.scene_id, frame.im_id), None, Some(p), None)?;
                }
            }
        }
        if let Some(csv) = &mut self.csv {
            for p in self.poses.as_slice() {
                csv.write(&BopResult {
                    scene_id: frame.scene_id,
                    im_id: frame.im_id,
                    obj_id: p.class_id,
                    score: p.confidence as f64,
                    pose: pose_of(p),
                    time_s: seconds,
                })?;
            }
        }
        Ok(())
    }

    /// Verifies every pose against the frame's depth, counts what fails
    /// (ghosts vs poses of real objects, judged by matching before the drop)
    /// and, with `--verify drop`, removes the failures.
    fn verify(
        &mut self,
        view: &FrameView<'_>,
        frame: &EvalFrame,
        seg: Option<&mut SegEngine>,
        metrics: &[ObjectMetric],
        seed: u64,
    ) {
        let Some(verifier) = self.verifier.as_mut() else { return };
        let start = Instant::now();
        let ws = &self.workspace;
        let min_region_probability = verifier.config().min_region_probability;
        let trace = std::env::var_os("FUSEPOSE_VERIFY_TRACE").is_some();
        // The segmenter's certainty is read only when judged or traced.
        let mut seg = seg.filter(|_| min_region_probability > 0.0 || trace || verifier.has_odds());
        let seg_ref = seg.as_deref();
        let mut verdicts: Vec<Option<fusepose_estimator::verify::Verification>> = self
            .poses
            .as_slice()
            .iter()
            // Only the built-in segmenter's regions carry a class probability.
            .map(|p| fusepose_estimator::verify::verify_on_region(verifier, view, ws, seg_ref, p))
            .collect();
        let mut passed: Vec<bool> = verdicts.iter().map(|v| v.is_some_and(|v| v.passed)).collect();
        // Of a region estimated as two classes, the better-verified pose stays (as the daemon).
        let mut marks = Vec::new();
        let key = |i: usize| verdicts[i].map_or((false, f32::NAN), |v| v.class_score());
        let lost = alternates::losers(self.poses.as_slice(), key, &mut marks);
        if lost > 0 {
            self.poses.remove_marked(&marks);
            fusepose_estimator::poses::remove_marked(&mut verdicts, &marks);
            fusepose_estimator::poses::remove_marked(&mut passed, &marks);
        }
        // For the trace: the poses before the second look (a pose not among them is a cut's piece).
        let before: Vec<[f64; 3]> =
            if trace { self.poses.as_slice().iter().map(|p| p.translation.into()).collect() } else { Vec::new() };
        if let Some((recut, net)) = self.recut.as_mut() {
            // The second look needs a verdict per pose; a pose without a region has none to cut.
            let mut all: Vec<fusepose_estimator::verify::Verification> = verdicts
                .iter()
                .map(|v| {
                    v.unwrap_or(fusepose_estimator::verify::Verification {
                        mask_coverage: f32::NAN,
                        ..Default::default()
                    })
                })
                .collect();
            let verifier = self.verifier.as_mut().expect("recut runs only with verification");
            match recut.run(
                view,
                &mut self.workspace,
                &mut self.poses,
                &mut all,
                net.as_mut(),
                verifier,
                seg.as_deref_mut(),
                seed,
            ) {
                Ok(s) => {
                    self.recut_stats += s;
                    if s.kept > 0 || s.replaced > 0 {
                        verdicts = all.into_iter().map(Some).collect();
                        passed = verdicts.iter().map(|v| v.is_some_and(|v| v.passed)).collect();
                    }
                }
                Err(e) => tracing::warn!("frame {}/{}: second look: {e}", frame.scene_id, frame.im_id),
            }
        }
        // For the trace: the poses before the second masks (one not among them was replaced).
        let before_remask: Vec<[f64; 3]> =
            if trace { self.poses.as_slice().iter().map(|p| p.translation.into()).collect() } else { Vec::new() };
        if let Some((remask, net)) = self.remask.as_mut() {
            let mut all: Vec<fusepose_estimator::verify::Verification> =
                verdicts.iter().map(|v| v.unwrap_or_default()).collect();
            let verifier = self.verifier.as_mut().expect("remask runs only with verification");
            match remask.run(
                view,
                &self.workspace,
                &mut self.poses,
                &mut all,
                net.as_mut(),
                verifier,
                seg.as_deref(),
                seed,
            ) {
                Ok(s) => {
                    self.remask_stats += s;
                    if s.kept > 0 {
                        for (v, a) in verdicts.iter_mut().zip(&all) {
                            if v.is_some() {
                                *v = Some(*a);
                            }
                        }
                        passed = verdicts.iter().map(|v| v.is_some_and(|v| v.passed)).collect();
                    }
                }
                Err(e) => tracing::warn!("frame {}/{}: second mask: {e}", frame.scene_id, frame.im_id),
            }
        }
        let instances = &self.workspace.instances;
        self.alternates_kept += self.poses.as_slice().iter().filter(|p| alternates::is_alternate(instances, p)).count();
        if let Some(out) = &self.odds_samples {
            write_odds_samples(out, frame, self.poses.as_slice(), &verdicts, metrics, &self.diameters);
        }
        if trace {
            let pairs = match_estimates(&frame.gt, self.poses.as_slice());
            for (p, v) in self.poses.as_slice().iter().zip(&verdicts) {
                let add_s = pairs.iter().find(|(_, e)| e.is_some_and(|e| std::ptr::eq(e, p))).and_then(|(gt, _)| {
                    metrics.get(gt.class_id as usize - 1).map(|m| m.errors(&pose_of(p), &gt.pose).add_s)
                });
                if let Some(v) = v {
                    let ws = &self.workspace;
                    // What the region truly covers: the most frequent true class under it (0 = no object).
                    let mut under = vec![0usize; metrics.len() + 1];
                    if let Some(id) = ws.component_id(p.instance_id as usize) {
                        for (&c, &l) in ws.component_ids().iter().zip(&frame.labels) {
                            if c == id {
                                under[(l as usize).min(metrics.len())] += 1;
                            }
                        }
                    }
                    let (under_class, _) = under.iter().enumerate().max_by_key(|&(_, n)| *n).unwrap_or((0, &0));
                    // True instances holding at least a tenth of the region.
                    let mut inside = std::collections::HashMap::<u16, usize>::new();
                    if let Some(id) = ws.component_id(p.instance_id as usize) {
                        for (&c, &t) in ws.component_ids().iter().zip(&frame.instances) {
                            if c == id && t != 0 {
                                *inside.entry(t).or_default() += 1;
                            }
                        }
                    }
                    let total: usize = inside.values().sum();
                    let copies = inside.values().filter(|&&n| n * 10 >= total.max(1)).count();
                    let sprob = v.region_probability;
                    let near = nearest_error(&frame.gt, p, metrics, &self.diameters);
                    // 1: a cut's piece, 2: a pose of a second mask.
                    let piece = if !before_remask.contains(&p.translation.into()) {
                        2
                    } else {
                        !before.contains(&p.translation.into()) as u8
                    };
                    eprintln!(
                        "VTRACE frame {}/{} class {} under {} copies {copies} px {} z {:.3} add_s {} near {near:.3} below {:.3} piece {piece} in {:.3} cov {:.3} beh {:.3} off {:.3} sup {:.3} cont {:.3} dcont {:.3} magree {:.3} fit {:.3} res {:.4} sprob {:.3} conf {:.3} area {:.4} odds {:.3} pass {}",
                        frame.scene_id,
                        frame.im_id,
                        p.class_id,
                        under_class,
                        p.mask_pixels,
                        p.translation.z,
                        add_s.map_or(-1.0, |a| a),
                        v.below_support,
                        v.inlier_fraction,
                        v.mask_coverage,
                        v.behind_fraction,
                        v.off_plane,
                        v.depth_support,
                        v.plane_continuation,
                        v.depth_continuity,
                        v.mask_agreement,
                        v.fit,
                        v.depth_residual_m,
                        sprob,
                        p.confidence,
                        v.region_area_share,
                        v.odds,
                        v.passed as u8
                    );
                }
            }
        }
        self.verify_ms.push(start.elapsed().as_secs_f64() * 1e3 / passed.len().max(1) as f64);
        let poses = self.poses.as_slice();
        let pairs = match_estimates(&frame.gt, poses);
        for (i, p) in poses.iter().enumerate() {
            self.verify_counts[3] += 1;
            if passed[i] {
                continue;
            }
            match pairs.iter().find(|(_, e)| e.is_some_and(|e| std::ptr::eq(e, p))) {
                None => self.verify_counts[0] += 1,
                Some((gt, _)) => {
                    self.verify_counts[1] += 1;
                    let good = metrics
                        .get(gt.class_id as usize - 1)
                        .map(|m| m.errors(&pose_of(p), &gt.pose))
                        .is_some_and(|e| e.add_s < 0.02);
                    self.verify_counts[2] += good as usize;
                }
            }
        }
        self.scores.clear();
        self.scores.extend(verdicts.iter().map(|v| v.map_or(f32::NAN, |v| v.fit)));
        if self.verify_drop {
            let mut it = passed.iter();
            self.poses.retain(|_| it.next().copied().unwrap_or(false));
            let mut it = passed.iter();
            self.scores.retain(|_| it.next().copied().unwrap_or(false));
        }
    }

    /// Drops duplicate poses ([`fusepose_estimator::duplicates`]), ranked by
    /// the verification fit when verifying, else by confidence.
    fn suppress_duplicates(&mut self) {
        if self.verifier.is_none() {
            self.scores.clear();
            self.scores.extend(self.poses.as_slice().iter().map(|p| p.confidence));
        }
        let mut dropped = Vec::new();
        self.duplicates +=
            fusepose_estimator::duplicates::suppress(&mut self.poses, &self.separations, &self.scores, &mut dropped);
        fusepose_estimator::poses::remove_marked(&mut self.scores, &dropped);
    }

    /// Drops the pose whose region another pose explains
    /// ([`fusepose_estimator::explained`]), as the daemon.
    fn suppress_explained(&mut self, view: &FrameView<'_>) {
        let Some(verifier) = self.verifier.as_mut() else { return };
        let ws = &self.workspace;
        let mask_of = |p: &ObjectPose| ws.component_id(p.instance_id as usize).map(|id| ws.mask_ref(id, p.bbox));
        let mut dropped = Vec::new();
        self.explained += fusepose_estimator::explained::suppress(
            verifier,
            view,
            mask_of,
            &mut self.poses,
            self.max_explained,
            &self.scores,
            &mut dropped,
        );
        fusepose_estimator::poses::remove_marked(&mut self.scores, &dropped);
    }

    /// Drops the pose more inside another ([`fusepose_estimator::interpenetration`]), as the daemon.
    fn suppress_interpenetrating(&mut self) {
        let mut dropped = Vec::new();
        self.interpenetrating +=
            self.solids.suppress(&mut self.poses, self.max_interpenetration, &self.scores, &mut dropped);
        fusepose_estimator::poses::remove_marked(&mut self.scores, &dropped);
    }

    fn print(&self, dataset: &str, frames: usize) {
        println!("\n{} on {dataset}: {frames} frames, {} ground-truth objects", self.name, self.table.overall().count);
        print!("{}", self.table);
        let (fm, fp) = (percentile(&self.frame_ms, 0.5), percentile(&self.frame_ms, 0.99));
        let (om, op) = (percentile(&self.object_ms, 0.5), percentile(&self.object_ms, 0.99));
        println!("time per frame: median {fm:.2} ms, p99 {fp:.2} ms; per object: median {om:.2} ms, p99 {op:.2} ms");
        println!(
            "estimates matched to no object: {} ({:.2} per frame)",
            self.unmatched,
            self.unmatched as f64 / self.frame_ms.len().max(1) as f64
        );
        println!(
            "stray poses (ADD-S >= {STRAY_ERROR} d from every object of their class): {} ({:.2} per frame), {} of them matched to an object",
            self.stray,
            self.stray as f64 / self.frame_ms.len().max(1) as f64,
            self.stray_matched
        );
        let buckets: Vec<String> = self
            .by_visibility
            .rows()
            .iter()
            .filter(|r| r.count > 0)
            .map(|r| format!("{} {:.2} / {:.2} (n={})", r.name, r.add_s_auc, r.add_s_auc_symmetric_aware, r.count))
            .collect();
        if !buckets.is_empty() {
            println!("ADD-S / ADD(S) AUC by visible fraction: {}", buckets.join("; "));
        }
        if self.joined > 0 {
            println!("regions joined as pieces of one object: {}", self.joined);
            println!("poses dropped as duplicates: {}", self.duplicates);
        }
        println!("poses dropped inside another: {}", self.interpenetrating);
        println!("poses dropped as explained by another: {}", self.explained);
        if self.class_alternates > 0.0 {
            println!(
                "class alternates (runner-up probability >= {}): {} regions estimated as a second class, {} kept as it",
                self.class_alternates, self.alternates_tried, self.alternates_kept
            );
        }
        if self.recut.is_some() {
            let fusepose_estimator::recut::RecutStats { tried, kept, by_votes, by_contacts, refused, replaced, .. } =
                self.recut_stats;
            let [unverified, close, explained, overlap] = refused;
            println!(
                "regions looked at again (pose coverage below the recut limit): {tried} cut ({by_votes} along centre votes, {by_contacts} along contacts), {kept} kept (as two or more copies); \
                 refused: {unverified} a piece's pose failed, {close} poses too close, {explained} one pose explains both, {overlap} solids overlap; {replaced} refused regions took their best piece's pose"
            );
        }
        if self.remask.is_some() {
            let fusepose_estimator::remask::RemaskStats { tried, kept, doubted_tried, doubted_kept, estimates } =
                self.remask_stats;
            println!(
                "failed poses given a second mask: {tried}, {kept} of them passed with it; passed poses doubted: {doubted_tried}, {doubted_kept} replaced ({estimates} estimates)"
            );
        }
        if self.instance_counts.truth > 0 {
            println!("{}", self.instance_counts.summary());
        }
        if let Some(v) = &self.verifier {
            let [ghosts, real, good, all] = self.verify_counts;
            println!(
                "verification ({}): {all} poses checked, {} failed: {ghosts} ghosts, {real} of real objects ({good} of them under 2 cm ADD-S); {:.3} ms per object (median); segmenter certainty floor {:.3}",
                if self.verify_drop { "failures dropped" } else { "flag only" },
                ghosts + real,
                percentile(&self.verify_ms, 0.5),
                v.config().min_region_probability
            );
        }
        if !self.refused.is_empty() {
            println!("frames refused: {:?}", self.refused);
        }
    }

    /// `{"overall": {...}, "per_object": {name: {...}}}`.
    fn summary(&self) -> serde_json::Value {
        let row = |r: &MetricsRow| {
            serde_json::json!({
                "add_s_auc": r.add_s_auc,
                "add_s_auc_symmetric_aware": r.add_s_auc_symmetric_aware,
                "add_s_lt_2cm": r.add_s_lt_2cm,
                "count": r.count,
            })
        };
        let mut overall = row(&self.table.overall());
        if let Some(o) = overall.as_object_mut() {
            o.insert("ms_per_frame_median".into(), percentile(&self.frame_ms, 0.5).into());
            o.insert("ms_per_frame_p99".into(), percentile(&self.frame_ms, 0.99).into());
            o.insert("ms_per_object_median".into(), percentile(&self.object_ms, 0.5).into());
            o.insert("ms_per_object_p99".into(), percentile(&self.object_ms, 0.99).into());
            o.insert("frames".into(), self.frame_ms.len().into());
            o.insert("frames_refused".into(), self.refused.values().sum::<usize>().into());
            o.insert("unmatched_estimates".into(), self.unmatched.into());
            o.insert("stray_poses".into(), self.stray.into());
            o.insert("stray_poses_matched".into(), self.stray_matched.into());
            o.insert("joined_parts".into(), self.joined.into());
            o.insert("split_regions".into(), self.split.into());
            o.insert("duplicates_dropped".into(), self.duplicates.into());
            o.insert("interpenetrating_dropped".into(), self.interpenetrating.into());
            if self.instance_counts.truth > 0 {
                o.insert("instances".into(), self.instance_counts.json());
            }
            if self.verifier.is_some() {
                let [ghosts, real, good, all] = self.verify_counts;
                o.insert(
                    "verification".into(),
                    serde_json::json!({
                        "mode": if self.verify_drop { "drop" } else { "flag" },
                        "checked": all, "failed_ghosts": ghosts, "failed_real": real,
                        "failed_real_under_2cm": good, "ms_per_object_median": percentile(&self.verify_ms, 0.5),
                    }),
                );
            }
        }
        let per_object: serde_json::Map<String, serde_json::Value> =
            self.table.rows().iter().map(|r| (r.name.clone(), row(r))).collect();
        let by_visibility: serde_json::Map<String, serde_json::Value> =
            self.by_visibility.rows().iter().filter(|r| r.count > 0).map(|r| (r.name.clone(), row(r))).collect();
        serde_json::json!({
            "estimator": self.kind.name(),
            "masks": self.masks.name(),
            "overall": overall,
            "per_object": per_object,
            "by_visibility": by_visibility,
        })
    }
}

/// A pose this far from every true object of its class (ADD-S / diameter) is
/// counted as stray: the "found" threshold of the pose-estimation literature.
const STRAY_ERROR: f64 = 0.1;

/// ADD-S / diameter from `p` to the nearest true object of its class
/// (infinite when the frame holds none).
fn nearest_error(gt: &[GtObject], p: &ObjectPose, metrics: &[ObjectMetric], diameters: &[f64]) -> f64 {
    let k = p.class_id as usize - 1;
    let (Some(m), Some(&d)) = (metrics.get(k), diameters.get(k)) else { return f64::INFINITY };
    gt.iter()
        .filter(|g| g.class_id == p.class_id)
        .map(|g| m.add_s(&pose_of(p), &g.pose) / d)
        .fold(f64::INFINITY, f64::min)
}

/// `--odds-samples`: one line per verified pose of the frame, labelled as
/// [`fusepose_estimator::pose_odds`] says (wrong: matched to no object, or
/// 0.1 diameters ADD-S or more from every object of its class; right: else
/// within 2 cm ADD-S of its object; poses in between are left out).
fn write_odds_samples(
    out: &SampleWriter,
    frame: &EvalFrame,
    poses: &[ObjectPose],
    verdicts: &[Option<fusepose_estimator::verify::Verification>],
    metrics: &[ObjectMetric],
    diameters: &[f64],
) {
    use std::io::Write;
    let pairs = match_estimates(&frame.gt, poses);
    let Ok(mut w) = out.lock() else { return };
    for (p, v) in poses.iter().zip(verdicts) {
        let Some(v) = v else { continue };
        let matched = pairs.iter().find(|(_, e)| e.is_some_and(|e| std::ptr::eq(e, p)));
        let add_s = matched
            .and_then(|(gt, _)| metrics.get(gt.class_id as usize - 1).map(|m| m.errors(&pose_of(p), &gt.pose).add_s));
        let right = match add_s {
            None => false,
            Some(_) if nearest_error(&frame.gt, p, metrics, diameters) >= 0.1 => false,
            Some(a) if a < 0.02 => true,
            Some(_) => continue,
        };
        let x = fusepose_estimator::pose_odds::features(v, p);
        if let Err(e) = writeln!(w, "{}", fusepose_estimator::pose_odds::sample_line(&x, right)) {
            tracing::warn!("--odds-samples: {e}");
            return;
        }
    }
}

/// Pairs each ground-truth object with an estimate of its class, or `None`:
/// closest pairs first (by translation distance; each estimate and each object
/// used once), so the result does not depend on the order the objects are
/// listed in. Taking the objects in list order instead let an object whose
/// own estimate was far off take a touching copy's good estimate, leaving
/// that copy the far one.
fn match_estimates<'a>(gt: &'a [GtObject], poses: &'a [ObjectPose]) -> Vec<(&'a GtObject, Option<&'a ObjectPose>)> {
    let mut candidates: Vec<(f64, usize, usize)> = gt
        .iter()
        .enumerate()
        .flat_map(|(g, o)| {
            poses
                .iter()
                .enumerate()
                .filter(move |(_, p)| p.class_id == o.class_id)
                .map(move |(e, p)| ((p.translation - o.pose.translation.vector).norm(), g, e))
        })
        .collect();
    candidates.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
    let mut of_gt: Vec<Option<usize>> = vec![None; gt.len()];
    let mut used = vec![false; poses.len()];
    for (_, g, e) in candidates {
        if of_gt[g].is_none() && !used[e] {
            of_gt[g] = Some(e);
            used[e] = true;
        }
    }
    gt.iter().zip(of_gt).map(|(g, e)| (g, e.map(|i| &poses[i]))).collect()
}

fn pose_of(p: &ObjectPose) -> Pose {
    Pose::from_parts(p.translation.into(), p.rotation)
}

/// The `q`-quantile (nearest rank) of `values`; NaN when empty.
fn percentile(values: &[f64], q: f64) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let rank = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len());
    v[rank - 1]
}

/// `dir/stem_suffix.ext` for `dir/stem.ext`.
fn suffixed(path: &Path, suffix: &str) -> PathBuf {
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let ext = path.extension().map(|e| format!(".{}", e.to_string_lossy())).unwrap_or_default();
    path.with_file_name(format!("{stem}_{suffix}{ext}"))
}

/// One estimator: a curve per object plus `ALL`; several: `ALL` per estimator.
fn write_plot(runners: &[Runner], path: &Path) -> anyhow::Result<()> {
    let mut curves: Vec<(String, Vec<f64>)> = Vec::new();
    for r in runners {
        let all: Vec<f64> = r.table.add_s_curves().into_iter().flat_map(|(_, e)| e).collect();
        if runners.len() == 1 {
            curves.extend(r.table.add_s_curves().into_iter().filter(|(_, e)| !e.is_empty()));
            curves.push(("ALL".to_string(), all));
        } else {
            curves.push((format!("{} ALL", r.name), all));
        }
    }
    let borrowed: Vec<(&str, Vec<f64>)> = curves.iter().map(|(n, e)| (n.as_str(), e.clone())).collect();
    plot_accuracy_curves(&borrowed, path).with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An estimate of `class_id` at x metres (pose built from scene's `Pose`,
    /// the CLI does not depend on nalgebra).
    fn at(class_id: u16, x: f64) -> ObjectPose {
        let p = Pose::translation(x, 0.0, 0.5);
        ObjectPose {
            class_id,
            instance_id: 0,
            rotation: p.rotation,
            translation: p.translation.vector,
            confidence: 1.0,
            mask_pixels: 100,
            bbox: [0; 4],
            iterations: 1,
        }
    }

    #[test]
    fn visibility_buckets_split_at_10_30_60_percent() {
        let b: Vec<usize> = [0.0, 0.099, 0.1, 0.29, 0.3, 0.59, 0.6, 1.0, f64::NAN].map(visibility_bucket).to_vec();
        assert_eq!(b, [0, 0, 1, 1, 2, 2, 3, 3, 3]);
    }

    #[test]
    fn matching_pairs_by_class_and_distance_and_reports_misses() {
        let gt = vec![
            GtObject { class_id: 1, pose: Pose::translation(0.1, 0.0, 0.5), visible: None },
            GtObject { class_id: 1, pose: Pose::translation(-0.1, 0.0, 0.5), visible: None },
            GtObject { class_id: 2, pose: Pose::translation(0.0, 0.0, 0.5), visible: None },
        ];
        let poses = vec![at(1, -0.09), at(1, 0.11)];
        let m = match_estimates(&gt, &poses);
        assert_eq!(m[0].1.map(|p| p.translation.x), Some(0.11));
        assert_eq!(m[1].1.map(|p| p.translation.x), Some(-0.09));
        assert!(m[2].1.is_none(), "class 2 has no estimate: a miss");
    }

    #[test]
    fn matching_takes_the_closest_pairs_first_whatever_the_listing_order() {
        // Two touching copies 0.1 m apart: the second copy's estimate is 1 cm
        // off, the first copy's 0.25 m off (on the far side). Taken in list
        // order, the first copy would grab the second's estimate (0.09 m from
        // it) and leave the second copy the far one.
        let gt = [
            GtObject { class_id: 1, pose: Pose::translation(0.0, 0.0, 0.5), visible: None },
            GtObject { class_id: 1, pose: Pose::translation(0.1, 0.0, 0.5), visible: None },
        ];
        let poses = [at(1, -0.25), at(1, 0.09)];
        for order in [[0, 1], [1, 0]] {
            let listed: Vec<GtObject> = order.iter().map(|&i| gt[i].clone()).collect();
            let m = match_estimates(&listed, &poses);
            for (g, e) in m {
                let want = if g.pose.translation.vector.x > 0.05 { 0.09 } else { -0.25 };
                assert_eq!(e.map(|p| p.translation.x), Some(want), "copy at x = {}", g.pose.translation.vector.x);
            }
        }
    }

    #[test]
    fn a_pose_is_stray_beyond_a_tenth_of_the_diameter_from_every_copy() {
        // A cross of four points 0.1 m across; two copies 0.2 m apart.
        let points =
            [(0.05, 0.0), (-0.05, 0.0), (0.0, 0.05), (0.0, -0.05)].map(|(x, y)| nalgebra::Point3::new(x, y, 0.0));
        let metrics = [ObjectMetric::new(&points, false).unwrap()];
        let gt = [-0.1, 0.1].map(|x| GtObject { class_id: 1, pose: Pose::translation(x, 0.0, 0.5), visible: None });
        let near = |x: f64| nearest_error(&gt, &at(1, x), &metrics, &[0.1]);
        // 9 mm from the second copy (every point 9 mm off): found.
        assert!((near(0.109) - 0.09).abs() < 1e-9, "{}", near(0.109));
        assert!(near(0.109) < STRAY_ERROR && near(-0.091) < STRAY_ERROR);
        // 11 mm off, or midway between the copies: stray.
        assert!(near(0.111) >= STRAY_ERROR && near(0.0) >= STRAY_ERROR, "{} {}", near(0.111), near(0.0));
        // A class the frame does not hold.
        assert_eq!(nearest_error(&gt, &at(2, 0.1), &metrics, &[0.1, 0.1]), f64::INFINITY);
    }

    #[test]
    fn percentiles_use_nearest_rank() {
        let v: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!(percentile(&v, 0.5), 50.0);
        assert_eq!(percentile(&v, 0.99), 99.0);
        assert!(percentile(&[], 0.5).is_nan());
    }

    #[test]
    fn compare_csv_names_get_the_estimator_suffix() {
        assert_eq!(suffixed(Path::new("out/res.csv"), "icp"), PathBuf::from("out/res_icp.csv"));
    }
}

/// `--auto-exposure`: `off`, `on` or the stage's parameter string.
#[derive(Clone, Copy, Debug)]
pub struct ExposureArg(pub Option<fusepose_estimator::exposure::ExposureConfig>);

impl std::str::FromStr for ExposureArg {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        fusepose_estimator::exposure::ExposureConfig::parse_setting(s).map(Self)
    }
}

/// `--white-balance`: `off`, `on` or settings.
#[derive(Clone, Copy, Debug)]
pub struct WhiteBalanceArg(pub Option<fusepose_estimator::white_balance::WhiteBalanceConfig>);

impl std::str::FromStr for WhiteBalanceArg {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        fusepose_estimator::white_balance::WhiteBalanceConfig::parse_setting(s).map(Self)
    }
}

/// `--seg-depth-regions`: `off` or the engine's parameter string.
#[derive(Clone, Copy, Debug)]
pub struct DepthRegionsArg(pub Option<fusepose_estimator::seg::DepthRegionParams>);

impl std::str::FromStr for DepthRegionsArg {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        fusepose_estimator::seg::DepthRegionParams::parse_setting(s).map(Self)
    }
}
