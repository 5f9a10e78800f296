//! One daemon per camera (issue 23): a second `fuseposed` for a camera that a
//! running daemon serves refuses to start and names the camera and the
//! running daemon's pid; the lock dies with its holder, so a SIGKILLed
//! daemon does not block its restart. Separate processes, transport only.

use std::time::Duration;

use fusepose_client::PoseStatus;
use fusepose_tests::*;

const TRANSPORT_ONLY: &str = "kind = \"none\"";

/// Runs a daemon that must refuse to start; returns its log.
fn refused(env: &TestEnv, config: &std::path::Path, log_name: &str) -> anyhow::Result<String> {
    let log = env.dir.path().join(log_name);
    let mut daemon = spawn_daemon(env, config, Some(&log))?;
    let status = daemon.wait_timeout(Duration::from_secs(30))?;
    let text = std::fs::read_to_string(&log)?;
    assert!(!status.success(), "the second daemon started: {status}\n{text}");
    Ok(text)
}

#[test]
fn a_second_daemon_for_a_served_camera_refuses_and_names_the_first() -> anyhow::Result<()> {
    let env = TestEnv::new("singleton")?;
    let config = env.write_daemon_config(TRANSPORT_ONLY)?;
    let mut first = start_daemon(&env, &config)?;
    let pid = first.pid();

    // Same configuration: refused, naming the camera, the pid and the node.
    let log = refused(&env, &config, "second.log")?;
    assert!(log.contains("camera cam0 is already served"), "{log}");
    assert!(log.contains(&format!("pid {pid}")), "the running daemon's pid {pid} is not named:\n{log}");
    assert!(log.contains("iceoryx2 node fuseposed"), "the running daemon's node is not named:\n{log}");

    // A configuration listing the camera among others is refused as well.
    let both = env.write_daemon_config_named("both.toml", &["cam1", "cam0"], TRANSPORT_ONLY)?;
    let log = refused(&env, &both, "both.log")?;
    assert!(log.contains("camera cam0 is already served"), "{log}");

    // The first daemon kept serving throughout.
    assert!(first.child.try_wait()?.is_none(), "the first daemon died");
    let consumer = start_consumer(&env, Duration::from_secs(30))?;
    let _producer = start_producer(&env, 0, 30.0, 0, &[])?;
    let mut lines = Vec::new();
    assert!(
        consumer.collect_until(&mut lines, Duration::from_secs(20), |l| pose_lines(l)
            .iter()
            .any(|p| p.status & PoseStatus::OK != 0)),
        "no poses from the first daemon after the refusals"
    );

    // Another camera in the same namespace is no conflict.
    let other = env.write_daemon_config_named("other.toml", &["cam1"], TRANSPORT_ONLY)?;
    let mut cam1 = spawn_daemon(&env, &other, Some(&env.dir.path().join("cam1.log")))?;
    std::thread::sleep(Duration::from_secs(2));
    assert!(
        cam1.child.try_wait()?.is_none(),
        "a daemon for cam1 did not start:\n{}",
        std::fs::read_to_string(env.dir.path().join("cam1.log"))?
    );
    cam1.signal(libc::SIGTERM);
    assert_eq!(cam1.wait_timeout(Duration::from_secs(10))?.code(), Some(0));
    Ok(())
}

#[test]
fn a_sigkilled_daemon_does_not_block_its_restart() -> anyhow::Result<()> {
    let env = TestEnv::new("singleton-kill")?;
    let config = env.write_daemon_config(TRANSPORT_ONLY)?;
    let mut first = start_daemon(&env, &config)?;
    first.signal(libc::SIGKILL);
    first.wait_timeout(Duration::from_secs(5))?;

    // The kernel released the lock with the process: the restart serves.
    let log = env.dir.path().join("restarted.log");
    let mut second = spawn_daemon(&env, &config, Some(&log))?;
    let stats = query_stats(&env, Duration::from_secs(20));
    assert!(second.child.try_wait()?.is_none(), "the restarted daemon exited:\n{}", std::fs::read_to_string(&log)?);
    assert!(stats.is_ok(), "the restarted daemon does not answer: {stats:?}");
    // Its own pid is in the lock file now.
    let lock = env.iox_root.join(format!("{}fuseposed.cam0.lock", env.prefix));
    let text = std::fs::read_to_string(&lock)?;
    assert!(text.contains(&format!("pid={}", second.pid())), "{}: {text}", lock.display());
    Ok(())
}
