//! Rejected frames are logged at most once per second *per kind*, and what a
//! second suppressed is reported afterwards (issue 23: only the first kind of
//! a burst, `bad_magic`, was logged; `wrong_camera` and `capture_too_old`
//! 100–200 ms later gave no line and no suppressed count). Separate processes:
//! the daemon (transport only) and this test as the camera.

use std::time::Duration;

use fusepose_client::{FrameLayout, InvalidReason, Ipc, Producer, camera_id, monotonic_ns};
use fusepose_tests::*;

#[test]
fn every_kind_of_rejection_gets_a_line_and_suppressed_counts_are_reported() -> anyhow::Result<()> {
    let env = TestEnv::new("reject-log")?;
    let config = env.write_daemon_config("kind = \"none\"")?;
    let log = env.dir.path().join("fuseposed.log");
    let mut daemon = spawn_daemon(&env, &config, Some(&log))?;
    query_stats(&env, Duration::from_secs(20))?;

    let ipc = Ipc::new(&env.ipc_options())?;
    let layout = FrameLayout { width: 64, height: 48, ..FrameLayout::vga_rgbd() };
    let mut producer = Producer::create(&ipc, "cam0", layout)?;
    let mut payload = vec![0u8; layout.payload_len()];
    let [_, depth, _] = layout.planes();
    for pair in payload[depth.offset as usize..(depth.offset + depth.len) as usize].chunks_mut(2) {
        pair.copy_from_slice(&800u16.to_le_bytes());
    }
    let good = |sequence: u64| {
        let mut h = layout.header(camera_id("cam0"));
        (h.fx, h.fy, h.cx, h.cy) = (60.0, 60.0, 31.5, 23.5);
        h.sequence = sequence;
        h.capture_time_ns = monotonic_ns();
        h
    };
    // One burst within ~0.3 s: three kinds, the last one three times.
    let mut frames = vec![{
        let mut h = good(1);
        h.magic = 0;
        h
    }];
    frames.push({
        let mut h = good(2);
        h.camera_id = camera_id("cam9");
        h
    });
    for sequence in 3..6 {
        let mut h = good(sequence);
        h.capture_time_ns = 1; // the boot instant: far too old
        frames.push(h);
    }
    for header in frames {
        producer.send_raw(header, &payload)?;
        // Let the daemon take each frame before the next supersedes it.
        std::thread::sleep(Duration::from_millis(50));
    }
    producer.send_raw(good(6), &payload)?;
    // The suppressed count is reported once the kind's second is over.
    std::thread::sleep(Duration::from_millis(1500));
    let stats = query_stats(&env, Duration::from_secs(5))?;
    assert_eq!(stats.invalid_by_reason[InvalidReason::BadMagic as usize], 1, "{stats:?}");
    assert_eq!(stats.invalid_by_reason[InvalidReason::WrongCamera as usize], 1, "{stats:?}");
    assert_eq!(stats.invalid_by_reason[InvalidReason::CaptureTooOld as usize], 3, "{stats:?}");
    daemon.signal(libc::SIGTERM);
    daemon.wait_timeout(Duration::from_secs(10))?;

    let text = std::fs::read_to_string(&log)?;
    let rejected: Vec<&str> = text.lines().filter(|l| l.contains("frame rejected")).collect();
    for reason in ["bad_magic", "wrong_camera", "capture_too_old"] {
        assert_eq!(
            rejected.iter().filter(|l| l.contains(reason)).count(),
            1,
            "one `frame rejected` line for {reason} expected:\n{text}"
        );
    }
    let reported: Vec<&str> =
        text.lines().filter(|l| l.contains("capture_too_old") && l.contains("suppressed=2")).collect();
    assert_eq!(reported.len(), 1, "the two suppressed capture_too_old lines were not reported:\n{text}");
    assert!(
        !text.lines().any(|l| (l.contains("bad_magic") || l.contains("wrong_camera")) && l.contains("more frames")),
        "nothing was suppressed for the other kinds:\n{text}"
    );
    Ok(())
}
