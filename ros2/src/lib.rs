//! # fusepose-ros2 — ROS 2 in and out over DDS
//!
//! Three bridges, each its own process beside `fuseposed` (which never links
//! DDS), speaking ROS 2 on the wire through `ros2-client` (RustDDS, pure Rust,
//! no ROS installation):
//! - [`camera_bridge`]: a ROS 2 camera driver's colour + aligned depth +
//!   CameraInfo topics → fusepose frames (iceoryx2);
//! - [`pose_bridge`]: fusepose pose messages → `vision_msgs/Detection3DArray`
//!   (and optionally `/tf`);
//! - [`cell_bridge`]: the daemon's cell poses (every camera's objects in one
//!   cell frame) → `vision_msgs/Detection3DArray` (and optionally `/tf`).
//!
//! Message types are defined here field by field ([`msg`]). See docs/ROS2.md.
//!
//! It may touch the wire contract (`fusepose-client`) and the object sets
//! (`fusepose-scene`, for names and boxes); never the daemon, the estimator
//! or the trainer, and nothing of the daemon depends on it.

pub mod camera_bridge;
pub mod cell_bridge;
pub mod clock;
pub mod detections;
pub mod detections_out;
pub mod image;
pub mod msg;
pub mod node;
pub mod pairing;
pub mod pose_bridge;
pub mod qos;
pub mod ratelog;
pub mod stamps;

use std::path::Path;

use anyhow::Context as _;
pub use camera_bridge::CameraBridgeArgs;
pub use cell_bridge::CellBridgeArgs;
pub use detections::{ObjectInfo, ObjectTable};
pub use pose_bridge::PoseBridgeArgs;

/// Log filter when `FUSEPOSE_LOG` is unset: RustDDS warns on every message
/// larger than one UDP datagram (each image), which says nothing to a user.
pub const DEFAULT_LOG_FILTER: &str = "info,rustdds=error,ros2_client=warn";

/// Logs to stderr, filtered by `FUSEPOSE_LOG` (else [`DEFAULT_LOG_FILTER`]),
/// without colour codes when stderr is not a terminal (log files). The
/// `fusepose` command line and `fusepose-ros2` log alike.
pub fn init_logging() {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_env("FUSEPOSE_LOG")
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(DEFAULT_LOG_FILTER)),
        )
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .init();
}

/// The bridges, as subcommands of `fusepose bridge` and of `fusepose-ros2`.
#[derive(Debug, clap::Subcommand)]
pub enum BridgeCommand {
    /// ROS 2 camera topics (colour, aligned depth, CameraInfo) → frames of a fusepose camera.
    #[command(name = "ros2-camera")]
    Ros2Camera(CameraBridgeArgs),
    /// Poses of a fusepose camera → vision_msgs/Detection3DArray (and /tf) on ROS 2.
    #[command(name = "ros2")]
    Ros2(PoseBridgeArgs),
    /// The daemon's cell poses (every camera's objects in the cell frame) → vision_msgs/Detection3DArray (and /tf).
    #[command(name = "ros2-cell")]
    Ros2Cell(CellBridgeArgs),
}

/// Runs the bridge `command` until it is killed.
pub fn run(command: &BridgeCommand) -> anyhow::Result<()> {
    match command {
        BridgeCommand::Ros2Camera(args) => camera_bridge::run(args),
        BridgeCommand::Ros2(args) => {
            let objects = args.out.object_table()?;
            pose_bridge::run(args, objects)
        }
        BridgeCommand::Ros2Cell(args) => cell_bridge::run(args, args.out.object_table()?),
    }
}

/// Names and boxes of the object set `source` (`builtin` or a mesh folder), in class-id order.
pub fn object_table(source: &str, scale: f64) -> anyhow::Result<ObjectTable> {
    let set = if source == "builtin" {
        fusepose_scene::builtin::builtin_objects()
    } else {
        fusepose_scene::mesh_io::load_object_dir(Path::new(source), scale)
            .with_context(|| format!("loading object set '{source}' (--objects)"))?
    };
    let objects = set
        .objects
        .iter()
        .map(|o| {
            let (lo, hi) = (o.bbox_min, o.bbox_max);
            ObjectInfo {
                name: o.name.clone(),
                size: [hi.x - lo.x, hi.y - lo.y, hi.z - lo.z],
                box_centre: [(hi.x + lo.x) / 2.0, (hi.y + lo.y) / 2.0, (hi.z + lo.z) / 2.0],
            }
        })
        .collect();
    Ok(ObjectTable { objects })
}
