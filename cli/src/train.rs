//! `fusepose train`: trains the fusion network (pose net + integrated refiner)
//! on scenes rendered on the fly and writes a safetensors weight file that
//! `fuseposed` loads; `--stage seg` trains the built-in segmenter instead
//! ([`seg`]). See docs/TRAINING.md.

mod pipeline;
mod seg;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use fusepose_scene::mesh_io::load_object_set;
use fusepose_scene::render::{DepthSensor, Randomize};
use fusepose_scene::sampler::SamplerConfig;
use fusepose_scene::symmetry_spec::{Describe, SymmetrySpec, apply_symmetry_specs};
use fusepose_train::data::Source;
use fusepose_train::trainer::{Stage, TrainOptions, train, validate_file};

#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum StageArg {
    /// The pose network only.
    Pose,
    /// The refiner only (colour features frozen).
    Refine,
    /// Pose network and refiner together (their losses summed).
    Both,
    /// The built-in instance segmenter (its own weights; see `--out`).
    Seg,
    /// Measures how sure the segmenter in `--out` is of real objects on
    /// rendered frames drawn like its training data (`--randomize`,
    /// `--depth-sensor`, `--intrinsics`; 400 of them) and stores
    /// it in that file, for `estimator.verify_region_certainty_quantile`.
    /// `--stage all` does this itself.
    Calibrate,
    /// Fits the model of a pose's odds of being right
    /// (`estimator.verify_min_odds`) to `--odds-samples` (written by `fusepose
    /// eval --odds-samples` with this file's networks) and stores it in `--out`.
    Odds,
    /// Everything for a new object set within `--minutes`: pose net + refiner,
    /// segmenter, fine-tune on the segmenter's masks, acceptance report.
    All,
}

#[derive(clap::Args, Clone, Debug)]
pub struct Args {
    /// Object set: `builtin` or a folder with one subfolder or .obj/.ply file per object.
    #[arg(long, default_value = "builtin")]
    pub objects: String,
    /// Metres per mesh-file unit (not applied to `builtin`).
    #[arg(long, alias = "mesh-scale", default_value_t = 1.0)]
    pub scale: f64,
    /// Declare an object's symmetry, repeatable: NAME=none | continuous:x|y|z |
    /// N-fold:x|y|z (N 2..12) | box | suggested, axes of the mesh file through the
    /// centroid of its surface; or a bare `suggested` for every object's geometric
    /// suggestion (the listing shows them). Used by the training loss and ADD(S),
    /// and stored in the weight file, which gives it to a mesh folder loaded without
    /// a models_info.json (daemon, eval).
    #[arg(long = "symmetry", value_name = "NAME=KIND")]
    pub symmetry: Vec<SymmetrySpec>,
    /// Train on a BOP dataset — its root (the --split folder is used) or a split
    /// folder (e.g. `data/out` or `data/out/train`; obj_ids = class ids) —
    /// instead of rendering: frames with index % 10 != 0 train, the others validate.
    #[arg(long)]
    pub dataset: Option<PathBuf>,
    /// Split of a --dataset root (ignored when --dataset is a split folder).
    #[arg(long, default_value = "train")]
    pub split: String,
    /// Output weight file. With `--stage seg`: a pose-network file here gets the
    /// segmenter embedded (objects must match), any other path a segmenter-only file.
    #[arg(long, default_value = "models/builtin.safetensors")]
    pub out: PathBuf,
    /// Training wall-time budget in minutes.
    #[arg(long)]
    pub minutes: Option<f64>,
    /// Stop at this total step count (resumed steps included).
    #[arg(long)]
    pub steps: Option<u64>,
    /// Continue from a checkpoint or a shipped weight file.
    #[arg(long)]
    pub resume: Option<PathBuf>,
    /// What to train [default: `all` for a fresh run on a mesh folder (the one
    /// command for your own objects), else `both`].
    #[arg(long, value_enum)]
    pub stage: Option<StageArg>,
    /// Rendered frames per optimisation step.
    #[arg(long, default_value_t = 8)]
    pub batch: usize,
    /// Seed of the training scenes and of the weight initialisation.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Peak Adam learning rate (cosine decay to a tenth over the budget).
    #[arg(long, default_value_t = 1e-3)]
    pub lr: f64,
    /// Folder for `checkpoint.safetensors`.
    #[arg(long, default_value = "scratch")]
    pub checkpoint_dir: PathBuf,
    /// Minutes between checkpoints.
    #[arg(long, default_value_t = 5.0)]
    pub checkpoint_minutes: f64,
    /// Append a plain-text log here.
    #[arg(long)]
    pub log: Option<PathBuf>,
    /// Validation scenes (held-out seeds).
    #[arg(long, default_value_t = 120)]
    pub val_frames: usize,
    /// Most object instances scored per validation.
    #[arg(long, default_value_t = 400)]
    pub val_samples: usize,
    /// Only validate the weight file given with --resume; no training.
    #[arg(long)]
    pub validate_only: bool,
    /// `--stage odds`: sample files of `fusepose eval --odds-samples`.
    #[arg(long, value_delimiter = ',', value_name = "CSV")]
    pub odds_samples: Vec<PathBuf>,
    /// `--stage odds`: terms the model leaves out (weight 0), e.g.
    /// `region_probability,confidence`, which a colour cast moves.
    #[arg(long, value_delimiter = ',', value_name = "TERM")]
    pub odds_without: Vec<String>,
    /// Points sampled per instance, for a fresh run (default 256; a resumed file keeps its own).
    #[arg(long)]
    pub points: Option<usize>,
    /// Colour crop side in pixels, for a fresh run (default 64; a resumed file keeps its own).
    #[arg(long)]
    pub crop: Option<usize>,
    /// Only time the inference engine (weights from --resume, else random) and exit.
    #[arg(long)]
    pub bench_engine: bool,
    /// Only time training-frame generation for these objects and flags (scene
    /// draw, render with the sensor model, crops and point clouds; one thread,
    /// 40 frames) and exit.
    #[arg(long)]
    pub bench_data: bool,
    /// Hide the progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// Share (0..1) of rendered training frames whose masks come from the
    /// segmenter embedded in the --resume file instead of the ground truth.
    #[arg(long, default_value_t = 0.0)]
    pub seg_masks: f64,
    /// Share (0..1) of the other frames (ground-truth masks) whose object
    /// masks are cut to a random 30-90 % part: the pose net learns from the
    /// partial masks a segmenter gives on unfamiliar images.
    #[arg(long, default_value_t = 0.0)]
    pub partial_masks: f64,
    /// Training samples per object per rendered frame: each one draws its own
    /// point subset and augmentation from the same render, so rendering costs
    /// less per sample (1..=8).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=8))]
    pub views_per_frame: u8,
    /// Further training samples per rendered frame of each object whose box
    /// touches the image border (0..=4): close views of objects cut by the
    /// image edge are drawn more often without rendering more.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..=4))]
    pub edge_views: u8,
    /// Train only on objects at least this visible (share of the silhouette, 0..1).
    #[arg(long, default_value_t = 0.1)]
    pub min_visible: f64,
    /// `--stage seg`: network input size `WxH` of a fresh run (default 160x120).
    #[arg(long)]
    pub seg_size: Option<String>,
    /// `--stage seg`: channel widths `E1,E2,E3,E4/D3,D2,D1` (default
    /// 16,32,64,64/32,16,16): a fresh run's architecture, or, with `--resume`,
    /// the widths the resumed segmenter is widened to before training (the
    /// same function at first: the new channels start with no influence).
    #[arg(long, value_name = "ENC/DEC")]
    pub seg_widths: Option<String>,
    /// `--stage seg`: lift each small object region's cells in the loss by up
    /// to this factor (√(200 cells / region cells), so partly hidden and far
    /// objects are not given up for a cleaner background; 1 = off).
    #[arg(long, default_value_t = 1.0)]
    pub seg_small_boost: f32,
    /// `--stage seg`: share of training frames given a random camera cast in
    /// linear light (white balance, tint, exposure, noise; 0 = none).
    #[arg(long, default_value_t = 0.0, value_parser = crate::render::probability)]
    pub seg_cast: f64,
    /// `--stage seg`: adapt the segmenter to a camera with pseudo-labelled
    /// frames of it (folders written by `fusepose eval --pseudo-labels DIR`,
    /// comma-separated), mixed with the rendered scenes.
    #[arg(long, value_delimiter = ',')]
    pub adapt_labels: Vec<PathBuf>,
    /// `--stage seg`: share of training frames drawn from `--adapt-labels`.
    #[arg(long, default_value_t = 0.5, value_parser = crate::render::probability)]
    pub adapt_share: f64,
    /// `--stage seg`: train the centre-offset head (`false` keeps a resumed
    /// file without one as it is, e.g. to fine-tune the shipped segmenter).
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub seg_offsets: bool,
    /// `--stage seg`: weight of the centre-offset loss beside the
    /// cross-entropy (lower it to add a head to a trained segmenter without
    /// moving its class features far).
    #[arg(long, default_value_t = 1.0, value_parser = loss_weight)]
    pub seg_offset_weight: f64,
    /// `--stage seg`: the centre-offset head reads its own 3x3 layer (a copy
    /// of the last decoder layer) instead of the class features; a resumed
    /// file without it gets one.
    #[arg(long)]
    pub seg_offset_branch: bool,
    /// `--stage seg`: train only the centre-offset head (and branch) of a
    /// resumed segmenter, on the offset loss alone; every other tensor, and so
    /// every class output, stays exactly as it was. Needs `--resume`.
    #[arg(long)]
    pub seg_freeze_trunk: bool,
    /// `--stage seg`: train the contact branch, which marks where two object
    /// instances touch (the second look's `contacts` cut proposal); a resumed
    /// file without it gets one. With `--seg-freeze-trunk` it learns alone.
    #[arg(long)]
    pub seg_contacts: bool,
    /// `--stage seg`: threads rendering training frames (default: one per
    /// core; the frames, and so the trained weights, are the same for any count).
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..=64))]
    pub seg_data_threads: Option<u16>,
    /// Where the networks train: `cpu` (default), or `gpu` / `gpu:N` (the
    /// N-th discrete GPU, through Vulkan; only in a build with `--features
    /// gpu`, never the default). Frames are still rendered on the CPU.
    #[arg(long, default_value = "cpu")]
    pub device: fusepose_train::device::TrainDevice,
    /// Pose stages: threads rendering training frames (default: 1 on the cpu,
    /// whose other cores the network needs; one per core with `--device gpu`).
    /// The frames, and so the trained weights, are the same for any count.
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..=64))]
    pub data_threads: Option<u16>,
    /// Domain randomisation of the rendered training scenes: off | default | strong
    /// (lights, shadows, materials, camera pipeline, tables, distractors, viewpoints).
    #[arg(long, default_value = "default")]
    pub randomize: Randomize,
    /// Depth-sensor model of the rendered training frames: ideal | basic | structured-light | tof.
    #[arg(long, default_value = "structured-light")]
    pub depth_sensor: DepthSensor,
    /// Several copies of one class per scene (touching pairs, heaps), as the
    /// training default; `--single-instances` draws each class at most once.
    #[arg(long)]
    pub single_instances: bool,
    /// Probability that a training scene holds a pair of identical objects
    /// side by side (default 0.35, as `render --pairs`).
    #[arg(long, value_name = "P", value_parser = crate::render::probability)]
    pub pairs: Option<f64>,
    /// Probability that a training scene holds a heap of 4-8 touching copies
    /// of one object (default 0.15, as `render --heap`).
    #[arg(long, value_name = "P", value_parser = crate::render::probability)]
    pub heap: Option<f64>,
    /// With randomisation on, the share of training scenes drawn plain
    /// (randomisation off, basic sensor) so accuracy on clean images holds.
    #[arg(long, default_value_t = SamplerConfig::training().plain_share)]
    pub plain_share: f64,
    #[arg(long, default_value = "ycb-video", value_parser = crate::camera_model::parse, help = crate::camera_model::HELP)]
    pub intrinsics: fusepose_scene::Intrinsics,
    /// A fresh run for new objects starts from this trained pose-network file
    /// (e.g. models/builtin.safetensors): its architecture and every layer
    /// that does not depend on the number of classes; the class heads start fresh.
    /// With `--stage all` and no --warm-start, the shipped model's trunk is used.
    #[arg(long, conflicts_with = "resume")]
    pub warm_start: Option<PathBuf>,
    /// `--stage all`: start from random weights instead of the shipped model's trunk.
    #[arg(long, conflicts_with = "warm_start")]
    pub cold: bool,
    /// Pose stages from a trained trunk (`--warm-start`, `--resume`): share 0..1 of
    /// the budget during which only the per-class output layers learn, the trunk
    /// frozen; then everything learns. 0 = off. With `--stage all` it applies to
    /// the first pose stage only, and defaults to 0.25 there when that stage
    /// warm-starts (measured: docs/TRAINING.md, session 29); 0 otherwise.
    #[arg(long)]
    pub heads_first: Option<f64>,
    /// Warm starts: how the per-class output layers begin. `fresh` (random,
    /// the default) or `class-mean` (the translation and confidence heads
    /// start as the mean of the trained file's classes; rotation heads fresh).
    #[arg(long, value_name = "fresh|class-mean", value_parser = fusepose_train::warm_start::WarmHeads::parse, default_value = "fresh")]
    pub warm_heads: fusepose_train::warm_start::WarmHeads,
    /// `--stage all`: shares of `--minutes` for the pose, segmenter and
    /// fine-tune stages, e.g. `0.4,0.35,0.2`; at most 0.95 in all (the rest
    /// pays for validation and the acceptance report).
    #[arg(long, value_name = "POSE,SEG,TUNE", value_parser = parse_stage_shares, default_value = "0.475,0.2375,0.2375")]
    pub stage_shares: StageShares,
}

/// Budget shares of the three trained stages of `--stage all`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StageShares(pub [f64; 3]);

fn parse_stage_shares(s: &str) -> Result<StageShares, String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let [pose, seg, tune] = parts[..] else {
        return Err(format!("expected three shares POSE,SEG,TUNE (e.g. 0.4,0.35,0.2), got '{s}'"));
    };
    let mut shares = [0.0; 3];
    for (out, (name, text)) in shares.iter_mut().zip([("POSE", pose), ("SEG", seg), ("TUNE", tune)]) {
        *out = text.parse::<f64>().map_err(|_| format!("{name} share '{text}' is not a number"))?;
        if !(out.is_finite() && *out > 0.0) {
            return Err(format!("{name} share {text} must be above 0 (every stage needs some time)"));
        }
    }
    let sum: f64 = shares.iter().sum();
    if sum > 0.95 + 1e-9 {
        return Err(format!(
            "the shares add up to {sum:.3}; at most 0.95, the rest of --minutes pays for validation and the acceptance report"
        ));
    }
    Ok(StageShares(shares))
}

impl Args {
    /// The stage asked for, or the default for these flags (see `--stage`).
    pub fn stage(&self) -> StageArg {
        let fresh_mesh_folder = self.objects != "builtin" && self.resume.is_none() && self.dataset.is_none();
        let only_measures = self.validate_only || self.bench_engine || self.bench_data;
        self.stage.unwrap_or(if fresh_mesh_folder && !only_measures { StageArg::All } else { StageArg::Both })
    }
}

/// `--stage odds`: fits [`PoseOdds`] to the sample files and stores it in `out`.
fn fit_odds(samples: &[PathBuf], without: &[String], out: &Path) -> anyhow::Result<()> {
    use fusepose_estimator::pose_odds::{FEATURES, PoseOdds, parse_samples};
    let left_out = without
        .iter()
        .map(|t| {
            FEATURES.iter().position(|f| f == t).with_context(|| {
                format!("--odds-without {t:?}: not a term of the model (terms: {})", FEATURES.join(", "))
            })
        })
        .collect::<anyhow::Result<Vec<usize>>>()?;
    anyhow::ensure!(
        !samples.is_empty(),
        "--stage odds needs --odds-samples: files written by `fusepose eval --odds-samples` on frames that are \
         neither tuning nor test frames"
    );
    let mut all = Vec::new();
    for path in samples {
        let text = std::fs::read_to_string(path).with_context(|| format!("--odds-samples {}", path.display()))?;
        all.extend(parse_samples(&text, &path.display().to_string())?);
    }
    let names: Vec<String> = samples.iter().map(|p| p.display().to_string()).collect();
    let model = PoseOdds::fit_without(&all, &left_out, &names.join(", "))?;
    model.store(out)?;
    println!(
        "pose odds: fitted on {} samples ({} right) and stored in {}",
        model.samples,
        model.positives,
        out.display()
    );
    for (name, w) in FEATURES.iter().zip(&model.weights) {
        println!("  {name:20} {w:+.3}");
    }
    println!("  {:20} {:+.3}", "bias", model.bias);
    Ok(())
}

/// The training scene sampler the flags ask for: `SamplerConfig::training()`
/// with their randomisation level and depth sensor; with `--randomize off
/// --depth-sensor basic --single-instances` exactly the scenes of runs before
/// randomisation existed.
pub fn training_sampler(args: &Args) -> SamplerConfig {
    let plain = args.randomize == Randomize::Off && args.depth_sensor == DepthSensor::Basic && args.single_instances;
    if plain {
        return SamplerConfig { intrinsics: args.intrinsics, ..SamplerConfig::default() };
    }
    let mut s = SamplerConfig {
        intrinsics: args.intrinsics,
        randomize: args.randomize,
        depth_sensor: args.depth_sensor,
        plain_share: args.plain_share,
        ..SamplerConfig::training()
    };
    if let Some(p) = args.pairs {
        s.pair_probability = p;
    }
    if let Some(p) = args.heap {
        s.heap_probability = p;
    }
    if args.single_instances {
        s.instances_per_class = (1, 1);
        s.pair_probability = 0.0;
        s.heap_probability = 0.0;
    }
    s
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if args.objects != "builtin"
        && args.out == Path::new(crate::weights::SHIPPED_WEIGHTS)
        && !args.validate_only
        && !args.bench_engine
        && !args.bench_data
    {
        anyhow::bail!(
            "--out defaults to the shipped built-in model ({}), which training '{}' would overwrite: \
             pass --out models/<name>.safetensors",
            crate::weights::SHIPPED_WEIGHTS,
            args.objects
        );
    }
    if !args.adapt_labels.is_empty() && !matches!(args.stage(), StageArg::Seg) {
        anyhow::bail!("--adapt-labels adapts the segmenter: give it with --stage seg");
    }
    if matches!(args.stage(), StageArg::Odds) {
        return fit_odds(&args.odds_samples, &args.odds_without, &args.out);
    }
    let set = training_objects(&args)?;
    let stage = match args.stage() {
        StageArg::Pose => Stage::Pose,
        StageArg::Refine => Stage::Refine,
        StageArg::Both => Stage::Both,
        StageArg::Seg => return seg::run(set, &args),
        StageArg::Calibrate => return seg::calibrate_file(&set, &args, &args.out).map(|_| ()),
        StageArg::Odds => unreachable!("handled above"),
        StageArg::All => return pipeline::run(&args),
    };
    if args.bench_engine {
        return bench(&set, args.resume.as_deref());
    }
    if args.bench_data {
        return bench_data(&set, &args);
    }
    let source = match &args.dataset {
        Some(dir) => Source::bop(&crate::dataset_path::resolve_bop_split(dir, &args.split)?, &set)?,
        None => Source::Rendered,
    };
    if args.validate_only {
        let path = args.resume.as_ref().context("--validate-only needs --resume FILE")?;
        let v = validate_file(&set, &source, path, args.val_frames, args.val_samples)?;
        println!("{}", fusepose_train::validate::summary(&v));
        return Ok(());
    }
    let mut config = fusepose_estimator::net::NetConfig::new(set.len());
    if let Some(n) = args.points {
        config.num_points = n;
    }
    if let Some(s) = args.crop {
        config.crop_size = s;
    }
    config.validate().map_err(|e| anyhow::anyhow!("network config: {e}"))?;
    if !(0.0..=1.0).contains(&args.min_visible) {
        anyhow::bail!("--min-visible must be in 0..=1, got {}", args.min_visible);
    }
    if !(0.0..=1.0).contains(&args.partial_masks) {
        anyhow::bail!("--partial-masks must be a share in 0..=1, got {}", args.partial_masks);
    }
    let sampler = training_sampler(&args);
    let opts = TrainOptions {
        warm_start: args.warm_start.clone(),
        out: args.out,
        minutes: args.minutes,
        steps: args.steps,
        resume: args.resume,
        stage,
        device: args.device,
        data_threads: args.data_threads.map_or_else(
            || match args.device {
                fusepose_train::device::TrainDevice::Cpu => 1,
                fusepose_train::device::TrainDevice::Gpu(_) => fusepose_train::seeded_workers::default_threads(),
            },
            usize::from,
        ),
        batch: args.batch,
        seed: args.seed,
        lr: args.lr,
        heads_first: args.heads_first.unwrap_or(0.0),
        warm_heads: args.warm_heads,
        loss_points: 500,
        checkpoint_dir: args.checkpoint_dir,
        checkpoint_every: Duration::from_secs_f64(args.checkpoint_minutes * 60.0),
        log: args.log,
        val_frames: args.val_frames,
        val_max_samples: args.val_samples,
        config: Some(config),
        data_desc: match &args.dataset {
            Some(d) => format!("{} objects, BOP frames from {}", args.objects, d.display()),
            None if args.seg_masks > 0.0 => format!(
                "{} objects, tabletop scenes rendered on the fly with sensor noise, {:.0} % of frames with segmenter masks",
                args.objects,
                args.seg_masks * 100.0
            ),
            None => format!("{} objects, tabletop scenes rendered on the fly with sensor noise", args.objects),
        } + &format!(
            ", objects >= {:.0} % visible, randomize {}, depth sensor {}, {}",
            args.min_visible * 100.0,
            args.randomize,
            args.depth_sensor,
            if args.single_instances { "one copy per class" } else { "several copies per class" }
        ) + &if args.partial_masks > 0.0 {
            format!(", {:.0} % of ground-truth-mask frames with masks cut to a part", args.partial_masks * 100.0)
        } else {
            String::new()
        } + &if args.views_per_frame > 1 {
            format!(", {} samples per object per rendered frame", args.views_per_frame)
        } else {
            String::new()
        } + &if args.edge_views > 0 {
            format!(", {} more of each object cut by the image edge", args.edge_views)
        } else {
            String::new()
        },
        source,
        progress: !args.quiet,
        seg_masks: args.seg_masks,
        partial_masks: args.partial_masks,
        min_visible: args.min_visible,
        sampler,
        views_per_frame: args.views_per_frame as usize,
        edge_views: args.edge_views as usize,
    };
    let summary = train(Arc::new(set), &opts)?;
    println!(
        "trained {} steps ({} samples, {:.0} s, {:.0} ms/step) -> {}",
        summary.record.steps,
        summary.record.samples,
        summary.record.seconds,
        summary.step_ms,
        summary.out.display()
    );
    println!("{}", fusepose_train::validate::summary(&summary.validation));
    Ok(())
}

/// The object set of `--objects` with its `--symmetry` declarations; objects
/// still without one take the symmetry the `--resume` file was trained with.
fn training_objects(args: &Args) -> anyhow::Result<fusepose_scene::ObjectSet> {
    let mut set =
        load_object_set(&args.objects, args.scale).with_context(|| format!("loading object set '{}'", args.objects))?;
    for (name, symmetry) in apply_symmetry_specs(&mut set, &args.symmetry)? {
        tracing::info!("{name}: symmetry {} (--symmetry)", Describe(&symmetry));
    }
    if let Some(resume) = &args.resume
        && let Ok(file) = fusepose_estimator::net::WeightFile::read(resume)
    {
        for name in file.adopt_symmetries(&mut set) {
            tracing::info!("{name}: symmetry from {}", resume.display());
        }
    }
    Ok(set)
}

/// `--bench-engine`: ms per object and GFLOP/s for 1/2 threads and 1/5 objects per frame.
fn bench(set: &fusepose_scene::ObjectSet, weights: Option<&std::path::Path>) -> anyhow::Result<()> {
    use fusepose_estimator::net::WeightFile;
    let file = match weights {
        Some(p) => WeightFile::read(p)?,
        None => fusepose_train::bench::random_weights(set)?,
    };
    let c = &file.config;
    println!(
        "network: {} parameters, N={} S={}, {:.1} MFLOP per object (pose net + {} refiner iterations)",
        c.parameter_count(),
        c.num_points,
        c.crop_size,
        c.flops_per_object(c.num_points, c.crop_size, c.refine_iters) / 1e6,
        c.refine_iters
    );
    for (instances, threads) in [(1, 1), (5, 1), (5, 2)] {
        let r = fusepose_train::bench::engine_speed(&file, set, instances, threads, 40)?;
        println!(
            "{} objects/frame, {} thread(s): {:.2} ms per object, {:.1} GFLOP/s",
            r.instances, r.threads, r.ms_per_object, r.gflops
        );
    }
    Ok(())
}

/// `--bench-data`: what one training frame costs the data thread, and per sample.
fn bench_data(set: &fusepose_scene::ObjectSet, args: &Args) -> anyhow::Result<()> {
    let cfg = fusepose_estimator::net::NetConfig::new(set.len());
    // As the trainer's data thread makes them (`fusepose_train::trainer::train`).
    let data = fusepose_train::data::DataConfig {
        min_visible: args.min_visible,
        augment: true,
        sampler: training_sampler(args),
        views_per_frame: args.views_per_frame as usize,
        edge_views: args.edge_views as usize,
        ..fusepose_train::data::DataConfig::unaugmented(
            args.points.unwrap_or(cfg.num_points),
            args.crop.unwrap_or(cfg.crop_size),
        )
    };
    let r = fusepose_train::bench::data_speed(set, &data, 1_000_000_001, 40)?;
    println!(
        "{} frames, {:.2} samples per frame; median ms per frame: scene {:.1}, render {:.1}, whole frame {:.1}; \
         {:.1} ms per sample",
        r.frames,
        r.samples_per_frame,
        r.scene_ms,
        r.render_ms,
        r.frame_ms,
        r.ms_per_sample()
    );
    Ok(())
}

/// A loss weight: a finite number >= 0.
fn loss_weight(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(w) if w.is_finite() && w >= 0.0 => Ok(w),
        _ => Err(format!("{s:?} is not a loss weight: expected a finite number >= 0 (1 = as much as the class loss)")),
    }
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;

    #[derive(Parser)]
    struct Cmd {
        #[command(flatten)]
        args: Args,
    }

    fn args(flags: &[&str]) -> Args {
        Cmd::try_parse_from(std::iter::once("train").chain(flags.iter().copied())).unwrap().args
    }

    #[test]
    fn the_offset_loss_weight_is_a_finite_number_at_least_zero() {
        assert_eq!(args(&[]).seg_offset_weight, 1.0);
        assert_eq!(args(&["--seg-offset-weight", "0.2"]).seg_offset_weight, 0.2);
        for bad in ["-1", "nan", "inf", "x"] {
            let flag = format!("--seg-offset-weight={bad}");
            let err = Cmd::try_parse_from(["train", flag.as_str()]).err().unwrap().to_string();
            assert!(err.contains("finite number >= 0"), "{bad}: {err}");
        }
    }

    #[test]
    fn the_offset_branch_and_frozen_trunk_are_off_unless_asked() {
        let plain = args(&[]);
        assert!(!plain.seg_offset_branch && !plain.seg_freeze_trunk);
        let asked = args(&["--seg-offset-branch", "--seg-freeze-trunk"]);
        assert!(asked.seg_offset_branch && asked.seg_freeze_trunk);
    }

    #[test]
    fn a_mesh_folder_gets_the_whole_pipeline_and_never_overwrites_the_shipped_model() {
        assert!(matches!(args(&["--objects", "meshes", "--out", "m.safetensors"]).stage(), StageArg::All));
        assert!(matches!(args(&[]).stage(), StageArg::Both), "builtin keeps its old default");
        assert!(matches!(args(&["--objects", "meshes", "--resume", "m.safetensors"]).stage(), StageArg::Both));
        assert!(matches!(args(&["--objects", "meshes", "--stage", "seg"]).stage(), StageArg::Seg));
        let err = run(args(&["--objects", "/nonexistent/meshes", "--minutes", "1"])).unwrap_err().to_string();
        assert!(err.contains("would overwrite") && err.contains("--out models/<name>.safetensors"), "{err}");
        assert_eq!(args(&["--intrinsics", "realsense-d435"]).intrinsics.fx, 615.0);
        assert_eq!(training_sampler(&args(&["--intrinsics", "realsense-d435"])).intrinsics.fx, 615.0);
    }

    #[test]
    fn pairs_and_heaps_set_the_multi_instance_scenes_and_single_instances_wins() {
        let default = training_sampler(&args(&[]));
        assert_eq!((default.pair_probability, default.heap_probability), (0.35, 0.15));
        let more = training_sampler(&args(&["--pairs", "0.5", "--heap", "0.3"]));
        assert_eq!((more.pair_probability, more.heap_probability), (0.5, 0.3));
        let single = training_sampler(&args(&["--pairs", "0.5", "--single-instances"]));
        assert_eq!((single.pair_probability, single.heap_probability, single.instances_per_class), (0.0, 0.0, (1, 1)));
        assert!(Cmd::try_parse_from(["train", "--heap", "1.5"]).is_err(), "a probability above 1 is refused");
    }

    #[test]
    fn one_sample_per_object_and_frame_unless_asked_and_at_most_eight() {
        assert_eq!(args(&[]).views_per_frame, 1);
        assert_eq!(args(&["--views-per-frame", "2"]).views_per_frame, 2);
        assert_eq!(args(&[]).edge_views, 0);
        assert_eq!(args(&["--edge-views", "2"]).edge_views, 2);
        for bad in ["0", "9"] {
            assert!(Cmd::try_parse_from(["train", "--views-per-frame", bad]).is_err(), "{bad} is refused");
        }
    }

    #[test]
    fn stage_shares_default_to_the_documented_split_and_bad_ones_are_named() {
        assert_eq!(args(&[]).stage_shares, StageShares([0.475, 0.2375, 0.2375]));
        assert_eq!(args(&["--stage-shares", "0.4, 0.35,0.2"]).stage_shares, StageShares([0.4, 0.35, 0.2]));
        let err = |v: &str| Cmd::try_parse_from(["train", "--stage-shares", v]).err().map(|e| e.to_string()).unwrap();
        assert!(err("0.5,0.5").contains("expected three shares"), "{}", err("0.5,0.5"));
        assert!(err("0.5,x,0.1").contains("SEG share 'x' is not a number"));
        assert!(err("0.5,0,0.1").contains("SEG share 0 must be above 0"));
        assert!(err("0.5,0.3,0.2").contains("add up to 1.000; at most 0.95"));
    }
}
