//! `fuseposed --config config/fuseposed.toml`: the pose daemon's entry point.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use fusepose_daemon::{DaemonConfig, engine};

/// fuseposed: serves 6D object poses for iceoryx2 cameras.
#[derive(Parser)]
#[command(name = "fuseposed", version, about)]
struct Args {
    /// Configuration file (TOML), e.g. config/fuseposed.toml, which documents
    /// every key. Without it every key takes its default. SIGHUP re-reads it
    /// (cameras added, removed or changed; the others keep running).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Check the configuration, print the measured budget (network configurations) and exit.
    #[arg(long)]
    check: bool,
}

fn main() -> ExitCode {
    let args = Args::parse();
    let config = match &args.config {
        Some(path) => DaemonConfig::load(path),
        None => Ok(DaemonConfig::default()),
    };
    let config = match config {
        Ok(c) => c,
        Err(e) => {
            eprintln!("fuseposed: configuration error: {e}");
            return ExitCode::from(2);
        }
    };
    let filter = tracing_subscriber::EnvFilter::try_from_env("FUSEPOSE_LOG")
        .or_else(|_| tracing_subscriber::EnvFilter::try_new(&config.log_level));
    let filter = match filter {
        Ok(f) => f,
        Err(e) => {
            eprintln!("fuseposed: configuration error: log_level = {:?}: {e}", config.log_level);
            return ExitCode::from(2);
        }
    };
    let ansi = std::io::IsTerminal::is_terminal(&std::io::stderr());
    tracing_subscriber::fmt().with_env_filter(filter).with_ansi(ansi).with_writer(std::io::stderr).init();
    iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Warn);

    let spec = match engine::resolve(&config.estimator) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("fuseposed: configuration error: {e:#}");
            return ExitCode::from(2);
        }
    };
    if args.check {
        println!("configuration ok: cameras {:?}, estimator {}", config.camera_names(), spec.description);
        if let Some(cost) = &spec.startup_cost {
            println!("budget: {}", cost.describe(config.deadline_ms));
        }
        return ExitCode::SUCCESS;
    }
    let options = fusepose_daemon::RunOptions { stop: None, config_path: args.config.clone() };
    match fusepose_daemon::run_with(&config, &spec, options) {
        Ok(_) => ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("fuseposed failed: {e:#}");
            ExitCode::FAILURE
        }
    }
}
