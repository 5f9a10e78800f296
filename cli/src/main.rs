//! # fusepose — the user command line
//!
//! Thin over the libraries: every subcommand parses flags and calls into
//! scene, estimator, train or client. No logic of its own beyond wiring.

mod adapt;
mod bridge;
mod camera;
mod camera_model;
mod dataset_path;
mod demo;
mod eval;
mod objects;
mod pose_overlay;
mod record;
mod render;
mod stats;
mod train;
mod watch;
mod weights;

use clap::{Parser, Subcommand};

/// fusepose: real-time 6D object pose from RGB-D frames.
#[derive(Parser)]
#[command(name = "fusepose", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// ROS 2 bridges over DDS: camera topics in (`ros2-camera`), detections out (`ros2`, `ros2-cell`).
    Bridge(bridge::Args),
    /// Act as a camera: replay a dataset or render frames, publish them to fuseposed.
    Camera(camera::Args),
    /// Print poses published by fuseposed as they arrive.
    Watch(watch::Args),
    /// Query fuseposed for its latency histograms and counters.
    Stats(stats::Args),
    /// Keep a camera's frames as a BOP split without ground truth (to adapt the segmenter to it).
    Record(record::Args),
    /// Adapt a weight file's segmenter to a camera from frames `record` kept (labels, fine-tune, report).
    Adapt(Box<adapt::Args>),
    /// Render a synthetic BOP dataset of tabletop scenes.
    Render(render::Args),
    /// Inspect or export object sets.
    Objects(objects::Args),
    /// Train the fusion network (and refiner, segmenter).
    Train(Box<train::Args>),
    /// Evaluate an estimator on a BOP or YCB-Video dataset.
    Eval(Box<eval::Args>),
    /// Run daemon, synthetic camera and consumer together and show live results.
    Demo(demo::Args),
    /// (internal) The demo's daemon process.
    #[command(name = "demo-daemon", hide = true)]
    DemoDaemon(demo::DaemonArgs),
    /// (internal) The demo's consumer process.
    #[command(name = "demo-consumer", hide = true)]
    DemoConsumer(demo::ConsumerArgs),
}

fn main() {
    // The bridges' logging setup (FUSEPOSE_LOG; no colour codes in log files such as the demo's logs/*.log).
    fusepose_ros2::init_logging();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Bridge(a) => bridge::run(a),
        Command::Camera(a) => camera::run(a),
        Command::Watch(a) => watch::run(a),
        Command::Stats(a) => stats::run(a),
        Command::Record(a) => record::run(a),
        Command::Adapt(a) => adapt::run(*a),
        Command::Render(a) => render::run(a),
        Command::Objects(a) => objects::run(a),
        Command::Train(a) => train::run(*a),
        Command::Eval(a) => eval::run(*a),
        Command::Demo(a) => demo::run(a),
        Command::DemoDaemon(a) => demo::run_daemon(a),
        Command::DemoConsumer(a) => demo::run_consumer(a),
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
