//! Overload and soak (issue 8) through `fp-soak` (tests/src/bin/fp_soak.rs):
//! daemon, producer and consumer as separate processes, ICP on the built-in
//! objects, 640x480 frames with producer-supplied labels.
//!
//! ICP is heavy on the shared 2-core CI box (tens of ms per object, more under
//! load), so CI runs small versions with one object per frame: 6 s at 200 fps
//! (the daemon far slower than the camera: keep-latest is the point) and 60 s
//! at 15 fps (no crash, no RSS growth). The long soak is the documented
//! command in docs/RELIABILITY.md.

use std::collections::HashMap;
use std::process::Command;

use fusepose_tests::{daemon_binary, package_binary};

/// Runs `fp-soak run <args>` and returns its `soak` line as key → value.
fn soak(args: &[&str]) -> anyhow::Result<HashMap<String, String>> {
    let out = Command::new(package_binary("fp-soak")?)
        .arg("run")
        .args(args)
        .arg("--daemon")
        .arg(daemon_binary()?)
        .output()?;
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    anyhow::ensure!(out.status.success(), "fp-soak failed ({}):\n{stdout}\n{stderr}", out.status);
    let line =
        stdout.lines().find(|l| l.starts_with("soak ")).ok_or_else(|| anyhow::anyhow!("no soak line:\n{stdout}"))?;
    println!("RESULT {line}");
    Ok(line
        .split_whitespace()
        .skip(1)
        .filter_map(|kv| kv.split_once('='))
        .map(|(k, v)| (k.to_owned(), v.to_owned()))
        .collect())
}

fn num(r: &HashMap<String, String>, key: &str) -> f64 {
    r.get(key).and_then(|v| v.parse().ok()).unwrap_or_else(|| panic!("no numeric {key} in {r:?}"))
}

#[test]
fn overload_at_200_fps_keeps_latency_bounded_and_counts_what_it_skips() -> anyhow::Result<()> {
    let r = soak(&["--seconds", "6", "--fps", "200", "--objects", "1", "--warmup", "2"])?;
    assert_eq!(num(&r, "crashes"), 0.0);
    let (sent, received, processed) = (num(&r, "sent"), num(&r, "received"), num(&r, "processed"));
    let (stale, missed, invalid) = (num(&r, "skipped_stale"), num(&r, "missed_sequence"), num(&r, "invalid"));
    assert!(sent >= 0.7 * 6.0 * 200.0, "producer reached only {sent} frames");
    assert_eq!(invalid, 0.0);
    // Every frame the daemon took is processed or skipped as stale; the rest
    // were overwritten in the 2-frame buffer (counted from sequence gaps) or
    // sent after its last look.
    assert_eq!(processed + stale, received, "{r:?}");
    assert!(received + missed <= sent, "{r:?}");
    assert!(stale + missed > 0.0, "the daemon kept up with 200 fps: no overload was tested: {r:?}");
    // Keep-latest: the daemon never works through a backlog, so latency stays
    // near one frame's processing time instead of growing with the run.
    assert!(num(&r, "e2e_max_ms") < 1000.0, "{r:?}");
    assert!(num(&r, "consumer_p99_us") < 1.0e6, "{r:?}");
    assert!(num(&r, "rss_growth_pct") < 5.0, "{r:?}");
    Ok(())
}

#[test]
fn one_minute_soak_has_no_crash_and_no_memory_growth() -> anyhow::Result<()> {
    let r = soak(&["--seconds", "60", "--fps", "15", "--objects", "1", "--warmup", "6"])?;
    assert_eq!(num(&r, "crashes"), 0.0);
    assert!(num(&r, "processed") >= 100.0, "{r:?}");
    assert_eq!(num(&r, "invalid"), 0.0);
    assert!(num(&r, "rss_growth_pct") < 5.0, "daemon RSS grew: {r:?}");
    Ok(())
}
