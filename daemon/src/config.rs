//! `fuseposed` configuration: a TOML file read with serde. Every key has a
//! default; unknown keys are errors; every semantic error names its key.

use std::path::{Path, PathBuf};

use serde::Deserialize;

/// Which estimator turns frames into poses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum EstimatorKind {
    /// Classical ICP baseline on the object models.
    Icp,
    /// The fusion network (`weights`); falls back to ICP with a warning when the weights are missing.
    Net,
    /// No estimation: every valid frame is answered with an OK message without
    /// objects. For transport checks and latency measurements only.
    None,
}

/// Where a frame's instance labels come from (`estimator.masks`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MaskSource {
    /// The frame's label plane when it has one, else the built-in segmenter when the
    /// weight file has one (else the frame is refused for missing labels).
    #[default]
    Auto,
    /// Only the frame's label plane; the segmenter is never loaded.
    Labels,
    /// Always the built-in segmenter (label planes are ignored); a weight file
    /// without one is a startup error.
    Net,
}

/// Default of `estimator.verify_region_certainty_quantile`: chosen on
/// tuning splits for the shipped segmenter and a 14-minute one
/// (docs/BENCHMARKS.md, "Session 20").
pub const DEFAULT_REGION_CERTAINTY_QUANTILE: f32 = fusepose_estimator::seg::file::DEFAULT_CERTAINTY_QUANTILE;

/// Default of `estimator.confirm_within_m` (metres): a network pose of a
/// still object moves by a few millimetres between frames.
pub const DEFAULT_CONFIRM_WITHIN_M: f64 = 0.01;

/// Most cameras one daemon serves.
pub const MAX_CAMERAS: usize = 16;

/// The whole configuration file.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DaemonConfig {
    /// Camera names served with the daemon-wide settings; each gets the
    /// services `fusepose/camera/<name>/…`. Unset when `[[camera]]` tables
    /// are given: then those are the cameras.
    pub cameras: Vec<String>,
    /// `[[camera]]` tables: cameras with their own settings (served besides `cameras`).
    pub camera: Vec<CameraEntry>,
    /// `tracing` filter (`error`, `warn`, `info`, `debug`, `trace`, or a directive list);
    /// the `FUSEPOSE_LOG` environment variable overrides it.
    pub log_level: String,
    /// Capture → publish budget, milliseconds (default 1/24 s).
    pub deadline_ms: f64,
    pub estimator: EstimatorConfig,
    pub stats: StatsConfig,
    pub ipc: IpcConfig,
    pub cell: CellConfig,
}

/// `[[camera]]`: one camera and what it does differently from the daemon-wide settings.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraEntry {
    pub name: String,
    /// Capture → publish budget of this camera's frames, ms (default: `deadline_ms`).
    pub deadline_ms: Option<f64>,
    /// Most instances estimated per frame (default: `estimator.max_instances`).
    pub max_instances: Option<usize>,
    /// Where instance masks come from (default: `estimator.masks`).
    pub masks: Option<MaskSource>,
    /// Network weights of this camera (default: `estimator.weights`).
    pub weights: Option<PathBuf>,
    /// Object set of this camera (default: `estimator.objects`); its objects
    /// join the cell output by name.
    pub objects: Option<String>,
    pub objects_scale: Option<f64>,
    /// Where the camera is in the cell (default: the cell frame itself).
    #[serde(default)]
    pub extrinsics: Extrinsics,
}

/// Camera → cell transform: a point `p` in the camera optical frame is
/// `R(quaternion_xyzw) p + translation_m` in the cell frame (metres).
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Extrinsics {
    pub translation_m: [f64; 3],
    /// Unit quaternion `[x, y, z, w]` (normalised when within 1e-3 of unit length).
    pub quaternion_xyzw: [f64; 4],
}

impl Default for Extrinsics {
    fn default() -> Self {
        Self { translation_m: [0.0; 3], quaternion_xyzw: [0.0, 0.0, 0.0, 1.0] }
    }
}

impl Extrinsics {
    /// The camera → cell isometry.
    pub fn isometry(&self) -> nalgebra::Isometry3<f64> {
        let [x, y, z, w] = self.quaternion_xyzw;
        let q = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
        let [tx, ty, tz] = self.translation_m;
        nalgebra::Isometry3::from_parts(nalgebra::Translation3::new(tx, ty, tz), q)
    }
}

/// `[cell]`: every camera's objects in one cell frame on `fusepose/cell/poses`.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CellConfig {
    /// Publish cell poses (one daemon per iceoryx2 namespace may).
    pub enabled: bool,
    /// A camera's latest poses join the cell while their capture is at most this old, ms.
    pub max_age_ms: f64,
    /// Two cameras' poses of one class are one object when their translations
    /// lie within this distance, metres; 0 = half the object's diameter.
    pub merge_distance_m: f64,
    /// Which pose an object's entry carries: "best-fit" (the view with the
    /// smallest verified depth residual) or "mean" (confidence-weighted mean).
    pub fusion: String,
    /// With `fusion = "mean"`: views whose rotation differs from the best
    /// view's by more than this (degrees) do not enter the mean rotation.
    pub max_rotation_deg: f64,
}

impl Default for CellConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            max_age_ms: 150.0,
            merge_distance_m: 0.0,
            fusion: "best-fit".to_owned(),
            max_rotation_deg: 20.0,
        }
    }
}

/// One served camera with every setting resolved.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraSettings {
    pub name: String,
    pub deadline_ns: u64,
    pub max_instances: usize,
    /// `[estimator]` with this camera's overrides applied (`max_instances` is the field above).
    pub estimator: EstimatorConfig,
    pub extrinsics: Extrinsics,
}

/// `[estimator]`
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EstimatorConfig {
    pub kind: EstimatorKind,
    /// Network weights (safetensors), for `kind = "net"`.
    pub weights: PathBuf,
    /// `builtin` or a directory of meshes (see `scene::mesh_io::load_object_dir`).
    pub objects: String,
    /// Mesh units → metres for an objects directory (0.001 for millimetre meshes).
    pub objects_scale: f64,
    /// Points sampled per instance (N). Unset: the network's own (from the
    /// weight file); ICP: 500. Set: overrides the weight file's N.
    pub num_points: Option<usize>,
    /// Colour crop side, pixels (S). Unset: the network's own (from the weight
    /// file); ICP: 64. Set: overrides the weight file's S.
    pub crop_size: Option<usize>,
    /// Most instances estimated per frame (largest first).
    pub max_instances: usize,
    /// Smallest instance mask kept, pixels.
    pub min_pixels: usize,
    /// Metres: an instance's pixels lying within this height of the surface
    /// the objects stand on (a plane fitted to the frame's background) are
    /// not its points: a mask that bled onto the table, a shadow or a table
    /// texture taken for an object. 0 = off
    /// (`fusepose_estimator::WorkspaceConfig::support_floor_m`).
    pub support_floor: f32,
    /// Refinement iterations (ICP iterations or refiner passes).
    pub refine_iterations: usize,
    /// Threads per frame for estimation: the network uses up to 2 (the loop
    /// thread plus one persistent worker); ICP runs inline (1). Larger values
    /// are accepted with a warning. Unset: as many as the machine has CPUs
    /// (at most 2), see [`EstimatorConfig::estimation_threads`].
    pub worker_threads: Option<usize>,
    /// Instance labels: `auto`, `labels` or `net` (see [`MaskSource`]).
    pub masks: MaskSource,
    /// Network: fit each frame into its deadline (fewer refiner iterations,
    /// then fewer points; the message then carries DEGRADED).
    pub deadline_aware: bool,
    /// Poses with a lower confidence (0..1) are not published. 0 publishes
    /// all; the useful threshold depends on the weights (docs/BENCHMARKS.md,
    /// "Ghost objects").
    pub min_confidence: f32,
    /// Pose verification against the depth image: "drop" (default: poses that
    /// fail are not published), "flag" (published with VERIFIED clear), "off".
    pub verify: String,
    /// Verification thresholds (`fusepose_estimator::verify::VerifyConfig`):
    /// least fit (inliers × coverage × (1 − behind)) and least inlier fraction.
    pub verify_min_fit: f32,
    pub verify_min_inliers: f32,
    /// Least share of a pose's silhouette with a depth reading (a pose over
    /// a void fails) and most share of a flat mask's border on its plane (a
    /// marking on a table or wall fails); see `VerifyConfig`.
    pub verify_min_depth_support: f32,
    pub verify_max_plane_continuation: f32,
    /// Most share of a mask's border where the depth goes on smoothly (any
    /// surface shape; `VerifyConfig::max_depth_continuity`).
    pub verify_max_depth_continuity: f32,
    /// For objects thinner than 2.5 cm, instead of depth continuity: least
    /// share of the model's depth-agreeing surface inside the mask
    /// (`VerifyConfig::min_thin_mask_agreement`).
    pub verify_min_thin_mask_agreement: f32,
    /// A pose of an object at least 15 cm across with at least this share of
    /// its depth-agreeing surface inside the mask is only imprecise, not a
    /// ghost: it needs just 0.3 inliers and 0.25 fit
    /// (`VerifyConfig::agreeing_mask_agreement`). Above 1 = off.
    pub verify_agreeing_mask_agreement: f32,
    /// A region whose pixels with depth lie at least this much on the
    /// support plane is judged on its other pixels (the segmenter spread the
    /// object's class over the table around it;
    /// `VerifyConfig::trim_table_share`). Above 1 = off.
    pub verify_trim_table_share: f32,
    /// A pose with more than this share of its surface samples 3 cm or more
    /// below the support plane fails: a solid object cannot stand inside the
    /// table (`VerifyConfig::max_below_support`). Above 1 = off, the default:
    /// 0.05 halves the wrong poses on path-traced images for 0.1-0.6 ADD(S)
    /// AUC (docs/BENCHMARKS.md, session 40).
    pub verify_max_below_support: f32,
    /// A pose whose region covers less than this share of the object's
    /// largest face (back-projected at the pose's depth) fails
    /// (`VerifyConfig::min_region_area_share`). 0 = off.
    pub verify_min_region_area_share: f32,
    /// A pose whose odds of being right, by the weight file's fitted model
    /// (`fusepose train --stage odds`; `fusepose_estimator::pose_odds`),
    /// are below this fails (`VerifyConfig::min_odds`). 0 = off, the
    /// default; a weight file without a model leaves it off (warned).
    pub verify_min_odds: f32,
    /// With the built-in segmenter: a pose whose region the segmenter nowhere
    /// gave its class with at least this probability fails (the segmenter
    /// made the region up; `VerifyConfig::min_region_probability`). 0 = off.
    pub verify_min_region_probability: f32,
    /// With the built-in segmenter: the same test with a floor set per model,
    /// the segmenter's certainty of real objects at this quantile as its
    /// weight file records it (`fusepose train --stage calibrate`; e.g. 0.05
    /// fails a region the segmenter is less sure of than it is of 95 % of
    /// real objects). 0 = off; the higher of this and
    /// `verify_min_region_probability` applies. A file without the record
    /// leaves it off, with a warning.
    pub verify_region_certainty_quantile: f32,
    /// Regions of one class whose points fit inside one object (within this
    /// factor × its diameter) are joined into one instance: an occluder that
    /// splits an object no longer makes two poses. 0 keeps every region.
    pub join_parts: f32,
    /// Several copies, not one: a region of one class whose points do not
    /// fit inside one object (this factor × its diameter) is cut into the
    /// fewest pieces that each do (`fusepose_estimator::split`). 0 = off.
    pub split_regions: f32,
    /// One object, not two: segmenter instances of a class whose 3D centres
    /// lie within this factor × the object's smallest side become one, and a
    /// pose that close to a better-fitting pose of its class is dropped
    /// (`fusepose_estimator::duplicates`). 0 = off.
    pub duplicates: f32,
    /// Two solid objects cannot share space: of two poses whose solids
    /// overlap by more than this share, the one more inside the other is
    /// dropped (`fusepose_estimator::interpenetration`). 1 = off.
    pub max_interpenetration: f32,
    /// One surface, one object: of two verified poses where one's model
    /// explains more than this share of the other's region, the one more
    /// explained by the other is dropped (`fusepose_estimator::explained`).
    /// Needs verification. 1 = off.
    pub max_explained_share: f32,
    /// Built-in segmenter with verification: a region whose runner-up class
    /// has at least this mean segmenter probability over it is estimated as
    /// that class too, and the better-verified pose is kept
    /// (`fusepose_estimator::alternates`). 0 = off.
    pub class_alternates: f32,
    /// With verification, on class-label planes: a region whose pose covers
    /// less than this share of it (copies side by side that passed as one)
    /// is cut (`recut_pieces`), each piece estimated, and the cut kept when
    /// two poses or more pass and are copies by the depth image
    /// (`fusepose_estimator::recut`). Failed poses are dropped after it has
    /// looked (`recut_poses`). 0 = off.
    pub recut: f32,
    /// `recut`: where the cut comes from: `votes` (the segmenter's
    /// centre-offset votes where its file has the head and they point at two
    /// centres, else as `creases`), `creases` (concave folds and steps of the
    /// depth image where they part the region, `fusepose_estimator::creases`,
    /// else the region's 3D points), `votes-only`, `contacts` (the
    /// segmenter's contact band where its file has the branch) or `points`
    /// (`fusepose_estimator::recut::CutProposal`).
    pub recut_proposal: String,
    /// `recut`: most pieces a region is cut into (2 to 6): one whose pose
    /// covers a share c of it is cut into 1 ÷ c pieces, rounded up
    /// (`fusepose_estimator::recut::pieces_for`).
    pub recut_pieces: usize,
    /// `recut`: which regions' poses qualify besides their coverage:
    /// `passed` (verified poses), `coverage` (also poses that failed on their
    /// coverage alone) or `any` (any pose of a region the segmenter was sure
    /// of) (`fusepose_estimator::recut::RecutPoses`).
    pub recut_poses: String,
    /// `recut`: once the pieces have poses, give each pixel to the piece whose
    /// posed bounding box holds it and estimate the pieces again
    /// (`fusepose_estimator::recut::RecutConfig::refit`).
    pub recut_refit: bool,
    /// `recut`: a piece counts as a copy only when its pose's verification
    /// fit is at least this (0 = any passing pose;
    /// `fusepose_estimator::recut::RecutConfig::min_piece_fit`).
    pub recut_min_piece_fit: f32,
    /// `recut`: a refused cut's best passed piece pose replaces the region's
    /// pose where it fits better
    /// (`fusepose_estimator::recut::RecutConfig::best_piece`).
    pub recut_best_piece: bool,
    /// With verification, on class-label planes: at most this many poses per
    /// frame that failed verification get a second mask, the pixels inside
    /// their posed bounding box grown by `remask_margin_m` (above the
    /// support plane, outside regions whose pose passed), are estimated
    /// again (`remask_rounds` times) and replaced when the new pose passes
    /// on their region (`fusepose_estimator::remask`). Budgeted like the
    /// second look. 0 = off.
    pub remask: usize,
    /// `remask`: metres the posed box grows by on every side.
    pub remask_margin_m: f32,
    /// `remask`: estimates per second mask, each pose placing the next box.
    pub remask_rounds: usize,
    /// A published pose gets `PoseFlags::CONFIRMED` when a pose of its class
    /// lay within this distance of it in the camera's previous processed
    /// frame that looked at the class (one that shed an instance of it to
    /// keep its deadline does not count) (metres, camera frame; 0 = never
    /// set) (`crate::confirm`).
    pub confirm_within_m: f64,
    /// `confirm_within_m`: in how many of the camera's last processed frames
    /// that looked at the class (1 = the last one; up to 24; frames that
    /// shed the class are skipped, 24 frames back at most): more bridges
    /// frames where the object was missed, but confirms more poses that lie
    /// between copies.
    pub confirm_frames: u32,
    /// Built-in segmenter: how its cell labels become frame labels: `refine:N`
    /// (pixel borders from interpolated scores, N pixels eroded), `erode-cells`
    /// or `cells` (`fusepose_estimator::seg::Boundary`).
    pub seg_boundary: String,
    /// Built-in segmenter with a centre-offset head: `on` (touching objects
    /// of a class separated by their centre votes), `off` (the head ignored:
    /// class regions, rejoined by `join_parts`) or a peak search
    /// `MIN_VOTES,MERGE_RADIUS_CELLS,MIN_CELLS` (`fusepose_estimator::seg::VotingMode`).
    pub seg_voting: String,
    /// Built-in segmenter: its cells regrouped by the depth image before the
    /// clean-up (`fusepose_estimator::seg::DepthRegions`): `on` (the measured
    /// defaults), `off`, or `KEY=VALUE,…` over the defaults (height, step,
    /// step-per-m, share, absorb, absorb-p, slack).
    pub seg_depth_regions: String,
    /// Dim frames brightened by one gain in linear light before the networks
    /// (`fusepose_estimator::exposure`): `on` (the default, with the measured
    /// settings), `off`, or `KEY=VALUE,…` over them (target, quantile, max-gain).
    pub auto_exposure: String,
    /// Strongly tinted frames' light undone by one gain per channel before
    /// the networks, after auto exposure (`fusepose_estimator::white_balance`):
    /// `off`, `on` (the measured settings) or `KEY=VALUE,…` over them (band, quantile).
    pub white_balance: String,
    /// CPUs to pin the loop thread and the network's worker thread to, in that
    /// order (empty = no pinning).
    pub pin_cpus: Vec<usize>,
    pub tracking: TrackingSettings,
}

/// `[estimator.tracking]`: start the refiner from the previous frame's pose (network only).
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrackingSettings {
    pub enabled: bool,
    /// A pose is kept and tracked when the median distance of the observed
    /// points to the posed model is at most this, millimetres.
    pub max_fit_mm: f64,
    /// A full estimate at least every this many frames per object.
    pub full_estimate_every: u32,
    /// Refiner iterations when tracking.
    pub refine_iterations: usize,
}

impl EstimatorConfig {
    /// Threads the network may use per frame: `worker_threads`, else the
    /// CPUs this process may run on (`available_parallelism`), at most 2.
    pub fn estimation_threads(&self) -> usize {
        let machine = || std::thread::available_parallelism().map_or(1, |n| n.get());
        self.worker_threads.unwrap_or_else(machine).clamp(1, 2)
    }
}

impl Default for TrackingSettings {
    fn default() -> Self {
        Self { enabled: false, max_fit_mm: 8.0, full_estimate_every: 5, refine_iterations: 2 }
    }
}

/// `[stats]`
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StatsConfig {
    /// Length of the "last window" histograms and of each `.hlog` interval, seconds.
    pub window_s: f64,
    /// How often a summary line per camera is logged, seconds (0 = never).
    pub summary_interval_s: f64,
    /// HdrHistogram interval log written at every window and on exit ("" = none).
    pub hlog_path: PathBuf,
}

/// `[ipc]`
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IpcConfig {
    /// iceoryx2 root directory ("" = iceoryx2's default `/tmp/iceoryx2/`).
    pub root_path: PathBuf,
    /// iceoryx2 resource prefix ("" = `iox2_`).
    pub prefix: String,
    /// How often resources of dead processes are removed, seconds.
    pub cleanup_interval_s: f64,
    /// Period of the loop's housekeeping tick (stats requests, windows, cleanup), milliseconds.
    pub tick_ms: u64,
    /// Poll for the next frame from this long before it is due (the camera
    /// period is learned) instead of waiting for the event wake-up, µs (0 =
    /// never). Applies only when the loop thread is pinned (`estimator.pin_cpus`).
    pub receive_spin_us: u64,
}

impl Default for DaemonConfig {
    fn default() -> Self {
        Self {
            cameras: vec!["cam0".to_owned()],
            log_level: "info".to_owned(),
            deadline_ms: 1000.0 / 24.0,
            camera: Vec::new(),
            estimator: EstimatorConfig::default(),
            stats: StatsConfig::default(),
            ipc: IpcConfig::default(),
            cell: CellConfig::default(),
        }
    }
}

impl Default for EstimatorConfig {
    fn default() -> Self {
        Self {
            kind: EstimatorKind::Net,
            weights: PathBuf::from("models/builtin.safetensors"),
            objects: "builtin".to_owned(),
            objects_scale: 1.0,
            num_points: None,
            crop_size: None,
            max_instances: 8,
            min_pixels: 50,
            support_floor: fusepose_estimator::workspace::DEFAULT_SUPPORT_FLOOR_M,
            refine_iterations: 2,
            worker_threads: None,
            masks: MaskSource::Auto,
            deadline_aware: true,
            min_confidence: 0.0,
            verify: "drop".to_owned(),
            verify_min_fit: fusepose_estimator::verify::VerifyConfig::default().min_fit,
            verify_min_inliers: fusepose_estimator::verify::VerifyConfig::default().min_inlier_fraction,
            verify_min_depth_support: fusepose_estimator::verify::VerifyConfig::default().min_depth_support,
            verify_max_plane_continuation: fusepose_estimator::verify::VerifyConfig::default().max_plane_continuation,
            verify_max_depth_continuity: fusepose_estimator::verify::VerifyConfig::default().max_depth_continuity,
            verify_min_thin_mask_agreement: fusepose_estimator::verify::VerifyConfig::default().min_thin_mask_agreement,
            verify_agreeing_mask_agreement: fusepose_estimator::verify::VerifyConfig::default().agreeing_mask_agreement,
            verify_trim_table_share: fusepose_estimator::verify::VerifyConfig::default().trim_table_share,
            verify_max_below_support: fusepose_estimator::verify::VerifyConfig::default().max_below_support,
            verify_min_region_area_share: fusepose_estimator::verify::VerifyConfig::default().min_region_area_share,
            verify_min_odds: fusepose_estimator::verify::VerifyConfig::default().min_odds,
            verify_min_region_probability: fusepose_estimator::verify::VerifyConfig::default().min_region_probability,
            verify_region_certainty_quantile: DEFAULT_REGION_CERTAINTY_QUANTILE,
            join_parts: 1.0,
            split_regions: 1.0,
            duplicates: 0.0,
            max_interpenetration: fusepose_estimator::interpenetration::DEFAULT_MAX_SHARE,
            max_explained_share: fusepose_estimator::explained::DEFAULT_MAX_SHARE,
            class_alternates: fusepose_estimator::alternates::DEFAULT_MIN_PROBABILITY,
            recut: fusepose_estimator::recut::RecutConfig::DEFAULT.max_coverage,
            recut_proposal: fusepose_estimator::recut::RecutConfig::DEFAULT.proposal.to_string(),
            recut_pieces: fusepose_estimator::recut::RecutConfig::DEFAULT.max_pieces,
            recut_poses: fusepose_estimator::recut::RecutConfig::DEFAULT.poses.to_string(),
            recut_refit: fusepose_estimator::recut::RecutConfig::DEFAULT.refit,
            recut_min_piece_fit: fusepose_estimator::recut::RecutConfig::DEFAULT.min_piece_fit,
            recut_best_piece: fusepose_estimator::recut::RecutConfig::DEFAULT.best_piece,
            remask: fusepose_estimator::remask::RemaskConfig::DEFAULT.max_regions,
            remask_margin_m: fusepose_estimator::remask::RemaskConfig::DEFAULT.margin_m,
            remask_rounds: fusepose_estimator::remask::RemaskConfig::DEFAULT.rounds,
            confirm_within_m: DEFAULT_CONFIRM_WITHIN_M,
            confirm_frames: 1,
            seg_boundary: fusepose_estimator::seg::Boundary::default().to_string(),
            seg_voting: "off".to_owned(),
            seg_depth_regions: "on".to_owned(),
            auto_exposure: "on".to_owned(),
            white_balance: "off".to_owned(),
            pin_cpus: Vec::new(),
            tracking: TrackingSettings::default(),
        }
    }
}

impl Default for StatsConfig {
    fn default() -> Self {
        Self { window_s: 10.0, summary_interval_s: 10.0, hlog_path: PathBuf::from("fuseposed.hlog") }
    }
}

impl Default for IpcConfig {
    fn default() -> Self {
        Self {
            root_path: PathBuf::new(),
            prefix: String::new(),
            cleanup_interval_s: 5.0,
            tick_ms: 20,
            receive_spin_us: 200,
        }
    }
}

/// Why a configuration was refused.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("cannot read {path}: {source}")]
    Read { path: PathBuf, source: std::io::Error },
    #[error("{path}: {message}")]
    Parse { path: PathBuf, message: String },
    #[error("{key} = {value}: {rule}")]
    Invalid { key: &'static str, value: String, rule: &'static str },
}

fn invalid(key: &'static str, value: impl std::fmt::Debug, rule: &'static str) -> ConfigError {
    ConfigError::Invalid { key, value: format!("{value:?}"), rule }
}

impl DaemonConfig {
    /// Reads and checks a configuration file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text =
            std::fs::read_to_string(path).map_err(|source| ConfigError::Read { path: path.to_owned(), source })?;
        Self::parse(&text).map_err(|e| match e {
            ConfigError::Parse { message, .. } => ConfigError::Parse { path: path.to_owned(), message },
            other => other,
        })
    }

    /// Parses and checks configuration text.
    pub fn parse(text: &str) -> Result<Self, ConfigError> {
        let parse_error =
            |e: toml::de::Error| ConfigError::Parse { path: PathBuf::from("<text>"), message: e.to_string() };
        let mut config: Self = toml::from_str(text).map_err(parse_error)?;
        // `[[camera]]` tables without a `cameras` list: those tables are the cameras.
        let table: toml::Table = toml::from_str(text).map_err(parse_error)?;
        if !table.contains_key("cameras") && !config.camera.is_empty() {
            config.cameras.clear();
        }
        config.validate()?;
        Ok(config)
    }

    /// Every served camera with its settings resolved: `cameras` first, then `[[camera]]` tables.
    pub fn camera_settings(&self) -> Vec<CameraSettings> {
        let plain = self.cameras.iter().map(|name| CameraSettings {
            name: name.clone(),
            deadline_ns: self.deadline_ns(),
            max_instances: self.estimator.max_instances,
            estimator: self.estimator.clone(),
            extrinsics: Extrinsics::default(),
        });
        let own = self.camera.iter().map(|c| {
            let mut estimator = self.estimator.clone();
            if let Some(w) = &c.weights {
                estimator.weights = w.clone();
            }
            if let Some(o) = &c.objects {
                estimator.objects = o.clone();
            }
            if let Some(s) = c.objects_scale {
                estimator.objects_scale = s;
            }
            if let Some(m) = c.masks {
                estimator.masks = m;
            }
            CameraSettings {
                name: c.name.clone(),
                deadline_ns: (c.deadline_ms.unwrap_or(self.deadline_ms) * 1e6).round() as u64,
                max_instances: c.max_instances.unwrap_or(self.estimator.max_instances),
                estimator,
                extrinsics: c.extrinsics,
            }
        });
        plain.chain(own).collect()
    }

    /// Names of every served camera, in [`DaemonConfig::camera_settings`] order.
    pub fn camera_names(&self) -> Vec<String> {
        self.cameras.iter().cloned().chain(self.camera.iter().map(|c| c.name.clone())).collect()
    }

    /// Checks value ranges; the error names the offending key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let names = self.camera_names();
        if names.is_empty() {
            return Err(invalid("cameras", &self.cameras, "list at least one camera (or give [[camera]] tables)"));
        }
        if names.len() > MAX_CAMERAS {
            return Err(invalid("cameras", names.len(), "at most 16 cameras per daemon"));
        }
        for (i, name) in names.iter().enumerate() {
            let key = if i < self.cameras.len() { "cameras" } else { "camera.name" };
            if fusepose_client::validate_camera_name(name).is_err() {
                return Err(invalid(key, name, "names are 1 to 64 characters of [A-Za-z0-9_-]"));
            }
            if names[..i].contains(name) {
                return Err(invalid(key, name, "each camera may appear once (in `cameras` or one [[camera]] table)"));
            }
        }
        for c in &self.camera {
            if let Some(d) = c.deadline_ms
                && !(d.is_finite() && d > 0.0)
            {
                return Err(invalid("camera.deadline_ms", (&c.name, d), "must be a positive number of milliseconds"));
            }
            if let Some(m) = c.max_instances
                && (m == 0 || m > fusepose_client::MAX_OBJECTS)
            {
                return Err(invalid("camera.max_instances", (&c.name, m), "must be in 1..=32 (poses per message)"));
            }
            if let Some(s) = c.objects_scale
                && !(s.is_finite() && s > 0.0)
            {
                return Err(invalid("camera.objects_scale", (&c.name, s), "must be positive"));
            }
            let x = &c.extrinsics;
            if !x.translation_m.iter().all(|v| v.is_finite() && v.abs() < 1e3) {
                return Err(invalid(
                    "camera.extrinsics.translation_m",
                    (&c.name, x.translation_m),
                    "must be finite metres (under 1 km)",
                ));
            }
            let norm = x.quaternion_xyzw.iter().map(|v| v * v).sum::<f64>().sqrt();
            if !(norm.is_finite() && (norm - 1.0).abs() <= 1e-3) {
                return Err(invalid(
                    "camera.extrinsics.quaternion_xyzw",
                    (&c.name, x.quaternion_xyzw),
                    "must be a unit quaternion [x, y, z, w] (length 1 within 1e-3)",
                ));
            }
        }
        let cell = &self.cell;
        if !(cell.max_age_ms.is_finite() && cell.max_age_ms > 0.0) {
            return Err(invalid("cell.max_age_ms", cell.max_age_ms, "must be a positive number of milliseconds"));
        }
        if !(cell.merge_distance_m.is_finite() && (0.0..=1.0).contains(&cell.merge_distance_m)) {
            return Err(invalid(
                "cell.merge_distance_m",
                cell.merge_distance_m,
                "must be in 0..=1 metres (0 = half the object's diameter)",
            ));
        }
        if cell.fusion.parse::<crate::cell::Fusion>().is_err() {
            return Err(invalid("cell.fusion", &cell.fusion, "must be \"best-fit\" or \"mean\""));
        }
        if !(cell.max_rotation_deg.is_finite() && (0.0..=180.0).contains(&cell.max_rotation_deg)) {
            return Err(invalid("cell.max_rotation_deg", cell.max_rotation_deg, "must be in 0..=180 degrees"));
        }
        if !(self.deadline_ms.is_finite() && self.deadline_ms > 0.0) {
            return Err(invalid("deadline_ms", self.deadline_ms, "must be a positive number of milliseconds"));
        }
        let e = &self.estimator;
        if !(e.objects_scale.is_finite() && e.objects_scale > 0.0) {
            return Err(invalid("estimator.objects_scale", e.objects_scale, "must be positive"));
        }
        if let Some(n) = e.num_points
            && (n == 0 || n > 1 << 20)
        {
            return Err(invalid("estimator.num_points", n, "must be in 1..=1048576 (or unset: the weight file's)"));
        }
        if let Some(s) = e.crop_size
            && (s == 0 || s > 1024)
        {
            return Err(invalid("estimator.crop_size", s, "must be in 1..=1024 (or unset: the weight file's)"));
        }
        if e.max_instances == 0 || e.max_instances > fusepose_client::MAX_OBJECTS {
            return Err(invalid("estimator.max_instances", e.max_instances, "must be in 1..=32 (poses per message)"));
        }
        if e.refine_iterations > 1000 {
            return Err(invalid("estimator.refine_iterations", e.refine_iterations, "must be at most 1000"));
        }
        if !(e.join_parts.is_finite() && (0.0..=4.0).contains(&e.join_parts)) {
            return Err(invalid("estimator.join_parts", e.join_parts, "must be in 0..=4 (0 = off)"));
        }
        if !(e.split_regions.is_finite() && (e.split_regions == 0.0 || (0.5..=4.0).contains(&e.split_regions))) {
            return Err(invalid("estimator.split_regions", e.split_regions, "must be 0 (off) or in 0.5..=4"));
        }
        if !(e.max_interpenetration.is_finite() && (0.05..=1.0).contains(&e.max_interpenetration)) {
            return Err(invalid(
                "estimator.max_interpenetration",
                e.max_interpenetration,
                "must be in 0.05..=1 (1 = off)",
            ));
        }
        if !(e.max_explained_share.is_finite() && (0.05..=1.0).contains(&e.max_explained_share)) {
            return Err(invalid(
                "estimator.max_explained_share",
                e.max_explained_share,
                "must be in 0.05..=1 (1 = off)",
            ));
        }
        if !(e.support_floor.is_finite() && (0.0..=0.05).contains(&e.support_floor)) {
            return Err(invalid(
                "estimator.support_floor",
                e.support_floor,
                "must be in 0..=0.05 metres (0 = off; 0.004 is the default, not 4 mm written as 4)",
            ));
        }
        if !(e.duplicates.is_finite() && (0.0..=2.0).contains(&e.duplicates)) {
            return Err(invalid("estimator.duplicates", e.duplicates, "must be in 0..=2 (0 = off)"));
        }
        if e.seg_boundary.parse::<fusepose_estimator::seg::Boundary>().is_err() {
            return Err(invalid(
                "estimator.seg_boundary",
                &e.seg_boundary,
                "must be refine:N (N in 0..=255), erode-cells or cells",
            ));
        }
        if e.recut_proposal.parse::<fusepose_estimator::recut::CutProposal>().is_err() {
            return Err(invalid(
                "estimator.recut_proposal",
                &e.recut_proposal,
                "must be \"votes\", \"votes-only\", \"contacts\" or \"points\"",
            ));
        }
        if !(0.0..=1.0).contains(&e.confirm_within_m) {
            return Err(invalid("estimator.confirm_within_m", e.confirm_within_m, "must be in 0..=1 metres (0 = off)"));
        }
        if !(1..=crate::confirm::MAX_CONFIRM_FRAMES).contains(&e.confirm_frames) {
            return Err(invalid("estimator.confirm_frames", e.confirm_frames, "must be in 1..=24 frames"));
        }
        if e.remask > fusepose_estimator::remask::MAX_REGIONS {
            return Err(invalid("estimator.remask", e.remask, "must be in 0..=16 poses per frame (0 = off)"));
        }
        if !(0.0..=0.1).contains(&e.remask_margin_m) {
            return Err(invalid("estimator.remask_margin_m", e.remask_margin_m, "must be in 0..=0.1 metres"));
        }
        if !(1..=fusepose_estimator::remask::MAX_ROUNDS).contains(&e.remask_rounds) {
            return Err(invalid("estimator.remask_rounds", e.remask_rounds, "must be in 1..=4"));
        }
        if !(2..=fusepose_estimator::recut::MAX_CUT_PIECES).contains(&e.recut_pieces) {
            return Err(invalid("estimator.recut_pieces", e.recut_pieces, "must be in 2..=6"));
        }
        if e.recut_poses.parse::<fusepose_estimator::recut::RecutPoses>().is_err() {
            return Err(invalid(
                "estimator.recut_poses",
                &e.recut_poses,
                "must be \"passed\", \"coverage\" or \"any\"",
            ));
        }
        if e.seg_voting.parse::<fusepose_estimator::seg::VotingMode>().is_err() {
            return Err(invalid(
                "estimator.seg_voting",
                &e.seg_voting,
                "must be \"on\", \"off\" or MIN_VOTES,MERGE_RADIUS_CELLS,MIN_CELLS (e.g. \"6,3,6\")",
            ));
        }
        if fusepose_estimator::seg::DepthRegionParams::parse_setting(&e.seg_depth_regions).is_err() {
            return Err(invalid(
                "estimator.seg_depth_regions",
                &e.seg_depth_regions,
                "must be \"on\", \"off\" or KEY=VALUE,... (keys height, step, step-per-m, share, absorb, absorb-p, slack; numbers >= 0)",
            ));
        }
        if fusepose_estimator::exposure::ExposureConfig::parse_setting(&e.auto_exposure).is_err() {
            return Err(invalid(
                "estimator.auto_exposure",
                &e.auto_exposure,
                "must be \"on\", \"off\" or KEY=VALUE,... (target in (0, 1] linear brightness, quantile in 0..=1, max-gain >= 1)",
            ));
        }
        if fusepose_estimator::white_balance::WhiteBalanceConfig::parse_setting(&e.white_balance).is_err() {
            return Err(invalid(
                "estimator.white_balance",
                &e.white_balance,
                "must be \"on\", \"off\" or KEY=VALUE,... (band >= 0 as a log ratio, quantile in 0..=1)",
            ));
        }
        if !["drop", "flag", "off"].contains(&e.verify.as_str()) {
            return Err(invalid("estimator.verify", &e.verify, "must be \"drop\", \"flag\" or \"off\""));
        }
        for (key, v) in [
            ("estimator.verify_min_fit", e.verify_min_fit),
            ("estimator.verify_min_inliers", e.verify_min_inliers),
            ("estimator.verify_min_depth_support", e.verify_min_depth_support),
            ("estimator.verify_max_plane_continuation", e.verify_max_plane_continuation),
            ("estimator.verify_max_depth_continuity", e.verify_max_depth_continuity),
            ("estimator.verify_min_thin_mask_agreement", e.verify_min_thin_mask_agreement),
            ("estimator.verify_min_region_probability", e.verify_min_region_probability),
            ("estimator.class_alternates", e.class_alternates),
            ("estimator.recut", e.recut),
            ("estimator.recut_min_piece_fit", e.recut_min_piece_fit),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(invalid(key, v, "must be in 0..=1"));
            }
        }
        let q = e.verify_region_certainty_quantile;
        if !(q == 0.0 || (0.01..=0.5).contains(&q)) {
            return Err(invalid(
                "estimator.verify_region_certainty_quantile",
                q,
                "must be 0 (off) or in 0.01..=0.5 (a quantile of the segmenter's certainty of real objects)",
            ));
        }
        if !(e.verify_agreeing_mask_agreement.is_finite() && e.verify_agreeing_mask_agreement >= 0.0) {
            return Err(invalid(
                "estimator.verify_agreeing_mask_agreement",
                e.verify_agreeing_mask_agreement,
                "must be a number >= 0 (above 1 turns it off)",
            ));
        }
        if !(e.verify_trim_table_share.is_finite() && e.verify_trim_table_share >= 0.0) {
            return Err(invalid(
                "estimator.verify_trim_table_share",
                e.verify_trim_table_share,
                "must be a number >= 0 (a share of the region's pixels; above 1 turns it off)",
            ));
        }
        if !(e.verify_max_below_support.is_finite() && e.verify_max_below_support >= 0.0) {
            return Err(invalid(
                "estimator.verify_max_below_support",
                e.verify_max_below_support,
                "must be a number >= 0 (a share of the model's surface; above 1 turns it off)",
            ));
        }
        if !(0.0..=1.0).contains(&e.verify_min_region_area_share) {
            return Err(invalid(
                "estimator.verify_min_region_area_share",
                e.verify_min_region_area_share,
                "must be in 0..=1 (a share of the object's largest face; 0 turns it off)",
            ));
        }
        if !(0.0..1.0).contains(&e.verify_min_odds) {
            return Err(invalid(
                "estimator.verify_min_odds",
                e.verify_min_odds,
                "must be in 0..1 (a probability that the pose is right; 0 turns it off)",
            ));
        }
        if !(0.0..=1.0).contains(&e.min_confidence) {
            return Err(invalid("estimator.min_confidence", e.min_confidence, "must be in 0..=1"));
        }
        if let Some(t) = e.worker_threads
            && (t == 0 || t > 64)
        {
            return Err(invalid("estimator.worker_threads", t, "must be in 1..=64 (or unset: the machine's CPUs)"));
        }
        let t = &e.tracking;
        if !(t.max_fit_mm.is_finite() && t.max_fit_mm > 0.0) {
            return Err(invalid(
                "estimator.tracking.max_fit_mm",
                t.max_fit_mm,
                "must be a positive number of millimetres",
            ));
        }
        if t.full_estimate_every == 0 {
            return Err(invalid("estimator.tracking.full_estimate_every", t.full_estimate_every, "must be at least 1"));
        }
        if t.refine_iterations == 0 || t.refine_iterations > 100 {
            return Err(invalid("estimator.tracking.refine_iterations", t.refine_iterations, "must be in 1..=100"));
        }
        if e.pin_cpus.len() > 2 {
            return Err(invalid("estimator.pin_cpus", &e.pin_cpus, "at most 2 CPUs (loop thread, network worker)"));
        }
        let s = &self.stats;
        if !(s.window_s.is_finite() && s.window_s >= 0.1) {
            return Err(invalid("stats.window_s", s.window_s, "must be at least 0.1 seconds"));
        }
        if !(s.summary_interval_s.is_finite() && s.summary_interval_s >= 0.0) {
            return Err(invalid("stats.summary_interval_s", s.summary_interval_s, "must be >= 0 (0 = never)"));
        }
        let i = &self.ipc;
        if !(i.cleanup_interval_s.is_finite() && i.cleanup_interval_s > 0.0) {
            return Err(invalid("ipc.cleanup_interval_s", i.cleanup_interval_s, "must be positive"));
        }
        if i.receive_spin_us > 100_000 {
            return Err(invalid("ipc.receive_spin_us", i.receive_spin_us, "must be at most 100000 (0 = never poll)"));
        }
        if i.tick_ms == 0 || i.tick_ms > 10_000 {
            return Err(invalid("ipc.tick_ms", i.tick_ms, "must be in 1..=10000"));
        }
        if !i.prefix.is_empty() && !i.prefix.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-') {
            return Err(invalid("ipc.prefix", &i.prefix, "use [A-Za-z0-9_-] only"));
        }
        Ok(())
    }

    pub fn deadline_ns(&self) -> u64 {
        (self.deadline_ms * 1e6).round() as u64
    }

    /// The client-library options for this configuration.
    pub fn ipc_options(&self) -> fusepose_client::IpcOptions {
        fusepose_client::IpcOptions {
            root_path: (!self.ipc.root_path.as_os_str().is_empty()).then(|| self.ipc.root_path.clone()),
            prefix: (!self.ipc.prefix.is_empty()).then(|| self.ipc.prefix.clone()),
            node_name: Some("fuseposed".to_owned()),
            handle_signals: true,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_file_gives_all_defaults() {
        let c = DaemonConfig::parse("").unwrap();
        assert_eq!(c, DaemonConfig::default());
        assert_eq!(c.deadline_ns(), 41_666_667);
        assert_eq!(c.estimator.kind, EstimatorKind::Net);
    }

    #[test]
    fn shipped_config_parses() {
        let text = include_str!("../../config/fuseposed.toml");
        let c = DaemonConfig::parse(text).unwrap();
        assert_eq!(c.cameras, ["cam0"]);
        assert_eq!(c.estimator.kind, EstimatorKind::Net, "the shipped config runs the shipped network");
        // Sizes come from the weight file and threads from the machine unless overridden.
        assert_eq!((c.estimator.num_points, c.estimator.crop_size, c.estimator.worker_threads), (None, None, None));
    }

    #[test]
    fn the_agreeing_mask_slack_is_checked_and_can_be_turned_off() {
        let default = DaemonConfig::default().estimator.verify_agreeing_mask_agreement;
        assert_eq!(default, fusepose_estimator::verify::VerifyConfig::default().agreeing_mask_agreement);
        let off = DaemonConfig::parse("[estimator]\nverify_agreeing_mask_agreement = 1.5\n").unwrap();
        assert_eq!(off.estimator.verify_agreeing_mask_agreement, 1.5, "above 1 is allowed: off");
        let err = DaemonConfig::parse("[estimator]\nverify_agreeing_mask_agreement = -0.1\n").unwrap_err().to_string();
        assert!(
            err.starts_with("estimator.verify_agreeing_mask_agreement") && err.contains("above 1 turns it off"),
            "{err}"
        );
    }

    #[test]
    fn the_below_support_share_is_checked_and_off_by_default() {
        let default = DaemonConfig::default().estimator.verify_max_below_support;
        assert_eq!(default, fusepose_estimator::verify::VerifyConfig::default().max_below_support);
        assert!(default > 1.0, "off by default");
        let odds = DaemonConfig::parse("[estimator]\nverify_min_odds = 0.3\n").unwrap();
        assert_eq!(odds.estimator.verify_min_odds, 0.3);
        let err = DaemonConfig::parse("[estimator]\nverify_min_odds = 1\n").unwrap_err().to_string();
        assert!(err.starts_with("estimator.verify_min_odds") && err.contains("probability"), "{err}");
        let area = DaemonConfig::parse("[estimator]\nverify_min_region_area_share = 0.02\n").unwrap();
        assert_eq!(area.estimator.verify_min_region_area_share, 0.02);
        let err = DaemonConfig::parse("[estimator]\nverify_min_region_area_share = 2\n").unwrap_err().to_string();
        assert!(err.starts_with("estimator.verify_min_region_area_share"), "{err}");
        let on = DaemonConfig::parse("[estimator]\nverify_max_below_support = 0.05\n").unwrap();
        assert_eq!(on.estimator.verify_max_below_support, 0.05);
        for bad in ["-0.1", "nan", "inf"] {
            let err = DaemonConfig::parse(&format!("[estimator]\nverify_max_below_support = {bad}\n"))
                .unwrap_err()
                .to_string();
            assert!(
                err.starts_with("estimator.verify_max_below_support") && err.contains("above 1 turns it off"),
                "{err}"
            );
        }
    }

    #[test]
    fn the_table_trimming_share_is_checked_and_can_be_turned_off() {
        let default = DaemonConfig::default().estimator.verify_trim_table_share;
        assert_eq!(default, fusepose_estimator::verify::VerifyConfig::default().trim_table_share);
        let off = DaemonConfig::parse("[estimator]\nverify_trim_table_share = 2.0\n").unwrap();
        assert_eq!(off.estimator.verify_trim_table_share, 2.0, "above 1 is allowed: off");
        for bad in ["-0.1", "nan"] {
            let err = DaemonConfig::parse(&format!("[estimator]\nverify_trim_table_share = {bad}\n"))
                .unwrap_err()
                .to_string();
            assert!(
                err.starts_with("estimator.verify_trim_table_share") && err.contains("above 1 turns it off"),
                "{err}"
            );
        }
    }

    #[test]
    fn the_region_certainty_quantile_is_checked() {
        let default = DaemonConfig::default().estimator.verify_region_certainty_quantile;
        assert_eq!(default, fusepose_estimator::seg::file::DEFAULT_CERTAINTY_QUANTILE);
        let off = DaemonConfig::parse("[estimator]\nverify_region_certainty_quantile = 0\n").unwrap();
        assert_eq!(off.estimator.verify_region_certainty_quantile, 0.0);
        for bad in ["0.005", "0.6", "-0.1"] {
            let err = DaemonConfig::parse(&format!("[estimator]\nverify_region_certainty_quantile = {bad}\n"))
                .unwrap_err()
                .to_string();
            assert!(
                err.starts_with("estimator.verify_region_certainty_quantile") && err.contains("0.01..=0.5"),
                "{err}"
            );
        }
    }

    #[test]
    fn the_region_probability_minimum_is_checked() {
        let default = DaemonConfig::default().estimator.verify_min_region_probability;
        assert_eq!(default, fusepose_estimator::verify::VerifyConfig::default().min_region_probability);
        let off = DaemonConfig::parse("[estimator]\nverify_min_region_probability = 0\n").unwrap();
        assert_eq!(off.estimator.verify_min_region_probability, 0.0);
        let err = DaemonConfig::parse("[estimator]\nverify_min_region_probability = 1.2\n").unwrap_err().to_string();
        assert!(err.starts_with("estimator.verify_min_region_probability") && err.contains("0..=1"), "{err}");
    }

    #[test]
    fn support_floor_is_metres_and_checked() {
        let default = DaemonConfig::parse("").unwrap().estimator.support_floor;
        assert_eq!(default, fusepose_estimator::workspace::DEFAULT_SUPPORT_FLOOR_M);
        assert_eq!(DaemonConfig::parse("[estimator]\nsupport_floor = 0\n").unwrap().estimator.support_floor, 0.0);
        // 4 (millimetres written as metres) would clear every object lower than 4 m.
        let err = DaemonConfig::parse("[estimator]\nsupport_floor = 4\n").unwrap_err().to_string();
        assert!(err.starts_with("estimator.support_floor") && err.contains("metres"), "{err}");
    }

    #[test]
    fn mask_sources_parse_and_default_to_auto() {
        assert_eq!(DaemonConfig::parse("").unwrap().estimator.masks, MaskSource::Auto);
        let c = DaemonConfig::parse("[estimator]\nmasks = \"net\"\n").unwrap();
        assert_eq!(c.estimator.masks, MaskSource::Net);
        let err = DaemonConfig::parse("[estimator]\nmasks = \"gt\"\n").unwrap_err().to_string();
        assert!(err.contains("masks") || err.contains("gt"), "{err}");
    }

    #[test]
    fn second_mask_keys_parse_and_are_checked() {
        let d = DaemonConfig::parse("").unwrap().estimator;
        assert_eq!((d.remask, d.remask_margin_m, d.remask_rounds), (4, 0.01, 2), "second masks on by default");
        for (line, key, rule) in [
            ("remask = 17", "estimator.remask", "0..=16"),
            ("remask_margin_m = 0.5", "estimator.remask_margin_m", "0..=0.1 metres"),
            ("remask_margin_m = nan", "estimator.remask_margin_m", "0..=0.1 metres"),
            ("remask_rounds = 0", "estimator.remask_rounds", "1..=4"),
        ] {
            let err = DaemonConfig::parse(&format!("[estimator]\n{line}\n")).unwrap_err().to_string();
            assert!(err.starts_with(key) && err.contains(rule), "{line}: {err}");
        }
        assert_eq!(DaemonConfig::parse("[estimator]\nremask = 0\n").unwrap().estimator.remask, 0);
    }

    #[test]
    fn tracking_deadline_and_spin_keys_parse_and_are_checked() {
        let c = DaemonConfig::parse(
            "[estimator]\ndeadline_aware = false\npin_cpus = [0, 1]\n[estimator.tracking]\nenabled = true\nmax_fit_mm = 5.0\n[ipc]\nreceive_spin_us = 0\n",
        )
        .unwrap();
        assert!(!c.estimator.deadline_aware && c.estimator.tracking.enabled && c.ipc.receive_spin_us == 0);
        assert_eq!((c.estimator.tracking.max_fit_mm, c.estimator.tracking.full_estimate_every), (5.0, 5));
        let err = DaemonConfig::parse("[estimator]\nmin_confidence = 1.5\n").unwrap_err().to_string();
        assert!(err.starts_with("estimator.min_confidence"), "{err}");
        assert_eq!(DaemonConfig::parse("[estimator]\nmin_confidence = 0.05\n").unwrap().estimator.min_confidence, 0.05);
        let err = DaemonConfig::parse("[estimator]\njoin_parts = -1.0\n").unwrap_err().to_string();
        assert!(err.starts_with("estimator.join_parts"), "{err}");
        assert_eq!(DaemonConfig::parse("[estimator]\njoin_parts = 0\n").unwrap().estimator.join_parts, 0.0);
        let err = DaemonConfig::parse("[estimator]\nconfirm_within_m = 10.0\n").unwrap_err().to_string();
        assert!(err.starts_with("estimator.confirm_within_m") && err.contains("metres"), "{err}");
        assert_eq!(DaemonConfig::parse("[estimator]\nconfirm_within_m = 0\n").unwrap().estimator.confirm_within_m, 0.0);
        let err = DaemonConfig::parse("[estimator]\nconfirm_frames = 0\n").unwrap_err().to_string();
        assert!(err.starts_with("estimator.confirm_frames") && err.contains("1..=24"), "{err}");
        assert_eq!(DaemonConfig::parse("[estimator]\nconfirm_frames = 3\n").unwrap().estimator.confirm_frames, 3);
        let err = DaemonConfig::parse("[estimator]\nrecut_min_piece_fit = 1.2\n").unwrap_err().to_string();
        assert!(err.starts_with("estimator.recut_min_piece_fit") && err.contains("0..=1"), "{err}");
        let c = DaemonConfig::parse("[estimator]\nrecut_min_piece_fit = 0.5\n").unwrap();
        assert_eq!(c.estimator.recut_min_piece_fit, 0.5);
        let err = DaemonConfig::parse("[estimator]\nrecut = 1.5\n").unwrap_err().to_string();
        assert!(err.starts_with("estimator.recut"), "{err}");
        assert_eq!(DaemonConfig::parse("[estimator]\nrecut = 0\n").unwrap().estimator.recut, 0.0);
        assert_eq!(
            DaemonConfig::parse("").unwrap().estimator.recut,
            fusepose_estimator::recut::RecutConfig::DEFAULT.max_coverage
        );
        let err = DaemonConfig::parse("[estimator]\nsplit_regions = 0.2\n").unwrap_err().to_string();
        assert!(err.starts_with("estimator.split_regions"), "{err}");
        assert_eq!(DaemonConfig::parse("[estimator]\nsplit_regions = 0\n").unwrap().estimator.split_regions, 0.0);
        let err = DaemonConfig::parse("[estimator]\nduplicates = 3\n").unwrap_err().to_string();
        assert!(err.starts_with("estimator.duplicates") && err.contains("0..=2"), "{err}");
        assert_eq!(DaemonConfig::parse("[estimator]\nduplicates = 0.5\n").unwrap().estimator.duplicates, 0.5);
        let err = DaemonConfig::parse("[estimator]\nmax_interpenetration = 0\n").unwrap_err().to_string();
        assert!(err.starts_with("estimator.max_interpenetration") && err.contains("1 = off"), "{err}");
        let err = DaemonConfig::parse("[estimator]\nmax_explained_share = 1.5\n").unwrap_err().to_string();
        assert!(err.starts_with("estimator.max_explained_share") && err.contains("1 = off"), "{err}");
        let err = DaemonConfig::parse("[estimator]\nseg_boundary = \"erode\"\n").unwrap_err().to_string();
        assert!(err.starts_with("estimator.seg_boundary"), "{err}");
        let err = DaemonConfig::parse("[estimator]\nrecut_proposal = \"vote\"\n").unwrap_err().to_string();
        assert!(err.starts_with("estimator.recut_proposal") && err.contains("\"votes-only\""), "{err}");
        let c = DaemonConfig::parse("[estimator]\nrecut_proposal = \"points\"\n").unwrap();
        assert_eq!(c.estimator.recut_proposal, "points");
        assert_eq!(DaemonConfig::parse("").unwrap().estimator.recut_proposal, "votes");
        for bad in ["1", "7"] {
            let err = DaemonConfig::parse(&format!("[estimator]\nrecut_pieces = {bad}\n")).unwrap_err().to_string();
            assert!(err.starts_with("estimator.recut_pieces") && err.contains("2..=6"), "{err}");
        }
        assert_eq!(DaemonConfig::parse("[estimator]\nrecut_pieces = 4\n").unwrap().estimator.recut_pieces, 4);
        let err = DaemonConfig::parse("[estimator]\nrecut_poses = \"all\"\n").unwrap_err().to_string();
        assert!(err.starts_with("estimator.recut_poses") && err.contains("\"coverage\""), "{err}");
        assert_eq!(DaemonConfig::parse("[estimator]\nrecut_poses = \"any\"\n").unwrap().estimator.recut_poses, "any");
        let err = DaemonConfig::parse("[estimator]\nseg_voting = \"no\"\n").unwrap_err().to_string();
        assert!(err.starts_with("estimator.seg_voting") && err.contains("\"off\""), "{err}");
        let c = DaemonConfig::parse("[estimator]\nseg_voting = \"12,6,6\"\n").unwrap();
        assert_eq!(c.estimator.seg_voting, "12,6,6");
        let err = DaemonConfig::parse("[estimator]\nseg_depth_regions = \"share=lots\"\n").unwrap_err().to_string();
        assert!(err.starts_with("estimator.seg_depth_regions") && err.contains("absorb-p"), "{err}");
        assert_eq!(DaemonConfig::default().estimator.seg_depth_regions, "on");
        let err = DaemonConfig::parse("[estimator]\nauto_exposure = \"target=2\"\n").unwrap_err().to_string();
        assert!(err.starts_with("estimator.auto_exposure") && err.contains("target in (0, 1]"), "{err}");
        let c = DaemonConfig::parse("[estimator]\nauto_exposure = \"max-gain=2\"\n").unwrap();
        assert_eq!(c.estimator.auto_exposure, "max-gain=2");
        let err = DaemonConfig::parse("[estimator]\nwhite_balance = \"band=-1\"\n").unwrap_err().to_string();
        assert!(err.starts_with("estimator.white_balance") && err.contains("band >= 0"), "{err}");
        let c = DaemonConfig::parse("[estimator]\nwhite_balance = \"band=0.2\"\n").unwrap();
        assert_eq!(c.estimator.white_balance, "band=0.2");
        let c = DaemonConfig::parse("[estimator]\nseg_depth_regions = \"off\"\n").unwrap();
        assert_eq!(c.estimator.seg_depth_regions, "off");
        let c = DaemonConfig::parse("[estimator]\nseg_boundary = \"erode-cells\"\n").unwrap();
        assert_eq!(c.estimator.seg_boundary, "erode-cells");
        let err = DaemonConfig::parse("[estimator.tracking]\nfull_estimate_every = 0\n").unwrap_err().to_string();
        assert!(err.starts_with("estimator.tracking.full_estimate_every"), "{err}");
        let err = DaemonConfig::parse("[estimator]\npin_cpus = [0, 1, 2]\n").unwrap_err().to_string();
        assert!(err.starts_with("estimator.pin_cpus"), "{err}");
    }

    #[test]
    fn sizes_and_threads_are_optional_overrides() {
        let c = DaemonConfig::parse("").unwrap();
        assert_eq!((c.estimator.num_points, c.estimator.crop_size, c.estimator.worker_threads), (None, None, None));
        let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
        assert_eq!(c.estimator.estimation_threads(), cpus.clamp(1, 2), "unset: the machine's CPUs, at most 2");
        let c = DaemonConfig::parse("[estimator]\nnum_points = 128\ncrop_size = 32\nworker_threads = 1\n").unwrap();
        assert_eq!((c.estimator.num_points, c.estimator.crop_size), (Some(128), Some(32)));
        assert_eq!(c.estimator.estimation_threads(), 1);
        let c = DaemonConfig::parse("[estimator]\nworker_threads = 8\n").unwrap();
        assert_eq!(c.estimator.estimation_threads(), 2, "the network uses at most 2");
        let err = DaemonConfig::parse("[estimator]\ncrop_size = 0\n").unwrap_err().to_string();
        assert!(err.starts_with("estimator.crop_size = 0"), "{err}");
        let err = DaemonConfig::parse("[estimator]\nworker_threads = 0\n").unwrap_err().to_string();
        assert!(err.starts_with("estimator.worker_threads = 0"), "{err}");
    }

    #[test]
    fn camera_tables_give_per_camera_settings() {
        let text = r#"
deadline_ms = 40.0
[estimator]
max_instances = 6
[[camera]]
name = "wrist"
deadline_ms = 30.0
max_instances = 3
masks = "labels"
[camera.extrinsics]
translation_m = [0.1, 0.0, 0.5]
quaternion_xyzw = [0.0, 0.0, 0.7071068, 0.7071068]
[[camera]]
name = "overhead"
"#;
        let c = DaemonConfig::parse(text).unwrap();
        assert!(c.cameras.is_empty(), "tables without `cameras`: no implicit cam0");
        let s = c.camera_settings();
        assert_eq!(s.iter().map(|s| s.name.as_str()).collect::<Vec<_>>(), ["wrist", "overhead"]);
        assert_eq!((s[0].deadline_ns, s[0].max_instances, s[0].estimator.masks), (30_000_000, 3, MaskSource::Labels));
        assert_eq!((s[1].deadline_ns, s[1].max_instances, s[1].estimator.masks), (40_000_000, 6, MaskSource::Auto));
        assert_eq!(s[1].estimator, c.estimator, "no overrides: the daemon-wide estimator");
        let p = s[0].extrinsics.isometry() * nalgebra::Point3::new(1.0, 0.0, 0.0);
        assert!((p - nalgebra::Point3::new(0.1, 1.0, 0.5)).norm() < 1e-6, "{p}");

        let both = DaemonConfig::parse("cameras = [\"cam0\"]\n[[camera]]\nname = \"cam1\"\n").unwrap();
        assert_eq!(both.camera_names(), ["cam0", "cam1"]);
        let err = DaemonConfig::parse("cameras = [\"cam0\"]\n[[camera]]\nname = \"cam0\"\n").unwrap_err().to_string();
        assert!(err.starts_with("camera.name"), "{err}");
        let err = DaemonConfig::parse(
            "[[camera]]\nname = \"a\"\n[camera.extrinsics]\nquaternion_xyzw = [0.0, 0.0, 0.0, 2.0]\n",
        )
        .unwrap_err()
        .to_string();
        assert!(err.starts_with("camera.extrinsics.quaternion_xyzw"), "{err}");
        let err = DaemonConfig::parse("[[camera]]\nname = \"a\"\nmax_instances = 0\n").unwrap_err().to_string();
        assert!(err.starts_with("camera.max_instances"), "{err}");
        let err = DaemonConfig::parse("[[camera]]\nname = \"a\"\ndeadline = 3\n").unwrap_err().to_string();
        assert!(err.contains("deadline"), "unknown key named: {err}");
        let err = DaemonConfig::parse("[cell]\nmax_age_ms = 0\n").unwrap_err().to_string();
        assert!(err.starts_with("cell.max_age_ms"), "{err}");
        let err = DaemonConfig::parse("[cell]\nfusion = \"median\"\n").unwrap_err().to_string();
        assert!(err.starts_with("cell.fusion"), "{err}");
        assert_eq!(DaemonConfig::parse("[cell]\nfusion = \"mean\"\n").unwrap().cell.fusion, "mean");
    }

    #[test]
    fn unknown_keys_are_named() {
        let err = DaemonConfig::parse("[estimator]\nnum_pionts = 3\n").unwrap_err().to_string();
        assert!(err.contains("num_pionts"), "{err}");
        let err = DaemonConfig::parse("deadline = 3\n").unwrap_err().to_string();
        assert!(err.contains("deadline"), "{err}");
    }

    #[test]
    fn wrong_types_and_ranges_are_named() {
        let err = DaemonConfig::parse("[estimator]\nkind = \"magic\"\n").unwrap_err().to_string();
        assert!(err.contains("kind") && err.contains("magic"), "{err}");
        let err = DaemonConfig::parse("[estimator]\nnum_points = 0\n").unwrap_err().to_string();
        assert!(err.starts_with("estimator.num_points = 0"), "{err}");
        let err = DaemonConfig::parse("cameras = [\"a/b\"]\n").unwrap_err().to_string();
        assert!(err.starts_with("cameras"), "{err}");
        let err = DaemonConfig::parse("deadline_ms = -1.0\n").unwrap_err().to_string();
        assert!(err.starts_with("deadline_ms"), "{err}");
    }
}
