//! fuseposed end to end: daemon, producer and consumers as separate processes
//! on an isolated iceoryx2 namespace per test.

use std::collections::BTreeSet;
use std::time::Duration;

use fusepose_client::{InvalidReason, PoseStatus, camera_id};
use fusepose_tests::*;

const TRANSPORT_ONLY: &str = "kind = \"none\"";

#[test]
fn every_pose_message_matches_a_sent_frame() -> anyhow::Result<()> {
    let env = TestEnv::new("match")?;
    let config = env.write_daemon_config(TRANSPORT_ONLY)?;
    let _daemon = start_daemon(&env, &config)?;
    let consumers = [start_consumer(&env, Duration::from_secs(60))?, start_consumer(&env, Duration::from_secs(60))?];

    let (first, count) = (100u64, 48u64);
    let last = first + count - 1;
    let producer = start_producer(&env, count, 30.0, first, &[])?;
    let mut produced = Vec::new();
    assert!(producer.collect_until(&mut produced, Duration::from_secs(30), |l| l.iter().any(|x| x == "done")));
    let sent: BTreeSet<u64> =
        produced.iter().filter_map(|l| l.strip_prefix("sent ")).map(|s| s.parse().unwrap()).collect();
    assert_eq!(sent, (first..=last).collect());

    for consumer in &consumers {
        let mut lines = Vec::new();
        let saw_last = consumer
            .collect_until(&mut lines, Duration::from_secs(15), |l| pose_lines(l).iter().any(|p| p.sequence == last));
        let poses = pose_lines(&lines);
        assert!(saw_last, "consumer never saw the last frame's poses; got {} messages", poses.len());
        for p in &poses {
            assert!(sent.contains(&p.sequence), "pose for unsent frame {}", p.sequence);
            assert_eq!(p.status & PoseStatus::OK, PoseStatus::OK, "{p:?}");
            assert_eq!(p.invalid_reason, 0);
            assert_eq!(p.camera_id, camera_id("cam0"));
            assert!(p.capture_ns <= p.received_ns && p.received_ns <= p.published_ns, "{p:?}");
        }
        let distinct: BTreeSet<u64> = poses.iter().map(|p| p.sequence).collect();
        assert_eq!(distinct.len(), poses.len(), "a frame was answered twice");
        assert!(distinct.len() as u64 >= count / 4, "only {} of {count} frames answered", distinct.len());
    }

    let stats = query_stats(&env, Duration::from_secs(5))?;
    assert_eq!(stats.frames_invalid, 0);
    assert_eq!(stats.frames_processed + stats.frames_skipped_stale, stats.frames_received);
    assert!(stats.frames_received + stats.frames_missed_sequence <= count);
    assert!(stats.frames_processed >= count / 4, "{stats:?}");
    assert_eq!(stats.since_start[fusepose_client::STAGE_COUNT].count, stats.frames_processed);
    Ok(())
}

#[test]
fn malformed_frame_is_rejected_counted_and_later_frames_served() -> anyhow::Result<()> {
    let env = TestEnv::new("malformed")?;
    let config = env.write_daemon_config(TRANSPORT_ONLY)?;
    let _daemon = start_daemon(&env, &config)?;
    let consumer = start_consumer(&env, Duration::from_secs(60))?;
    let producer = start_producer(&env, 30, 30.0, 0, &[10])?;
    let mut produced = Vec::new();
    assert!(producer.collect_until(&mut produced, Duration::from_secs(30), |l| l.iter().any(|x| x == "done")));
    assert!(produced.iter().any(|l| l == "malformed 10"));

    let mut lines = Vec::new();
    consumer.collect_until(&mut lines, Duration::from_secs(15), |l| pose_lines(l).iter().any(|p| p.sequence == 29));
    let poses = pose_lines(&lines);
    let rejected: Vec<_> = poses.iter().filter(|p| p.sequence == 10).collect();
    assert_eq!(rejected.len(), 1, "expected one message for the malformed frame: {poses:?}");
    assert_eq!(rejected[0].status & PoseStatus::INVALID_FRAME, PoseStatus::INVALID_FRAME);
    assert_eq!(rejected[0].status & PoseStatus::OK, 0);
    assert_eq!(rejected[0].invalid_reason, InvalidReason::PlaneOutOfBounds as u32);
    assert_eq!(rejected[0].objects, 0);
    assert!(poses.iter().any(|p| p.sequence > 10 && p.status & PoseStatus::OK != 0), "no frame served after it");
    assert!(poses.iter().filter(|p| p.sequence != 10).all(|p| p.status & PoseStatus::OK != 0));

    let stats = query_stats(&env, Duration::from_secs(5))?;
    assert_eq!(stats.frames_invalid, 1, "{stats:?}");
    assert_eq!(stats.invalid_by_reason[InvalidReason::PlaneOutOfBounds as usize], 1);
    Ok(())
}

#[test]
fn sigterm_exits_zero_and_leaves_a_readable_hlog() -> anyhow::Result<()> {
    let env = TestEnv::new("sigterm")?;
    let config = env.write_daemon_config(TRANSPORT_ONLY)?;
    let mut daemon = start_daemon(&env, &config)?;
    let producer = start_producer(&env, 20, 40.0, 0, &[])?;
    let mut produced = Vec::new();
    assert!(producer.collect_until(&mut produced, Duration::from_secs(30), |l| l.iter().any(|x| x == "done")));
    let stats = query_stats(&env, Duration::from_secs(5))?;
    assert!(stats.frames_processed > 0);

    daemon.signal(libc::SIGTERM);
    let status = daemon.wait_timeout(Duration::from_secs(10))?;
    assert_eq!(status.code(), Some(0), "fuseposed exit status {status}");

    let intervals = read_hlog(&env.hlog_path())?;
    let e2e: u64 = intervals.iter().filter(|(tag, _)| tag == "cam0.end_to_end").map(|(_, h)| h.len()).sum();
    assert_eq!(e2e, stats.frames_processed, "end-to-end samples in the .hlog");
    assert!(intervals.iter().any(|(tag, _)| tag == "cam0.ingest"));
    for (tag, h) in &intervals {
        assert!(h.max() < 60_000_000_000, "{tag}: implausible max {}", h.max());
    }
    Ok(())
}

#[test]
fn frames_flow_again_after_the_producer_is_killed_and_restarted() -> anyhow::Result<()> {
    let env = TestEnv::new("restart")?;
    let config = env.write_daemon_config(TRANSPORT_ONLY)?;
    let _daemon = start_daemon(&env, &config)?;
    let consumer = start_consumer(&env, Duration::from_secs(90))?;

    let first = start_producer(&env, 0, 30.0, 0, &[])?;
    let mut lines = Vec::new();
    assert!(
        consumer.collect_until(&mut lines, Duration::from_secs(20), |l| pose_lines(l).iter().any(|p| p.sequence >= 10)),
        "no poses from the first producer"
    );
    first.signal(libc::SIGKILL);
    drop(first);

    let _second = start_producer(&env, 0, 30.0, 5_000, &[])?;
    let resumed = consumer.collect_until(&mut lines, Duration::from_secs(20), |l| {
        pose_lines(l).iter().filter(|p| p.sequence >= 5_000 && p.status & PoseStatus::OK != 0).count() >= 10
    });
    assert!(resumed, "frames did not flow again after the restart");
    Ok(())
}
