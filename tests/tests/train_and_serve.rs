//! "Your objects, served within the hour" as a pipeline check (issue 20), not
//! an accuracy test: two meshes written here as a user's folder, the one
//! command `fusepose train --objects DIR --minutes M --out FILE` for a few
//! seconds (the whole pipeline by default, warm-started from the shipped trunk), its
//! acceptance report, and a separate `fuseposed` started with exactly the
//! `fuseposed.toml` lines the report prints, answering an unlabelled frame of
//! those objects (so its own segmenter runs) with an OK pose message. The
//! objects' `--symmetry` declarations reach the daemon through the weight file.

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use fusepose_client::{Consumer, Ipc, Producer};
use fusepose_scene::Intrinsics;
use fusepose_scene::render::{NoiseConfig, RenderTarget};
use fusepose_scene::sampler::{LabelKind, SamplerConfig, render_view_labelled, sample_scene};
use fusepose_tests::*;

/// A closed triangle mesh as Wavefront OBJ (metres, counter-clockwise faces seen from outside).
fn write_obj(path: &Path, vertices: &[[f64; 3]], faces: &[[usize; 3]]) -> anyhow::Result<()> {
    let mut text = String::from("# written by tests/train_and_serve.rs\n");
    for v in vertices {
        text += &format!("v {} {} {}\n", v[0], v[1], v[2]);
    }
    for f in faces {
        text += &format!("f {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1);
    }
    std::fs::write(path, text)?;
    Ok(())
}

/// A box of half extents `h`, centred at the origin.
fn write_box(path: &Path, h: [f64; 3]) -> anyhow::Result<()> {
    let v: Vec<[f64; 3]> = (0..8)
        .map(|i| {
            let s = |b: usize| if i & b != 0 { 1.0 } else { -1.0 };
            [s(1) * h[0], s(2) * h[1], s(4) * h[2]]
        })
        .collect();
    let faces = [
        [0, 2, 3],
        [0, 3, 1],
        [4, 5, 7],
        [4, 7, 6],
        [0, 1, 5],
        [0, 5, 4],
        [2, 6, 7],
        [2, 7, 3],
        [0, 4, 6],
        [0, 6, 2],
        [1, 3, 7],
        [1, 7, 5],
    ];
    write_obj(path, &v, &faces)
}

/// A hexagonal prism (a can-like object) of radius `r` and half height `hz`.
fn write_prism(path: &Path, r: f64, hz: f64) -> anyhow::Result<()> {
    let mut v = Vec::new();
    for z in [-hz, hz] {
        for k in 0..6 {
            let a = k as f64 * std::f64::consts::PI / 3.0;
            v.push([r * a.cos(), r * a.sin(), z]);
        }
    }
    v.push([0.0, 0.0, -hz]);
    v.push([0.0, 0.0, hz]);
    let mut faces = Vec::new();
    for k in 0..6 {
        let n = (k + 1) % 6;
        faces.push([k, n, 6 + n]);
        faces.push([k, 6 + n, 6 + k]);
        faces.push([12, n, k]);
        faces.push([13, 6 + k, 6 + n]);
    }
    write_obj(path, &v, &faces)
}

#[test]
fn one_command_trains_a_new_object_set_and_the_daemon_serves_it() -> anyhow::Result<()> {
    let env = TestEnv::new("trainserve")?;
    let dir = tempfile::tempdir()?;
    let objects = dir.path().join("my_objects");
    std::fs::create_dir_all(&objects)?;
    write_box(&objects.join("tea_box.obj"), [0.045, 0.03, 0.07])?;
    write_prism(&objects.join("hex_can.obj"), 0.035, 0.05)?;
    let out = dir.path().join("mine.safetensors");

    let mut cmd = Command::new(workspace_binary("fusepose-cli", "fusepose")?);
    cmd.args(["train", "--objects"]).arg(&objects);
    // No --stage: a fresh run on a mesh folder is the whole pipeline, warm-started from the shipped trunk.
    cmd.args(["--minutes", "0.25", "--batch", "2", "--val-frames", "3", "--val-samples", "6"]);
    cmd.args(["--quiet", "--checkpoint-dir"]).arg(dir.path().join("work")).arg("--out").arg(&out);
    // Declared symmetries travel in the weight file: the folder has no models_info.json,
    // so the daemon below only passes its weight check if it takes them from there.
    cmd.args(["--symmetry", "hex_can=6-fold:z", "--symmetry", "tea_box=box"]);
    let run = cmd.output()?;
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(run.status.success(), "train failed:\n{stdout}\n{}", String::from_utf8_lossy(&run.stderr));
    assert!(stdout.contains("warm start from"), "no warm start:\n{stdout}");
    // The warm-started pose stage trains the new heads alone first (the one command's default).
    assert!(stdout.contains("heads first: the new class heads learn alone for 25 %"), "no heads-first:\n{stdout}");
    assert!(stdout.contains("tea_box") && stdout.contains("suggested from geometry"), "no mesh listing:\n{stdout}");
    let listed = |name: &str| stdout.lines().find(|l| l.contains(name)).unwrap_or_default().to_owned();
    assert!(listed("hex_can").contains("discrete (5 + identity)"), "{}", listed("hex_can"));
    assert!(listed("tea_box").contains("discrete (3 + identity)"), "{}", listed("tea_box"));
    for stage in ["stage 1/4", "stage 2/4", "stage 3/4", "stage 4/4"] {
        assert!(stdout.contains(stage), "{stage} missing from:\n{stdout}");
    }
    // The segmenter's certainty of real objects is measured and travels into the
    // final file (stage 3 re-embeds the segmenter), for the verifier's floor.
    assert!(stdout.contains("segmenter certainty of real objects"), "no calibration:\n{stdout}");
    let certainty = fusepose_estimator::seg::SegFile::read(&out)?.certainty.expect("a certainty record");
    assert!(certainty.regions > 0 && certainty.quantile(0.05).is_some_and(|p| (0.0..=1.0).contains(&p)));

    // The report: both mask sources scored on the held-out split, and the config lines.
    let report = std::fs::read_to_string(out.with_extension("report.md"))?;
    assert!(report.contains("| true masks |") && report.contains("| built-in segmenter |"), "{report}");
    assert!(report.contains("| tea_box |") && report.contains("| hex_can |"), "{report}");
    let toml = report.split("```toml\n").nth(1).and_then(|s| s.split("```").next()).expect("a toml block");
    let lines: Vec<&str> = toml.lines().filter(|l| !l.starts_with('[')).collect();
    assert!(lines.iter().any(|l| l.starts_with("weights = ")), "{toml}");

    // The daemon with those lines answers an unlabelled frame of the new objects.
    let config = env.write_daemon_config(&(lines.join("\n") + "\nmax_instances = 8"))?;
    let _daemon = start_daemon(&env, &config)?;
    let set = fusepose_scene::mesh_io::load_object_set(&objects.to_string_lossy(), 1.0)?;
    let k = Intrinsics::YCB_VIDEO;
    let ipc = Ipc::new(&env.ipc_options())?;
    let mut producer = Producer::create(&ipc, "cam0", rendered_layout(&k))?;
    let mut consumer = Consumer::open(&ipc, "cam0")?;
    let cfg = SamplerConfig { min_objects: 2, max_objects: 2, ..SamplerConfig::default() };
    let scene = sample_scene(&set, &cfg, 77).map_err(|e| anyhow::anyhow!("{e}"))?;
    let mut target = RenderTarget::for_intrinsics(&k);
    render_view_labelled(&scene, &set, 0, &k, &NoiseConfig::default(), LabelKind::Class, &mut target)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let sequence = send_rendered(&mut producer, &k, &target)?;
    let msg = wait_for_sequence(&mut consumer, sequence, Duration::from_secs(120))?;
    assert!(msg.is_ok(), "status {:#x}, reason {:?}", msg.status, msg.invalid());
    assert!(msg.objects().iter().all(|o| (1..=2).contains(&o.class_id)), "{:?}", msg.objects());
    Ok(())
}
