//! `fusepose adapt` as a pipeline check, not an accuracy test: a split written
//! the way `fusepose record` writes one (frames, no ground truth) is adapted
//! to with a few training steps; the command labels it, holds its first
//! frames out of the training, writes a copy of the shipped file with the
//! fine-tuned segmenter and its certainty, and reports both files on the
//! held-out frames; run again, it reuses the labels. Bad arguments and a file
//! without a training record are refused before any work.

use std::path::Path;
use std::process::Command;

use fusepose_estimator::seg::SegFile;
use fusepose_scene::bop::{BopDataset, read_pseudo_manifest};
use fusepose_tests::*;

/// Empties every frame's ground truth and its info, as `fusepose record` leaves them.
fn forget_ground_truth(split: &Path) -> anyhow::Result<()> {
    for scene in std::fs::read_dir(split)? {
        let scene = scene?.path();
        for file in ["scene_gt.json", "scene_gt_info.json"] {
            let path = scene.join(file);
            let frames: serde_json::Map<String, serde_json::Value> =
                serde_json::from_str(&std::fs::read_to_string(&path)?)?;
            let empty: serde_json::Map<String, serde_json::Value> =
                frames.keys().map(|k| (k.clone(), serde_json::json!([]))).collect();
            std::fs::write(&path, serde_json::to_string(&empty)?)?;
        }
    }
    Ok(())
}

fn fusepose() -> anyhow::Result<Command> {
    let mut cmd = Command::new(workspace_binary("fusepose-cli", "fusepose")?);
    cmd.current_dir(workspace_root()?);
    Ok(cmd)
}

#[test]
fn one_command_adapts_the_segmenter_to_recorded_frames_and_reports_held_out_ones() -> anyhow::Result<()> {
    let dir = tempfile::tempdir()?;
    let frames = dir.path().join("cell");
    let render = fusepose()?
        .args(["render", "--split", "test", "--scenes", "2", "--frames-per-scene", "2", "--seed", "901"])
        .args(["--randomize", "off", "--depth-sensor", "basic", "--out"])
        .arg(&frames)
        .output()?;
    assert!(render.status.success(), "render failed: {}", String::from_utf8_lossy(&render.stderr));
    forget_ground_truth(&frames.join("test"))?;

    let shipped = workspace_root()?.join("models/builtin.safetensors");
    let before = SegFile::read(&shipped)?;
    let out = dir.path().join("cam0.safetensors");
    let work = dir.path().join("work");
    let run = fusepose()?
        .args(["adapt", "--frames"])
        .arg(&frames)
        .args(["--steps", "2", "--val-frames", "2", "--hold-out", "0.25", "--out"])
        .arg(&out)
        .arg("--work")
        .arg(&work)
        .output()?;
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(run.status.success(), "adapt failed:\n{stdout}\n{}", String::from_utf8_lossy(&run.stderr));
    assert!(stdout.contains("4 frames labelled, 3 for training"), "{stdout}");
    assert!(stdout.contains("the first 1 held out"), "{stdout}");
    // The rendered half follows the shipped segmenter's record, seen through the recorded camera.
    assert!(stdout.contains("--randomize off --depth-sensor basic"), "{stdout}");
    let k = fusepose_scene::Intrinsics::YCB_VIDEO;
    assert!(stdout.contains(&format!("--intrinsics {},{},{},{},640,480", k.fx, k.fy, k.cx, k.cy)), "{stdout}");

    // The training manifest leaves the held-out frame out; the full one keeps it.
    let data = BopDataset::open_split(&frames, "test")?;
    let first = data.frame_ids()[0];
    let labels = work.join("labels").join("0-cell");
    let trained = read_pseudo_manifest(&labels)?;
    assert_eq!(trained.frames.len(), 3);
    assert!(!trained.frames.iter().any(|f| f.scene_id == first.scene_id && f.im_id == first.im_id));
    assert!(labels.join("pseudo_labels.all.json").is_file());

    // A copy of the shipped file whose segmenter trained two more steps, with its certainty measured.
    let after = SegFile::read(&out)?;
    let steps = |f: &SegFile| f.train.as_ref().map_or(0, |t| t.steps);
    assert_eq!(steps(&after), steps(&before) + 2);
    let certainty = after.certainty.as_ref().expect("no certainty record");
    assert!(certainty.regions > 0, "{certainty:?}");
    // Measured on randomised frames, not on the plain ones the shipped segmenter trained on (whose floor is 0.98).
    assert!(certainty.data.contains("randomize Default"), "{}", certainty.data);
    let moved =
        before.config.tensor_shapes().iter().any(|(name, _)| before.tensor(name).ok() != after.tensor(name).ok());
    assert!(moved, "the adapted segmenter's weights equal the shipped ones");
    // The pose network is the shipped one: same layout, same training record.
    let pose = |p: &Path| fusepose_estimator::net::WeightFile::read(p).map(|w| (w.config, w.train.map(|t| t.steps)));
    assert_eq!(pose(&out)?, pose(&shipped)?, "the pose network changed");

    // The report: one row for the held-out frame, before -> after.
    let table = stdout.split("held-out frames (not trained on").nth(1).unwrap_or_default();
    let row = table.lines().find(|l| l.trim_start().starts_with("0-cell")).unwrap_or_default();
    assert_eq!(row.matches("->").count(), 2, "{stdout}");
    assert!(row.split_whitespace().nth(1) == Some("1"), "{row}");

    // Run again (no hold-out this time): the labels the same file made are reused, not made again.
    let again = fusepose()?
        .args(["adapt", "--frames"])
        .arg(&frames)
        .args(["--steps", "1", "--val-frames", "1", "--hold-out", "0", "--out"])
        .arg(dir.path().join("cam0b.safetensors"))
        .arg("--work")
        .arg(&work)
        .output()?;
    let stdout = String::from_utf8_lossy(&again.stdout);
    assert!(again.status.success(), "adapt again failed:\n{stdout}\n{}", String::from_utf8_lossy(&again.stderr));
    assert!(stdout.contains("reusing the labels") && !stdout.contains("labelling"), "{stdout}");
    assert!(stdout.contains("4 frames labelled, 4 for training"), "{stdout}");
    Ok(())
}

#[test]
fn adapt_refuses_to_overwrite_its_file_a_folder_that_is_no_recording_and_a_file_without_a_recipe() -> anyhow::Result<()>
{
    let dir = tempfile::tempdir()?;
    let run = fusepose()?
        .args(["adapt", "--frames"])
        .arg(dir.path())
        .args(["--out", "models/builtin.safetensors"])
        .output()?;
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success());
    assert!(stderr.contains("would overwrite") && stderr.contains("name a new file"), "{stderr}");

    let run = fusepose()?
        .args(["adapt", "--frames"])
        .arg(dir.path().join("nothing"))
        .arg("--out")
        .arg(dir.path().join("cam.safetensors"))
        .output()?;
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success());
    assert!(stderr.contains("not a recorded split") && stderr.contains("fusepose record"), "{stderr}");

    // A file that does not say how its segmenter was trained has no recipe for the rendered half.
    let shipped = std::fs::read(workspace_root()?.join("models/builtin.safetensors"))?;
    let bare = dir.path().join("bare.safetensors");
    std::fs::write(&bare, fusepose_estimator::seg::file::with_metadata(&shipped, "fusepose.seg.hyper", "{}".into())?)?;
    let run = fusepose()?
        .args(["adapt", "--frames"])
        .arg(dir.path())
        .arg("--weights")
        .arg(&bare)
        .arg("--out")
        .arg(dir.path().join("cam.safetensors"))
        .output()?;
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success());
    assert!(stderr.contains("no scene recipe") && stderr.contains("by hand"), "{stderr}");
    Ok(())
}
