//! `fusepose demo` end to end: the real executable with its daemon, camera and
//! consumer processes, for a couple of seconds.

use std::os::unix::process::CommandExt;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const EXE: &str = env!("CARGO_BIN_EXE_fusepose");

/// Live processes of process group `pgid` (field 5 of /proc/<pid>/stat).
fn processes_in_group(pgid: u32) -> usize {
    let mut count = 0;
    for entry in std::fs::read_dir("/proc").into_iter().flatten().flatten() {
        let Ok(stat) = std::fs::read_to_string(entry.path().join("stat")) else {
            continue;
        };
        // The command name (field 2) may hold spaces: split after its closing parenthesis.
        let Some((_, rest)) = stat.rsplit_once(')') else {
            continue;
        };
        let fields: Vec<&str> = rest.split_whitespace().collect();
        // rest: state, ppid, pgrp, ...; zombies (state Z) are already gone for our purpose.
        if fields.len() > 2 && fields[0] != "Z" && fields[2] == pgid.to_string() {
            count += 1;
        }
    }
    count
}

fn shm_with_prefix(prefix: &str) -> Vec<String> {
    std::fs::read_dir("/dev/shm")
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(prefix))
        .collect()
}

fn json(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap()
}

#[test]
fn demo_runs_scores_poses_writes_overlays_and_cleans_up() {
    let out = tempfile::tempdir().unwrap();
    let child = Command::new(EXE)
        .args(["demo", "--seconds", "2", "--overlays", "1", "--preload", "4", "--out"])
        .arg(out.path())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .process_group(0)
        .spawn()
        .unwrap();
    let pid = child.id();
    let run = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(run.status.success(), "demo failed:\n{stdout}\n{}", String::from_utf8_lossy(&run.stderr));
    assert!(stdout.contains("=== fusepose demo summary"), "{stdout}");
    assert!(stdout.contains("[  1 s]"), "no live line: {stdout}");

    let summary = json(&out.path().join("summary.json"));
    assert!(summary["pose_messages"].as_u64().unwrap() > 0, "{summary}");
    assert_eq!(summary["invalid"].as_u64(), Some(0), "{summary}");
    let objects = summary["objects"].as_array().unwrap();
    let all = objects.iter().find(|o| o["name"] == "ALL").expect("overall row");
    assert!(all["poses"].as_u64().unwrap() > 0);
    // The shipped network is far better than chance on unseen synthetic scenes.
    let median_mm = all["add_s_median_mm"].as_f64().unwrap();
    assert!(median_mm < 30.0, "median ADD-S {median_mm} mm");

    let pngs: Vec<_> = std::fs::read_dir(out.path())
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().ends_with(".png"))
        .collect();
    assert_eq!(pngs.len(), 1, "one overlay asked for");
    let img = image_size(&pngs[0].path());
    assert_eq!(img, (640, 480));
    assert!(out.path().join("logs/daemon.log").exists());

    assert_eq!(processes_in_group(pid), 0, "children left behind");
    let leftover = shm_with_prefix(&format!("fpdemo{pid}_"));
    assert!(leftover.is_empty(), "shared memory left behind: {leftover:?}");
}

/// Width and height from a PNG's IHDR chunk.
fn image_size(path: &Path) -> (u32, u32) {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(&bytes[1..4], b"PNG");
    let be = |i: usize| u32::from_be_bytes(bytes[i..i + 4].try_into().unwrap());
    (be(16), be(20))
}

#[test]
fn ctrl_c_stops_every_process_and_removes_shared_memory() {
    let out = tempfile::tempdir().unwrap();
    let demo = Command::new(EXE)
        .args(["demo", "--seconds", "60", "--overlays", "0", "--preload", "4", "--out"])
        .arg(out.path())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .process_group(0) // its own group, as a terminal's foreground job is
        .spawn()
        .unwrap();
    let pid = demo.id();
    // Wait until daemon, camera and consumer run.
    let t0 = Instant::now();
    while processes_in_group(pid) < 4 && t0.elapsed() < Duration::from_secs(30) {
        std::thread::sleep(Duration::from_millis(100));
    }
    assert_eq!(processes_in_group(pid), 4, "demo + daemon + camera + consumer");
    std::thread::sleep(Duration::from_secs(2));
    // SAFETY: kill(2) on the process group this test created: what Ctrl-C does.
    unsafe { libc::kill(-(pid as i32), libc::SIGINT) };
    let output = demo.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert_eq!(output.status.code(), Some(130), "{stdout}\n{}", String::from_utf8_lossy(&output.stderr));
    assert!(stdout.contains("=== fusepose demo summary"), "summary still printed: {stdout}");
    assert_eq!(processes_in_group(pid), 0, "children left behind");
    let leftover = shm_with_prefix(&format!("fpdemo{pid}_"));
    assert!(leftover.is_empty(), "shared memory left behind: {leftover:?}");
}
