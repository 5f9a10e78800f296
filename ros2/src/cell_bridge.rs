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
use crate::detections_out::DetectionsOut;
use crate::msg::Time;
use crate::node::open_node;
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
    #[command(flatten)]
    pub out: DetectionsOut,
}

/// Runs the cell bridge until killed (or `--count` arrays are out).
pub fn run(args: &CellBridgeArgs, objects: ObjectTable) -> anyhow::Result<()> {
    let ipc = Ipc::new(&IpcOptions::from_env().with_node_name("ros2_cell_bridge"))?;
    let mut consumer = CellConsumer::open(&ipc).context("subscribing to the daemon's cell poses")?;
    let domain = crate::node::domain_id(args.domain_id)?;
    let mut node = open_node(domain, "fusepose_cell_bridge")?;
    let (publisher, tf_publisher) = args.out.writers(&mut node, &args.topic, args.tf)?;
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
        if args.out.done(published) {
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
