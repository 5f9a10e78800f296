//! iceoryx2 capacity limits come back as `ClientError::Capacity` naming the
//! service, the limit and its value, the likely cause and what to do (issue
//! 23): subscribers, publishers, stats clients, nodes and service settings
//! provoked in this process, and a daemon that cannot publish because the
//! pose service is full, as a separate process. Each test has its own
//! iceoryx2 namespace.

use std::time::Duration;

use fusepose_client::{
    CameraServices, CapacityLimit, ClientError, Consumer, FrameLayout, Ipc, PoseMessage, Producer, StatsClient, limits,
};
use fusepose_tests::*;

/// Asserts `result` is a capacity error of `limit` on `service` whose text has `needles`.
fn assert_capacity<T>(result: Result<T, ClientError>, service: &str, limit: CapacityLimit, needles: &[&str]) {
    let err = match result {
        Ok(_) => panic!("expected {limit:?} on {service}, but it succeeded"),
        Err(e) => e,
    };
    let text = err.to_string();
    match &err {
        ClientError::Capacity { service: s, limit: l, .. } => {
            assert_eq!((s.as_str(), *l), (service, limit), "{text}");
        }
        other => panic!("expected a capacity error, got {other:?}: {text}"),
    }
    assert!(text.contains("likely cause:") && text.contains("what to do:"), "{text}");
    for needle in needles {
        assert!(text.contains(needle), "{needle:?} missing in: {text}");
    }
    println!("RESULT {text}");
}

#[test]
fn too_many_consumers_producers_and_stats_clients_are_named() -> anyhow::Result<()> {
    let env = TestEnv::new("capacity")?;
    let ipc = Ipc::new(&env.ipc_options())?;

    let consumers: Vec<Consumer> =
        (0..limits::POSE_SUBSCRIBERS).map(|_| Consumer::open(&ipc, "cam0")).collect::<Result<_, _>>()?;
    assert_capacity(
        Consumer::open(&ipc, "cam0"),
        "fusepose/camera/cam0/poses",
        CapacityLimit::Subscribers,
        &["too many subscribers", "limit 16", "ExceedsMaxSupportedSubscribers", "consumers"],
    );
    drop(consumers);
    // Freed again once they are gone.
    let _consumer = Consumer::open(&ipc, "cam0")?;

    let producers: Vec<Producer> = (0..limits::FRAME_PUBLISHERS)
        .map(|_| Producer::create(&ipc, "cam0", FrameLayout::vga_rgbd()))
        .collect::<Result<_, _>>()?;
    assert_capacity(
        Producer::create(&ipc, "cam0", FrameLayout::vga_rgbd()),
        "fusepose/camera/cam0/frames",
        CapacityLimit::Publishers,
        &["too many publishers", "limit 2", "camera name"],
    );
    drop(producers);

    let services = CameraServices::open(&ipc, "cam0")?;
    let readers: Vec<_> =
        (0..limits::FRAME_SUBSCRIBERS).map(|_| services.frame_subscriber()).collect::<Result<_, _>>()?;
    assert_capacity(
        services.frame_subscriber(),
        "fusepose/camera/cam0/frames",
        CapacityLimit::Subscribers,
        &["limit 3"],
    );
    drop(readers);

    let clients: Vec<StatsClient> =
        (0..limits::STATS_CLIENTS).map(|_| StatsClient::open(&ipc, "cam0")).collect::<Result<_, _>>()?;
    assert_capacity(
        StatsClient::open(&ipc, "cam0"),
        "fusepose/camera/cam0/stats",
        CapacityLimit::Clients,
        &["too many clients", "limit 8", "fusepose stats"],
    );
    drop(clients);
    Ok(())
}

#[test]
fn too_many_processes_on_a_camera_are_named() -> anyhow::Result<()> {
    let env = TestEnv::new("capacity-nodes")?;
    // Each Ipc is one iceoryx2 node, as a process would have.
    let mut held = Vec::new();
    for _ in 0..limits::MAX_NODES {
        let ipc = Ipc::new(&env.ipc_options())?;
        let services = CameraServices::open(&ipc, "cam0")?;
        held.push((services, ipc));
    }
    let one_more = Ipc::new(&env.ipc_options())?;
    assert_capacity(
        CameraServices::open(&one_more, "cam0"),
        "fusepose/camera/cam0/frames",
        CapacityLimit::Nodes,
        &["too many processes", "limit 32", "ExceedsMaxNumberOfNodes"],
    );
    Ok(())
}

#[test]
fn a_service_created_with_smaller_settings_is_named() -> anyhow::Result<()> {
    use iceoryx2::prelude::*;
    use iceoryx2::service::attribute::{AttributeKey, AttributeSpecifier, AttributeValue};
    let env = TestEnv::new("capacity-settings")?;
    let ipc = Ipc::new(&env.ipc_options())?;
    // A foreign program created the pose service first, with a buffer of 1 (fusepose asks for 4).
    let key = AttributeKey::new(b"fusepose.wire_version").unwrap();
    let value = AttributeValue::new(fusepose_client::WIRE_VERSION.to_string().as_bytes()).unwrap();
    let _foreign = ipc
        .node()
        .service_builder(&ServiceName::new("fusepose/camera/cam0/poses").unwrap())
        .publish_subscribe::<PoseMessage>()
        .enable_safe_overflow(true)
        .subscriber_max_buffer_size(1)
        .subscriber_max_borrowed_samples(2)
        .history_size(1)
        .max_publishers(2)
        .max_subscribers(16)
        .max_nodes(32)
        .create_with_attributes(&AttributeSpecifier::new().define(&key, &value).unwrap())
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    assert_capacity(
        CameraServices::open(&ipc, "cam0"),
        "fusepose/camera/cam0/poses",
        CapacityLimit::ServiceSettings,
        &["smaller settings", "DoesNotSupportRequestedMinBufferSize", "docs/PROTOCOL.md"],
    );
    Ok(())
}

/// The daemon's own ports: a pose service whose publishers are all taken
/// (two foreign publishers) stops `fuseposed` with the typed error.
#[test]
fn a_daemon_that_cannot_publish_poses_says_why() -> anyhow::Result<()> {
    let env = TestEnv::new("capacity-daemon")?;
    let ipc = Ipc::new(&env.ipc_options())?;
    let services = CameraServices::open(&ipc, "cam0")?;
    let _taken: Vec<_> = (0..limits::POSE_PUBLISHERS).map(|_| services.pose_publisher()).collect::<Result<_, _>>()?;
    let config = env.write_daemon_config("kind = \"none\"")?;
    let log = env.dir.path().join("fuseposed.log");
    let mut daemon = spawn_daemon(&env, &config, Some(&log))?;
    let status = daemon.wait_timeout(Duration::from_secs(30))?;
    let text = std::fs::read_to_string(&log)?;
    assert!(!status.success(), "fuseposed started without a pose publisher:\n{text}");
    for needle in ["fusepose/camera/cam0/poses", "too many publishers", "limit 2", "second fuseposed", "what to do"] {
        assert!(text.contains(needle), "{needle:?} missing in the daemon's log:\n{text}");
    }
    Ok(())
}
