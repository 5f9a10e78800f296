//! Overload and soak (issue 8) through `fp-soak` (tests/src/bin/fp_soak.rs):
//! daemon, producer and consumer as separate processes, ICP on the built-in
//! objects, 640x480 frames with producer-supplied labels.
//!
//! ICP is heavy on the shared 2-core CI box (tens of ms per object, more under
//! load), so CI runs small versions with one object per frame: 6 s at 200 fps
//! (the daemon far slower than the camera: keep-latest is the point) and 60 s
//! at 15 fps (no crash, no memory growth). The network soak is
//! `reliability_soak_net.rs`; the hour-long one is the documented command in
//! docs/RELIABILITY.md.
//!
//! Memory growth is judged on the daemon's private memory (`RssAnon`) after
//! a settle period, not on its whole RSS: the RSS also counts the pages of the
//! producer's shared-memory frames the daemon has read, which grow in ~1.5 MB
//! steps whenever the producer first hands over a sample slot the daemon had
//! not read yet (bounded by the frame segment) — the cause of the flaky
//! "RSS grew 5.44 %" failures (docs/RELIABILITY.md, "Memory in soaks").

use fusepose_tests::{MAX_SETTLED_GROWTH_PCT, run_fp_soak as soak, soak_number as num};

#[test]
fn overload_at_200_fps_keeps_latency_bounded_and_counts_what_it_skips() -> anyhow::Result<()> {
    let r = soak(&["--seconds", "6", "--fps", "200", "--objects-per-frame", "1", "--warmup", "2"])?;
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
    assert!(num(&r, "anon_growth_pct") < 5.0, "{r:?}");
    Ok(())
}

#[test]
fn one_minute_soak_has_no_crash_and_no_memory_growth() -> anyhow::Result<()> {
    let r = soak(&["--seconds", "60", "--fps", "15", "--objects-per-frame", "1", "--warmup", "6"])?;
    assert_eq!(num(&r, "crashes"), 0.0);
    assert!(num(&r, "processed") >= 100.0, "{r:?}");
    assert_eq!(num(&r, "invalid"), 0.0);
    // Private memory after the first 20 s: flat to the KiB over 300 s in
    // measurement (steps ≤ 32 KiB after settling, < 0.3 % here); 1 % is a real leak.
    assert!(num(&r, "anon_growth_pct") < MAX_SETTLED_GROWTH_PCT, "daemon private memory grew: {r:?}");
    Ok(())
}
