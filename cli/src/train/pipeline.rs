//! `fusepose train --stage all`: one command from a folder of meshes to a
//! daemon-ready model. It runs every stage itself within the `--minutes`
//! budget — pose net + refiner (47.5 %), segmenter (23.75 %), fine-tune of
//! both pose stages on the segmenter's masks (23.75 %; `--stage-shares`), 5 % for validation and the report — then an acceptance
//! report on a held-out split rendered from the same meshes, and prints the
//! `fuseposed.toml` lines that serve the model. Finished stages are kept in
//! the work folder (`<checkpoint-dir>/<out stem>-stages/`), so running the same
//! command again after an interruption continues with the first unfinished stage.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Parser;

use super::{Args, StageArg};

/// Render seed of the acceptance split (test-split seeds; training and
/// validation scenes are drawn from other ranges).
const ACCEPT_SEED: u64 = 7_340_021;

#[derive(Parser)]
struct RenderCmd {
    #[command(flatten)]
    args: crate::render::Args,
}

#[derive(Parser)]
struct EvalCmd {
    #[command(flatten)]
    args: crate::eval::Args,
}

/// The stage outputs inside the work folder.
struct Work {
    dir: PathBuf,
}

impl Work {
    fn pose(&self) -> PathBuf {
        self.dir.join("1-pose.safetensors")
    }
    fn seg(&self) -> PathBuf {
        self.dir.join("2-seg.safetensors")
    }
    /// Written when stage 3 has written `--out`.
    fn tuned(&self) -> PathBuf {
        self.dir.join("3-done")
    }
    fn pose_seg(&self) -> PathBuf {
        self.dir.join("2-pose-seg.safetensors")
    }
}

pub fn run(args: &Args) -> anyhow::Result<()> {
    let minutes = args.minutes.context(
        "--stage all needs --minutes (the whole budget, e.g. --minutes 60; stages get 47.5 / 23.75 / 23.75 % of it by default, --stage-shares, the rest is for validation and the report)",
    )?;
    if !minutes.is_finite() || minutes <= 0.0 {
        anyhow::bail!("--minutes must be a positive number of minutes, got {minutes}");
    }
    let stem = args.out.file_stem().map_or("model".into(), |s| s.to_string_lossy().into_owned());
    let work = Work { dir: args.checkpoint_dir.join(format!("{stem}-stages")) };
    std::fs::create_dir_all(&work.dir).with_context(|| format!("creating {}", work.dir.display()))?;
    // The rest of the budget (at least 5 %) pays for the validation after each
    // stage and the acceptance report, so the command ends within `--minutes`.
    let [pose_min, seg_min, tune_min] = args.stage_shares.0.map(|s| s * minutes);
    println!(
        "== training {} -> {} in {minutes:.0} min; work folder {}",
        args.objects,
        args.out.display(),
        work.dir.display()
    );

    crate::objects::print_listing(&args.objects, args.scale, &args.symmetry)?;

    // 1. Pose net + refiner, from the warm-start trunk or the --resume file when given.
    if work.pose().exists() {
        println!("== stage 1/4 done before: {}", work.pose().display());
    } else {
        println!("== stage 1/4: pose net + refiner, {pose_min:.1} min");
        let mut a = stage_args(args, StageArg::Both, pose_min, work.pose(), work.dir.join("1-checkpoints"));
        a.seg_masks = 0.0;
        let heads_first =
            args.heads_first.unwrap_or(if trunk(args)?.is_some() { ONE_COMMAND_HEADS_FIRST } else { 0.0 });
        // An interrupted run continues from its last checkpoint with what is left of the stage.
        let ckpt = a.checkpoint_dir.join("checkpoint.safetensors");
        if ckpt.exists() {
            let base = args.resume.as_deref().map_or(Ok(0.0), trained_seconds)?;
            let used = (trained_seconds(&ckpt)? - base) / 60.0;
            a.minutes = Some((pose_min - used).max(0.5));
            println!("   continuing from {} ({used:.1} min done)", ckpt.display());
            (a.resume, a.warm_start) = (Some(ckpt), None);
            // The heads-first share is of the whole stage; what is left of it, of what is left.
            a.heads_first = Some(((heads_first * pose_min - used) / (pose_min - used).max(1e-9)).clamp(0.0, 1.0));
        } else {
            a.warm_start = trunk(args)?;
            a.heads_first = Some(heads_first);
            if let Some(t) = &a.warm_start {
                println!("   warm start from {} (--cold for random weights)", t.display());
                if heads_first > 0.0 {
                    println!(
                        "   heads first: the new class heads learn alone for {:.0} % of the stage (--heads-first 0 for off)",
                        100.0 * heads_first
                    );
                }
            }
        }
        super::run(a)?;
    }

    // 2. Segmenter for these objects, embedded into a copy of the pose file.
    if work.pose_seg().exists() {
        println!("== stage 2/4 done before: {}", work.pose_seg().display());
    } else {
        println!("== stage 2/4: segmenter, {seg_min:.1} min");
        let mut a = stage_args(args, StageArg::Seg, seg_min, work.seg(), work.dir.join("2-checkpoints"));
        a.resume = None;
        // The shipped segmenter's encoder and decoder carry over; a fresh head learns these classes.
        a.warm_start = trunk(args)?.filter(|t| fusepose_estimator::seg::file::SegFile::read(t).is_ok());
        a.lr = if a.warm_start.is_some() { 1e-3 } else { 2e-3 };
        if let Some(t) = &a.warm_start {
            println!("   segmenter warm start from {}", t.display());
        }
        super::run(a)?;
        let tmp = work.dir.join("2-pose-seg.tmp.safetensors");
        std::fs::copy(work.pose(), &tmp).with_context(|| format!("copying {}", work.pose().display()))?;
        super::seg::embed_into(&work.seg(), &tmp)?;
        // How sure this segmenter is of real objects sets the verifier's certainty threshold.
        super::seg::calibrate_file(&super::training_objects(args)?, args, &tmp)?;
        std::fs::rename(&tmp, work.pose_seg())?;
    }

    // 3. Both pose stages again, half the frames with the segmenter's masks.
    if work.tuned().exists() && args.out.exists() {
        println!("== stage 3/4 done before: {}", args.out.display());
    } else {
        println!("== stage 3/4: fine-tune on segmenter masks, {tune_min:.1} min");
        let mut a = stage_args(args, StageArg::Both, tune_min, args.out.clone(), work.dir.join("3-checkpoints"));
        a.resume = Some(work.pose_seg());
        a.warm_start = None;
        a.seg_masks = 0.5;
        a.lr = args.lr.min(3e-4);
        a.heads_first = Some(0.0);
        super::run(a)?;
        std::fs::write(work.tuned(), args.out.display().to_string())?;
    }

    // 4. Acceptance on a held-out split of the same meshes.
    println!("== stage 4/4: acceptance report");
    let report = acceptance(args, &work)?;
    let report_path = args.out.with_extension("report.md");
    std::fs::write(&report_path, &report).with_context(|| format!("writing {}", report_path.display()))?;
    println!("{report}");
    println!("== report written to {}", report_path.display());
    Ok(())
}

/// `args` for one stage: what to train, its minutes, its output and checkpoint folder.
/// The share of a warm-started first pose stage in which only the new class
/// heads learn, unless `--heads-first` says otherwise. Chosen by a rule on the
/// tuning splits (the 60-minute one command on the YCB sample meshes: +1.1 and
/// +7.2 ADD(S) with its own segmenter); the test split and a replicate run put
/// that within one run's spread (docs/TRAINING.md, session 29).
const ONE_COMMAND_HEADS_FIRST: f64 = 0.25;

fn stage_args(args: &Args, stage: StageArg, minutes: f64, out: PathBuf, checkpoints: PathBuf) -> Args {
    Args { stage: Some(stage), minutes: Some(minutes), out, checkpoint_dir: checkpoints, ..args.clone() }
}

/// The trained file new networks start from: `--warm-start`, else the shipped
/// weights; none with `--cold` or `--resume` (which continues its own file).
fn trunk(args: &Args) -> anyhow::Result<Option<PathBuf>> {
    if args.cold || args.resume.is_some() {
        return Ok(None);
    }
    match &args.warm_start {
        Some(path) => Ok(Some(path.clone())),
        None => crate::weights::resolve_weights(None).map(Some),
    }
}

/// Training seconds recorded in a pose-network file.
fn trained_seconds(path: &Path) -> anyhow::Result<f64> {
    let file =
        fusepose_estimator::net::WeightFile::read(path).with_context(|| format!("reading {}", path.display()))?;
    Ok(file.train.map_or(0.0, |r| r.seconds))
}

/// The two acceptance splits: plain scenes (no randomisation, 3–8 objects,
/// so a set of fewer classes repeats some: comparable with the project's own
/// test splits) and randomised ones (lights, tables, distractors, pairs and
/// heaps: closer to a real cell), as (folder name, render flags, description).
const SPLITS: [(&str, &[&str], &str); 2] = [
    ("accept-plain", &["--randomize", "off"], "plain scenes, 3-8 objects (a class repeats where the set has fewer)"),
    ("accept-randomized", &[], "randomised scenes with touching pairs and heaps"),
];

/// Renders the acceptance splits, evaluates the model on each with true
/// instance masks and with its own segmenter (verification as the daemon
/// does it) and returns the report (Markdown), ending with the daemon's config lines.
fn acceptance(args: &Args, work: &Work) -> anyhow::Result<String> {
    let scale = args.scale.to_string();
    let sensor = args.depth_sensor.to_string();
    let camera = crate::camera_model::format(&args.intrinsics);
    let mut results = Vec::new();
    for (i, (name, flags, _)) in SPLITS.iter().enumerate() {
        let split = work.dir.join(name);
        if !split.join("test").exists() {
            let seed = (ACCEPT_SEED + i as u64).to_string();
            let mut argv = vec!["render", "--objects", &args.objects, "--scale", &scale, "--out"];
            let out = split.to_string_lossy();
            argv.extend([&*out, "--split", "test", "--seed", &seed, "--scenes", "10", "--frames-per-scene", "3"]);
            argv.extend(["--depth-sensor", &sensor, "--intrinsics", &camera]);
            argv.extend(flags.iter().copied());
            crate::render::run(RenderCmd::try_parse_from(argv)?.args)?;
        }
        let json = work.dir.join(format!("{name}-eval.json"));
        // The plot and overlays show the plain split.
        let plot = args.out.with_extension("report.png");
        let overlays = args.out.with_extension("overlays");
        let (weights, data, json_s) = (args.out.to_string_lossy(), split.to_string_lossy(), json.to_string_lossy());
        let mut argv = vec!["eval", "--dataset", &data, "--estimator", "net", "--weights", &weights];
        argv.extend(["--objects", &args.objects, "--scale", &scale, "--masks", "gt-instances,net", "--json", &json_s]);
        let (plot_s, overlays_s) = (plot.to_string_lossy(), overlays.to_string_lossy());
        if i == 0 {
            argv.extend(["--plot", &plot_s, "--overlay", &overlays_s]);
        }
        crate::eval::run(EvalCmd::try_parse_from(argv)?.args)?;
        results.push(serde_json::from_slice::<serde_json::Value>(&std::fs::read(&json)?)?);
    }
    Ok(report_text(args, work, &results))
}

fn num(v: &serde_json::Value, path: &[&str]) -> f64 {
    path.iter().fold(v, |v, k| &v[*k]).as_f64().unwrap_or(f64::NAN)
}

/// The acceptance report: per split, overall and per-object AUCs for true
/// and segmenter masks, ghosts (estimates matching no object) and stray poses
/// (at ADD-S ≥ 0.1 d from every object of their class) per frame and what
/// verification dropped, then the config lines.
fn report_text(args: &Args, work: &Work, results: &[serde_json::Value]) -> String {
    let mut s = format!(
        "# Acceptance report: {}\n\nHeld-out splits rendered from the same meshes (seeds {ACCEPT_SEED}.., 30 frames \
         each, {} depth sensor; no training or validation scene), in {}. ADD-S / ADD(S) AUC (0-10 cm), %. \
         Verification against depth as the daemon does it (failed poses dropped, counting as misses).\n\n\
         | split | masks | ADD-S AUC | ADD(S) AUC | ADD-S < 2 cm | objects | ghosts / frame | stray poses / frame | real poses dropped by verification |\n\
         |---|---|---|---|---|---|---|---|---|\n",
        args.out.display(),
        args.depth_sensor,
        work.dir.display()
    );
    let mut per_object = String::new();
    for ((_, _, split), results) in SPLITS.iter().zip(results) {
        for (key, label) in [("net/gt-instances-masks", "true masks"), ("net/net-masks", "built-in segmenter")] {
            let r = &results[key];
            let frames = num(r, &["overall", "frames"]).max(1.0);
            s += &format!(
                "| {split} | {label} | {:.1} | {:.1} | {:.1} % | {} | {:.2} | {:.2} | {} |\n",
                num(r, &["overall", "add_s_auc"]),
                num(r, &["overall", "add_s_auc_symmetric_aware"]),
                num(r, &["overall", "add_s_lt_2cm"]),
                num(r, &["overall", "count"]),
                num(r, &["overall", "unmatched_estimates"]) / frames,
                num(r, &["overall", "stray_poses"]) / frames,
                num(r, &["overall", "verification", "failed_real"])
            );
            if let Some(objects) = r["per_object"].as_object() {
                per_object +=
                    &format!("\n{split}, {label}:\n\n| object | ADD-S AUC | ADD(S) AUC | count |\n|---|---|---|---|\n");
                for (name, o) in objects {
                    per_object += &format!(
                        "| {name} | {:.1} | {:.1} | {} |\n",
                        num(o, &["add_s_auc"]),
                        num(o, &["add_s_auc_symmetric_aware"]),
                        num(o, &["count"])
                    );
                }
            }
        }
    }
    s += &per_object;
    s += &format!(
        "\nAccuracy-threshold curves (plain split): {}\nOverlays of the plain split (segmenter masks tinted, poses drawn), one per frame: {}/\n\n## Serve it\n\nIn `fuseposed.toml`:\n\n```toml\n[estimator]\nkind = \"net\"\n\
         weights = \"{}\"\nobjects = \"{}\"\nobjects_scale = {}\nmasks = \"auto\"\n```\n",
        args.out.with_extension("report.png").display(),
        args.out.with_extension("overlays").display(),
        args.out.display(),
        args.objects,
        args.scale
    );
    s
}
