//! `fusepose bridge`: the ROS 2 bridges of the `fusepose-ros2` crate
//! (`ros2-camera`: camera topics in; `ros2`: a camera's detections out; `ros2-cell`:
//! the cell's detections out). See docs/ROS2.md.

#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    pub command: fusepose_ros2::BridgeCommand,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    fusepose_ros2::run(&args.command)
}
