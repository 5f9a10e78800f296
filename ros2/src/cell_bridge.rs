//! `fusepose bridge ros2-cell`: the daemon's cell output (every camera's
//! objects in the cell frame, `fusepose/cell/poses`) →
//! `vision_msgs/msg/Detection3DArray` on `/fusepose/cell/detections`, and
//! optionally `tf2_msgs/msg/TFMessage` on `/tf`.
//!
//! Frame: `--frame-id` (the frame the daemon's camera extrinsics map into).
//! Stamps: each object's newest view's capture time (`CLOCK_MONOTONIC`)
//! mapped to the ROS clock ([`crate::clock`]).

use std::time::Duration;

use anyhow::Context as _;
use fusepose_client::{CellConsumer, CellPoseMessage, Ipc, IpcOptions};

use crate::clock::ClockMap;
use crate::detections::{ObjectTable, cell_detections, cell_transforms};
use crate::msg::{Detection3DArray, TfMessage, Time};
use crate::node::{open_node, topic};
use crate::qos::{DurabilityArg, ReliabilityArg, profile, tf_profile};
use crate::ratelog::RateLog;

/// Flags of `fusepose bridge ros2-cell`.
#[derive(Clone, Debug, clap::Args)]
pub struct CellBridgeArgs {
    /// ROS 2 domain id [default: $ROS_DOMAIN_ID, else 0].
    #[arg(long)]
    pub domain_id: Option<u16>,
    /// Frame id of the cell (the parent frame of the daemon's `[[camera]] extrinsics`).
    #[arg(long, default_value = "fusepose_cell")]
    pub frame_id: String,
    /// Detections topic.
    #[arg(long, default_value = "/fusepose/cell/detections")]
    pub topic: String,
    /// Also publish one transform per cell object on /tf (child `fusepose/cell/<object>_<camera id>_<instance>`).
    #[arg(long)]
    pub tf: bool,
    /// Object set of the daemon: `builtin` or a folder with one subfolder or .obj/.ply file per object.
    #[arg(long, default_value = "builtin")]
    pub objects: String,
    /// Metres per mesh-file unit of --objects DIR (0.001 for millimetre models).
    #[arg(long, default_value_t = 1.0)]
    pub scale: f64,
    /// Reliability of the detections writer.
    #[arg(long, value_enum, default_value = "reliable")]
    pub reliability: ReliabilityArg,
    /// History depth (keep last N) of the detections writer.
    #[arg(long, default_value_t = 10)]
    pub history_depth: usize,
    /// Durability of the detections writer.
    #[arg(long, value_enum, default_value = "volatile")]
    pub durability: DurabilityArg,
    /// Exit after publishing this many detection arrays (default: run until killed).
    #[arg(long)]
    pub count: Option<u64>,
}

/// Runs the cell bridge until killed (or `--count` arrays are out).
pub fn run(args: &CellBridgeArgs, objects: ObjectTable) -> anyhow::Result<()> {
    let ipc = Ipc::new(&IpcOptions::from_env().with_node_name("ros2_cell_bridge"))?;
    let mut consumer = CellConsumer::open(&ipc).context("subscribing to the daemon's cell poses")?;
    let domain = crate::node::domain_id(args.domain_id)?;
    let mut node = open_node(domain, "fusepose_cell_bridge")?;
    let qos = profile(args.reliability, args.history_depth, args.durability);
    let det_topic = topic(&mut node, &args.topic, "vision_msgs", "Detection3DArray", &qos)?;
    let publisher = node
        .create_publisher::<Detection3DArray>(&det_topic, None)
        .map_err(|e| anyhow::anyhow!("creating the writer of {}: {e:?}", args.topic))?;
    let tf_publisher = if args.tf {
        let tf_topic = topic(&mut node, "/tf", "tf2_msgs", "TFMessage", &tf_profile())?;
        Some(
            node.create_publisher::<TfMessage>(&tf_topic, None)
                .map_err(|e| anyhow::anyhow!("creating /tf writer: {e:?}"))?,
        )
    } else {
        None
    };
    tracing::info!(
        domain,
        topic = %args.topic,
        frame = %args.frame_id,
        tf = args.tf,
        objects = objects.objects.len(),
        "ROS 2 cell bridge running"
    );

    let mut clock = ClockMap::new();
    let mut log = RateLog::default();
    let mut batch: Vec<CellPoseMessage> = Vec::new();
    let mut published = 0u64;
    loop {
        if args.count.is_some_and(|n| published >= n) {
            return Ok(());
        }
        if !consumer.wait_ready(Duration::from_millis(200))? {
            continue;
        }
        batch.clear();
        consumer.drain(&mut batch)?;
        for msg in &batch {
            let mut stamp_of = |ns: u64| Time::from_ns(clock.monotonic_to_ros(ns));
            let array = cell_detections(msg, &objects, &mut stamp_of, &args.frame_id);
            if let Err(e) = publisher.publish(array) {
                log.warn("publish", || format!("publishing on {}: {e:?} (array dropped)", args.topic));
            }
            if let Some(tf) = &tf_publisher
                && msg.object_count > 0
                && let Err(e) = tf.publish(cell_transforms(msg, &objects, stamp_of, &args.frame_id, "fusepose/cell"))
            {
                log.warn("tf", || format!("publishing on /tf: {e:?} (transforms dropped)"));
            }
            published += 1;
        }
    }
}
