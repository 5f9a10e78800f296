//! The training loop: batches from the background renderer, the DenseFusion
//! loss for the pose net, the refiner loss on perturbed ground truth (and, once
//! the pose net is decent, on its own detached estimates), Adam with a cosine
//! learning-rate decay over the planned budget, a progress bar, a plain-text log,
//! resumable checkpoints and a final held-out validation written into the
//! weight file's metadata.
//!
//! Checkpoints hold weights and the step/sample counters only: Adam's moments
//! restart on resume, behind a 200-step linear learning-rate warm-up.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use burn::optim::{AdamConfig, GradientsParams};
use burn::prelude::{Int, Tensor, TensorData};
use fusepose_estimator::net::meta::{TrainRecord, object_entries};
use fusepose_estimator::net::{NetConfig, WeightFile};
use fusepose_scene::ObjectSet;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

use crate::data::{DataConfig, Sample, SegMaskSource, Source, Stream};
use crate::geometry::{pose_from_parts, rot_rows};
use crate::loss::{GtInstance, model_tensor, pose_loss, refine_loss};
use crate::model::FusionNet;
use crate::seeded_workers::RecvError;
use crate::store;
use crate::validate::{self, Validation};
use fusepose_estimator::seg::file::{SegFile, embed, has_embedded};

/// Steps of linear learning-rate warm-up at the start of every run.
pub const WARMUP_STEPS: u64 = 200;

/// Which parts are trained.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    /// Colour CNN + pose net only.
    Pose,
    /// Refiner only (colour features detached; pose net frozen).
    Refine,
    /// Everything, both losses summed.
    Both,
}

/// Everything a training run needs.
#[derive(Clone, Debug)]
pub struct TrainOptions {
    pub out: PathBuf,
    /// Stop after this much wall time (training only; validation comes after).
    pub minutes: Option<f64>,
    /// Stop after this many steps (counted from the start of the run, including resumed steps).
    pub steps: Option<u64>,
    pub resume: Option<PathBuf>,
    pub stage: Stage,
    pub batch: usize,
    pub seed: u64,
    pub lr: f64,
    /// Model points per instance in the loss.
    pub loss_points: usize,
    pub checkpoint_dir: PathBuf,
    pub checkpoint_every: Duration,
    pub log: Option<PathBuf>,
    /// Validation scenes and sample cap.
    pub val_frames: usize,
    pub val_max_samples: usize,
    /// Architecture for a fresh run (ignored on resume: the file's config wins).
    pub config: Option<NetConfig>,
    /// A fresh run starts from this trained file's trunk (its architecture,
    /// every tensor that fits; [`crate::warm_start`]) instead of random weights.
    pub warm_start: Option<PathBuf>,
    /// Where training (and validation) frames come from.
    pub source: Source,
    /// Human description of the data for the record.
    pub data_desc: String,
    pub progress: bool,
    /// Share of rendered training frames whose masks come from the segmenter
    /// embedded in the `resume` file (0 = ground-truth masks only).
    pub seg_masks: f64,
    /// [`DataConfig::partial_masks`].
    pub partial_masks: f64,
    /// Objects less visible than this (share of their silhouette, 0..1) are
    /// not trained on.
    pub min_visible: f64,
    /// How rendered training scenes are drawn (randomisation, depth sensor,
    /// copies per class); validation always uses the plain default scenes.
    pub sampler: fusepose_scene::sampler::SamplerConfig,
    /// Samples per object per rendered frame ([`DataConfig::views_per_frame`]).
    pub views_per_frame: usize,
    /// Further samples per rendered frame of each object cut by the image
    /// edge ([`DataConfig::edge_views`]).
    pub edge_views: usize,
    /// Where the network trains ([`crate::device`]).
    pub device: crate::device::TrainDevice,
    /// Threads rendering training frames: the samples are the same for any
    /// count ([`crate::seeded_workers`]). One keeps a 2-core CPU's second core
    /// for the network; a GPU run wants every core rendering.
    pub data_threads: usize,
    /// Share (0..1) of the run's budget, from its start, during which only
    /// the per-class output layers learn ([`FusionNet::with_trunk_learning`]);
    /// then everything does. 0 = off. Meant for a warm start: new class
    /// heads first learn to read a trained trunk before it moves.
    pub heads_first: f64,
    /// How a warm start's per-class heads begin ([`crate::warm_start::WarmHeads`]).
    pub warm_heads: crate::warm_start::WarmHeads,
}

/// What a finished run reports.
#[derive(Clone, Debug)]
pub struct TrainSummary {
    pub record: TrainRecord,
    pub validation: Validation,
    pub out: PathBuf,
    pub step_ms: f64,
}

struct Log(Option<std::fs::File>);

impl Log {
    fn line(&mut self, s: &str) {
        if let Some(f) = &mut self.0 {
            let _ = writeln!(f, "{s}");
            let _ = f.flush();
        }
    }
}

fn random_rotation(rng: &mut Pcg64, max_angle: f64) -> UnitQuaternion<f64> {
    let axis = loop {
        let v = Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
        let n = v.norm();
        if n > 1e-3 && n <= 1.0 {
            break v / n;
        }
    };
    UnitQuaternion::from_scaled_axis(axis * rng.random_range(0.0..max_angle))
}

/// The segmenter mask source of `opts.seg_masks` (from the file resumed from).
fn seg_masks(opts: &TrainOptions, set: &ObjectSet) -> anyhow::Result<Option<SegMaskSource>> {
    if opts.seg_masks <= 0.0 {
        return Ok(None);
    }
    if !matches!(opts.source, Source::Rendered) {
        bail!("segmenter masks are for rendered training frames only");
    }
    let path = opts.resume.as_ref().context("segmenter masks need --resume with a file that embeds a segmenter")?;
    let file = SegFile::read(path)
        .and_then(|f| f.check_objects(set).map(|()| f))
        .with_context(|| format!("loading the segmenter embedded in {}", path.display()))?;
    Ok(Some(SegMaskSource { file: Arc::new(file), fraction: opts.seg_masks }))
}

/// Runs training and validation; writes `opts.out`.
pub fn train(set: Arc<ObjectSet>, opts: &TrainOptions) -> anyhow::Result<TrainSummary> {
    if set.is_empty() {
        bail!("the object set is empty");
    }
    if opts.batch == 0 {
        bail!("batch must be at least 1");
    }
    if !(0.0..=1.0).contains(&opts.heads_first) {
        bail!("--heads-first is a share of the run, 0..=1; got {}", opts.heads_first);
    }
    if opts.heads_first > 0.0 && opts.warm_start.is_none() && opts.resume.is_none() {
        bail!(
            "--heads-first freezes a trained trunk, but this run starts from random weights: \
             give --warm-start FILE (or --resume FILE), or leave --heads-first at 0"
        );
    }
    let device = opts.device.autodiff()?;
    device.seed(opts.seed);
    let objects = object_entries(&set);
    let mut log = Log(match &opts.log {
        Some(p) => Some(
            std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(p)
                .with_context(|| format!("opening {}", p.display()))?,
        ),
        None => None,
    });
    let (mut net, cfg, mut record) = match &opts.resume {
        Some(path) => {
            let loaded = store::load(path, &device)?;
            loaded
                .file
                .check_objects(&set)
                .with_context(|| format!("{} does not fit the object set", path.display()))?;
            let record = loaded.file.train.clone().unwrap_or_default();
            (loaded.net, loaded.file.config.clone(), record)
        }
        None if opts.warm_start.is_some() => {
            let path = opts.warm_start.as_ref().expect("checked");
            let (net, cfg, w) = crate::warm_start::warm_start(path, set.len(), opts.warm_heads, &device)?;
            log.line(&w.log_line(path));
            (net, cfg, TrainRecord { seed: opts.seed, ..TrainRecord::default() })
        }
        None => {
            let cfg = opts.config.clone().unwrap_or_else(|| NetConfig::new(set.len()));
            if cfg.num_classes != set.len() {
                bail!("config has {} classes, the object set {}", cfg.num_classes, set.len());
            }
            (FusionNet::new(&cfg, &device), cfg, TrainRecord { seed: opts.seed, ..TrainRecord::default() })
        }
    };
    record.batch = opts.batch;
    record.data = opts.data_desc.clone();
    let start_steps = record.steps;
    log.line(&format!(
        "# start {} | stage {:?} on {} batch {} lr {} seed {} min_visible {} | resume {:?} at step {} | params {}",
        chrono_like_now(),
        opts.stage,
        opts.device,
        opts.batch,
        opts.lr,
        opts.seed,
        opts.min_visible,
        opts.resume,
        start_steps,
        cfg.parameter_count()
    ));

    let data_cfg = DataConfig {
        min_visible: opts.min_visible,
        augment: true,
        sampler: opts.sampler.clone(),
        views_per_frame: opts.views_per_frame,
        edge_views: opts.edge_views,
        partial_masks: opts.partial_masks,
        ..DataConfig::unaugmented(cfg.num_points, cfg.crop_size)
    };
    // Training scenes: a per-seed, per-resume range far from the validation seeds.
    let first_seed = (opts.seed % 1000) * 1_000_000_000 + start_steps * 7 + 1;
    let seg = seg_masks(opts, &set)?;
    // Read once: checkpoints overwrite the resumed file when resuming from one.
    let carried = match &opts.resume {
        Some(resume) => embedded_segmenter(resume)?,
        None => None,
    };
    let mut stream =
        Stream::spawn(set.clone(), data_cfg, opts.source.clone(), first_seed, 512, seg, opts.data_threads.max(1))?;
    let mut rng = Pcg64::seed_from_u64(opts.seed ^ start_steps.wrapping_mul(0x9e37_79b9));
    let mut optim = AdamConfig::new().init();

    let budget = opts.minutes.map(|m| Duration::from_secs_f64(m * 60.0));
    let step_limit = opts.steps;
    if budget.is_none() && step_limit.is_none() {
        bail!("give --minutes or --steps");
    }
    let bar = if opts.progress {
        let len =
            step_limit.map(|s| s.saturating_sub(start_steps)).unwrap_or_else(|| budget.map_or(0, |d| d.as_secs()));
        let b = indicatif::ProgressBar::new(len);
        b.set_style(
            indicatif::ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} ETA {eta} {msg}")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        b
    } else {
        indicatif::ProgressBar::hidden()
    };

    let (n, s, b) = (cfg.num_points, cfg.crop_size, opts.batch);
    let mut pool: Vec<Sample> = Vec::with_capacity(256);
    let t_start = Instant::now();
    let mut last_ckpt = Instant::now();
    let mut w_conf = 0.015f32;
    let mut ema_pose = f64::NAN;
    let mut ema_ref = f64::NAN;
    let mut ema_loss = f64::NAN;
    let mut step_time = 0.0f64;
    let ema = |e: f64, v: f64| if e.is_nan() { v } else { 0.98 * e + 0.02 * v };
    let mut trunk_frozen = opts.heads_first > 0.0;
    if trunk_frozen {
        net = net.with_trunk_learning(false);
        log.line(&format!("# heads first: trunk frozen for {:.0} % of the run", 100.0 * opts.heads_first.min(1.0)));
    }
    loop {
        let elapsed = t_start.elapsed();
        let done = record.steps - start_steps;
        let frac = match (budget, step_limit) {
            (Some(d), _) if elapsed >= d => break,
            (_, Some(l)) if record.steps >= l => break,
            (Some(d), Some(l)) => {
                (elapsed.as_secs_f64() / d.as_secs_f64()).max(done as f64 / (l - start_steps).max(1) as f64)
            }
            (Some(d), None) => elapsed.as_secs_f64() / d.as_secs_f64(),
            (None, Some(l)) => done as f64 / (l - start_steps).max(1) as f64,
            (None, None) => unreachable!(),
        };
        if trunk_frozen && frac >= opts.heads_first {
            net = net.with_trunk_learning(true);
            trunk_frozen = false;
            log.line(&format!("# heads first: trunk learns from step {}", record.steps));
        }
        // Batch: keep a shuffle pool of a few batches (samples of one frame are correlated).
        while pool.len() < 4 * b {
            stream.check()?;
            // A slow sample is waited for (a process paused with SIGSTOP must
            // resume); a data thread that died is an error (`check`).
            match stream.recv_timeout(Duration::from_secs(60)) {
                Ok(x) => pool.push(x),
                Err(RecvError::Timeout(_)) => tracing::warn!("no training sample for 60 s; waiting on"),
                Err(e) => return Err(e.into()),
            }
        }
        while let Some(x) = stream.try_recv() {
            if pool.len() >= 256 {
                break;
            }
            pool.push(x);
        }
        pool.shuffle(&mut rng);
        let batch: Vec<Sample> = pool.drain(pool.len() - b..).collect();
        let t_step = Instant::now();
        // Linear warm-up over the run's first WARMUP_STEPS (Adam's moments start
        // empty, also on resume), then cosine decay to a tenth over the budget.
        let warm = ((done + 1) as f64 / WARMUP_STEPS as f64).min(1.0);
        let lr = warm * opts.lr * (0.1 + 0.9 * 0.5 * (1.0 + (std::f64::consts::PI * frac.min(1.0)).cos()));
        let classes: Vec<usize> = batch.iter().map(|x| x.class).collect();
        let gts: Vec<GtInstance> = batch
            .iter()
            .map(|x| {
                let m = &set.objects[x.class];
                let pts: Vec<[f32; 3]> = (0..opts.loss_points)
                    .map(|_| {
                        let p = m.samples[rng.random_range(0..m.samples.len())];
                        [p.x as f32, p.y as f32, p.z as f32]
                    })
                    .collect();
                GtInstance::new(x.pose, pts, &m.symmetry)
            })
            .collect();
        let crops = Tensor::<4>::from_data(
            TensorData::new(batch.iter().flat_map(|x| x.crop.iter().copied()).collect::<Vec<_>>(), [b, 3, s, s]),
            &device,
        );
        let points = Tensor::<3>::from_data(
            TensorData::new(batch.iter().flat_map(|x| x.points.iter().copied()).collect::<Vec<_>>(), [b, n, 3]),
            &device,
        );
        let choose_v: Vec<i64> = batch.iter().flat_map(|x| x.choose.iter().map(|&c| c as i64)).collect();
        let half_v: Vec<i64> =
            choose_v.iter().map(|&c| ((c as usize / s / 2) * (s / 2) + (c as usize % s) / 2) as i64).collect();
        let choose = Tensor::<2, Int>::from_data(TensorData::new(choose_v, [b, n]), &device);
        let half = Tensor::<2, Int>::from_data(TensorData::new(half_v, [b, n]), &device);
        let model = model_tensor(&gts, &device);

        let emb = net.cnn.forward(crops, choose, half);
        let mut total: Option<Tensor<1>> = None;
        let mut pose_best: Option<Vec<Isometry3<f64>>> = None;
        if opts.stage != Stage::Refine {
            let out = net.pose.forward(&cfg, points.clone(), emb.clone(), &classes);
            let (lp, st) = pose_loss(&out, model.clone(), &gts, w_conf);
            ema_pose = ema(ema_pose, st.best_dis);
            if ema_pose < 0.03 {
                let q = out.quat.clone().into_data().try_to_vec::<f32>().unwrap_or_default();
                let t = out.trans.clone().into_data().try_to_vec::<f32>().unwrap_or_default();
                pose_best = Some(
                    st.best
                        .iter()
                        .enumerate()
                        .map(|(bi, &i)| {
                            let k = bi * n + i;
                            pose_from_parts(
                                [q[4 * k], q[4 * k + 1], q[4 * k + 2], q[4 * k + 3]],
                                [t[3 * k], t[3 * k + 1], t[3 * k + 2]],
                            )
                        })
                        .collect(),
                );
            }
            total = Some(lp);
        }
        if opts.stage != Stage::Pose {
            // Refiner input: the pose net's own estimate (once it is decent, half the
            // time), otherwise the ground truth perturbed by up to 30° and ±3 cm.
            let use_est = pose_best.is_some() && rng.random_bool(0.5);
            let starts: Vec<Isometry3<f64>> = match (use_est, &pose_best) {
                (true, Some(p)) => p.clone(),
                _ => gts
                    .iter()
                    .map(|g| {
                        let dr = random_rotation(&mut rng, 30f64.to_radians());
                        let dt = Vector3::new(
                            rng.random_range(-0.03..0.03),
                            rng.random_range(-0.03..0.03),
                            rng.random_range(-0.03..0.03),
                        );
                        Isometry3::from_parts(Translation3::from(g.pose.translation.vector + dt), dr * g.pose.rotation)
                    })
                    .collect(),
            };
            let r0 = Tensor::<3>::from_data(
                TensorData::new(starts.iter().flat_map(rot_rows).collect::<Vec<_>>(), [b, 3, 3]),
                &device,
            );
            let t0 = Tensor::<2>::from_data(
                TensorData::new(
                    starts
                        .iter()
                        .flat_map(|p| p.translation.vector.iter().map(|&v| v as f32).collect::<Vec<_>>())
                        .collect::<Vec<_>>(),
                    [b, 3],
                ),
                &device,
            );
            let emb_r = if opts.stage == Stage::Refine { emb.detach() } else { emb };
            let color = net.refine.color(emb_r);
            let (r1, t1) = net.refine.step(&cfg, points, &color, r0, t0, &classes);
            let lr_ = refine_loss(r1, t1, model, &gts);
            let v = lr_.clone().into_data().try_to_vec::<f32>().unwrap_or_default().first().copied().unwrap_or(f32::NAN)
                as f64;
            ema_ref = ema(ema_ref, v);
            total = Some(match total {
                Some(t) => t + lr_,
                None => lr_,
            });
        }
        let total = total.expect("some stage");
        let lv = total.clone().into_data().try_to_vec::<f32>().unwrap_or_default().first().copied().unwrap_or(f32::NAN)
            as f64;
        if !lv.is_finite() {
            bail!("loss is {lv} at step {}", record.steps);
        }
        ema_loss = ema(ema_loss, lv);
        let grads = GradientsParams::from_grads(total.backward(), &net);
        net = optim.step(lr, net, grads);
        record.steps += 1;
        record.samples += b as u64;
        let dt = t_step.elapsed().as_secs_f64();
        step_time = if step_time == 0.0 { dt } else { 0.95 * step_time + 0.05 * dt };
        // DenseFusion: once the pose net is accurate, weaken the confidence regulariser.
        if ema_pose < 0.016 && w_conf > 0.01 {
            w_conf = 0.015 * 0.3;
            log.line(&format!("# step {}: pose distance {:.4} m < 0.016: w -> {w_conf}", record.steps, ema_pose));
        }
        let msg = format!(
            "loss {:.4} pose {:.1} mm ref {:.1} mm | {:.1} samples/s lr {:.1e}",
            ema_loss,
            ema_pose * 1000.0,
            ema_ref * 1000.0,
            b as f64 / step_time,
            lr
        );
        if step_limit.is_some() {
            bar.set_position(record.steps - start_steps);
        } else {
            bar.set_position(t_start.elapsed().as_secs());
        }
        bar.set_message(msg.clone());
        if record.steps % 25 == 0 {
            log.line(&format!(
                "step {} samples {} t {:.0}s | {msg} | step {:.0} ms",
                record.steps,
                record.samples,
                t_start.elapsed().as_secs_f64(),
                step_time * 1000.0
            ));
        }
        if last_ckpt.elapsed() >= opts.checkpoint_every {
            record.seconds += last_ckpt.elapsed().as_secs_f64();
            last_ckpt = Instant::now();
            let p = opts.checkpoint_dir.join("checkpoint.safetensors");
            store::save(&net, &cfg, &objects, &record, &p)?;
            // A checkpoint must resume like the file it came from, segmenter included
            // (`--seg-masks` needs it).
            if let Some(seg) = &carried {
                embed_segmenter(seg, &p)?;
            }
            log.line(&format!("# checkpoint {} at step {}", p.display(), record.steps));
        }
    }
    bar.finish_and_clear();
    record.seconds += last_ckpt.elapsed().as_secs_f64();
    drop(stream);

    // Final weights, then validation through the engine, then the record with metrics.
    let ckpt = opts.checkpoint_dir.join("checkpoint.safetensors");
    store::save(&net, &cfg, &objects, &record, &ckpt)?;
    log.line(&format!(
        "# trained: {} steps, {} samples, {:.0} s; validating",
        record.steps, record.samples, record.seconds
    ));
    let val_set = validate::validation_set(
        &set,
        &opts.source,
        cfg.num_points,
        cfg.crop_size,
        opts.val_frames,
        opts.val_max_samples,
    )?;
    let file = WeightFile::read(&ckpt)?;
    let validation = validate::validate(&file, &set, &val_set, cfg.refine_iters)?;
    log.line(&format!("# {}", validate::summary(&validation)));
    record.metrics = validation.metrics.clone();
    store::save(&net, &cfg, &objects, &record, &opts.out)?;
    store::save(&net, &cfg, &objects, &record, &ckpt)?;
    if let (Some(seg), Some(resume)) = (&carried, &opts.resume) {
        embed_segmenter(seg, &opts.out)?;
        embed_segmenter(seg, &ckpt)?;
        log.line(&format!("# kept the segmenter embedded in {}", resume.display()));
    }
    log.line(&format!("# wrote {}", opts.out.display()));
    Ok(TrainSummary { record, validation, out: opts.out.clone(), step_ms: step_time * 1000.0 })
}

/// The segmenter embedded in `resume`, if it has one: retraining the pose
/// network keeps the file's segmenter ([`embed_segmenter`]).
fn embedded_segmenter(resume: &Path) -> anyhow::Result<Option<SegFile>> {
    let bytes = std::fs::read(resume).with_context(|| format!("reading {}", resume.display()))?;
    let Ok((_, header)) = safetensors::SafeTensors::read_metadata(&bytes) else { return Ok(None) };
    if !has_embedded(&header.metadata().clone().unwrap_or_default()) {
        return Ok(None);
    }
    let seg = SegFile::from_bytes(&bytes)
        .with_context(|| format!("reading the segmenter embedded in {}", resume.display()))?;
    Ok(Some(seg))
}

/// Embeds `seg` into the freshly written pose-network file `out`.
fn embed_segmenter(seg: &SegFile, out: &Path) -> anyhow::Result<()> {
    let pose = std::fs::read(out).with_context(|| format!("reading {}", out.display()))?;
    let merged = embed(&pose, seg).with_context(|| format!("embedding the segmenter into {}", out.display()))?;
    std::fs::write(out, merged).with_context(|| format!("writing {}", out.display()))
}

/// Seconds since the Unix epoch (no clock crate needed for a log stamp).
fn chrono_like_now() -> String {
    let s = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_secs()).unwrap_or(0);
    format!("unix {s}")
}

/// Validates an existing weight file (no training).
pub fn validate_file(
    set: &ObjectSet,
    source: &Source,
    path: &Path,
    frames: usize,
    max_samples: usize,
) -> anyhow::Result<Validation> {
    let file = WeightFile::read(path)?;
    file.check_objects(set)?;
    let val_set =
        validate::validation_set(set, source, file.config.num_points, file.config.crop_size, frames, max_samples)?;
    validate::validate(&file, set, &val_set, file.config.refine_iters)
}
