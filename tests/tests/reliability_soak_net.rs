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
    // The segmenter finds the rendered objects (5 per frame) and their poses
    // pass verification. On a loaded machine the daemon sheds instances to
    // keep the frame rate (session 29, load 5: 4.2 of 5.2 found per frame
    // shed, 0.85 posed), so what it found counts posed, shed and failed alike.
    let processed = num(&r, "processed");
    let (posed, shed, failed) =
        (num(&r, "consumer_objects"), num(&r, "objects_shed"), num(&r, "poses_failed_verification"));
    assert!(posed + shed + failed >= 3.0 * processed, "the segmenter found few of the 5 objects per frame: {r:?}");
    // Every answered frame estimates at least one instance; most pass the depth check.
    assert!(posed + failed >= processed, "frames answered without any estimate: {r:?}");
    assert!(posed >= failed, "most poses fail verification: {r:?}");
    assert!(num(&r, "anon_growth_pct") < MAX_SETTLED_GROWTH_PCT, "daemon private memory grew: {r:?}");
    Ok(())
}
