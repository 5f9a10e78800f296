//! The estimator side of the daemon: object set, workspace and estimator per
//! camera, chosen from the configuration, timed per stage.

use std::sync::Arc;

use fusepose_client::{STAGE_COUNT, Stage};
use fusepose_estimator::net::{NetEstimator, NetLoadError, NetOptions};
use fusepose_estimator::{
    EstimateError, Estimator, FrameError, FrameView, IcpConfig, IcpEstimator, ObjectPose, PoseSet, Workspace, WorkspaceConfig,
};
use fusepose_scene::ObjectSet;

use crate::config::{EstimatorConfig, EstimatorKind};

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
}

/// The object set named by `estimator.objects`.
pub fn load_objects(config: &EstimatorConfig) -> anyhow::Result<ObjectSet> {
    if config.objects == "builtin" {
        return Ok(fusepose_scene::builtin::builtin_objects());
    }
    let dir = std::path::Path::new(&config.objects);
    fusepose_scene::mesh_io::load_object_dir(dir, config.objects_scale)
        .map_err(|e| anyhow::anyhow!("estimator.objects = {:?}: {e}", config.objects))
}

fn workspace_config(config: &EstimatorConfig, objects: &ObjectSet) -> WorkspaceConfig {
    WorkspaceConfig {
        max_instances: config.max_instances,
        num_points: config.num_points,
        crop_size: config.crop_size,
        min_pixels: config.min_pixels,
        num_classes: objects.len().min(u16::MAX as usize) as u16,
        ..WorkspaceConfig::default()
    }
}

/// The ICP baseline over `objects` (its own defaults; `refine_iterations` is the network refiner's).
fn icp_factory(objects: Arc<ObjectSet>) -> EstimatorFactory {
    Box::new(move || {
        let icp = IcpEstimator::new(&objects, IcpConfig::default()).map_err(|e| anyhow::anyhow!("estimator (icp): {e}"))?;
        Ok(Box::new(icp) as Box<dyn Estimator>)
    })
}

/// Resolves `[estimator]`: loads objects, applies the net → ICP fallback.
pub fn resolve(config: &EstimatorConfig) -> anyhow::Result<EngineSpec> {
    let objects = Arc::new(load_objects(config)?);
    let workspace = workspace_config(config, &objects);
    let icp = || -> anyhow::Result<EngineSpec> {
        Ok(EngineSpec {
            description: format!("icp ({} objects)", objects.len()),
            factory: Some(icp_factory(objects.clone())),
            estimate_stage: Stage::Refine,
            workspace,
        })
    };
    match config.kind {
        EstimatorKind::None => Ok(EngineSpec {
            description: "none (transport only: valid frames get OK messages without objects)".to_owned(),
            factory: None,
            estimate_stage: Stage::Network,
            workspace,
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

/// The fusion network from `estimator.weights`, checked against the object set now.
fn net(config: &EstimatorConfig, objects: Arc<ObjectSet>) -> anyhow::Result<EngineSpec> {
    let options = || NetOptions {
        refine_iterations: Some(config.refine_iterations),
        threads: config.worker_threads.clamp(1, 2),
    };
    let weights_error = |e: NetLoadError| anyhow::anyhow!("estimator.weights = {:?}: {e}", config.weights.display().to_string());
    let probe = NetEstimator::load(&config.weights, &objects, options()).map_err(weights_error)?;
    let workspace = WorkspaceConfig { min_pixels: config.min_pixels, ..probe.workspace_config(config.max_instances) };
    if (workspace.num_points, workspace.crop_size) != (config.num_points, config.crop_size) {
        tracing::warn!(
            num_points = workspace.num_points,
            crop_size = workspace.crop_size,
            "estimator.num_points / crop_size replaced by the sizes the network was trained with"
        );
    }
    let description = format!("net ({}, {} objects, {} refine iterations)", config.weights.display(), objects.len(), config.refine_iterations);
    // The probe serves the first camera; further cameras load their own copy.
    let first = std::sync::Mutex::new(Some(probe));
    let (path, threads, refine_iterations) = (config.weights.clone(), config.worker_threads.clamp(1, 2), config.refine_iterations);
    let factory: EstimatorFactory = Box::new(move || {
        if let Some(net) = first.lock().ok().and_then(|mut f| f.take()) {
            return Ok(Box::new(net) as Box<dyn Estimator>);
        }
        let options = NetOptions { refine_iterations: Some(refine_iterations), threads };
        let net = NetEstimator::load(&path, &objects, options).map_err(|e| anyhow::anyhow!("estimator.weights: {e}"))?;
        Ok(Box::new(net) as Box<dyn Estimator>)
    });
    Ok(EngineSpec { description, factory: Some(factory), estimate_stage: Stage::Network, workspace })
}

/// Why the engine produced no poses for a frame.
#[derive(Debug, thiserror::Error)]
pub enum EngineFailure {
    /// The estimator's own validation refused the frame (counted as invalid).
    #[error("frame refused: {0}")]
    Refused(#[from] FrameError),
    #[error("estimator failed: {0}")]
    Estimate(EstimateError),
    /// The estimator panicked (a bug in it); the frame gets an ESTIMATOR_FAILED message.
    #[error("estimator panicked")]
    Panicked,
}

/// One camera's estimator, workspace and pose buffer (allocated once).
pub struct PoseEngine {
    estimator: Option<Box<dyn Estimator>>,
    workspace: Option<Workspace>,
    poses: PoseSet,
    estimate_stage: Stage,
}

/// Stage durations of one frame, ns (0 = stage not run).
pub type StageTimes = [u64; STAGE_COUNT];

impl PoseEngine {
    pub fn new(spec: &EngineSpec) -> anyhow::Result<Self> {
        let estimator = spec.factory.as_ref().map(|f| f()).transpose()?;
        let workspace = match estimator {
            Some(_) => Some(Workspace::new(spec.workspace).map_err(|e| anyhow::anyhow!("estimator: {e}"))?),
            None => None,
        };
        Ok(Self {
            estimator,
            workspace,
            poses: PoseSet::with_capacity(spec.workspace.max_instances),
            estimate_stage: spec.estimate_stage,
        })
    }

    /// An engine around a given estimator (tests, embedding).
    pub fn with_estimator(estimator: Box<dyn Estimator>, workspace: WorkspaceConfig, estimate_stage: Stage) -> anyhow::Result<Self> {
        Ok(Self {
            estimator: Some(estimator),
            workspace: Some(Workspace::new(workspace).map_err(|e| anyhow::anyhow!("estimator: {e}"))?),
            poses: PoseSet::with_capacity(workspace.max_instances),
            estimate_stage,
        })
    }

    /// Runs prepare + estimate on `frame`; poses are then in [`PoseEngine::poses`].
    pub fn run(&mut self, frame: &FrameView<'_>, seed: u64, times: &mut StageTimes) -> Result<(), EngineFailure> {
        self.poses.clear();
        let (Some(estimator), Some(workspace)) = (self.estimator.as_mut(), self.workspace.as_mut()) else {
            return frame.validate().map_err(EngineFailure::Refused);
        };
        let t0 = fusepose_client::monotonic_ns();
        workspace.prepare(frame, seed)?;
        let t1 = fusepose_client::monotonic_ns();
        let result = estimator.estimate(frame, workspace, &mut self.poses);
        let t2 = fusepose_client::monotonic_ns();
        times[Stage::Sampling as usize] = t1 - t0;
        times[self.estimate_stage as usize] = t2 - t1;
        match result {
            Ok(()) => Ok(()),
            Err(EstimateError::Frame(e)) => Err(EngineFailure::Refused(e)),
            Err(e) => Err(EngineFailure::Estimate(e)),
        }
    }

    pub fn poses(&self) -> &[ObjectPose] {
        self.poses.as_slice()
    }

    /// Instances found in the last frame but not estimated (beyond capacity).
    pub fn instances_found(&self) -> usize {
        self.workspace.as_ref().map_or(0, |w| w.instances.len())
    }
}
