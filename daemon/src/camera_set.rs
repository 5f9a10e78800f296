//! The cameras a daemon serves, opened and closed as the configuration says:
//! at start and on reload (SIGHUP). Each camera holds its lock, ports, state
//! and its place in the cell; cameras on the same estimator settings share
//! one engine spec (one copy of the weights, one worker thread).

use std::rc::Rc;

use fusepose_client::Ipc;
use fusepose_scene::ObjectSet;
use nalgebra::Isometry3;

use crate::camera::{CameraPorts, CameraState};
use crate::camera_lock::CameraLock;
use crate::config::{CameraSettings, EstimatorConfig};
use crate::engine::{self, EngineSpec, PoseEngine};
use crate::stable_ids::StableIds;

/// One served camera.
pub struct Camera {
    pub settings: CameraSettings,
    /// Shared with the loop's WaitSet attachments of the current epoch.
    pub ports: Rc<CameraPorts>,
    pub state: CameraState,
    /// Camera → cell.
    pub cell_from_camera: Isometry3<f64>,
    /// This camera's class id → the cell's (empty: the same object set).
    pub class_map: Vec<u16>,
    _lock: CameraLock,
}

/// Engine specs by estimator settings: the daemon-wide one, and one per
/// distinct per-camera override (resolved when first needed).
pub struct EngineCatalog<'a> {
    main_config: EstimatorConfig,
    main: &'a EngineSpec,
    main_objects: Rc<ObjectSet>,
    extra: Vec<(EstimatorConfig, Rc<EngineSpec>)>,
}

impl<'a> EngineCatalog<'a> {
    pub fn new(main_config: &EstimatorConfig, main: &'a EngineSpec, main_objects: Rc<ObjectSet>) -> Self {
        Self { main_config: main_config.clone(), main, main_objects, extra: Vec::new() }
    }

    /// The cell's object set (the daemon-wide `[estimator] objects`).
    pub fn cell_objects(&self) -> &ObjectSet {
        &self.main_objects
    }

    /// A new engine for a camera with `settings`.
    pub fn engine(&mut self, settings: &CameraSettings) -> anyhow::Result<PoseEngine> {
        let mut engine = if settings.estimator == self.main_config {
            PoseEngine::with_max_instances(self.main, settings.max_instances)?
        } else {
            let spec = match self.extra.iter().find(|(c, _)| *c == settings.estimator) {
                Some((_, spec)) => spec.clone(),
                None => {
                    let spec = Rc::new(
                        engine::resolve(&settings.estimator)
                            .map_err(|e| anyhow::anyhow!("camera {}: its estimator settings: {e:#}", settings.name))?,
                    );
                    self.extra.push((settings.estimator.clone(), spec.clone()));
                    spec
                }
            };
            PoseEngine::with_max_instances(&spec, settings.max_instances)?
        };
        engine.set_deadline_aware(self.main_config.deadline_aware);
        Ok(engine)
    }

    /// Whether a camera with `settings` uses the cell's object set.
    fn uses_cell_objects(&self, settings: &CameraSettings) -> bool {
        let (a, b) = (&settings.estimator, &self.main_config);
        (&a.objects, a.objects_scale) == (&b.objects, b.objects_scale)
    }

    /// The object set of a camera with `settings`.
    fn objects(&self, settings: &CameraSettings) -> anyhow::Result<Rc<ObjectSet>> {
        if self.uses_cell_objects(settings) {
            return Ok(self.main_objects.clone());
        }
        let own = engine::load_objects(&settings.estimator)
            .map_err(|e| anyhow::anyhow!("camera {}: {e:#}", settings.name))?;
        Ok(Rc::new(own))
    }

    /// Stable instance ids for a camera in tracking mode (None otherwise):
    /// an object keeps its id while it moves less than half its diameter per frame.
    pub fn stable_ids(&self, settings: &CameraSettings) -> anyhow::Result<Option<StableIds>> {
        if !settings.estimator.tracking.enabled {
            return Ok(None);
        }
        Ok(Some(StableIds::new(merge_distances(&*self.objects(settings)?, 0.0))))
    }

    /// The camera's class ids → the cell's, by object name (empty when the
    /// camera uses the cell's object set; 0 = no such object in the cell).
    pub fn class_map(&self, settings: &CameraSettings) -> anyhow::Result<Vec<u16>> {
        if self.uses_cell_objects(settings) {
            return Ok(Vec::new());
        }
        let own = self.objects(settings)?;
        let mut map = vec![0u16];
        let mut missing = Vec::new();
        for o in &own.objects {
            let id = self.main_objects.class_of(&o.name).unwrap_or(0);
            if id == 0 {
                missing.push(o.name.as_str());
            }
            map.push(id);
        }
        if !missing.is_empty() {
            tracing::warn!(
                camera = %settings.name,
                "objects {missing:?} are not in the cell's object set ([estimator] objects): their poses are published for this camera but not in the cell"
            );
        }
        Ok(map)
    }

    /// Drops specs no camera uses any more (after a reload).
    pub fn retain_used(&mut self, cameras: &[Camera]) {
        self.extra.retain(|(c, _)| cameras.iter().any(|cam| cam.settings.estimator == *c));
    }
}

impl Camera {
    /// Opens and sets up a camera whose lock is taken ([`lock_camera`]);
    /// nothing is kept when a step fails.
    pub fn open(
        ipc: &Ipc,
        lock: CameraLock,
        settings: &CameraSettings,
        catalog: &mut EngineCatalog<'_>,
        now_ns: u64,
    ) -> anyhow::Result<Self> {
        let class_map = catalog.class_map(settings)?;
        let engine = catalog.engine(settings)?;
        let stable_ids = catalog.stable_ids(settings)?;
        let ports = Rc::new(CameraPorts::open(ipc, &settings.name)?);
        let mut state = CameraState::new(&settings.name, engine, settings.deadline_ns, now_ns);
        state.set_stable_ids(stable_ids);
        state.set_confirmation(settings.estimator.confirm_within_m, settings.estimator.confirm_frames);
        Ok(Self {
            settings: settings.clone(),
            ports,
            state,
            cell_from_camera: settings.extrinsics.isometry(),
            class_map,
            _lock: lock,
        })
    }

    /// Prepares changed settings of this camera (a new engine only when its
    /// estimator settings changed); nothing changes until [`Camera::apply`].
    pub fn prepare_update(
        &self,
        settings: &CameraSettings,
        catalog: &mut EngineCatalog<'_>,
    ) -> anyhow::Result<PreparedUpdate> {
        let engine_changed =
            settings.estimator != self.settings.estimator || settings.max_instances != self.settings.max_instances;
        let (engine, class_map, stable_ids) = if engine_changed {
            (Some(catalog.engine(settings)?), Some(catalog.class_map(settings)?), Some(catalog.stable_ids(settings)?))
        } else {
            (None, None, None)
        };
        Ok(PreparedUpdate { settings: settings.clone(), engine, class_map, stable_ids })
    }

    /// Applies prepared settings in place: counters, histograms and ports
    /// stay. Returns what changed, for the log.
    pub fn apply(&mut self, update: PreparedUpdate) -> String {
        let mut changed = Vec::new();
        let s = &update.settings;
        if let Some(engine) = update.engine {
            changed.push("estimator settings");
            self.state.replace_engine(engine);
        }
        if let Some(map) = update.class_map {
            self.class_map = map;
        }
        if let Some(ids) = update.stable_ids {
            self.state.set_stable_ids(ids);
        }
        let confirm = |s: &CameraSettings| (s.estimator.confirm_within_m, s.estimator.confirm_frames);
        if confirm(s) != confirm(&self.settings) {
            self.state.set_confirmation(s.estimator.confirm_within_m, s.estimator.confirm_frames);
        }
        if s.deadline_ns != self.settings.deadline_ns {
            changed.push("deadline");
            self.state.set_deadline_ns(s.deadline_ns);
        }
        if s.extrinsics != self.settings.extrinsics {
            changed.push("extrinsics");
            self.cell_from_camera = s.extrinsics.isometry();
        }
        self.settings = update.settings;
        changed.join(", ")
    }
}

/// New settings of a served camera, ready to apply.
pub struct PreparedUpdate {
    settings: CameraSettings,
    engine: Option<PoseEngine>,
    class_map: Option<Vec<u16>>,
    stable_ids: Option<Option<StableIds>>,
}

/// One daemon per camera: takes `camera`'s lock (before any of its ports
/// open) and writes this daemon's node into it.
pub fn lock_camera(root: &std::path::Path, prefix: &str, node: &str, camera: &str) -> anyhow::Result<CameraLock> {
    let mut lock = CameraLock::acquire(root, prefix, camera)?;
    if let Err(e) = lock.record_node(node) {
        tracing::warn!(path = %lock.path().display(), error = %e, "cannot write the node into the camera lock");
    }
    Ok(lock)
}

/// Per-class merge distances of the cell (metres; class id − 1): the
/// configured one, or half of each object's diameter.
pub fn merge_distances(objects: &ObjectSet, merge_distance_m: f64) -> Vec<f64> {
    objects.objects.iter().map(|o| if merge_distance_m > 0.0 { merge_distance_m } else { 0.5 * o.diameter }).collect()
}
