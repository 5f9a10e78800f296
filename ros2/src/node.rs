//! The bridges' ROS 2 node (one DDS participant) and topic helpers.

use anyhow::Context as _;
use ros2_client::{Context, ContextOptions, MessageTypeName, Name, Node, NodeName, NodeOptions, QosProfile};

/// A ROS 2 node `/fusepose/<base>` on DDS domain `domain_id`.
pub fn open_node(domain_id: u16, base: &str) -> anyhow::Result<Node> {
    anyhow::ensure!(domain_id <= 232, "--domain-id {domain_id} is out of range: ROS 2 domain ids are 0..=232");
    let context = Context::with_options(ContextOptions::new().domain_id(domain_id))
        .map_err(|e| anyhow::anyhow!("creating the DDS participant on domain {domain_id}: {e:?}"))?;
    let name = NodeName::new("/fusepose", &node_base_name(base))
        .map_err(|e| anyhow::anyhow!("node name for '{base}': {e:?}"))?;
    // No rosout or parameter services: the bridge is a plain pub/sub node.
    context
        .new_node(name, NodeOptions::new().enable_rosout(false).start_parameter_services(false))
        .map_err(|e| anyhow::anyhow!("creating the ROS 2 node: {e:?}"))
}

/// The domain id: `flag`, else `$ROS_DOMAIN_ID`, else 0 (as ROS 2 tools choose it).
pub fn domain_id(flag: Option<u16>) -> anyhow::Result<u16> {
    if let Some(id) = flag {
        return Ok(id);
    }
    match std::env::var("ROS_DOMAIN_ID") {
        Ok(v) if !v.trim().is_empty() => v.trim().parse().map_err(|_| {
            anyhow::anyhow!("ROS_DOMAIN_ID='{v}' is not a domain id: set a number 0..=232 or pass --domain-id")
        }),
        _ => Ok(0),
    }
}

/// `base` with every character a ROS name may not hold replaced by `_`.
pub fn node_base_name(base: &str) -> String {
    let mut out: String = base.chars().map(|c| if c.is_ascii_alphanumeric() { c } else { '_' }).collect();
    while out.contains("__") {
        out = out.replace("__", "_");
    }
    if !out.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_') {
        out.insert(0, 'n');
    }
    out
}

/// The topic `topic` (an absolute ROS name such as `/camera/camera/color/image_raw`) of type `pkg/msg/ty`.
pub fn topic(
    node: &mut Node,
    topic: &str,
    pkg: &str,
    ty: &str,
    qos: &QosProfile,
) -> anyhow::Result<ros2_client::dds::rustdds::Topic> {
    let name = Name::parse(topic).map_err(|e| {
        anyhow::anyhow!("'{topic}' is not a valid ROS 2 topic name ({e:?}): use an absolute name like /camera/camera/color/image_raw")
    })?;
    node.create_topic(&name, MessageTypeName::new(pkg, ty), qos)
        .map_err(|e| anyhow::anyhow!("creating topic {topic}: {e:?}"))
        .with_context(|| format!("type {pkg}/msg/{ty}"))
}

#[cfg(test)]
mod tests {
    #[test]
    fn node_names_are_made_valid() {
        assert_eq!(super::node_base_name("cam0_pose_bridge"), "cam0_pose_bridge");
        assert_eq!(super::node_base_name("0-left cam"), "n0_left_cam");
    }
}
