//! Peers dying (issue 8): producer, consumer and daemon killed with SIGKILL
//! and restarted, and the daemon ended with SIGTERM/SIGINT. Every party is a
//! separate process; each test has its own iceoryx2 root and prefix, so they
//! run in parallel. Transport only (`kind = "none"`): the point is the IPC.

use std::collections::BTreeSet;
use std::time::{Duration, Instant};

use fusepose_client::{PoseStatus, STAGE_COUNT, monotonic_ns};
use fusepose_tests::*;

const TRANSPORT_ONLY: &str = "kind = \"none\"";

/// Sequences a consumer printed so far (collecting for up to `timeout` until `done`).
fn collect_poses(
    consumer: &Proc,
    lines: &mut Vec<String>,
    timeout: Duration,
    done: impl Fn(&[PoseLine]) -> bool,
) -> bool {
    consumer.collect_until(lines, timeout, |l| done(&pose_lines(l)))
}

/// iceoryx2's per-node entries under the root (`<root>/nodes/`). Read from the
/// file system: creating a node to ask iceoryx2 would clean dead ones itself.
fn node_entries(env: &TestEnv) -> anyhow::Result<BTreeSet<String>> {
    let dir = env.iox_root.join("nodes");
    // One directory per node (named by its id) beside the node's monitor files.
    Ok(std::fs::read_dir(&dir)?
        .flatten()
        .filter(|e| e.file_type().is_ok_and(|t| t.is_dir()))
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect())
}

#[test]
fn killed_producer_restarts_and_frames_flow_without_restarting_anything_else() -> anyhow::Result<()> {
    let env = TestEnv::new("peer-producer")?;
    let config = env.write_daemon_config(TRANSPORT_ONLY)?;
    let mut daemon = start_daemon(&env, &config)?;
    let consumer = start_consumer(&env, Duration::from_secs(60))?;
    let mut lines = Vec::new();

    let first = start_producer(&env, 0, 50.0, 0, &[])?;
    assert!(collect_poses(&consumer, &mut lines, Duration::from_secs(20), |p| p.iter().any(|p| p.sequence >= 10)));
    let alive = node_entries(&env)?;
    first.signal(libc::SIGKILL);
    drop(first);
    std::thread::sleep(Duration::from_millis(300));
    assert!(daemon.child.try_wait()?.is_none(), "fuseposed died with the producer");

    // The restarted producer counts from 0 again: a new publisher, not a regression.
    let restarted = Instant::now();
    let _second = start_producer(&env, 0, 50.0, 0, &[])?;
    let before = lines.len();
    assert!(
        consumer.collect_until(&mut lines, Duration::from_secs(20), |l| pose_lines(&l[before..])
            .iter()
            .filter(|p| p.status & PoseStatus::OK != 0)
            .count()
            >= 10),
        "frames did not flow again after the producer restart"
    );
    let resumed_ms = restarted.elapsed().as_secs_f64() * 1e3;
    let stats = query_stats(&env, Duration::from_secs(5))?;
    assert_eq!(stats.frames_invalid, 0, "the restart's sequence 0 must not count as invalid: {stats:?}");
    assert!(stats.producer_restarts >= 1, "{stats:?}");
    // The killed producer's node entry is gone (removed by the new producer's
    // node creation, iceoryx2's default, or the daemon's periodic cleanup).
    let now = node_entries(&env)?;
    assert_eq!(alive.difference(&now).count(), 1, "stale node of the killed producer: before {alive:?}, now {now:?}");
    println!("RESULT producer_restart_to_10_poses_ms={resumed_ms:.0}");
    Ok(())
}

#[test]
fn killed_consumer_leaves_daemon_and_other_consumers_unaffected() -> anyhow::Result<()> {
    let env = TestEnv::new("peer-consumer")?;
    let config = env.write_daemon_config(TRANSPORT_ONLY)?;
    let mut daemon = start_daemon(&env, &config)?;
    let _producer = start_producer(&env, 0, 50.0, 0, &[])?;
    let mut victim = start_consumer(&env, Duration::from_secs(60))?;
    let survivor = start_consumer(&env, Duration::from_secs(60))?;
    let (mut victim_lines, mut lines) = (Vec::new(), Vec::new());
    assert!(collect_poses(&victim, &mut victim_lines, Duration::from_secs(20), |p| !p.is_empty()));
    assert!(collect_poses(&survivor, &mut lines, Duration::from_secs(20), |p| !p.is_empty()));

    victim.signal(libc::SIGKILL);
    victim.wait_timeout(Duration::from_secs(5))?;
    let killed_at = pose_lines(&lines).last().map_or(0, |p| p.sequence);
    // The other consumer keeps getting every frame's poses (50 fps: ~50 in a second).
    assert!(
        collect_poses(&survivor, &mut lines, Duration::from_secs(10), |p| p
            .iter()
            .filter(|p| p.sequence > killed_at)
            .count()
            >= 40),
        "the surviving consumer stalled after the other was killed"
    );
    let after: BTreeSet<u64> = pose_lines(&lines).iter().map(|p| p.sequence).filter(|&s| s > killed_at).collect();
    let span = after.last().unwrap() - after.first().unwrap() + 1;
    assert!(after.len() as u64 * 10 >= span * 9, "survivor lost frames: {} of {span}", after.len());
    assert!(daemon.child.try_wait()?.is_none(), "fuseposed died with the consumer");

    // A restarted consumer receives again.
    let restarted = monotonic_ns();
    let again = start_consumer(&env, Duration::from_secs(60))?;
    let mut again_lines = Vec::new();
    assert!(collect_poses(&again, &mut again_lines, Duration::from_secs(10), |p| p
        .iter()
        .any(|p| p.published_ns > restarted)));
    let first = pose_lines(&again_lines).into_iter().find(|p| p.published_ns > restarted).unwrap();
    println!("RESULT consumer_restart_first_pose_ms={:.1}", (first.published_ns - restarted) as f64 / 1e6);
    let stats = query_stats(&env, Duration::from_secs(5))?;
    assert_eq!(stats.frames_invalid, 0);
    Ok(())
}

#[test]
fn killed_daemon_leaves_peers_running_and_a_restarted_daemon_serves_within_a_second() -> anyhow::Result<()> {
    let env = TestEnv::new("peer-daemon")?;
    let config = env.write_daemon_config(TRANSPORT_ONLY)?;
    let mut daemon = start_daemon(&env, &config)?;
    let mut producer = start_producer(&env, 0, 50.0, 0, &[])?;
    let mut consumer = start_consumer(&env, Duration::from_secs(60))?;
    let mut lines = Vec::new();
    assert!(collect_poses(&consumer, &mut lines, Duration::from_secs(20), |p| p.len() >= 5));
    let alive = node_entries(&env)?;
    assert_eq!(alive.len(), 3, "daemon, producer, consumer: {alive:?}");

    daemon.signal(libc::SIGKILL);
    daemon.wait_timeout(Duration::from_secs(5))?;
    let killed = monotonic_ns();
    // For a second: the producer keeps sending, the consumer waits, nobody crashes.
    let mut produced = Vec::new();
    producer.collect_until(&mut produced, Duration::from_secs(1), |_| false);
    let sent_after = produced.iter().filter(|l| l.starts_with("sent ")).count();
    assert!(sent_after >= 30, "producer stalled without the daemon: {sent_after} frames in 1 s");
    let before = lines.len();
    consumer.collect_until(&mut lines, Duration::from_millis(200), |_| false);
    assert!(pose_lines(&lines[before..]).iter().all(|p| p.published_ns < killed), "poses without a daemon?");
    assert!(
        producer.child.try_wait()?.is_none() && consumer.child.try_wait()?.is_none(),
        "a peer died with the daemon"
    );
    assert_eq!(node_entries(&env)?, alive, "the killed daemon's node stays until someone cleans it up");

    // Restart: time from spawning the process to the first pose the consumer holds.
    let spawned = monotonic_ns();
    let log = env.dir.path().join("restarted.log");
    let _restarted = spawn_daemon(&env, &config, Some(&log))?;
    let before = lines.len();
    assert!(
        consumer.collect_until(&mut lines, Duration::from_secs(10), |l| !pose_lines(&l[before..]).is_empty()),
        "the restarted daemon never served"
    );
    let first = pose_lines(&lines[before..])[0].clone();
    let serve_ms = (first.published_ns - spawned) as f64 / 1e6;
    println!("RESULT daemon_restart_to_first_pose_ms={serve_ms:.1}");
    assert!(first.status & PoseStatus::OK != 0, "{first:?}");
    assert!(serve_ms < 1000.0, "restarted daemon served after {serve_ms:.0} ms (limit 1 s)");
    // The restarted daemon's node creation removed the dead daemon's node (nothing else started a node).
    let now = node_entries(&env)?;
    assert_eq!(alive.difference(&now).count(), 1, "stale node of the killed daemon: before {alive:?}, now {now:?}");
    assert_eq!(now.len(), 3, "{now:?}");
    Ok(())
}

#[test]
fn sigterm_and_sigint_exit_zero_with_final_stats_and_hlog() -> anyhow::Result<()> {
    for (name, signal) in [("sigterm", libc::SIGTERM), ("sigint", libc::SIGINT)] {
        let env = TestEnv::new(name)?;
        let config = env.write_daemon_config(TRANSPORT_ONLY)?;
        let log = env.dir.path().join("fuseposed.log");
        let mut daemon = spawn_daemon(&env, &config, Some(&log))?;
        query_stats(&env, Duration::from_secs(20))?;
        let producer = start_producer(&env, 15, 50.0, 0, &[])?;
        let mut produced = Vec::new();
        assert!(producer.collect_until(&mut produced, Duration::from_secs(30), |l| l.iter().any(|x| x == "done")));
        std::thread::sleep(Duration::from_millis(300)); // let the last frame be processed
        let stats = query_stats(&env, Duration::from_secs(5))?;
        assert!(stats.frames_processed > 0, "{name}: {stats:?}");

        daemon.signal(signal);
        let status = daemon.wait_timeout(Duration::from_secs(10))?;
        assert_eq!(status.code(), Some(0), "{name}: fuseposed exit status {status}");
        let text = std::fs::read_to_string(&log)?;
        let final_line = text
            .lines()
            .find(|l| l.contains("final: received"))
            .unwrap_or_else(|| panic!("{name}: no final stats in\n{text}"));
        assert!(final_line.contains(&format!("processed {} ", stats.frames_processed)), "{name}: {final_line}");
        assert!(text.contains("final end_to_end"), "{name}: no final percentiles");
        let intervals = read_hlog(&env.hlog_path())?;
        let e2e: u64 = intervals.iter().filter(|(tag, _)| tag == "cam0.end_to_end").map(|(_, h)| h.len()).sum();
        assert_eq!(e2e, stats.frames_processed, "{name}: end-to-end samples in the .hlog");
        assert_eq!(stats.since_start[STAGE_COUNT].count, stats.frames_processed);
    }
    Ok(())
}
