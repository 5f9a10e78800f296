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

/// The whole configuration file.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DaemonConfig {
    /// Camera names served; each gets the services `fusepose/camera/<name>/…`.
    pub cameras: Vec<String>,
    /// `tracing` filter (`error`, `warn`, `info`, `debug`, `trace`, or a directive list);
    /// the `FUSEPOSE_LOG` environment variable overrides it.
    pub log_level: String,
    /// Capture → publish budget, milliseconds (default 1/24 s).
    pub deadline_ms: f64,
    pub estimator: EstimatorConfig,
    pub stats: StatsConfig,
    pub ipc: IpcConfig,
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
    /// Points sampled per instance (N).
    pub num_points: usize,
    /// Colour crop side, pixels (S).
    pub crop_size: usize,
    /// Most instances estimated per frame (largest first).
    pub max_instances: usize,
    /// Smallest instance mask kept, pixels.
    pub min_pixels: usize,
    /// Refinement iterations (ICP iterations or refiner passes).
    pub refine_iterations: usize,
    /// Threads per frame for estimation: the network uses up to 2 (the loop
    /// thread plus one persistent worker); ICP runs inline (1). Larger values
    /// are accepted with a warning.
    pub worker_threads: usize,
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
}

impl Default for DaemonConfig {
    fn default() -> Self {
        Self {
            cameras: vec!["cam0".to_owned()],
            log_level: "info".to_owned(),
            deadline_ms: 1000.0 / 24.0,
            estimator: EstimatorConfig::default(),
            stats: StatsConfig::default(),
            ipc: IpcConfig::default(),
        }
    }
}

impl Default for EstimatorConfig {
    fn default() -> Self {
        Self {
            kind: EstimatorKind::Icp,
            weights: PathBuf::from("models/builtin.safetensors"),
            objects: "builtin".to_owned(),
            objects_scale: 1.0,
            num_points: 500,
            crop_size: 64,
            max_instances: 8,
            min_pixels: 50,
            refine_iterations: 2,
            worker_threads: 1,
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
        Self { root_path: PathBuf::new(), prefix: String::new(), cleanup_interval_s: 5.0, tick_ms: 20 }
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
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read { path: path.to_owned(), source })?;
        Self::parse(&text).map_err(|e| match e {
            ConfigError::Parse { message, .. } => ConfigError::Parse { path: path.to_owned(), message },
            other => other,
        })
    }

    /// Parses and checks configuration text.
    pub fn parse(text: &str) -> Result<Self, ConfigError> {
        let config: Self =
            toml::from_str(text).map_err(|e| ConfigError::Parse { path: PathBuf::from("<text>"), message: e.to_string() })?;
        config.validate()?;
        Ok(config)
    }

    /// Checks value ranges; the error names the offending key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.cameras.is_empty() {
            return Err(invalid("cameras", &self.cameras, "list at least one camera"));
        }
        for (i, name) in self.cameras.iter().enumerate() {
            if fusepose_client::validate_camera_name(name).is_err() {
                return Err(invalid("cameras", name, "names are 1 to 64 characters of [A-Za-z0-9_-]"));
            }
            if self.cameras[..i].contains(name) {
                return Err(invalid("cameras", name, "each camera may appear once"));
            }
        }
        if !(self.deadline_ms.is_finite() && self.deadline_ms > 0.0) {
            return Err(invalid("deadline_ms", self.deadline_ms, "must be a positive number of milliseconds"));
        }
        let e = &self.estimator;
        if !(e.objects_scale.is_finite() && e.objects_scale > 0.0) {
            return Err(invalid("estimator.objects_scale", e.objects_scale, "must be positive"));
        }
        if e.num_points == 0 || e.num_points > 1 << 20 {
            return Err(invalid("estimator.num_points", e.num_points, "must be in 1..=1048576"));
        }
        if e.crop_size == 0 || e.crop_size > 1024 {
            return Err(invalid("estimator.crop_size", e.crop_size, "must be in 1..=1024"));
        }
        if e.max_instances == 0 || e.max_instances > fusepose_client::MAX_OBJECTS {
            return Err(invalid("estimator.max_instances", e.max_instances, "must be in 1..=32 (poses per message)"));
        }
        if e.refine_iterations > 1000 {
            return Err(invalid("estimator.refine_iterations", e.refine_iterations, "must be at most 1000"));
        }
        if e.worker_threads == 0 || e.worker_threads > 64 {
            return Err(invalid("estimator.worker_threads", e.worker_threads, "must be in 1..=64"));
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
        assert_eq!(c.estimator.kind, EstimatorKind::Icp);
    }

    #[test]
    fn shipped_config_parses() {
        let text = include_str!("../../config/fuseposed.toml");
        let c = DaemonConfig::parse(text).unwrap();
        assert_eq!(c.cameras, ["cam0"]);
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
