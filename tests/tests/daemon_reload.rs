//! SIGHUP re-reads the daemon's configuration (issue 21): a camera is added
//! while another keeps running with its counters, a bad file is refused and
//! the running cameras stay, a removed camera stops being served, and the
//! log names every change.

use std::time::{Duration, Instant};

use fusepose_tests::*;

fn write_config(env: &TestEnv, path: &std::path::Path, cameras: &str) -> anyhow::Result<()> {
    let text = format!(
        "log_level = \"info\"\n{cameras}\n\n[estimator]\nkind = \"none\"\n\n[stats]\nhlog_path = \"\"\n\n[ipc]\nroot_path = {:?}\nprefix = {:?}\n",
        env.iox_root, env.prefix
    );
    Ok(std::fs::write(path, text)?)
}

fn wait_log(log: &std::path::Path, needle: &str, timeout: Duration) -> anyhow::Result<String> {
    let end = Instant::now() + timeout;
    loop {
        let text = std::fs::read_to_string(log).unwrap_or_default();
        if text.contains(needle) {
            return Ok(text);
        }
        anyhow::ensure!(Instant::now() < end, "no {needle:?} in the daemon log:\n{text}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn sighup_adds_changes_and_removes_cameras_and_refuses_a_bad_file() -> anyhow::Result<()> {
    let env = TestEnv::new("reload")?;
    let config = env.dir.path().join("fuseposed.toml");
    let log = env.dir.path().join("fuseposed.log");
    write_config(&env, &config, "cameras = [\"cam0\"]")?;
    let daemon = spawn_daemon(&env, &config, Some(&log))?;
    query_stats_of(&env, "cam0", Duration::from_secs(20))?;
    let producer = start_producer_of(&env, "cam0", 0, 30.0, 0, &[])?;
    std::thread::sleep(Duration::from_millis(700));
    let before = query_stats_of(&env, "cam0", Duration::from_secs(5))?;
    assert!(before.frames_processed > 5, "{before:?}");

    // Add cam1 with its own deadline; cam0 keeps its counters.
    write_config(&env, &config, "cameras = [\"cam0\"]\n\n[[camera]]\nname = \"cam1\"\ndeadline_ms = 30.0")?;
    daemon.signal(libc::SIGHUP);
    wait_log(&log, "reload: camera cam1 added", Duration::from_secs(10))?;
    let cam1 = query_stats_of(&env, "cam1", Duration::from_secs(10))?;
    assert_eq!(cam1.deadline_ns, 30_000_000);
    let producer1 = start_producer_of(&env, "cam1", 0, 30.0, 0, &[])?;
    std::thread::sleep(Duration::from_millis(700));
    let after = query_stats_of(&env, "cam0", Duration::from_secs(5))?;
    assert!(after.frames_processed > before.frames_processed, "cam0 was not served on: {after:?}");
    assert!(after.uptime_ns > before.uptime_ns + 500_000_000, "cam0's state was not carried over");
    assert!(query_stats_of(&env, "cam1", Duration::from_secs(5))?.frames_processed > 5);

    // A bad file: refused, both cameras keep running.
    std::fs::write(&config, "cameras = [\"cam0\", \"cam0\"]\n")?;
    daemon.signal(libc::SIGHUP);
    wait_log(&log, "reload refused", Duration::from_secs(10))?;
    let held0 = query_stats_of(&env, "cam0", Duration::from_secs(5))?.frames_processed;
    let held1 = query_stats_of(&env, "cam1", Duration::from_secs(5))?.frames_processed;
    std::thread::sleep(Duration::from_millis(500));
    assert!(query_stats_of(&env, "cam0", Duration::from_secs(5))?.frames_processed > held0);
    assert!(query_stats_of(&env, "cam1", Duration::from_secs(5))?.frames_processed > held1);

    // Change cam1's deadline, remove cam0.
    write_config(&env, &config, "[[camera]]\nname = \"cam1\"\ndeadline_ms = 35.0")?;
    daemon.signal(libc::SIGHUP);
    let text = wait_log(&log, "reload: camera cam0 removed", Duration::from_secs(10))?;
    assert!(text.contains("reload: camera cam1 changed (deadline)"), "{text}");
    let cam1 = query_stats_of(&env, "cam1", Duration::from_secs(5))?;
    assert_eq!(cam1.deadline_ns, 35_000_000);
    assert!(cam1.frames_processed > held1, "cam1's counters carried over");
    assert!(
        query_stats_of(&env, "cam0", Duration::from_millis(800)).is_err(),
        "cam0 still answers stats after its removal"
    );
    drop(producer);
    drop(producer1);
    Ok(())
}
