//! The Python client example (`client/examples/python/`, PyPI `iceoryx2`
//! 0.10.0, written from docs/PROTOCOL.md) against a real `fuseposed`: its
//! camera publishes frames, its consumer decodes the pose messages answering
//! them, and its stats query decodes the snapshot. Every message it decodes
//! must equal, field by field, what the Rust client decodes from the same
//! sample. Skipped, with a message, where `python3 -c 'import iceoryx2'`
//! fails (`.ci/run` installs the package).

use std::collections::HashMap;
use std::process::Command;
use std::time::Duration;

use fusepose_client::{Consumer, Ipc, PoseMessage, PoseStatus, camera_id};
use fusepose_tests::*;

/// Why the Python side cannot run here, if it cannot.
fn python_missing() -> Option<String> {
    match Command::new("python3").args(["-c", "import iceoryx2"]).output() {
        Err(e) => Some(format!("python3 not runnable: {e}")),
        Ok(out) if !out.status.success() => Some(format!(
            "`python3 -c 'import iceoryx2'` failed ({}): {}",
            out.status,
            String::from_utf8_lossy(&out.stderr).lines().last().unwrap_or("")
        )),
        Ok(_) => None,
    }
}

/// The first `key {json}` lines of `stdout`, parsed.
fn json_lines(stdout: &str, key: &str) -> Vec<serde_json::Value> {
    let prefix = format!("{key} ");
    stdout
        .lines()
        .filter_map(|l| l.strip_prefix(&prefix))
        .map(|j| serde_json::from_str(j).expect("valid JSON"))
        .collect()
}

fn u64_of(v: &serde_json::Value, key: &str) -> u64 {
    v[key].as_u64().unwrap_or_else(|| panic!("{key} missing in {v}"))
}

/// Compares the Python decoding of a message with the Rust one.
fn assert_same(py: &serde_json::Value, rust: &PoseMessage) {
    let seq = rust.frame_sequence;
    assert_eq!(u64_of(py, "format_version"), rust.format_version as u64, "frame {seq}");
    assert_eq!(u64_of(py, "camera_id"), rust.camera_id as u64, "frame {seq}");
    assert_eq!(u64_of(py, "status"), rust.status as u64, "frame {seq}");
    for (key, value) in [
        ("capture_time_ns", rust.capture_time_ns),
        ("received_time_ns", rust.received_time_ns),
        ("published_time_ns", rust.published_time_ns),
    ] {
        assert_eq!(u64_of(py, key), value, "frame {seq}: {key}");
    }
    let stages: Vec<u64> = py["stage_ns"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap()).collect();
    assert_eq!(stages, rust.stage_ns, "frame {seq}: stage_ns");
    let objects = py["objects"].as_array().unwrap();
    assert_eq!(objects.len(), rust.objects().len(), "frame {seq}: object count");
    for (o, r) in objects.iter().zip(rust.objects()) {
        assert_eq!(u64_of(o, "class_id"), r.class_id as u64);
        assert_eq!(u64_of(o, "instance_id"), r.instance_id as u64);
        assert_eq!(u64_of(o, "refine_iterations"), r.refine_iterations as u64);
        assert_eq!(u64_of(o, "flags"), r.flags as u64);
        assert_eq!(u64_of(o, "mask_pixels"), r.mask_pixels as u64);
        let floats = |k: &str| -> Vec<f64> { o[k].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect() };
        // Python prints the shortest round-trip text; serde_json (without its
        // float_roundtrip feature) may read it back one ulp off: equal to 2 ulp.
        let same = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(x, y)| (x - y).abs() <= 2.0 * f64::EPSILON * y.abs());
        assert!(same(&floats("quaternion_xyzw"), &r.quaternion), "frame {seq}: {:?} vs {:?}", o, r.quaternion);
        assert!(same(&floats("translation_m"), &r.translation_m), "frame {seq}: {:?} vs {:?}", o, r.translation_m);
        assert_eq!(floats("quaternion_xyzw").len(), 4);
        assert_eq!(o["confidence"].as_f64().unwrap() as f32, r.confidence, "frame {seq}");
        // NaN (not verified) travels as JSON null.
        for (key, value) in [("fit_score", r.fit_score), ("depth_residual_m", r.depth_residual_m)] {
            match o[key].as_f64() {
                Some(v) => assert_eq!(v as f32, value, "frame {seq}: {key}"),
                None => assert!(value.is_nan(), "frame {seq}: {key} is {value}, Python decoded null"),
            }
        }
        let bbox: Vec<u16> = o["bbox"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap() as u16).collect();
        assert_eq!(bbox, r.bbox, "frame {seq}");
    }
}

#[test]
fn python_producer_consumer_and_stats_query_against_a_real_daemon() -> anyhow::Result<()> {
    if let Some(why) = python_missing() {
        println!("SKIPPED python_client: {why}; install it with `python3 -m pip install --user iceoryx2==0.10.0`");
        return Ok(());
    }
    let root = workspace_root()?;
    let weights = root.join("models/builtin.safetensors").canonicalize()?;
    let env = TestEnv::new("python")?;
    // The network on the producer's label plane (no segmenter). The box is no
    // real object, so its poses fail verification: flagged (kept, with their
    // fit values), not dropped.
    let config = env.write_daemon_config(&format!(
        "kind = \"net\"\nweights = {:?}\nmasks = \"labels\"\nverify = \"flag\"",
        weights.display().to_string()
    ))?;
    let _daemon = start_daemon(&env, &config)?;

    // The Rust side decodes every message as well (in its own thread: ports are not Send).
    let (ipc_options, stop) = (env.ipc_options(), std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false)));
    let stop_flag = stop.clone();
    let rust_side = std::thread::spawn(move || -> anyhow::Result<Vec<PoseMessage>> {
        let ipc = Ipc::new(&ipc_options)?;
        let mut consumer = Consumer::open(&ipc, "cam0")?;
        let mut all = Vec::new();
        while !stop_flag.load(std::sync::atomic::Ordering::Relaxed) {
            if consumer.wait_ready(Duration::from_millis(50))? {
                consumer.drain(&mut all)?;
            }
        }
        Ok(all)
    });
    std::thread::sleep(Duration::from_millis(300));

    let script_dir = root.join("client/examples/python");
    let mut cmd = Command::new("python3");
    cmd.current_dir(&script_dir).args([
        "fusepose_example.py",
        "--camera",
        "cam0",
        "run",
        "--frames",
        "24",
        "--fps",
        "12",
    ]);
    env.apply(&mut cmd);
    cmd.env("PYTHONDONTWRITEBYTECODE", "1"); // no __pycache__ in the checkout
    let out = cmd.output()?;
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    std::thread::sleep(Duration::from_millis(300));
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let rust = rust_side.join().map_err(|_| anyhow::anyhow!("the Rust consumer panicked"))??;
    assert!(out.status.success(), "the Python client failed ({}):\n{stdout}\n{stderr}", out.status);

    let poses = json_lines(&stdout, "pose");
    let by_sequence: HashMap<u64, &PoseMessage> = rust.iter().map(|m| (m.frame_sequence, m)).collect();
    assert!(poses.len() >= 12, "only {} of 24 frames answered:\n{stdout}\n{stderr}", poses.len());
    let (mut with_objects, mut compared) = (0, 0);
    for py in &poses {
        let seq = u64_of(py, "frame_sequence");
        // A loaded machine may starve the Rust thread past its 4-message buffer: compare what both hold.
        let Some(rust) = by_sequence.get(&seq) else { continue };
        assert_same(py, rust);
        compared += 1;
        assert_eq!(rust.camera_id, camera_id("cam0"));
        assert!(rust.status & PoseStatus::OK != 0, "frame {seq}: status {:#x}", rust.status);
        with_objects += usize::from(rust.objects().iter().any(|o| o.class_id == 1));
    }
    assert!(compared * 2 >= poses.len(), "only {compared} of {} messages were seen by both clients", poses.len());
    assert!(with_objects * 2 >= compared, "the box of class 1 was posed in only {with_objects} messages");

    let stats = json_lines(&stdout, "stats");
    assert_eq!(stats.len(), 1, "{stdout}");
    let s = &stats[0];
    assert_eq!(u64_of(s, "camera_id"), camera_id("cam0") as u64);
    assert_eq!(u64_of(s, "frames_invalid"), 0, "{s}");
    assert!(u64_of(s, "frames_processed") >= poses.len() as u64, "{s}");
    assert_eq!(u64_of(s, "frames_processed"), s["since_start"]["end_to_end"]["count"].as_u64().unwrap(), "{s}");
    let rust_stats = query_stats(&env, Duration::from_secs(5))?;
    assert!(rust_stats.frames_processed >= u64_of(s, "frames_processed"));

    // The cell service decoded from PROTOCOL.md's layout: one camera with the
    // identity extrinsics, so each cell object is that frame's pose as it was.
    let cells = json_lines(&stdout, "cell");
    assert!(!cells.is_empty(), "the Python client read no cell message:\n{stdout}\n{stderr}");
    let mut cell_objects = 0;
    for c in &cells {
        assert_eq!(u64_of(c, "format_version"), fusepose_client::WIRE_VERSION as u64);
        assert_eq!((u64_of(c, "camera_count"), u64_of(c, "trigger_camera_id")), (1, camera_id("cam0") as u64), "{c}");
        for o in c["objects"].as_array().unwrap() {
            let view = &o["views"][0];
            assert_eq!((u64_of(o, "view_count"), u64_of(view, "camera_id")), (1, camera_id("cam0") as u64), "{o}");
            let Some(rust) = by_sequence.get(&u64_of(view, "frame_sequence")) else { continue };
            // `instance_id` is the pose's id (stable while the object stays in view), not its index in the message.
            let id = u64_of(view, "instance_id");
            let r = rust.objects().iter().find(|r| r.instance_id as u64 == id);
            let r = r.unwrap_or_else(|| {
                panic!("cell object {o} names instance {id}, absent from frame {}", rust.frame_sequence)
            });
            assert_eq!(u64_of(o, "class_id"), r.class_id as u64, "{o}");
            let t: Vec<f64> = o["translation_m"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
            // The identity extrinsics are still a rotation and an addition in f64: the last bit may move.
            assert!(t.iter().zip(r.translation_m).all(|(a, b)| (a - b).abs() < 1e-12), "{o} vs {:?}", r.translation_m);
            assert_eq!(u64_of(view, "capture_time_ns"), rust.capture_time_ns);
            cell_objects += 1;
        }
    }
    assert!(cell_objects > 0, "no cell object matched a pose the Rust client saw:\n{stdout}");
    println!(
        "RESULT python client: {compared} of {} messages decoded identically to the Rust client; {} cell messages, {cell_objects} objects checked; stats {s}",
        poses.len(),
        cells.len()
    );
    Ok(())
}
