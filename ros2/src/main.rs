//! `fusepose-ros2`: the ROS 2 bridges on their own (the same subcommands as
//! `fusepose bridge`), for machines that need nothing else of the CLI.

use clap::Parser;

/// fusepose ROS 2 bridges over DDS.
#[derive(Parser)]
#[command(name = "fusepose-ros2", version, about)]
struct Cli {
    #[command(subcommand)]
    command: fusepose_ros2::BridgeCommand,
}

fn main() {
    fusepose_ros2::init_logging();
    let cli = Cli::parse();
    if let Err(e) = fusepose_ros2::run(&cli.command) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
