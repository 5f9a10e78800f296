//! The estimator side of the daemon: object set, workspace and estimator per
//! camera, chosen from the configuration, timed per stage. Frames without a
//! label plane are segmented by the built-in segmenter when the weight file
//! has one (`estimator.masks`).

use std::sync::{Arc, Mutex};

use fusepose_client::{STAGE_COUNT, Stage};
use fusepose_estimator::alternates;
use fusepose_estimator::exposure::{AutoExposure, ExposureConfig};
use fusepose_estimator::interpenetration::Solids;
use fusepose_estimator::net::{NetEstimator, NetLoadError, NetOptions, WeightFile};
use fusepose_estimator::pose_odds::PoseOdds;
use fusepose_estimator::recut::{Recut, RecutConfig};
use fusepose_estimator::remask::{Remask, RemaskConfig};
use fusepose_estimator::seg::{Boundary, DepthRegionParams, DepthRegions, SegEngine, SegError, SegFile, VotingMode};
use fusepose_estimator::split::CutLimits;
use fusepose_estimator::verify::{Verification, Verifier, VerifyConfig};
use fusepose_estimator::white_balance::{WhiteBalance, WhiteBalanceConfig};
use fusepose_estimator::{
    EstimateError, Estimator, FrameError, FrameView, IcpConfig, IcpEstimator, LabelPlane, ObjectPose, PoseSet,
    Workspace, WorkspaceConfig,
};
use fusepose_scene::ObjectSet;

use crate::config::{EstimatorConfig, EstimatorKind, MaskSource};

/// Builds one estimator per camera (estimators keep per-camera state).
pub type EstimatorFactory = Box<dyn Fn() -> anyhow::Result<Box<dyn Estimator>>>;

/// How frames become poses, resolved from the configuration.
pub struct EngineSpec {
    /// What actually runs (after fallbacks), for logs.
    pub description: String,
    /// None for `kind = "none"` (transport only).
    pub factory: Option<EstimatorFactory>,
    /// Stage the estimator's time is recorded under.
    pub estimate_stage: Stage,
    pub workspace: WorkspaceConfig,
    /// The built-in segmenter (checked against the object set), when masks may come from it.
    pub segmenter: Option<Arc<SegFile>>,
    pub masks: MaskSource,
    /// Poses less confident than this are not published (`estimator.min_confidence`).
    pub min_confidence: f32,
    /// Pose verification against the depth image (`estimator.verify*`); `None` = off.
    pub verify: Option<(Arc<ObjectSet>, VerifyConfig, bool)>,
    /// The weight file's model of a pose's odds, where `estimator.verify_min_odds` asks for it.
    pub pose_odds: Option<PoseOdds>,
    /// Per class (id − 1): regions of the class whose points lie within this
    /// many metres of each other are one instance (`estimator.join_parts`);
    /// empty = never join.
    pub part_extents: Vec<f32>,
    /// Per class (id − 1): the support floor (`estimator.support_floor`,
    /// lower for thin objects: `fusepose_estimator::support::class_floors`);
    /// empty = the workspace's one floor for all.
    pub support_floors: Vec<f32>,
    /// Per class: when a region holds several copies and is cut
    /// (`estimator.split_regions`); empty extents = never cut.
    pub cut_limits: CutLimits,
    /// Per-class distance under which two instances or poses are one object
    /// (`estimator.duplicates`); empty = off.
    pub separations: Vec<f32>,
    /// Object solids and `estimator.max_interpenetration` (None = off).
    pub interpenetration: Option<(Arc<Solids>, f32)>,
    /// `estimator.max_explained_share`: of two verified poses, the one whose
    /// region the other explains more than this is dropped (1 = off).
    pub max_explained: f32,
    /// `estimator.class_alternates`: the runner-up class probability at which a
    /// segmenter region is estimated as that class too (0 = off).
    pub class_alternates: f32,
    /// Makes the estimator of [`fusepose_estimator::recut`]'s pieces (one
    /// that never tracks); None for `kind = "none"`.
    pub piece_factory: Option<EstimatorFactory>,
    /// `estimator.recut`: the objects, their solids and the second look's
    /// settings (None = off).
    pub recut: Option<(Arc<ObjectSet>, Arc<Solids>, RecutConfig)>,
    /// `estimator.remask`: the objects and the second masks' settings (None = off).
    pub remask: Option<(Arc<ObjectSet>, RemaskConfig)>,
    /// How the segmenter's cells become frame labels (`estimator.seg_boundary`).
    pub seg_boundary: Boundary,
    /// What the segmenter does with a centre-offset head (`estimator.seg_voting`).
    pub seg_voting: VotingMode,
    /// `estimator.seg_depth_regions` with the objects' diameters (`None` = off).
    pub seg_depth_regions: Option<(Vec<f32>, DepthRegionParams)>,
    /// `estimator.auto_exposure`: dim frames brightened before the networks (`None` = off).
    pub auto_exposure: Option<ExposureConfig>,
    /// `estimator.white_balance`: strongly tinted frames corrected before the networks (`None` = off).
    pub white_balance: Option<WhiteBalanceConfig>,
    /// The network's and segmenter's cost measured at start (network only).
    pub startup_cost: Option<crate::startup_cost::StartupCost>,
    /// The segmenter engine every camera of this spec uses (made by the first
    /// [`PoseEngine::new`]): one copy of its weights and buffers; cameras take turns.
    pub shared_segmenter: std::sync::OnceLock<Arc<Mutex<SegEngine>>>,
}

/// The object set named by `estimator.objects`. A mesh folder's objects that
/// declare no symmetry take the one `estimator.weights` was trained with
/// (e.g. `fusepose train --symmetry`), so the weight check sees the same set.
pub fn load_objects(config: &EstimatorConfig) -> anyhow::Result<ObjectSet> {
    if config.objects == "builtin" {
        return Ok(fusepose_scene::builtin::builtin_objects());
    }
    let dir = std::path::Path::new(&config.objects);
    let mut set = fusepose_scene::mesh_io::load_object_dir(dir, config.objects_scale)
        .map_err(|e| anyhow::anyhow!("estimator.objects = {:?}: {e}", config.objects))?;
    // An unreadable file is reported where the network is loaded.
    if config.kind == EstimatorKind::Net
        && let Ok(file) = WeightFile::read(&config.weights)
    {
        for name in file.adopt_symmetries(&mut set) {
            tracing::debug!(object = %name, weights = %config.weights.display(), "symmetry from the weight file");
        }
    }
    Ok(set)
}

/// Points and crop side without a network to take them from (ICP, transport only).
const ICP_NUM_POINTS: usize = 500;
const ICP_CROP_SIZE: usize = 64;

fn workspace_config(config: &EstimatorConfig, objects: &ObjectSet) -> WorkspaceConfig {
    WorkspaceConfig {
        max_instances: config.max_instances,
        num_points: config.num_points.unwrap_or(ICP_NUM_POINTS),
        crop_size: config.crop_size.unwrap_or(ICP_CROP_SIZE),
        min_pixels: config.min_pixels,
        num_classes: objects.len().min(u16::MAX as usize) as u16,
        support_floor_m: config.support_floor,
        ..WorkspaceConfig::default()
    }
}

/// The ICP baseline over `objects` (its own defaults; `refine_iterations` is the network refiner's).
fn icp_factory(objects: Arc<ObjectSet>) -> EstimatorFactory {
    Box::new(move || {
        let icp =
            IcpEstimator::new(&objects, IcpConfig::default()).map_err(|e| anyhow::anyhow!("estimator (icp): {e}"))?;
        Ok(Box::new(icp) as Box<dyn Estimator>)
    })
}

/// The segmenter embedded in `estimator.weights`, per `estimator.masks`: `labels` never
/// loads one; `auto` uses one when the file has it (a file for other objects is an
/// error, a file without one is not); `net` requires one.
fn segmenter(config: &EstimatorConfig, objects: &ObjectSet) -> anyhow::Result<Option<Arc<SegFile>>> {
    let weights = config.weights.display().to_string();
    let error =
        |e: NetLoadError| anyhow::anyhow!("estimator.masks = {:?}, estimator.weights = {weights:?}: {e}", config.masks);
    match config.masks {
        MaskSource::Labels => Ok(None),
        MaskSource::Auto if !config.weights.exists() => Ok(None),
        MaskSource::Auto | MaskSource::Net => match SegFile::read(&config.weights) {
            Ok(file) => {
                file.check_objects(objects).map_err(error)?;
                Ok(Some(Arc::new(file)))
            }
            Err(NetLoadError::NoSegmenter) if config.masks == MaskSource::Auto => Ok(None),
            Err(e) => Err(error(e)),
        },
    }
}

/// The region-probability floor `estimator.verify_region_certainty_quantile`
/// asks of this segmenter: its recorded certainty of real objects at that
/// quantile; 0 when off or when the file has no record (warned).
fn calibrated_floor(config: &EstimatorConfig, seg: &SegFile) -> f32 {
    let q = config.verify_region_certainty_quantile;
    if q <= 0.0 {
        return 0.0;
    }
    match seg.certainty.as_ref().and_then(|c| c.quantile(q)) {
        Some(p) => {
            tracing::info!(
                quantile = %q,
                min_region_probability = %p,
                "segmenter certainty term: the segmenter's calibrated certainty of real objects at this quantile"
            );
            p
        }
        None => {
            tracing::warn!(
                weights = %config.weights.display(),
                "estimator.verify_region_certainty_quantile = {q}, but the weight file records no segmenter certainty: \
                 the term stays off (record it with `fusepose train --stage calibrate --objects ... --out {}`)",
                config.weights.display()
            );
            0.0
        }
    }
}

/// The weight file's model of a pose's odds where `estimator.verify_min_odds`
/// asks for one; None when off, or when the file records none (warned: the
/// term stays off).
fn pose_odds(config: &EstimatorConfig) -> anyhow::Result<Option<PoseOdds>> {
    if config.verify_min_odds <= 0.0 {
        return Ok(None);
    }
    let odds = PoseOdds::read(&config.weights)?;
    match &odds {
        Some(m) => tracing::info!(
            min_odds = %config.verify_min_odds,
            samples = m.samples,
            "pose odds term: the weight file's fitted model of a pose's odds of being right"
        ),
        None => tracing::warn!(
            weights = %config.weights.display(),
            "estimator.verify_min_odds = {}, but the weight file records no pose odds model: the term stays off \
             (fit one with `fusepose eval --odds-samples` and `fusepose train --stage odds --out {}`)",
            config.verify_min_odds,
            config.weights.display()
        ),
    }
    Ok(odds)
}

/// Resolves `[estimator]`: loads objects, applies the net → ICP fallback, loads the segmenter.
pub fn resolve(config: &EstimatorConfig) -> anyhow::Result<EngineSpec> {
    let mut spec = resolve_estimator(config)?;
    spec.min_confidence = config.min_confidence;
    if spec.factory.is_some() {
        let objects = load_objects(config)?;
        if config.verify != "off" {
            let cfg = VerifyConfig {
                min_fit: config.verify_min_fit,
                min_inlier_fraction: config.verify_min_inliers,
                min_depth_support: config.verify_min_depth_support,
                max_plane_continuation: config.verify_max_plane_continuation,
                max_depth_continuity: config.verify_max_depth_continuity,
                min_thin_mask_agreement: config.verify_min_thin_mask_agreement,
                agreeing_mask_agreement: config.verify_agreeing_mask_agreement,
                min_region_probability: config.verify_min_region_probability,
                trim_table_share: config.verify_trim_table_share,
                max_below_support: config.verify_max_below_support,
                min_region_area_share: config.verify_min_region_area_share,
                min_odds: config.verify_min_odds,
                ..VerifyConfig::default()
            };
            spec.verify = Some((Arc::new(objects.clone()), cfg, config.verify == "drop"));
            spec.pose_odds = pose_odds(config)?;
        }
        spec.part_extents = fusepose_estimator::parts::extents(&objects, config.join_parts);
        spec.support_floors = fusepose_estimator::support::class_floors(&objects, config.support_floor);
        spec.cut_limits = CutLimits::new(&objects, config.split_regions);
        spec.separations = fusepose_estimator::duplicates::separations(&objects, config.duplicates);
        spec.max_explained = config.max_explained_share;
        spec.class_alternates = config.class_alternates;
        if config.max_interpenetration < 1.0 {
            spec.interpenetration = Some((Arc::new(Solids::new(&objects)), config.max_interpenetration));
        }
        // A second look needs a pose's verification to decide.
        // Validated with the rest of the configuration.
        let proposal = config.recut_proposal.parse().unwrap_or(RecutConfig::DEFAULT.proposal);
        let poses = config.recut_poses.parse().unwrap_or(RecutConfig::DEFAULT.poses);
        let recut = RecutConfig {
            max_coverage: config.recut,
            proposal,
            max_pieces: config.recut_pieces,
            poses,
            refit: config.recut_refit,
            min_piece_fit: config.recut_min_piece_fit,
            best_piece: config.recut_best_piece,
            ..RecutConfig::DEFAULT
        };
        if let Some((objects, _, _)) = spec.verify.as_ref().filter(|_| recut.is_on()) {
            let solids = match &spec.interpenetration {
                Some((solids, _)) => solids.clone(),
                None => Arc::new(Solids::new(objects)),
            };
            spec.recut = Some((objects.clone(), solids, recut));
        }
        // Second masks need verification to judge the failed poses and their replacements.
        let remask = RemaskConfig {
            max_regions: config.remask,
            margin_m: config.remask_margin_m,
            rounds: config.remask_rounds,
            ..RemaskConfig::DEFAULT
        };
        if let Some((objects, _, _)) = spec.verify.as_ref().filter(|_| remask.is_on()) {
            spec.remask = Some((objects.clone(), remask));
        }
        spec.segmenter = segmenter(config, &objects)?;
        if let (Some((_, cfg, _)), Some(seg)) = (spec.verify.as_mut(), spec.segmenter.as_deref()) {
            cfg.min_region_probability = cfg.min_region_probability.max(calibrated_floor(config, seg));
        }
        // Checked by the config's validation; a bad value there is an error, not this default.
        spec.seg_boundary =
            config.seg_boundary.parse().map_err(|e: String| anyhow::anyhow!("estimator.seg_boundary: {e}"))?;
        spec.seg_voting =
            config.seg_voting.parse().map_err(|e: String| anyhow::anyhow!("estimator.seg_voting: {e}"))?;
        spec.seg_depth_regions = DepthRegionParams::parse_setting(&config.seg_depth_regions)
            .map_err(|e| anyhow::anyhow!("estimator.seg_depth_regions: {e}"))?
            .map(|p| (fusepose_estimator::parts::extents(&objects, 1.0), p));
        spec.masks = config.masks;
        spec.auto_exposure = ExposureConfig::parse_setting(&config.auto_exposure)
            .map_err(|e| anyhow::anyhow!("estimator.auto_exposure: {e}"))?;
        spec.white_balance = WhiteBalanceConfig::parse_setting(&config.white_balance)
            .map_err(|e| anyhow::anyhow!("estimator.white_balance: {e}"))?;
        if let (Some(seg), Some(cost)) = (&spec.segmenter, spec.startup_cost.as_mut()) {
            match crate::startup_cost::measure_segmenter(seg, spec.seg_boundary, spec.seg_depth_regions.as_ref()) {
                Ok(ns) => cost.segment_ns = Some(ns),
                Err(e) => tracing::warn!(error = %e, "timing the segmenter at start failed"),
            }
        }
        if let Some(seg) = &spec.segmenter {
            spec.description += &format!(
                "; masks {:?}: segmenter {}x{} when frames carry no labels",
                config.masks, seg.config.input_width, seg.config.input_height
            );
        }
    }
    Ok(spec)
}

fn resolve_estimator(config: &EstimatorConfig) -> anyhow::Result<EngineSpec> {
    let objects = Arc::new(load_objects(config)?);
    let workspace = workspace_config(config, &objects);
    let icp = || -> anyhow::Result<EngineSpec> {
        Ok(EngineSpec {
            description: format!("icp ({} objects)", objects.len()),
            factory: Some(icp_factory(objects.clone())),
            estimate_stage: Stage::Refine,
            workspace,
            segmenter: None,
            masks: MaskSource::Labels,
            min_confidence: 0.0,
            verify: None,
            pose_odds: None,
            part_extents: Vec::new(),
            support_floors: Vec::new(),
            cut_limits: CutLimits::default(),
            separations: Vec::new(),
            interpenetration: None,
            max_explained: 1.0,
            class_alternates: 0.0,
            piece_factory: Some(icp_factory(objects.clone())),
            recut: None,
            remask: None,
            seg_boundary: Boundary::default(),
            seg_voting: VotingMode::Off,
            seg_depth_regions: None,
            auto_exposure: None,
            white_balance: None,
            startup_cost: None,
            shared_segmenter: Default::default(),
        })
    };
    match config.kind {
        EstimatorKind::None => Ok(EngineSpec {
            description: "none (transport only: valid frames get OK messages without objects)".to_owned(),
            factory: None,
            estimate_stage: Stage::Network,
            workspace,
            segmenter: None,
            masks: MaskSource::Labels,
            min_confidence: 0.0,
            verify: None,
            pose_odds: None,
            part_extents: Vec::new(),
            support_floors: Vec::new(),
            cut_limits: CutLimits::default(),
            separations: Vec::new(),
            interpenetration: None,
            max_explained: 1.0,
            class_alternates: 0.0,
            piece_factory: None,
            recut: None,
            remask: None,
            seg_boundary: Boundary::default(),
            seg_voting: VotingMode::Off,
            seg_depth_regions: None,
            auto_exposure: None,
            white_balance: None,
            startup_cost: None,
            shared_segmenter: Default::default(),
        }),
        EstimatorKind::Icp => icp(),
        EstimatorKind::Net => {
            if !config.weights.exists() {
                tracing::warn!(
                    weights = %config.weights.display(),
                    "estimator.kind = \"net\" but estimator.weights does not exist: falling back to ICP"
                );
                return icp();
            }
            net(config, objects)
        }
    }
}

/// Load options of the network from `[estimator]` (threads, refiner, tracking).
fn net_options(config: &EstimatorConfig) -> NetOptions {
    let t = &config.tracking;
    NetOptions {
        refine_iterations: Some(config.refine_iterations),
        threads: config.estimation_threads(),
        tracking: t.enabled.then(|| fusepose_estimator::tracking::TrackingConfig {
            max_fit_m: t.max_fit_mm / 1000.0,
            full_estimate_every: t.full_estimate_every,
            refine_iterations: t.refine_iterations,
        }),
        pin_worker_cpu: config.pin_cpus.get(1).copied(),
    }
}

/// The fusion network from `estimator.weights`, checked against the object set now.
fn net(config: &EstimatorConfig, objects: Arc<ObjectSet>) -> anyhow::Result<EngineSpec> {
    let options = || net_options(config);
    let weights_error =
        |e: NetLoadError| anyhow::anyhow!("estimator.weights = {:?}: {e}", config.weights.display().to_string());
    let mut probe = NetEstimator::load(&config.weights, &objects, options()).map_err(weights_error)?;
    // Sizes come from the weight file; the configuration may override them.
    let own = probe.workspace_config(config.max_instances);
    let workspace = WorkspaceConfig {
        min_pixels: config.min_pixels,
        support_floor_m: config.support_floor,
        num_points: config.num_points.unwrap_or(own.num_points),
        crop_size: config.crop_size.unwrap_or(own.crop_size),
        ..own
    };
    if (workspace.num_points, workspace.crop_size) != (own.num_points, own.crop_size) {
        tracing::info!(
            num_points = workspace.num_points,
            crop_size = workspace.crop_size,
            "estimator.num_points / crop_size override the weight file's {} points, {} px crop",
            own.num_points,
            own.crop_size
        );
    }
    let startup_cost = match crate::startup_cost::measure_net(&mut probe, workspace) {
        Ok(cost) => Some(cost),
        Err(e) => {
            tracing::warn!(error = %e, "timing the network at start failed");
            None
        }
    };
    let description = format!(
        "net ({}, {} objects, {} refine iterations)",
        config.weights.display(),
        objects.len(),
        config.refine_iterations
    );
    // Every camera gets a sibling of the probe: one copy of the weights and
    // one worker thread for all cameras (they take turns), own buffers and state.
    let pieces = probe.untracked_sibling();
    let factory: EstimatorFactory = Box::new(move || Ok(Box::new(probe.sibling()) as Box<dyn Estimator>));
    let piece_factory: EstimatorFactory = Box::new(move || Ok(Box::new(pieces.sibling()) as Box<dyn Estimator>));
    Ok(EngineSpec {
        description,
        factory: Some(factory),
        estimate_stage: Stage::Network,
        workspace,
        segmenter: None,
        masks: MaskSource::Labels,
        min_confidence: 0.0,
        verify: None,
        pose_odds: None,
        part_extents: Vec::new(),
        support_floors: Vec::new(),
        cut_limits: CutLimits::default(),
        separations: Vec::new(),
        interpenetration: None,
        max_explained: 1.0,
        class_alternates: 0.0,
        piece_factory: Some(piece_factory),
        recut: None,
        remask: None,
        seg_boundary: Boundary::default(),
        seg_voting: VotingMode::Off,
        seg_depth_regions: None,
        auto_exposure: None,
        white_balance: None,
        startup_cost,
        shared_segmenter: Default::default(),
    })
}

/// Why the engine produced no poses for a frame.
#[derive(Debug, thiserror::Error)]
pub enum EngineFailure {
    /// The estimator's own validation refused the frame (counted as invalid).
    #[error("frame refused: {0}")]
    Refused(#[from] FrameError),
    #[error("estimator failed: {0}")]
    Estimate(EstimateError),
    #[error("segmenter failed: {0}")]
    Segment(SegError),
    /// The estimator panicked (a bug in it); the frame gets an ESTIMATOR_FAILED message.
    #[error("estimator panicked")]
    Panicked,
}

/// One camera's estimator, workspace, segmenter and buffers (allocated once;
/// the label buffer again only when the frame size changes).
pub struct PoseEngine {
    estimator: Option<Box<dyn Estimator>>,
    workspace: Option<Workspace>,
    poses: PoseSet,
    estimate_stage: Stage,
    segmenter: Option<Arc<Mutex<SegEngine>>>,
    masks: MaskSource,
    /// The segmenter's label plane for the current frame.
    labels: Vec<u16>,
    /// `estimator.deadline_aware = false`: deadlines are not passed on.
    ignore_deadlines: bool,
    /// Poses less confident than this are dropped after each estimate.
    min_confidence: f32,
    /// Checks each pose against the depth image; with `verify_drop` failing poses are dropped.
    verifier: Option<Verifier>,
    verify_drop: bool,
    /// `estimator.duplicates` per class (empty = off), and scratch for [`drop_duplicates`].
    separations: Vec<f32>,
    /// Object solids and `estimator.max_interpenetration` (None = off).
    interpenetration: Option<(Arc<Solids>, f32)>,
    /// `estimator.max_explained_share` (1 = off).
    max_explained: f32,
    /// `estimator.class_alternates` (0 = off), and the segmenter's per-class
    /// means of one region (scratch for [`fusepose_estimator::alternates::mark`]).
    class_alternates: f32,
    class_means: Vec<f32>,
    scores: Vec<f32>,
    duplicate_marks: Vec<bool>,
    /// The verification of each pose in `poses` (same order), when verifying.
    verdicts: Vec<Verification>,
    /// Poses dropped by verification in the last frame.
    rejected: usize,
    /// Poses that failed verification in the last frame (dropped or flagged).
    failed_verification: usize,
    /// Moving average of the time after the estimate (verification,
    /// duplicates) per pose, ns; [`POST_ESTIMATE_MARGIN`] × it × the frame's
    /// instances is kept free of the estimator's deadline.
    post_estimate_ns: f64,
    /// The frame's own deadline (`set_deadline`); the estimator gets it less
    /// the post-estimate reserve once the frame's instances are known.
    deadline: Option<std::time::Instant>,
    /// The segmenter's instance → class table for the current frame.
    instance_classes: Vec<u16>,
    /// `estimator.recut`: the second look and the estimator of its pieces.
    recut: Option<(Recut, Box<dyn Estimator>)>,
    /// The second look's time per piece it estimates (each refit round
    /// counted again).
    recut_cost: EstimateCost,
    /// `estimator.remask`: the second masks and the estimator of their poses.
    remask: Option<(Remask, Box<dyn Estimator>)>,
    /// The second masks' time per estimate.
    remask_cost: EstimateCost,
    /// `estimator.auto_exposure`: the brightened copy of a dim frame's colour.
    auto_exposure: Option<AutoExposure>,
    /// `estimator.white_balance`: the corrected copy of a tinted frame's colour.
    white_balance: Option<WhiteBalance>,
}

/// Moving average of a step's time per estimate it made (ns; 0 = not yet
/// measured), which sizes the step in the next frames.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct EstimateCost(f64);

impl EstimateCost {
    /// Estimates the time left before `deadline` pays for, at the measured
    /// cost with [`POST_ESTIMATE_MARGIN`] (before a first measurement, at
    /// `fallback_ns` each).
    fn affordable(&self, deadline: std::time::Instant, fallback_ns: f64) -> usize {
        let left = deadline.saturating_duration_since(std::time::Instant::now()).as_nanos() as f64;
        let per_estimate = POST_ESTIMATE_MARGIN * if self.0 == 0.0 { fallback_ns } else { self.0 };
        (left / per_estimate.max(1.0)) as usize
    }

    /// Adds a frame where the step took `ns` for `estimates` estimates.
    fn record(&mut self, ns: u64, estimates: usize) {
        if estimates > 0 {
            let ns = ns as f64 / estimates as f64;
            self.0 = if self.0 == 0.0 { ns } else { self.0 + POST_ESTIMATE_GAIN * (ns - self.0) };
        }
    }
}

/// Safety factor on the measured post-estimate time per pose when reserving it.
const POST_ESTIMATE_MARGIN: f64 = 1.5;
/// Weight of a new frame in the post-estimate moving average.
const POST_ESTIMATE_GAIN: f64 = 0.1;

/// Checks each pose against the frame's depth and its instance mask into
/// `verdicts` (same order); [`drop_failed`] removes the failures once the
/// second look has seen them. No allocation.
/// `segmenter`: the built-in segmenter when it made this frame's regions (its
/// class probabilities are judged too). Of a region estimated as two classes
/// (`fusepose_estimator::alternates`) only the better-verified pose stays,
/// before failures are counted (`marks` is scratch for that).
#[allow(clippy::too_many_arguments)]
fn verify_poses(
    verifier: Option<&mut Verifier>,
    ws: Option<&Workspace>,
    segmenter: Option<&SegEngine>,
    poses: &mut PoseSet,
    verdicts: &mut Vec<Verification>,
    frame: &FrameView<'_>,
    marks: &mut Vec<bool>,
) {
    verdicts.clear();
    let (Some(verifier), Some(ws)) = (verifier, ws) else { return };
    // The segmenter's certainty is read only where its floor or the odds judge it.
    let segmenter = segmenter.filter(|_| verifier.config().min_region_probability > 0.0 || verifier.has_odds());
    for pose in poses.as_slice() {
        let v = fusepose_estimator::verify::verify_on_region(verifier, frame, ws, segmenter, pose).unwrap_or(
            Verification {
                depth_residual_m: f32::NAN,
                region_probability: f32::NAN,
                region_area_share: f32::NAN,
                odds: f32::NAN,
                ..Verification::default()
            },
        );
        verdicts.push(v);
    }
    let any_alternate = ws.instances.iter().any(|i| i.alt_class_id != 0);
    if any_alternate && alternates::losers(poses.as_slice(), |i| verdicts[i].class_score(), marks) > 0 {
        poses.remove_marked(marks);
        fusepose_estimator::poses::remove_marked(verdicts, marks);
    }
}

/// Counts the poses whose verification failed and, with `drop`, removes
/// them (keeping `verdicts` in step). Without verdicts (verification off)
/// nothing is counted or dropped.
fn drop_failed(poses: &mut PoseSet, verdicts: &mut Vec<Verification>, drop: bool) -> usize {
    if verdicts.len() != poses.len() {
        return 0;
    }
    let failed = verdicts.iter().filter(|v| !v.passed).count();
    if drop {
        let mut it = verdicts.iter();
        poses.retain(|_| it.next().is_some_and(|v| v.passed));
        verdicts.retain(|v| v.passed);
    }
    failed
}

/// Drops poses that duplicate a better-fitting pose of their class
/// (`fusepose_estimator::duplicates`), ranked by the verification fit when
/// verifying (keeping `verdicts` in step), else by confidence. No allocation.
fn drop_duplicates(
    poses: &mut PoseSet,
    verdicts: &mut Vec<Verification>,
    separations: &[f32],
    scores: &mut Vec<f32>,
    marks: &mut Vec<bool>,
) {
    if separations.is_empty() || poses.len() < 2 {
        return;
    }
    rank(poses, verdicts, scores);
    let dropped = fusepose_estimator::duplicates::suppress(poses, separations, scores, marks);
    forget_dropped(dropped, verdicts, marks);
}

/// Drops poses whose region another pose explains
/// (`fusepose_estimator::explained`), keeping `verdicts` in step. Needs
/// verification (its verifier, and verdicts to rank by). No allocation.
#[allow(clippy::too_many_arguments)] // the engine's parts, borrowed one by one
fn drop_explained(
    verifier: Option<&mut Verifier>,
    ws: Option<&Workspace>,
    poses: &mut PoseSet,
    verdicts: &mut Vec<Verification>,
    max_share: f32,
    frame: &FrameView<'_>,
    scores: &mut Vec<f32>,
    marks: &mut Vec<bool>,
) {
    let (Some(verifier), Some(ws)) = (verifier, ws) else { return };
    if max_share >= 1.0 || poses.len() < 2 {
        return;
    }
    rank(poses, verdicts, scores);
    let mask_of = |p: &ObjectPose| ws.component_id(p.instance_id as usize).map(|id| ws.mask_ref(id, p.bbox));
    let dropped = fusepose_estimator::explained::suppress(verifier, frame, mask_of, poses, max_share, scores, marks);
    forget_dropped(dropped, verdicts, marks);
}

/// Drops the pose more inside another (`fusepose_estimator::interpenetration`),
/// keeping `verdicts` in step. No allocation.
fn drop_interpenetrating(
    poses: &mut PoseSet,
    verdicts: &mut Vec<Verification>,
    solids: Option<&(Arc<Solids>, f32)>,
    scores: &mut Vec<f32>,
    marks: &mut Vec<bool>,
) {
    let Some((solids, max_share)) = solids else { return };
    if poses.len() < 2 {
        return;
    }
    rank(poses, verdicts, scores);
    let dropped = solids.suppress(poses, *max_share, scores, marks);
    forget_dropped(dropped, verdicts, marks);
}

/// Scores that rank poses: the verification fit when verifying, else the confidence.
fn rank(poses: &PoseSet, verdicts: &[Verification], scores: &mut Vec<f32>) {
    scores.clear();
    if verdicts.len() == poses.len() {
        scores.extend(verdicts.iter().map(|v| v.fit));
    } else {
        scores.extend(poses.as_slice().iter().map(|p| p.confidence));
    }
}

/// Removes the verdicts of the poses `marks` dropped.
fn forget_dropped(dropped: usize, verdicts: &mut Vec<Verification>, marks: &[bool]) {
    if dropped > 0 && !verdicts.is_empty() {
        fusepose_estimator::poses::remove_marked(verdicts, marks);
    }
}

/// Stage durations of one frame, ns (0 = stage not run).
pub type StageTimes = [u64; STAGE_COUNT];

impl PoseEngine {
    pub fn new(spec: &EngineSpec) -> anyhow::Result<Self> {
        Self::with_max_instances(spec, spec.workspace.max_instances)
    }

    /// As [`PoseEngine::new`], estimating at most `max_instances` per frame
    /// (a camera's own `max_instances`).
    pub fn with_max_instances(spec: &EngineSpec, max_instances: usize) -> anyhow::Result<Self> {
        let estimator = spec.factory.as_ref().map(|f| f()).transpose()?;
        let workspace_config = WorkspaceConfig { max_instances, ..spec.workspace };
        let workspace = match estimator {
            Some(_) => {
                let mut ws = Workspace::new(workspace_config).map_err(|e| anyhow::anyhow!("estimator: {e}"))?;
                ws.join_parts(&spec.part_extents);
                ws.support_floors(&spec.support_floors);
                ws.split_regions(&spec.cut_limits);
                Some(ws)
            }
            None => None,
        };
        let recut = match (&workspace, &spec.recut, &spec.piece_factory) {
            (Some(_), Some((objects, solids, config)), Some(factory)) => {
                let recut = Recut::new(objects, solids.clone(), workspace_config, *config)
                    .map_err(|e| anyhow::anyhow!("estimator.recut: {e}"))?;
                Some((recut, factory()?))
            }
            _ => None,
        };
        let remask = match (&workspace, &spec.remask, &spec.piece_factory) {
            (Some(_), Some((objects, config)), Some(factory)) => {
                let remask = Remask::new(objects, workspace_config, *config)
                    .map_err(|e| anyhow::anyhow!("estimator.remask: {e}"))?;
                Some((remask, factory()?))
            }
            _ => None,
        };
        let segmenter = match (&estimator, &spec.segmenter) {
            (Some(_), Some(file)) => Some(match spec.shared_segmenter.get() {
                Some(shared) => shared.clone(),
                None => {
                    let mut seg = SegEngine::new(file).map_err(|e| anyhow::anyhow!("segmenter: {e}"))?;
                    seg.set_boundary(spec.seg_boundary);
                    seg.set_voting_mode(spec.seg_voting);
                    seg.set_depth_regions(spec.seg_depth_regions.as_ref().map(|(d, p)| DepthRegions::new(d, *p)));
                    seg.set_instance_separation(spec.separations.clone());
                    spec.shared_segmenter.get_or_init(|| Arc::new(Mutex::new(seg))).clone()
                }
            }),
            _ => None,
        };
        Ok(Self {
            estimator,
            workspace,
            // Room for each instance's class alternate.
            poses: PoseSet::with_capacity(2 * max_instances),
            estimate_stage: spec.estimate_stage,
            segmenter,
            masks: spec.masks,
            labels: Vec::new(),
            ignore_deadlines: false,
            min_confidence: spec.min_confidence,
            verifier: spec.verify.as_ref().map(|(objects, cfg, _)| {
                let mut verifier = Verifier::new(objects, *cfg);
                verifier.set_odds(spec.pose_odds.clone());
                verifier
            }),
            verify_drop: spec.verify.as_ref().is_some_and(|v| v.2),
            verdicts: Vec::with_capacity(2 * max_instances),
            separations: spec.separations.clone(),
            interpenetration: spec.interpenetration.clone(),
            max_explained: spec.max_explained,
            class_alternates: spec.class_alternates,
            // One mean per class and background: filled without allocating.
            class_means: Vec::with_capacity(spec.segmenter.as_ref().map_or(0, |s| s.config.num_classes + 1)),
            scores: Vec::with_capacity(2 * max_instances),
            duplicate_marks: Vec::with_capacity(2 * max_instances),
            rejected: 0,
            failed_verification: 0,
            post_estimate_ns: 0.0,
            deadline: None,
            instance_classes: Vec::with_capacity(fusepose_estimator::seg::voting::MAX_INSTANCES + 1),
            recut,
            recut_cost: EstimateCost::default(),
            remask,
            remask_cost: EstimateCost::default(),
            auto_exposure: spec.auto_exposure.map(AutoExposure::new),
            white_balance: spec.white_balance.map(WhiteBalance::new),
        })
    }

    /// An engine around a given estimator (tests, embedding).
    pub fn with_estimator(
        estimator: Box<dyn Estimator>,
        workspace: WorkspaceConfig,
        estimate_stage: Stage,
    ) -> anyhow::Result<Self> {
        Ok(Self {
            estimator: Some(estimator),
            workspace: Some(Workspace::new(workspace).map_err(|e| anyhow::anyhow!("estimator: {e}"))?),
            poses: PoseSet::with_capacity(workspace.max_instances),
            estimate_stage,
            segmenter: None,
            masks: MaskSource::Labels,
            labels: Vec::new(),
            ignore_deadlines: false,
            min_confidence: 0.0,
            verifier: None,
            verify_drop: false,
            verdicts: Vec::new(),
            separations: Vec::new(),
            interpenetration: None,
            max_explained: 1.0,
            class_alternates: 0.0,
            class_means: Vec::new(),
            scores: Vec::new(),
            duplicate_marks: Vec::new(),
            rejected: 0,
            failed_verification: 0,
            post_estimate_ns: 0.0,
            deadline: None,
            instance_classes: Vec::new(),
            recut: None,
            recut_cost: EstimateCost::default(),
            remask: None,
            remask_cost: EstimateCost::default(),
            auto_exposure: None,
            white_balance: None,
        })
    }

    /// Runs prepare + estimate on `frame`; poses are then in [`PoseEngine::poses`].
    /// With `estimator.auto_exposure` the networks see a dim frame brightened
    /// (its colour copied through one gain; the producer's frame untouched),
    /// then with `estimator.white_balance` a strongly tinted one corrected.
    pub fn run(&mut self, frame: &FrameView<'_>, seed: u64, times: &mut StageTimes) -> Result<(), EngineFailure> {
        // Taken out for the frame (no allocation) so their copies can be borrowed beside `self`.
        let mut exposure = self.auto_exposure.take().filter(|_| self.estimator.is_some());
        let mut balance = self.white_balance.take().filter(|_| self.estimator.is_some());
        // A frame with planes of the wrong size is refused in `run_frame`, corrected or not.
        let gained = exposure.as_mut().and_then(|ae| ae.apply(frame));
        let exposed = gained.as_ref().unwrap_or(frame);
        let balanced = balance.as_mut().and_then(|wb| wb.apply(exposed));
        let result = self.run_frame(balanced.as_ref().unwrap_or(exposed), seed, times);
        self.auto_exposure = exposure;
        self.white_balance = balance;
        result
    }

    /// Gains (red, green, blue) applied to the last frame by
    /// `estimator.white_balance` (all 1 = none or off).
    pub fn white_balance_gains(&self) -> [f64; 3] {
        self.white_balance.as_ref().map_or([1.0; 3], WhiteBalance::last_gains)
    }

    /// Gain applied to the last frame by `estimator.auto_exposure` (1 = none or off).
    pub fn exposure_gain(&self) -> f64 {
        self.auto_exposure.as_ref().map_or(1.0, AutoExposure::last_gain)
    }

    fn run_frame(&mut self, frame: &FrameView<'_>, seed: u64, times: &mut StageTimes) -> Result<(), EngineFailure> {
        self.poses.clear();
        let (Some(estimator), Some(workspace)) = (self.estimator.as_mut(), self.workspace.as_mut()) else {
            return frame.validate().map_err(EngineFailure::Refused);
        };
        // Segment when the frame brings no labels (`auto`) or always (`net`).
        let segmented;
        let mut used_segmenter = false;
        let frame = match self.segmenter.as_mut() {
            Some(seg) if self.masks == MaskSource::Net || frame.labels.is_none() => {
                let ts = fusepose_client::monotonic_ns();
                frame.validate()?;
                // Shared by the cameras of this spec; the loop runs one frame at a time.
                let mut seg = seg.lock().unwrap_or_else(|e| e.into_inner());
                // With the centre-offset head the segmenter separates touching
                // copies of a class: an instance plane (its class table copied
                // into a buffer of fixed capacity), else a class plane.
                let plane = seg.segment_plane(frame, &mut self.labels).map_err(|e| match e {
                    SegError::Frame(f) => EngineFailure::Refused(f),
                    other => EngineFailure::Segment(other),
                })?;
                let is_instances = plane.is_instances();
                self.instance_classes.clear();
                if let LabelPlane::Instances { classes, .. } = plane {
                    let n = classes.len().min(self.instance_classes.capacity());
                    self.instance_classes.extend_from_slice(&classes[..n]);
                }
                times[Stage::Segmentation as usize] = fusepose_client::monotonic_ns() - ts;
                let labels = if is_instances {
                    LabelPlane::Instances { ids: &self.labels, classes: &self.instance_classes }
                } else {
                    LabelPlane::U16(&self.labels)
                };
                segmented = FrameView { labels: Some(labels), ..*frame };
                used_segmenter = true;
                &segmented
            }
            _ => frame,
        };
        let t0 = fusepose_client::monotonic_ns();
        // A pair cut in the last frame is cut again now, so that its pieces
        // are in this frame's own estimate (`Recut::hints`).
        if let Some((recut, _)) = self.recut.as_ref() {
            workspace.set_cut_hints(recut.hints());
        }
        let instances = workspace.prepare(frame, seed)?;
        if used_segmenter
            && self.class_alternates > 0.0
            && self.verifier.is_some()
            && let Some(seg) = self.segmenter.as_ref()
        {
            let seg = seg.lock().unwrap_or_else(|e| e.into_inner());
            alternates::mark(workspace, &seg, self.class_alternates, &mut self.class_means);
        }
        // What verification will take for these instances comes off the estimator's time.
        let reserve = std::time::Duration::from_nanos(
            (POST_ESTIMATE_MARGIN * self.post_estimate_ns * instances.min(workspace.config.max_instances) as f64)
                as u64,
        );
        estimator.set_deadline(self.deadline.map(|d| d.checked_sub(reserve).unwrap_or(d)));
        let t1 = fusepose_client::monotonic_ns();
        let result = estimator.estimate(frame, workspace, &mut self.poses);
        let t2 = fusepose_client::monotonic_ns();
        times[Stage::Sampling as usize] = t1 - t0;
        times[self.estimate_stage as usize] = t2 - t1;
        match result {
            Ok(()) => {
                self.poses.retain_confident(self.min_confidence);
                let estimated = self.poses.len();
                // The segmenter is shared by the cameras of this spec, which
                // run one frame at a time: its logits are still this frame's.
                let mut seg = self
                    .segmenter
                    .as_ref()
                    .filter(|_| used_segmenter)
                    .map(|s| s.lock().unwrap_or_else(|e| e.into_inner()));
                // Failed poses stay until the second look has seen them: in a
                // heap the one pose of several copies fails, and the second
                // look cuts its region (`recut_poses = "any"`), as in `fusepose eval`.
                verify_poses(
                    self.verifier.as_mut(),
                    self.workspace.as_ref(),
                    seg.as_deref(),
                    &mut self.poses,
                    &mut self.verdicts,
                    frame,
                    &mut self.duplicate_marks,
                );
                // Before their first measurement, the second look's and the
                // second masks' estimates cost what this frame's did.
                let own_cost = (t2 - t1) as f64 / instances.max(1) as f64;
                let recut_start = fusepose_client::monotonic_ns();
                let mut recut_estimates = 0;
                if let (Some((recut, pieces)), Some(verifier), Some(ws)) =
                    (self.recut.as_mut(), self.verifier.as_mut(), self.workspace.as_mut())
                {
                    // The pieces get what is left of the frame's time less the
                    // steps after them, and are shed first: their time is not
                    // in the post-estimate reserve, so they never take the
                    // frame's own poses' time.
                    let deadline = self.deadline.map(|d| d.checked_sub(reserve).unwrap_or(d));
                    pieces.set_deadline(deadline);
                    if let Some(d) = deadline {
                        // As many piece estimates as the time left pays for: a
                        // region of a heap is cut into up to six pieces, each
                        // estimated up to three times with its refits. Too few
                        // for a region's pieces and rounds: the next frame's
                        // estimate poses them.
                        recut.budget_next_frame(self.recut_cost.affordable(d, own_cost));
                    }
                    let (poses, verdicts, seg) = (&mut self.poses, &mut self.verdicts, seg.as_deref_mut());
                    match recut.run(frame, ws, poses, verdicts, pieces.as_mut(), verifier, seg, seed) {
                        Ok(stats) => recut_estimates = stats.estimates,
                        Err(e) => {
                            tracing::debug!(error = %e, "second look at a region failed; the region keeps its pose")
                        }
                    }
                }
                let recut_ns = fusepose_client::monotonic_ns() - recut_start;
                self.recut_cost.record(recut_ns, recut_estimates);
                // Second masks for the poses still failing, in the time left
                // after the second look, at their own measured cost; not in a
                // frame whose own estimate gave up accuracy or objects for
                // its deadline: its time left is the next frame's (live, five
                // objects on a 2-core box that sheds every frame: 23 % of the
                // objects found when they took it, 28-36 % off or with this
                // rule; docs/BENCHMARKS.md, session 33).
                let remask_start = fusepose_client::monotonic_ns();
                let mut remask_estimates = 0;
                let spare = self.deadline.is_none() || !(estimator.degraded() || estimator.shed() > 0);
                // Sized now, not in the first spare frame, which may come
                // minutes into a stream (RELIABILITY.md, "Memory in soaks").
                if let Some((remask, net)) = self.remask.as_mut()
                    && let Err(e) = remask.warm_up_for(frame, net.as_mut(), seed)
                {
                    tracing::debug!(error = %e, "warming the second masks up failed; they warm up on their first run");
                }
                if let (true, Some((remask, net)), Some(verifier), Some(ws)) =
                    (spare, self.remask.as_mut(), self.verifier.as_mut(), self.workspace.as_ref())
                {
                    let deadline = self.deadline.map(|d| d.checked_sub(reserve).unwrap_or(d));
                    net.set_deadline(deadline);
                    if let Some(d) = deadline {
                        remask.budget_next_frame(self.remask_cost.affordable(d, own_cost));
                    }
                    // Judged as the first poses were: the certainty floor where it is on.
                    let seg = seg.as_deref().filter(|_| verifier.config().min_region_probability > 0.0);
                    match remask.run(frame, ws, &mut self.poses, &mut self.verdicts, net.as_mut(), verifier, seg, seed)
                    {
                        Ok(stats) => remask_estimates = stats.estimates,
                        Err(e) => tracing::debug!(error = %e, "second mask failed; the poses keep their verdicts"),
                    }
                }
                let remask_ns = fusepose_client::monotonic_ns() - remask_start;
                self.remask_cost.record(remask_ns, remask_estimates);
                drop(seg);
                self.failed_verification = drop_failed(&mut self.poses, &mut self.verdicts, self.verify_drop);
                self.rejected = if self.verify_drop { self.failed_verification } else { 0 };
                drop_explained(
                    self.verifier.as_mut(),
                    self.workspace.as_ref(),
                    &mut self.poses,
                    &mut self.verdicts,
                    self.max_explained,
                    frame,
                    &mut self.scores,
                    &mut self.duplicate_marks,
                );
                // Counted by `fusepose eval`; the stats message has no field for it.
                drop_duplicates(
                    &mut self.poses,
                    &mut self.verdicts,
                    &self.separations,
                    &mut self.scores,
                    &mut self.duplicate_marks,
                );
                drop_interpenetrating(
                    &mut self.poses,
                    &mut self.verdicts,
                    self.interpenetration.as_ref(),
                    &mut self.scores,
                    &mut self.duplicate_marks,
                );
                // Per pose: a frame with many objects verifies longest, and is
                // planned with its own count (a decaying maximum of whole frames
                // kept one slow frame's cost for the next hundred).
                if estimated > 0 {
                    let per_pose =
                        (fusepose_client::monotonic_ns() - t2 - recut_ns - remask_ns) as f64 / estimated as f64;
                    self.post_estimate_ns = match self.post_estimate_ns {
                        0.0 => per_pose,
                        old => old + POST_ESTIMATE_GAIN * (per_pose - old),
                    };
                }
                Ok(())
            }
            Err(EstimateError::Frame(e)) => Err(EngineFailure::Refused(e)),
            Err(e) => Err(EngineFailure::Estimate(e)),
        }
    }

    /// The next [`PoseEngine::run`] should end by `deadline` (the estimator
    /// degrades to fit), unless deadline-aware estimation is off.
    pub fn set_deadline(&mut self, deadline: Option<std::time::Instant>) {
        self.deadline = deadline.filter(|_| !self.ignore_deadlines);
    }

    /// `estimator.deadline_aware`: false runs every frame in full whatever its deadline.
    pub fn set_deadline_aware(&mut self, on: bool) {
        self.ignore_deadlines = !on;
    }

    /// Whether the last run gave up accuracy to meet its deadline.
    pub fn degraded(&self) -> bool {
        self.estimator.as_ref().is_some_and(|e| e.degraded())
    }

    pub fn poses(&self) -> &[ObjectPose] {
        self.poses.as_slice()
    }

    /// The verification of each pose of [`PoseEngine::poses`] (same order);
    /// empty when verification is off.
    pub fn verdicts(&self) -> &[Verification] {
        &self.verdicts
    }

    /// Poses the last frame's verification dropped (`estimator.verify = "drop"`).
    pub fn rejected_by_verification(&self) -> usize {
        self.rejected
    }

    /// Poses the last frame's verification failed (dropped or published unverified).
    pub fn failed_verification(&self) -> usize {
        self.failed_verification
    }

    /// Instances the last frame's deadline did not pay for (no pose).
    pub fn shed(&self) -> usize {
        self.estimator.as_ref().map_or(0, |e| e.shed())
    }

    /// Whether the last frame's deadline left an instance of class
    /// `class_id` without a pose.
    pub fn class_shed(&self, class_id: u16) -> bool {
        self.estimator.as_ref().is_some_and(|e| e.shed_class(class_id))
    }

    /// Instances found in the last frame but not estimated (beyond capacity).
    pub fn instances_found(&self) -> usize {
        self.workspace.as_ref().map_or(0, |w| w.instances.len())
    }

    /// Largest label id a producer may send: the object set's classes (0 = any, transport only).
    pub fn label_classes(&self) -> u16 {
        self.workspace.as_ref().map_or(0, |w| w.config.num_classes)
    }

    /// Whether a frame's own label plane defines the masks when it has one
    /// (false when `estimator.masks = "net"` segments every frame).
    pub fn uses_frame_labels(&self) -> bool {
        !(self.segmenter.is_some() && self.masks == MaskSource::Net)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shipped_config() -> EstimatorConfig {
        let weights = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/builtin.safetensors");
        EstimatorConfig { weights, ..EstimatorConfig::default() }
    }

    #[test]
    fn the_certainty_floor_is_the_files_quantile_and_off_without_a_record() {
        let config = shipped_config();
        let mut file = SegFile::read(&config.weights).unwrap();
        let q = config.verify_region_certainty_quantile;
        let expected = file.certainty.as_ref().expect("the shipped file records it").quantile(q).unwrap();
        assert!(expected > 0.0);
        assert_eq!(calibrated_floor(&config, &file), expected);
        // The daemon's verifier gets it: the higher of the floor and the plain minimum.
        let spec = resolve(&config).unwrap();
        assert_eq!(spec.verify.as_ref().unwrap().1.min_region_probability, expected);
        let plain = EstimatorConfig { verify_min_region_probability: 0.99, ..shipped_config() };
        assert_eq!(resolve(&plain).unwrap().verify.unwrap().1.min_region_probability, 0.99);
        let off = EstimatorConfig { verify_region_certainty_quantile: 0.0, ..shipped_config() };
        assert_eq!(calibrated_floor(&off, &file), 0.0);
        assert_eq!(resolve(&off).unwrap().verify.unwrap().1.min_region_probability, 0.0);
        file.certainty = None;
        assert_eq!(calibrated_floor(&config, &file), 0.0, "a file without a record leaves the term off");
    }

    #[test]
    fn the_odds_term_reads_the_files_model_only_when_asked() {
        assert!(resolve(&shipped_config()).unwrap().pose_odds.is_none(), "off by default: not even read");
        let on = EstimatorConfig { verify_min_odds: 0.3, ..shipped_config() };
        let spec = resolve(&on).unwrap();
        assert!(spec.pose_odds.as_ref().is_some_and(|m| m.samples > 0), "the shipped file records a model");
        assert_eq!(spec.verify.as_ref().unwrap().1.min_odds, 0.3);
        // The engine's verifier holds it.
        let engine = PoseEngine::new(&spec).unwrap();
        assert!(engine.verifier.as_ref().is_some_and(Verifier::has_odds));
    }

    #[test]
    fn depth_regrouping_is_on_by_default_with_each_objects_diameter() {
        let spec = resolve(&shipped_config()).unwrap();
        let (diameters, params) = spec.seg_depth_regions.expect("on by default");
        assert_eq!(params, DepthRegionParams::default());
        let objects = load_objects(&shipped_config()).unwrap();
        assert_eq!(diameters.len(), objects.len());
        for (d, o) in diameters.iter().zip(&objects.objects) {
            assert!((*d as f64 - o.diameter).abs() < 1e-6, "{}: {d} vs {}", o.name, o.diameter);
        }
        let tuned = EstimatorConfig { seg_depth_regions: "share=0.5,absorb=0".into(), ..shipped_config() };
        let (_, p) = resolve(&tuned).unwrap().seg_depth_regions.unwrap();
        assert_eq!((p.min_majority_share, p.absorb_below_share), (0.5, 0.0));
        let off = EstimatorConfig { seg_depth_regions: "off".into(), ..shipped_config() };
        assert!(resolve(&off).unwrap().seg_depth_regions.is_none());
    }

    #[test]
    fn the_second_look_is_on_by_default_and_needs_verification() {
        let spec = resolve(&shipped_config()).unwrap();
        let (objects, _, config) = spec.recut.as_ref().expect("on by default");
        assert_eq!(*config, RecutConfig::DEFAULT);
        assert_eq!(objects.len(), load_objects(&shipped_config()).unwrap().len());
        let engine = PoseEngine::new(&spec).unwrap();
        assert!(engine.recut.is_some(), "each camera's engine has its own second look and piece estimator");
        let tuned = EstimatorConfig { recut: 0.7, ..shipped_config() };
        assert_eq!(resolve(&tuned).unwrap().recut.unwrap().2.max_coverage, 0.7);
        let heaps =
            EstimatorConfig { recut_pieces: 5, recut_poses: "coverage".into(), recut_refit: true, ..shipped_config() };
        let config = resolve(&heaps).unwrap().recut.unwrap().2;
        let want = (5, fusepose_estimator::recut::RecutPoses::Coverage, true);
        assert_eq!((config.max_pieces, config.poses, config.refit), want);
        let off = EstimatorConfig { recut: 0.0, ..shipped_config() };
        assert!(resolve(&off).unwrap().recut.is_none());
        let unverified = EstimatorConfig { verify: "off".into(), ..shipped_config() };
        assert!(resolve(&unverified).unwrap().recut.is_none(), "no verdicts, nothing to decide with");
    }

    #[test]
    fn a_steps_estimate_cost_sizes_its_next_frames() {
        let mut cost = EstimateCost::default();
        cost.record(5_000_000, 0);
        assert_eq!(cost, EstimateCost(0.0), "a frame without estimates measures nothing");
        let in_30_ms = std::time::Instant::now() + std::time::Duration::from_millis(30);
        // Before a measurement at the fallback: 30 ms / (1.5 x 2 ms) = 10 (9 once some time passed).
        assert!((9..=10).contains(&cost.affordable(in_30_ms, 2e6)));
        cost.record(20_000_000, 4);
        assert_eq!(cost, EstimateCost(5e6), "the first measurement is taken as it is");
        assert!((3..=4).contains(&cost.affordable(in_30_ms, 2e6)), "30 ms / (1.5 x 5 ms)");
        cost.record(15_000_000, 1);
        assert_eq!(cost, EstimateCost(5e6 + POST_ESTIMATE_GAIN * 10e6), "then a moving average");
        let past = std::time::Instant::now() - std::time::Duration::from_millis(1);
        assert_eq!(cost.affordable(past, 2e6), 0, "no time left, no estimate");
    }

    #[test]
    fn second_masks_are_on_by_default_and_need_verification() {
        let spec = resolve(&shipped_config()).unwrap();
        let (_, config) = spec.remask.as_ref().expect("on by default");
        assert_eq!(*config, RemaskConfig::DEFAULT);
        let engine = PoseEngine::new(&spec).unwrap();
        assert!(engine.remask.is_some(), "each camera's engine has its own second masks and estimator");
        let tuned = EstimatorConfig { remask: 2, remask_margin_m: 0.02, remask_rounds: 1, ..shipped_config() };
        let config = resolve(&tuned).unwrap().remask.unwrap().1;
        assert_eq!((config.max_regions, config.margin_m, config.rounds), (2, 0.02, 1));
        let off = EstimatorConfig { remask: 0, ..shipped_config() };
        assert!(resolve(&off).unwrap().remask.is_none());
        let unverified = EstimatorConfig { verify: "off".into(), ..shipped_config() };
        assert!(resolve(&unverified).unwrap().remask.is_none(), "no verdicts, nothing to replace");
    }

    /// An RGB frame without labels.
    fn rgb_frame<'a>(intrinsics: fusepose_scene::Intrinsics, color: &'a [u8], depth: &'a [f32]) -> FrameView<'a> {
        FrameView {
            intrinsics,
            color_format: fusepose_estimator::ColorFormat::Rgb8,
            color,
            depth: fusepose_estimator::DepthPlane::F32(depth),
            labels: None,
        }
    }

    #[test]
    fn white_balance_is_off_by_default_and_corrects_only_tinted_frames() {
        assert!(resolve(&shipped_config()).unwrap().white_balance.is_none(), "off by default");
        let on = EstimatorConfig { white_balance: "on".into(), ..shipped_config() };
        let spec = resolve(&on).unwrap();
        assert_eq!(spec.white_balance, Some(WhiteBalanceConfig::default()));
        let mut engine = PoseEngine::new(&spec).unwrap();
        let intrinsics = fusepose_scene::Intrinsics::YCB_VIDEO;
        let pixels = (intrinsics.width * intrinsics.height) as usize;
        let depth = vec![1.0f32; pixels];
        let mut times = [0; STAGE_COUNT];
        // Grey and coloured patches under white light, then under a strongly warm one (blue at a third).
        for (blue, tinted) in [(1.0f32, false), (0.35, true), (1.0, false)] {
            let color: Vec<u8> = (0..pixels)
                .flat_map(|p| {
                    let px = match p % 640 / 160 {
                        0 => [180u8, 180, 180],
                        1 => [170, 60, 50],
                        2 => [50, 70, 160],
                        _ => [20, 20, 20],
                    };
                    [px[0], px[1], (px[2] as f32 * blue) as u8]
                })
                .collect();
            engine.run(&rgb_frame(intrinsics, &color, &depth), 1, &mut times).unwrap();
            let gains = engine.white_balance_gains();
            assert_eq!(gains[2] > 1.0, tinted, "blue at {blue}: gains {gains:?}");
        }
        let bad = EstimatorConfig { white_balance: "band=-1".into(), ..shipped_config() };
        assert!(resolve(&bad).err().unwrap().to_string().starts_with("estimator.white_balance"));
    }

    #[test]
    fn auto_exposure_is_on_by_default_and_brightens_only_dim_frames() {
        assert_eq!(resolve(&shipped_config()).unwrap().auto_exposure, Some(ExposureConfig::default()), "on by default");
        let off = EstimatorConfig { auto_exposure: "off".into(), ..shipped_config() };
        assert!(resolve(&off).unwrap().auto_exposure.is_none());
        let spec = resolve(&shipped_config()).unwrap();
        let mut engine = PoseEngine::new(&spec).unwrap();
        let intrinsics = fusepose_scene::Intrinsics::YCB_VIDEO;
        let pixels = (intrinsics.width * intrinsics.height) as usize;
        let depth = vec![1.0f32; pixels];
        let mut times = [0; STAGE_COUNT];
        // A table at 1 m under a lit patch; at −1.2 EV its highlights fall below the target.
        for (level, dim) in [(200u8, false), (90, true), (200, false)] {
            let color: Vec<u8> = (0..pixels)
                .flat_map(|p| if p % 640 < 400 { [level, level / 2, level / 3] } else { [20, 20, 20] })
                .collect();
            engine.run(&rgb_frame(intrinsics, &color, &depth), 1, &mut times).unwrap();
            assert_eq!(engine.exposure_gain() > 1.0, dim, "level {level}: gain {}", engine.exposure_gain());
        }
        let bad = EstimatorConfig { auto_exposure: "target=0".into(), ..shipped_config() };
        assert!(resolve(&bad).err().unwrap().to_string().starts_with("estimator.auto_exposure"));
    }
}
