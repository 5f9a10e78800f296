//! One CLI vocabulary (issue 23): every `fusepose` and `fusepose-bench`
//! subcommand answers `--help`; shared flags carry the same names
//! (`--dataset` + `--split`, `--scale`, `--weights` defaulting to the
//! shipped weights, `--seed`, `--fps`, `--objects` for an object set); and
//! each subcommand runs once for real with tiny sizes — commands that take a
//! dataset given the dataset root and the split folder alike.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Duration;

use fusepose_tests::*;

const SUBCOMMANDS: [&str; 11] =
    ["camera", "watch", "stats", "render", "objects", "train", "eval", "demo", "bridge", "record", "adapt"];
const BENCH_SUBCOMMANDS: [&str; 5] = ["transport", "estimator", "e2e", "tracking", "ros2"];

fn fusepose() -> PathBuf {
    workspace_binary("fusepose-cli", "fusepose").expect("building fusepose")
}

fn bench() -> PathBuf {
    workspace_binary("fusepose-bench", "fusepose-bench").expect("building fusepose-bench")
}

/// Runs `exe args` in `dir` within `env`'s namespace; fails with its output unless it succeeds.
fn run(env: &TestEnv, dir: &Path, exe: &Path, args: &[&str]) -> anyhow::Result<String> {
    let mut cmd = Command::new(exe);
    cmd.args(args).current_dir(dir);
    env.apply(&mut cmd);
    let out: Output = cmd.output()?;
    let text = String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    anyhow::ensure!(out.status.success(), "`{} {}` failed ({}):\n{text}", exe.display(), args.join(" "), out.status);
    Ok(text)
}

fn help(env: &TestEnv, exe: &Path, sub: &[&str]) -> anyhow::Result<String> {
    let args: Vec<&str> = sub.iter().copied().chain(["--help"]).collect();
    run(env, env.dir.path(), exe, &args)
}

#[test]
fn every_subcommand_has_help_with_the_shared_flag_names() -> anyhow::Result<()> {
    let env = TestEnv::new("cli-help")?;
    let (fp, fb) = (fusepose(), bench());
    let mut helps = std::collections::HashMap::new();
    for sub in SUBCOMMANDS {
        helps.insert(sub, help(&env, &fp, &[sub])?);
    }
    helps.insert("objects list", help(&env, &fp, &["objects", "list"])?);
    // Datasets: root or split folder, the same flags everywhere.
    for sub in ["camera", "eval", "train"] {
        assert!(helps[sub].contains("--dataset") && helps[sub].contains("--split"), "{sub}:\n{}", helps[sub]);
    }
    // Metres per mesh unit: --scale everywhere (--mesh-scale only as a hidden alias).
    for sub in ["render", "train", "eval", "objects list", "record", "adapt"] {
        assert!(helps[sub].contains("--scale"), "{sub} has no --scale:\n{}", helps[sub]);
        assert!(!helps[sub].contains("--mesh-scale"), "{sub} still shows --mesh-scale:\n{}", helps[sub]);
    }
    // Commands that run the network default to the shipped weights.
    for sub in ["eval", "demo", "adapt"] {
        assert!(helps[sub].contains("--weights"), "{sub}");
        assert!(helps[sub].contains("models/builtin.safetensors"), "{sub}: no default weights:\n{}", helps[sub]);
    }
    for sub in ["render", "train", "eval", "camera", "demo", "adapt"] {
        assert!(helps[sub].contains("--seed"), "{sub} has no --seed");
    }
    for sub in ["camera", "demo"] {
        assert!(helps[sub].contains("--fps"), "{sub} has no --fps");
    }
    for sub in ["render", "train", "eval", "record", "adapt"] {
        assert!(helps[sub].contains("--objects <OBJECTS>"), "{sub}: --objects names the object set:\n{}", helps[sub]);
    }
    // The ROS 2 bridges: the daemon's camera by --name, the DDS domain by --domain-id, QoS flags alike.
    for bridge in ["ros2-camera", "ros2", "ros2-cell"] {
        let text = help(&env, &fp, &["bridge", bridge])?;
        for flag in ["--domain-id", "--reliability", "--history-depth", "--durability"] {
            assert!(text.contains(flag), "bridge {bridge} has no {flag}:\n{text}");
        }
        // The cell bridge serves every camera; the others serve the camera named by --name.
        assert_eq!(text.contains("--name"), bridge != "ros2-cell", "bridge {bridge}:\n{text}");
    }
    for sub in BENCH_SUBCOMMANDS {
        let text = help(&env, &fb, &[sub])?;
        if sub != "transport" {
            assert!(text.contains("--weights") && text.contains("models/builtin.safetensors"), "bench {sub}:\n{text}");
        }
        if ["e2e", "estimator", "tracking", "ros2"].contains(&sub) {
            assert!(text.contains("--objects-per-frame"), "bench {sub}: counts are --objects-per-frame:\n{text}");
        }
        if sub == "e2e" || sub == "ros2" {
            assert!(text.contains("--fps") && text.contains("--seed"), "bench e2e:\n{text}");
        }
    }
    Ok(())
}

#[test]
fn every_subcommand_runs_once_with_tiny_sizes() -> anyhow::Result<()> {
    let env = TestEnv::new("cli-run")?;
    let (fp, fb) = (fusepose(), bench());
    let dir = env.dir.path();
    let s = |p: &Path| p.display().to_string();
    let data = dir.join("data");

    // render: a 2-frame test split (metres per mesh unit via --scale).
    run(
        &env,
        dir,
        &fp,
        &[
            "render",
            "--scenes",
            "1",
            "--frames-per-scene",
            "2",
            "--split",
            "test",
            "--seed",
            "3",
            "--noise",
            "off",
            "--scale",
            "1",
            "--out",
            &s(&data),
        ],
    )?;
    assert!(data.join("test/000000/scene_gt.json").is_file());
    // The old flag still works, hidden.
    let legacy = dir.join("legacy");
    run(
        &env,
        dir,
        &fp,
        &["render", "--scenes", "1", "--frames-per-scene", "1", "--mesh-scale", "1", "--out", &s(&legacy)],
    )?;

    let text = run(&env, dir, &fp, &["objects", "list"])?;
    assert!(text.lines().count() >= 8, "{text}");

    // objects export of a user's mesh folder: a millimetre cube comes out in
    // metres, with the declared symmetry, where the Blender script reads it.
    let meshes = dir.join("meshes");
    std::fs::create_dir_all(&meshes)?;
    let mut cube = String::new();
    for i in 0..8 {
        let c = |b: usize| if i & b != 0 { 20.0 } else { -20.0 };
        cube += &format!("v {} {} {}\n", c(1), c(2), c(4));
    }
    for f in [[1, 3, 4], [1, 4, 2], [5, 6, 8], [5, 8, 7], [1, 2, 6], [1, 6, 5]] {
        cube += &format!("f {} {} {}\n", f[0], f[1], f[2]);
    }
    for f in [[3, 7, 8], [3, 8, 4], [1, 5, 7], [1, 7, 3], [2, 4, 8], [2, 8, 6]] {
        cube += &format!("f {} {} {}\n", f[0], f[1], f[2]);
    }
    std::fs::write(meshes.join("dice.obj"), cube)?;
    let exported = dir.join("exported");
    run(
        &env,
        dir,
        &fp,
        &["objects", "export", &s(&exported), "--objects", &s(&meshes), "--scale", "0.001", "--symmetry", "dice=box"],
    )?;
    let info: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(exported.join("models_info.json"))?)?;
    let dice = &info["objects"][0];
    assert_eq!((info["units"].as_str(), dice["name"].as_str()), (Some("metres"), Some("dice")), "{info}");
    assert!((dice["bbox_max"][0].as_f64().unwrap_or(0.0) - 0.02).abs() < 1e-6, "scaled to metres: {info}");
    assert_eq!(dice["symmetry"]["kind"].as_str(), Some("discrete"), "{info}");
    assert!(exported.join(dice["mesh"].as_str().unwrap_or("-")).is_file(), "{info}");

    // objects procedural: the built-ins then three made-up objects, as a folder
    // that `objects list` (and so `train --objects`) loads back with textures.
    let procedural = dir.join("procedural");
    run(&env, dir, &fp, &["objects", "procedural", &s(&procedural), "--count", "3", "--seed", "4", "--with-builtin"])?;
    let listing = run(&env, dir, &fp, &["objects", "list", "--objects", &s(&procedural)])?;
    let rows: Vec<&str> = listing.lines().filter(|l| l.trim_start().starts_with(char::is_numeric)).collect();
    assert_eq!(rows.len(), 11, "{listing}");
    assert!(rows[0].contains("cracker_box") && rows[10].contains("proc_002"), "{listing}");
    assert!(!listing.contains("warning:"), "procedural textures load without warnings: {listing}");

    // eval: the network with the shipped weights by default; root and split folder give the same result.
    let (by_root, by_split) = (dir.join("root.json"), dir.join("split.json"));
    run(
        &env,
        dir,
        &fp,
        &["eval", "--dataset", &s(&data), "--estimator", "net", "--limit", "2", "--seed", "5", "--json", &s(&by_root)],
    )?;
    run(
        &env,
        dir,
        &fp,
        &[
            "eval",
            "--dataset",
            &s(&data.join("test")),
            "--estimator",
            "net",
            "--limit",
            "2",
            "--seed",
            "5",
            "--mesh-scale",
            "1",
            "--json",
            &s(&by_split),
        ],
    )?;
    let (a, b): (serde_json::Value, serde_json::Value) = (
        serde_json::from_str(&std::fs::read_to_string(&by_root)?)?,
        serde_json::from_str(&std::fs::read_to_string(&by_split)?)?,
    );
    assert_eq!(a["overall"]["count"], b["overall"]["count"]);
    assert_eq!(a["overall"]["add_s_auc"], b["overall"]["add_s_auc"], "root and split folder differ");
    // A root without the split says what it found.
    let mut bad = Command::new(&fp);
    bad.args(["eval", "--dataset", &s(&data), "--split", "val"]).current_dir(dir);
    let out = bad.output()?;
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("splits found there: test"), "{err}");

    // train: one tiny step on the dataset root's test split.
    run(
        &env,
        dir,
        &fp,
        &[
            "train",
            "--dataset",
            &s(&data),
            "--split",
            "test",
            "--steps",
            "1",
            "--batch",
            "1",
            "--val-frames",
            "1",
            "--val-samples",
            "1",
            "--points",
            "32",
            "--crop",
            "16",
            "--seed",
            "2",
            "--scale",
            "1",
            "--quiet",
            "--checkpoint-dir",
            &s(&dir.join("ck")),
            "--out",
            &s(&dir.join("tiny.safetensors")),
        ],
    )?;
    assert!(dir.join("tiny.safetensors").is_file());

    // camera (dataset root) → daemon → watch, then stats.
    let config = env.write_daemon_config("kind = \"none\"")?;
    let _daemon = start_daemon(&env, &config)?;
    let mut watch = Command::new(&fp);
    watch.args(["watch", "--count", "1", "--json", "--idle-timeout-s", "60"]).current_dir(dir);
    env.apply(&mut watch);
    let watch = Proc::spawn("fusepose watch", watch)?;
    std::thread::sleep(Duration::from_millis(500));
    run(&env, dir, &fp, &["camera", "--dataset", &s(&data), "--frames", "2", "--fps", "20", "--seed", "1"])?;
    let line = watch.wait_for_line("{", Duration::from_secs(30))?;
    assert!(line.contains("\"frame_sequence\""), "{line}");
    let text = run(&env, dir, &fp, &["stats"])?;
    assert!(text.contains("frames: received"), "{text}");

    // demo: one second of the whole system, shipped weights by default.
    let demo = dir.join("demo-out");
    run(
        &env,
        dir,
        &fp,
        &[
            "demo",
            "--seconds",
            "1",
            "--preload",
            "2",
            "--views-per-scene",
            "2",
            "--overlays",
            "0",
            "--fps",
            "12",
            "--seed",
            "500000001",
            "--out",
            &s(&demo),
        ],
    )?;
    assert!(demo.join("summary.json").is_file());

    // fusepose-bench: each benchmark's smoke run, from the checkout (shipped weights by default).
    let root = workspace_root()?;
    let out = dir.join("bench");
    for args in [
        vec!["transport", "--smoke"],
        vec!["estimator", "--smoke", "--objects-per-frame", "1"],
        vec!["tracking", "--smoke", "--objects-per-frame", "1"],
        vec!["e2e", "--smoke", "--fps", "12", "--objects-per-frame", "2", "--seed", "3"],
    ] {
        let sub_out = out.join(args[0]);
        std::fs::create_dir_all(&sub_out)?;
        let mut all: Vec<&str> = args.clone();
        let sub_out = s(&sub_out);
        all.extend(["--out", &sub_out]);
        run(&env, &root, &fb, &all)?;
    }
    Ok(())
}
