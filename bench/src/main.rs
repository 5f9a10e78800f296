//! `fusepose-bench`: benchmark subcommands (transport, estimator, e2e,
//! tracking), each printing a table and writing its files under `--out`.

use clap::{Parser, Subcommand};
use fusepose_bench::alloc_count::CountingAlloc;
use fusepose_bench::e2e::{self, E2eArgs};
use fusepose_bench::estimator::{self, EstimatorArgs};
use fusepose_bench::ros2_bridges::{self, Ros2Args};
use fusepose_bench::tracking::{self, TrackingArgs};
use fusepose_bench::transport::{self, TransportArgs};

#[global_allocator]
static ALLOC: CountingAlloc = CountingAlloc;

#[derive(Parser)]
#[command(name = "fusepose-bench", about = "fusepose benchmarks: measured numbers, no pass/fail")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// One-way latency of a 640x480 RGB-D frame: iceoryx2 vs a Unix-socket copy.
    Transport(TransportArgs),
    /// Per-stage estimator latency (sampling, network, refiner, ICP) vs objects per frame.
    Estimator(EstimatorArgs),
    /// Daemon + producer + consumer at given frame rates: latency, FPS, skipped, late.
    E2e(E2eArgs),
    /// The network with and without tracking on rendered videos: time, accuracy.
    Tracking(TrackingArgs),
    /// Latency and CPU of the ROS 2 bridges around a daemon (ROS image → frame, pose → DDS).
    Ros2(Ros2Args),
    /// Receiver process of `transport` (internal).
    #[command(hide = true)]
    TransportReceiver {
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        args: Vec<String>,
    },
    /// The daemon process of `e2e` (internal).
    #[command(hide = true)]
    E2eDaemon {
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        args: Vec<String>,
    },
    /// The producer process of `e2e` (internal).
    #[command(hide = true)]
    E2eProducer {
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        args: Vec<String>,
    },
    /// The consumer process of `e2e` (internal).
    #[command(hide = true)]
    E2eConsumer {
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        args: Vec<String>,
    },
    /// The all-cameras consumer of `e2e --cameras N` (internal).
    #[command(hide = true)]
    E2eConsumerAll {
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        args: Vec<String>,
    },
}

fn main() -> anyhow::Result<()> {
    match Cli::parse().command {
        Command::Transport(args) => {
            let report = transport::run(&args)?;
            let text = transport::render(&report);
            print!("{text}");
            std::fs::write(args.out.join("transport.txt"), &text)?;
        }
        Command::Estimator(args) => {
            let report = estimator::run(&args)?;
            let text = estimator::table::render(&report);
            print!("{text}");
            std::fs::write(args.out.join("estimator.txt"), &text)?;
        }
        Command::E2e(args) => {
            let report = e2e::run(&args)?;
            let text = e2e::render(&report);
            print!("{text}");
            std::fs::write(args.out.join("e2e.txt"), &text)?;
        }
        Command::Tracking(args) => {
            let report = tracking::run(&args)?;
            let text = tracking::render(&report);
            print!("{text}");
            std::fs::create_dir_all(&args.out)?;
            std::fs::write(args.out.join("tracking.txt"), &text)?;
        }
        Command::Ros2(args) => {
            let report = ros2_bridges::run(&args)?;
            let text = ros2_bridges::render(&report);
            print!("{text}");
            std::fs::write(args.out.join("ros2.txt"), &text)?;
        }
        Command::TransportReceiver { args } => transport::receiver::main(&args)?,
        Command::E2eDaemon { args } => e2e::processes::daemon_main(&args)?,
        Command::E2eProducer { args } => e2e::processes::producer_main(&args)?,
        Command::E2eConsumer { args } => e2e::processes::consumer_main(&args)?,
        Command::E2eConsumerAll { args } => e2e::processes::consumer_all_main(&args)?,
    }
    Ok(())
}
