//! `fusepose bridge ros2`: pose messages of one camera (iceoryx2) →
//! `vision_msgs/msg/Detection3DArray` on `/fusepose/<camera>/detections`, and
//! optionally `tf2_msgs/msg/TFMessage` on `/tf`.
//!
//! Stamps: the capture time (`CLOCK_MONOTONIC`) mapped to the ROS clock
//! (`CLOCK_REALTIME`, [`crate::clock`]), snapped to the stamp of the
//! camera's `CameraInfo` of that frame when one was seen ([`crate::stamps`]).

use std::time::Duration;

use anyhow::Context as _;
use fusepose_client::{Consumer, Ipc, IpcOptions, PoseMessage};

use crate::clock::ClockMap;
use crate::detections::{ObjectTable, detections, transforms};
use crate::detections_out::DetectionsOut;
use crate::msg::{CameraInfo, Time};
use crate::node::{open_node, topic};
use crate::qos::{DurabilityArg, ReliabilityArg, profile};
use crate::ratelog::RateLog;
use crate::stamps::RecentStamps;

/// Flags of `fusepose bridge ros2`.
#[derive(Clone, Debug, clap::Args)]
pub struct PoseBridgeArgs {
    /// Camera name (the daemon's `cameras` entry).
    #[arg(long, default_value = "cam0")]
    pub name: String,
    /// ROS 2 domain id [default: $ROS_DOMAIN_ID, else 0].
    #[arg(long)]
    pub domain_id: Option<u16>,
    /// Frame id of the detections [default: the CameraInfo's frame id, else `<camera>_color_optical_frame`].
    #[arg(long)]
    pub frame_id: Option<String>,
    /// Detections topic [default: /fusepose/<camera>/detections].
    #[arg(long)]
    pub topic: Option<String>,
    /// Also publish one transform per object instance on /tf (child `fusepose/<camera>/<object>_<instance>`).
    #[arg(long)]
    pub tf: bool,
    /// The camera's CameraInfo topic, for the exact image stamps and frame id; `none` to map times only.
    #[arg(long, default_value = "/camera/camera/color/camera_info")]
    pub info: String,
    #[command(flatten)]
    pub out: DetectionsOut,
}

/// How far a mapped capture time may lie from a CameraInfo stamp and still take it, ns.
const SNAP_TOLERANCE_NS: i64 = 2_000_000;

/// Runs the pose bridge until killed (or `--count` arrays are out).
pub fn run(args: &PoseBridgeArgs, objects: ObjectTable) -> anyhow::Result<()> {
    let ipc = Ipc::new(&IpcOptions::from_env().with_node_name(&format!("ros2_pose_bridge_{}", args.name)))?;
    let mut consumer = Consumer::open(&ipc, &args.name)
        .with_context(|| format!("subscribing to the poses of camera '{}'", args.name))?;
    let mut node = open_node(crate::node::domain_id(args.domain_id)?, &format!("{}_pose_bridge", args.name))?;
    let topic_name = args.topic.clone().unwrap_or_else(|| format!("/fusepose/{}/detections", args.name));
    let (publisher, tf_publisher) = args.out.writers(&mut node, &topic_name, args.tf)?;
    let info = if args.info == "none" {
        None
    } else {
        let sensor = profile(ReliabilityArg::BestEffort, 5, DurabilityArg::Volatile);
        let info_topic = topic(&mut node, &args.info, "sensor_msgs", "CameraInfo", &sensor)?;
        Some(
            node.create_subscription::<CameraInfo>(&info_topic, None)
                .map_err(|e| anyhow::anyhow!("subscribing to {}: {e:?}", args.info))?,
        )
    };
    tracing::info!(
        camera = %args.name,
        domain = crate::node::domain_id(args.domain_id)?,
        topic = %topic_name,
        tf = args.tf,
        info = %args.info,
        objects = objects.objects.len(),
        "ROS 2 pose bridge running"
    );

    let default_frame = format!("{}_color_optical_frame", args.name);
    let tf_prefix = format!("fusepose/{}", args.name);
    let mut clock = ClockMap::new();
    let mut recent = RecentStamps::new(64, SNAP_TOLERANCE_NS);
    let mut log = RateLog::default();
    let mut batch: Vec<PoseMessage> = Vec::new();
    let mut published = 0u64;
    loop {
        if args.out.done(published) {
            return Ok(());
        }
        let ready = consumer.wait_ready(Duration::from_millis(200))?;
        if let Some(sub) = &info {
            loop {
                match sub.take() {
                    Ok(Some((ci, _))) => recent.push(ci.header.stamp.to_ns(), ci.header.frame_id),
                    Ok(None) => break,
                    Err(e) => {
                        log.warn("info_read", || format!("reading {}: {e:?} (message dropped)", args.info));
                        break;
                    }
                }
            }
        }
        if !ready {
            continue;
        }
        batch.clear();
        consumer.drain(&mut batch)?;
        for msg in &batch {
            if msg.format_version != fusepose_client::WIRE_VERSION {
                log.warn("version", || {
                    format!(
                        "pose message of wire version {} dropped (ours {})",
                        msg.format_version,
                        fusepose_client::WIRE_VERSION
                    )
                });
                continue;
            }
            let mapped = clock.monotonic_to_ros(msg.capture_time_ns);
            let (stamp_ns, seen_frame) = match recent.snap(mapped) {
                Some((s, f)) => (s, Some(f.to_owned())),
                None => (mapped, recent.latest_frame_id().map(str::to_owned)),
            };
            let frame_id =
                args.frame_id.clone().or(seen_frame.filter(|f| !f.is_empty())).unwrap_or_else(|| default_frame.clone());
            let stamp = Time::from_ns(stamp_ns);
            let array = detections(msg, &objects, stamp, &frame_id);
            if let Err(e) = publisher.publish(array) {
                log.warn("publish", || format!("publishing on {topic_name}: {e:?} (array dropped)"));
            }
            if let Some(tf) = &tf_publisher
                && msg.object_count > 0
                && let Err(e) = tf.publish(transforms(msg, &objects, stamp, &frame_id, &tf_prefix))
            {
                log.warn("tf", || format!("publishing on /tf: {e:?} (transforms dropped)"));
            }
            published += 1;
        }
    }
}
