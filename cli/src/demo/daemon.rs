//! The demo's daemon process (`fusepose demo-daemon`, hidden): the same loop
//! as `fuseposed` (`fusepose_daemon::run`), configured in code so that
//! `cargo run -p fusepose-cli -- demo` needs no second binary. iceoryx2 root
//! and prefix come from `FUSEPOSE_IOX2_ROOT` / `FUSEPOSE_IOX2_PREFIX`.

use std::path::PathBuf;

use anyhow::Context;
use fusepose_client::IpcOptions;
use fusepose_daemon::config::{EstimatorConfig, IpcConfig, StatsConfig};
use fusepose_daemon::{DaemonConfig, EstimatorKind, engine};

/// Which estimator the demo's daemon runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum DemoEstimator {
    /// The fusion network with its refiner (the product path).
    Net,
    /// The classical ICP baseline (slow: about a quarter second per frame).
    Icp,
}

#[derive(clap::Args)]
pub struct Args {
    /// Camera name served.
    #[arg(long)]
    pub camera: String,
    /// Estimator to run.
    #[arg(long, value_enum)]
    pub estimator: DemoEstimator,
    /// Network weights (safetensors).
    #[arg(long)]
    pub weights: PathBuf,
}

/// The daemon configuration of a demo run.
pub fn demo_config(args: &Args, ipc: &IpcOptions) -> DaemonConfig {
    let defaults = DaemonConfig::default();
    DaemonConfig {
        cameras: vec![args.camera.clone()],
        estimator: EstimatorConfig {
            kind: match args.estimator {
                DemoEstimator::Net => EstimatorKind::Net,
                DemoEstimator::Icp => EstimatorKind::Icp,
            },
            weights: args.weights.clone(),
            ..defaults.estimator
        },
        stats: StatsConfig { hlog_path: PathBuf::new(), summary_interval_s: 5.0, ..defaults.stats },
        ipc: IpcConfig {
            root_path: ipc.root_path.clone().unwrap_or_default(),
            prefix: ipc.prefix.clone().unwrap_or_default(),
            ..defaults.ipc
        },
        ..defaults
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let config = demo_config(&args, &IpcOptions::from_env());
    config.validate().context("demo daemon configuration")?;
    let spec = engine::resolve(&config.estimator)?;
    tracing::info!(estimator = %spec.description, "demo daemon starting");
    // The loop logs its final counters and latency percentiles itself.
    fusepose_daemon::run(&config, &spec, None)?;
    Ok(())
}
