//! `fusepose adapt`: a weight file's segmenter adapted to one camera, in one
//! command, from frames `fusepose record` kept (docs/TRAINING.md, "Adapting
//! the segmenter to your camera").
//!
//! The steps are the documented commands, each run as a child `fusepose`
//! process with its output in the work folder: pseudo-labels from the file's
//! own depth-confirmed poses (`eval --pseudo-labels`), the segmenter
//! fine-tuned on them beside rendered scenes drawn as its file records, seen
//! through the recorded camera's intrinsics (`train --stage seg --adapt-labels`), embedded into a copy of the file and
//! its certainty recorded on randomised frames (`train --stage calibrate`). The first share of each
//! recorded split's frames is held out of the training and both files are run
//! on it: no ground truth exists there, so the report counts what the depth
//! image says of each file's poses.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use anyhow::{Context, bail};
use fusepose_estimator::seg::SegFile;
use fusepose_estimator::seg::file::KEY_HYPER;
use fusepose_scene::bop::{BopDataset, PSEUDO_MANIFEST_FILE};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Recorded splits (`fusepose record --out DIR`), comma-separated.
    #[arg(long, value_delimiter = ',', required = true, value_name = "DIR")]
    pub frames: Vec<PathBuf>,
    /// Split folder inside each of them.
    #[arg(long, default_value = "test")]
    pub split: String,
    /// The weight file to adapt (pose network with its embedded segmenter).
    #[arg(long, default_value = crate::weights::SHIPPED_WEIGHTS)]
    pub weights: PathBuf,
    /// The adapted file to write: a copy of --weights with the new segmenter.
    #[arg(long)]
    pub out: PathBuf,
    /// Object set of the weights (`builtin` or a mesh folder).
    #[arg(long, default_value = "builtin")]
    pub objects: String,
    /// Metres per mesh-file unit for a mesh folder (0.001 for millimetre meshes).
    #[arg(long, default_value_t = 1.0)]
    pub scale: f64,
    /// Training time on this machine (minutes).
    #[arg(long, default_value_t = 60.0)]
    pub minutes: f64,
    /// A step budget instead of the time (quick looks, tests).
    #[arg(long)]
    pub steps: Option<u64>,
    /// Share of the training frames drawn from the labelled camera frames.
    #[arg(long, default_value_t = 0.4, value_parser = crate::render::probability)]
    pub share: f64,
    /// Share of each recorded split (its first frames) held out of the training for the report.
    #[arg(long, default_value_t = 0.2)]
    pub hold_out: f64,
    /// Learning rate of the fine-tune.
    #[arg(long, default_value_t = 3e-4)]
    pub lr: f64,
    /// Seed of the fine-tune's frame draws.
    #[arg(long, default_value_t = 48)]
    pub seed: u64,
    /// Rendered frames the trainer validates on (mIoU, as every segmenter run reports).
    #[arg(long, default_value_t = 120)]
    pub val_frames: usize,
    /// Folder for labels, logs and the segmenter alone (default: next to --out, `<stem>-adapt`).
    /// Labels the same --weights made there are reused, so the command can be run again after a stop.
    #[arg(long)]
    pub work: Option<PathBuf>,
}

/// What the depth image said of one file's poses on held-out frames.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthVerdict {
    pub frames: usize,
    /// Poses that passed verification (published).
    pub published: usize,
    /// Poses the depth image refused: a region the segmenter made that no pose of its class fits.
    pub refused: usize,
}

impl DepthVerdict {
    /// From the `--json` summary `fusepose eval` writes (its `net` run).
    pub fn from_eval_json(v: &serde_json::Value) -> anyhow::Result<Self> {
        let o = &v["net"]["overall"];
        let n = |x: &serde_json::Value, what: &str| {
            x.as_u64().map(|x| x as usize).with_context(|| format!("the evaluation summary has no `{what}`"))
        };
        let ver = &o["verification"];
        let checked = n(&ver["checked"], "verification.checked")?;
        let refused = n(&ver["failed_ghosts"], "verification.failed_ghosts")?
            + n(&ver["failed_real"], "verification.failed_real")?;
        Ok(Self { frames: n(&o["frames"], "frames")?, published: checked.saturating_sub(refused), refused })
    }

    fn per_frame(self, count: usize) -> f64 {
        count as f64 / self.frames.max(1) as f64
    }
}

/// The scene sampler the segmenter was trained with, as `fusepose train`
/// flags, read from the file's training record (`fusepose.seg.hyper`): the
/// rendered half of the fine-tune draws frames like its training did.
pub fn recipe_flags(hyper: &serde_json::Value) -> anyhow::Result<Vec<String>> {
    let data = hyper["data"].as_str().context("the segmenter's training record has no `data` entry")?;
    // "scene sampler (randomize off, plain share 0, depth sensor basic, copies per class (1, 1), pairs 0, heaps 0), ..."
    let field = |name: &str| -> anyhow::Result<String> {
        let start =
            data.find(name).with_context(|| format!("the training record `{data}` has no `{name}`"))? + name.len();
        let rest = data[start..].trim_start();
        let end = if rest.starts_with('(') {
            rest.find(')').map_or(rest.len(), |e| e + 1)
        } else {
            rest.find([',', ')']).unwrap_or(rest.len())
        };
        Ok(rest[..end].trim().to_string())
    };
    let mut flags = vec![
        "--randomize".to_string(),
        field("randomize")?,
        "--depth-sensor".to_string(),
        field("depth sensor")?,
        "--plain-share".to_string(),
        field("plain share")?,
    ];
    let copies = field("copies per class")?;
    let (pairs, heaps) = (field("pairs")?, field("heaps")?);
    let single = copies.replace(' ', "") == "(1,1)";
    let zero = |p: &str| p.parse::<f64>().is_ok_and(|p| p == 0.0);
    if single && zero(&pairs) && zero(&heaps) {
        flags.push("--single-instances".into());
    } else {
        flags.extend(["--pairs".into(), pairs, "--heap".into(), heaps]);
    }
    if let Some(cast) = hyper["camera_cast"].as_f64() {
        flags.extend(["--seg-cast".into(), cast.to_string()]);
    }
    Ok(flags)
}

/// `--seg-offsets` / `--seg-contacts` as the file's segmenter has them, so the fine-tune adds no head.
fn head_flags(seg: &SegFile) -> Vec<String> {
    let mut f = vec!["--seg-offsets".to_string(), seg.config.offsets.to_string()];
    if seg.config.offsets && seg.config.offset_branch {
        f.push("--seg-offset-branch".into());
    }
    if seg.config.contacts {
        f.push("--seg-contacts".into());
    }
    f
}

fn os(p: &Path) -> String {
    p.display().to_string()
}

/// `fusepose eval` of the network with the segmenter's masks and verification, on one recorded split.
fn eval_argv(dir: &Path, split: &str, weights: &Path, objects: &[String]) -> Vec<String> {
    let mut a: Vec<String> =
        ["eval", "--dataset", &os(dir), "--split", split, "--estimator", "net"].map(String::from).into();
    a.extend(["--weights".into(), os(weights), "--masks".into(), "net".into(), "--verify".into(), "drop".into()]);
    a.extend(objects.iter().cloned());
    a
}

/// Runs `fusepose ARGS`, its output appended to `log` (or shown with `show`).
fn fusepose(args: &[String], log: &Path, show: bool) -> anyhow::Result<()> {
    let exe = std::env::current_exe().context("locating the fusepose executable")?;
    let mut cmd = Command::new(exe);
    cmd.args(args);
    if !show {
        let file = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(log)
            .with_context(|| format!("opening {}", log.display()))?;
        cmd.stdout(file.try_clone()?).stderr(file);
    } else {
        cmd.stdout(Stdio::inherit()).stderr(Stdio::inherit());
    }
    let status = cmd.status().with_context(|| format!("starting fusepose {}", args[0]))?;
    if !status.success() {
        let tail = if show { String::new() } else { format!("; its output is in {}", log.display()) };
        bail!("`fusepose {}` failed ({status}){tail}", args.join(" "));
    }
    Ok(())
}

/// The frames of a split held out of the training: its first `share` (at least one when the share is above 0, at
/// most all but one).
pub fn held_out_count(frames: usize, share: f64) -> usize {
    if share <= 0.0 || frames < 2 {
        return 0;
    }
    ((frames as f64 * share).round() as usize).clamp(1, frames - 1)
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if !(0.0..=0.9).contains(&args.hold_out) {
        bail!("--hold-out is the share of frames kept for the report: 0..=0.9, got {}", args.hold_out);
    }
    if args.share <= 0.0 {
        bail!("--share 0 would not use the camera's frames at all: give a share in (0, 1]");
    }
    let shipped = Path::new(crate::weights::SHIPPED_WEIGHTS);
    if args.out == args.weights || args.out == shipped {
        bail!(
            "--out {} would overwrite the file being adapted or the shipped one: name a new file, \
             e.g. models/cam0.safetensors",
            args.out.display()
        );
    }
    let seg = SegFile::read(&args.weights)
        .with_context(|| format!("{} has no segmenter to adapt (read as a weight file)", args.weights.display()))?;
    let hyper: Option<serde_json::Value> = seg.metadata.get(KEY_HYPER).and_then(|h| serde_json::from_str(h).ok());
    let mut recipe = hyper
        .with_context(|| {
            format!("{} does not record how its segmenter was trained ({KEY_HYPER})", args.weights.display())
        })
        .and_then(|h| recipe_flags(&h))
        .context(
            "no scene recipe to fine-tune with: adapt it by hand with the flags it was trained with \
             (docs/TRAINING.md, \"Adapting the segmenter to your camera\", the steps by hand)",
        )?;
    let work = args.work.clone().unwrap_or_else(|| {
        let stem = args.out.file_stem().map_or_else(|| "adapted".into(), |s| s.to_string_lossy().into_owned());
        args.out.with_file_name(format!("{stem}-adapt"))
    });
    std::fs::create_dir_all(work.join("labels")).with_context(|| format!("creating {}", work.display()))?;
    let objects = ["--objects".to_string(), args.objects.clone(), "--scale".into(), args.scale.to_string()];

    // 1. Pseudo-labels, and the training share of each split's frames.
    let mut label_dirs = Vec::new();
    let mut checks = Vec::new();
    let mut camera = None;
    for (i, dir) in args.frames.iter().enumerate() {
        let data = BopDataset::open_split(dir, &args.split)
            .with_context(|| format!("--frames {}: not a recorded split (fusepose record --out DIR)", dir.display()))?;
        if data.is_empty() {
            bail!("--frames {}: the split holds no frames", dir.display());
        }
        if camera.is_none() {
            let k = data.load(0).with_context(|| format!("reading the first frame of {}", dir.display()))?.intrinsics;
            camera = Some(crate::camera_model::format(&k));
        }
        let name = format!("{i}-{}", dir.file_name().map_or_else(|| "frames".into(), |n| n.to_string_lossy()));
        let labels = work.join("labels").join(&name);
        let full = labels.join("pseudo_labels.all.json");
        // Labels are reused only when the same file (path and size) made them.
        let stamp_path = labels.join("labelled_by.txt");
        let stamp = format!("{} {}\n", os(&args.weights), std::fs::metadata(&args.weights)?.len());
        if !full.is_file() || std::fs::read_to_string(&stamp_path).ok().as_deref() != Some(stamp.as_str()) {
            if labels.exists() {
                std::fs::remove_dir_all(&labels).with_context(|| format!("clearing {}", labels.display()))?;
            }
            println!("labelling {} ({} frames) with {}", dir.display(), data.len(), args.weights.display());
            let mut a = eval_argv(dir, &args.split, &args.weights, &objects);
            a.extend(["--pseudo-labels".into(), os(&labels)]);
            fusepose(&a, &work.join(format!("label-{name}.log")), false)?;
            std::fs::rename(labels.join(PSEUDO_MANIFEST_FILE), &full)?;
            std::fs::write(&stamp_path, &stamp)?;
        } else {
            println!("reusing the labels of {} in {}", dir.display(), labels.display());
        }
        let text = std::fs::read_to_string(&full).with_context(|| format!("reading {}", full.display()))?;
        let mut manifest: fusepose_scene::bop::PseudoLabelManifest =
            serde_json::from_str(&text).with_context(|| format!("reading {}", full.display()))?;
        let held = held_out_count(data.len(), args.hold_out);
        let held_ids = &data.frame_ids()[..held];
        let before = manifest.frames.len();
        manifest.frames.retain(|f| !held_ids.iter().any(|id| id.scene_id == f.scene_id && id.im_id == f.im_id));
        if manifest.frames.is_empty() {
            bail!(
                "{}: no labelled frame is left for training after holding {held} out; record more frames",
                dir.display()
            );
        }
        std::fs::write(labels.join(PSEUDO_MANIFEST_FILE), serde_json::to_string_pretty(&manifest)?)?;
        let poses: u32 = manifest.frames.iter().map(|f| f.poses).sum();
        println!(
            "  {name}: {} frames labelled, {} for training ({poses} confirmed poses), the first {held} held out",
            before,
            manifest.frames.len()
        );
        label_dirs.push(labels);
        if held > 0 {
            checks.push((name, dir.clone(), held));
        }
    }

    // The rendered half is seen through the recorded camera (the first split's first frame).
    let intrinsics = ["--intrinsics".to_string(), camera.expect("at least one split")];
    recipe.extend(intrinsics.iter().cloned());

    // 2. The fine-tune (its progress shown), 3. embedded into a copy and calibrated.
    let seg_out = work.join("seg.safetensors");
    let mut a: Vec<String> = vec!["train".into(), "--stage".into(), "seg".into(), "--resume".into(), os(&args.weights)];
    match args.steps {
        Some(s) => a.extend(["--steps".into(), (seg.train.as_ref().map_or(0, |t| t.steps) + s).to_string()]),
        None => a.extend(["--minutes".into(), args.minutes.to_string()]),
    }
    a.extend([
        "--batch".into(),
        "8".into(),
        "--lr".into(),
        args.lr.to_string(),
        "--seed".into(),
        args.seed.to_string(),
    ]);
    a.extend(recipe.iter().cloned());
    a.extend(head_flags(&seg));
    a.extend(["--seg-data-threads".into(), "1".into(), "--val-frames".into(), args.val_frames.to_string()]);
    a.extend(["--adapt-labels".into(), label_dirs.iter().map(|d| os(d)).collect::<Vec<_>>().join(",")]);
    a.extend(["--adapt-share".into(), args.share.to_string(), "--out".into(), os(&seg_out)]);
    a.extend(["--checkpoint-dir".into(), os(&work.join("checkpoints")), "--log".into(), os(&work.join("train.log"))]);
    a.extend(objects.iter().cloned());
    println!("fine-tuning the segmenter: fusepose {}", a.join(" "));
    fusepose(&a, &work.join("train.out"), true)?;

    if let Some(parent) = args.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).with_context(|| format!("creating {}", parent.display()))?;
    }
    std::fs::copy(&args.weights, &args.out)
        .with_context(|| format!("copying {} to {}", args.weights.display(), args.out.display()))?;
    let mut embed: Vec<String> = vec!["train".into(), "--stage".into(), "seg".into(), "--resume".into(), os(&seg_out)];
    embed.extend(["--steps".into(), "0".into(), "--val-frames".into(), "8".into(), "--out".into(), os(&args.out)]);
    embed.extend(head_flags(&seg));
    embed.extend(["--checkpoint-dir".into(), os(&work.join("checkpoints")), "--quiet".into()]);
    embed.extend(objects.iter().cloned());
    fusepose(&embed, &work.join("embed.log"), false)?;
    // The certainty floor is measured on randomised frames (the calibration's own default, as the shipped record
    // was), not on the recipe's: on the plain frames it trained on, the shipped segmenter's 5 % floor is 0.984
    // against 0.765, and a floor that high refuses the camera's true objects with its ghosts (session 50).
    let mut cal: Vec<String> =
        vec!["train".into(), "--stage".into(), "calibrate".into(), "--out".into(), os(&args.out)];
    cal.extend(intrinsics);
    cal.push("--quiet".into());
    cal.extend(objects.iter().cloned());
    fusepose(&cal, &work.join("calibrate.log"), false)?;
    println!(
        "wrote {} (the segmenter of {} adapted to the recorded frames)",
        args.out.display(),
        args.weights.display()
    );

    // 4. Both files on the held-out frames.
    if checks.is_empty() {
        println!("no frames held out (--hold-out 0): nothing to compare");
        return Ok(());
    }
    println!("held-out frames (not trained on; no ground truth: what the depth image says of each file's poses):");
    println!("  {:<28} {:>6}  {:>22}  {:>22}", "split", "frames", "published / frame", "refused by depth / frame");
    for (name, dir, held) in &checks {
        let mut verdicts = Vec::new();
        for (tag, weights) in [("before", &args.weights), ("after", &args.out)] {
            let json = work.join(format!("check-{name}-{tag}.json"));
            let mut a = eval_argv(dir, &args.split, weights, &objects);
            a.extend(["--limit".into(), held.to_string(), "--json".into(), os(&json)]);
            fusepose(&a, &work.join(format!("check-{name}-{tag}.log")), false)?;
            let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json)?)
                .with_context(|| format!("reading {}", json.display()))?;
            verdicts.push(DepthVerdict::from_eval_json(&v)?);
        }
        let (b, a) = (verdicts[0], verdicts[1]);
        println!(
            "  {:<28} {:>6}  {:>9.2} -> {:<10.2}  {:>9.2} -> {:<10.2}",
            name,
            b.frames,
            b.per_frame(b.published),
            a.per_frame(a.published),
            b.per_frame(b.refused),
            a.per_frame(a.refused)
        );
    }
    println!(
        "fewer refused regions with as many published poses is the sign it learned the camera's colours \
         (docs/TRAINING.md); frames with ground truth are the real check"
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_segmenters_recipe_becomes_its_training_flags() {
        let hyper = serde_json::json!({
            "camera_cast": 0.5,
            "data": "scene sampler (randomize off, plain share 0, depth sensor basic, copies per class (1, 1), pairs 0, heaps 0), rendered on the fly",
        });
        let f = recipe_flags(&hyper).unwrap();
        assert_eq!(
            f,
            [
                "--randomize",
                "off",
                "--depth-sensor",
                "basic",
                "--plain-share",
                "0",
                "--single-instances",
                "--seg-cast",
                "0.5"
            ]
        );
        let hyper = serde_json::json!({
            "data": "scene sampler (randomize default, plain share 0.2, depth sensor structured-light, copies per class (1, 2), pairs 0.35, heaps 0.15), rendered on the fly",
        });
        let f = recipe_flags(&hyper).unwrap();
        assert_eq!(
            f,
            [
                "--randomize",
                "default",
                "--depth-sensor",
                "structured-light",
                "--plain-share",
                "0.2",
                "--pairs",
                "0.35",
                "--heap",
                "0.15"
            ]
        );
        let e = recipe_flags(&serde_json::json!({"data": "BOP frames"})).unwrap_err();
        assert!(e.to_string().contains("randomize"), "{e}");
    }

    #[test]
    fn held_out_frames_leave_at_least_one_to_train_on() {
        assert_eq!(held_out_count(100, 0.2), 20);
        assert_eq!(held_out_count(3, 0.2), 1);
        assert_eq!(held_out_count(2, 0.9), 1);
        assert_eq!(held_out_count(1, 0.5), 0);
        assert_eq!(held_out_count(50, 0.0), 0);
    }

    #[test]
    fn the_depth_verdict_reads_evals_summary() {
        let v = serde_json::json!({"net": {"overall": {"frames": 6, "verification": {"checked": 49, "failed_ghosts": 9, "failed_real": 1}}}});
        let d = DepthVerdict::from_eval_json(&v).unwrap();
        assert_eq!(d, DepthVerdict { frames: 6, published: 39, refused: 10 });
        assert!(DepthVerdict::from_eval_json(&serde_json::json!({"icp": {}})).is_err());
    }
}
