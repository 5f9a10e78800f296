//! The real pipeline under a two-minute soak (issue 23): `fuseposed` with the
//! shipped network and its segmenter (frames carry no labels), a producer of
//! rendered tabletop scenes with 5 objects at 24 FPS and a consumer, as
//! separate processes (`fp-soak`, tests/src/bin/fp_soak.rs). No crash, every
//! answered frame posed without errors, and no growth of the daemon's private
//! memory after the first 40 s. The hour-long run is the documented command in
//! docs/RELIABILITY.md; latency is not asserted (CI is shared and loaded), only
//! printed per 20-second window.

use fusepose_tests::{MAX_SETTLED_GROWTH_PCT, run_fp_soak, soak_number as num};

#[test]
fn two_minute_network_soak_with_the_segmenter_has_no_crash_and_no_memory_growth() -> anyhow::Result<()> {
    let r = run_fp_soak(&[
        "--seconds",
        "120",
        "--fps",
        "24",
        "--estimator",
        "net",
        "--objects-per-frame",
        "5",
        "--report-window-s",
        "20",
    ])?;
    assert_eq!(num(&r, "crashes"), 0.0, "{r:?}");
    assert_eq!(num(&r, "invalid"), 0.0, "{r:?}");
    assert_eq!(num(&r, "estimator_failures"), 0.0, "{r:?}");
    // Keep-latest: what the daemon took is processed or skipped as stale.
    assert_eq!(num(&r, "processed") + num(&r, "skipped_stale"), num(&r, "received"), "{r:?}");
    assert!(num(&r, "processed") >= 100.0, "the daemon answered too few frames: {r:?}");
    // The segmenter finds the rendered objects and poses pass verification:
    // answers carry poses (3.5 per frame measured under load 9, 5 rendered).
    assert!(num(&r, "consumer_objects") >= num(&r, "consumer_ok"), "few objects posed: {r:?}");
    assert!(num(&r, "anon_growth_pct") < MAX_SETTLED_GROWTH_PCT, "daemon private memory grew: {r:?}");
    Ok(())
}
