//! Each benchmark subcommand in its `--smoke` mode, as the binary (child
//! processes included), so they keep building and running: the run must
//! succeed and print its table with measured (finite, non-zero) numbers.
//! No timing thresholds.

use std::path::PathBuf;
use std::process::Command;

fn bench(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_fusepose-bench")).args(args).output().expect("run fusepose-bench");
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "fusepose-bench {args:?} failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    println!("{stdout}");
    stdout
}

/// `fusepose-bench e2e --smoke` with verification flagging instead of
/// dropping (the tests count poses), the shipped weights, `extra` and an
/// output folder.
fn e2e_smoke(weights: &str, out: &std::path::Path, extra: &[&str]) -> String {
    let mut args = vec!["e2e", "--smoke", "--weights", weights, "--estimator-extra", "verify = \"flag\""];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["--out", out.to_str().expect("a UTF-8 temp path")]);
    bench(&args)
}

/// The e2e consumer's accuracy line: true objects to find, and at least
/// half of them found.
fn assert_most_found(text: &str) {
    let line = text.lines().find(|l| l.contains("true objects >=")).expect("an accuracy line");
    let count = |before: &str| -> f64 {
        line.split(before).next().and_then(|s| s.rsplit(' ').next()).and_then(|s| s.parse().ok()).unwrap()
    };
    let (visible, found) = (count(" true objects >="), count(" found ("));
    assert!(visible > 0.0 && found >= 0.5 * visible, "{line}");
}

fn out_dir(tag: &str) -> PathBuf {
    std::env::temp_dir().join(format!("fusepose-bench-smoke-{tag}-{}", std::process::id()))
}

fn weights() -> Option<String> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../models/builtin.safetensors");
    if path.exists() {
        Some(path.display().to_string())
    } else {
        eprintln!("SKIPPED: {} is missing (the shipped network weights)", path.display());
        None
    }
}

/// The numeric columns of the table row starting with `label`.
fn row_numbers(text: &str, label: &str) -> Vec<f64> {
    let line = text
        .lines()
        .find(|l| l.trim_start().starts_with(label))
        .unwrap_or_else(|| panic!("no row {label:?} in\n{text}"));
    line[line.find(label).unwrap() + label.len()..]
        .split_whitespace()
        .filter_map(|w| w.trim_end_matches('%').parse().ok())
        .collect()
}

#[test]
fn transport_smoke_measures_all_four_transports() {
    let out = out_dir("transport");
    let text = bench(&["transport", "--smoke", "--out", out.to_str().unwrap()]);
    for label in ["iceoryx2, spin-then-wait", "iceoryx2, block on event", "iceoryx2, busy poll", "Unix socket, copy"] {
        let v = row_numbers(&text, label);
        // n, p50, p99, p99.9, max, lost, CPU
        assert!(v.len() >= 6 && v[0] > 0.0 && v[1] > 0.0 && v[1] <= v[4], "{label}: {v:?}");
    }
    assert!(text.contains("ratio p50 Unix socket"), "{text}");
    assert!(out.join("transport.png").exists() && out.join("transport.hlog").exists());
    let _ = std::fs::remove_dir_all(out);
}

#[test]
fn e2e_smoke_poses_frames_through_daemon_and_consumer() {
    let Some(weights) = weights() else { return };
    let out = out_dir("e2e");
    // Verification flags instead of dropping, and deadline-aware degradation is
    // off: on a loaded machine the daemon would shed the smallest instances to
    // keep its deadline (tested in the estimator), and this test counts the
    // poses of every labelled object.
    let text = e2e_smoke(&weights, &out, &["--no-degrade", "--fps", "30"]);
    let v = row_numbers(&text, "cam0");
    // fps, achieved, deadline, sent, posed, skipped, missed, late, degraded, p50, p99, p99.9, max, iters
    assert!(v.len() == 14 && v[0] == 30.0, "{v:?}");
    let v = &v[1..];
    assert!(v[0] > 0.0 && v[3] > 0.0 && v[8] > 0.0 && v[8] <= v[11], "{v:?}");
    assert!(text.contains("5.00 objects per message"), "every message poses the 5 labelled objects:\n{text}");
    // The consumer scored the poses against the video's truth: most are found.
    assert_most_found(&text);
    let _ = std::fs::remove_dir_all(out);
}

/// `e2e --source`: the producer replays a BOP split (here a two-image one
/// written as `fusepose render` writes one), with a colour cast, and the
/// consumer scores the poses against the split's own truth.
#[test]
fn e2e_smoke_replays_a_bop_split_with_a_colour_cast() {
    let Some(weights) = weights() else { return };
    let out = out_dir("e2e-bop");
    let split = out.join("split");
    fusepose_bench::video::write_test_split(&split, 2).expect("a BOP split");
    let source = ["--no-degrade", "--fps", "30", "--source", split.to_str().unwrap(), "--hold", "3", "--cast", "dim"];
    let text = e2e_smoke(&weights, &out, &source);
    assert!(text.contains("BOP split") && text.contains("colour cast dim"), "{text}");
    assert_most_found(&text);
    let _ = std::fs::remove_dir_all(out);
}

#[test]
fn e2e_smoke_serves_two_cameras_and_their_cell() {
    let Some(weights) = weights() else { return };
    let out = out_dir("e2e2");
    let text = e2e_smoke(&weights, &out, &["--cameras", "2", "--fps", "20"]);
    for camera in ["cam0", "cam1"] {
        let v = row_numbers(&text, camera);
        assert!(v.len() == 14 && v[4] > 0.0, "{camera} posed frames: {v:?}\n{text}");
        assert!(text.contains(&format!("{camera} 20 fps:")) && text.contains("messages of another camera 0"), "{text}");
    }
    let line = text.lines().find(|l| l.contains("all-cameras consumer")).unwrap_or_else(|| panic!("{text}"));
    assert!(line.contains("of a wrong camera 0") && !line.contains("cell messages 0 "), "{line}");
    assert!(line.contains("daemon RSS at the end"), "{line}");
    let _ = std::fs::remove_dir_all(out);
}

#[test]
fn tracking_smoke_poses_with_and_without_tracking() {
    let Some(weights) = weights() else { return };
    let out = out_dir("tracking");
    let text = bench(&["tracking", "--smoke", "--objects", "1", "--weights", &weights, "--out", out.to_str().unwrap()]);
    for mode in ["off", "on"] {
        let line = text
            .lines()
            .find(|l| l.split_whitespace().nth(1) == Some(mode))
            .unwrap_or_else(|| panic!("no {mode} row:\n{text}"));
        let v: Vec<f64> = line.split_whitespace().filter_map(|w| w.trim_end_matches('%').parse().ok()).collect();
        // objects, frames, poses, ms p50, ms p90, CPU ms, poses/s, tracked %, ADD(S) mm, ...
        assert!(v[2] > 0.0 && v[3] > 0.0 && v[6] > 0.0 && v[8].is_finite(), "{mode}: {v:?}");
        assert_eq!(v.last(), Some(&0.0), "{mode}: no allocations per steady-state frame: {line}");
    }
    let _ = std::fs::remove_dir_all(out);
}
