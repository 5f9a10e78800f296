//! What the two detection bridges (one camera's, the cell's) share: the
//! object set that names the classes, the writer's QoS and run length, and
//! the detections and `/tf` writers built from them.

use ros2_client::{Node, Publisher};

use crate::detections::ObjectTable;
use crate::msg::{Detection3DArray, TfMessage};
use crate::node::topic;
use crate::qos::{DurabilityArg, ReliabilityArg, profile, tf_profile};

/// Flags of `fusepose bridge ros2` and `ros2-cell` about their output.
#[derive(Clone, Debug, clap::Args)]
pub struct DetectionsOut {
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

/// The detections writer on `topic_name` and, with `tf`, a `/tf` writer.
pub type Writers = (Publisher<Detection3DArray>, Option<Publisher<TfMessage>>);

impl DetectionsOut {
    /// Names and boxes of `--objects`.
    pub fn object_table(&self) -> anyhow::Result<ObjectTable> {
        crate::object_table(&self.objects, self.scale)
    }

    /// Whether `published` arrays are all `--count` asked for.
    pub fn done(&self, published: u64) -> bool {
        self.count.is_some_and(|n| published >= n)
    }

    /// Creates the writers on `node`.
    pub fn writers(&self, node: &mut Node, topic_name: &str, tf: bool) -> anyhow::Result<Writers> {
        let qos = profile(self.reliability, self.history_depth, self.durability);
        let det_topic = topic(node, topic_name, "vision_msgs", "Detection3DArray", &qos)?;
        let detections = node
            .create_publisher::<Detection3DArray>(&det_topic, None)
            .map_err(|e| anyhow::anyhow!("creating the writer of {topic_name}: {e:?}"))?;
        let tf = if tf {
            let tf_topic = topic(node, "/tf", "tf2_msgs", "TFMessage", &tf_profile())?;
            Some(
                node.create_publisher::<TfMessage>(&tf_topic, None)
                    .map_err(|e| anyhow::anyhow!("creating /tf writer: {e:?}"))?,
            )
        } else {
            None
        };
        Ok((detections, tf))
    }
}
