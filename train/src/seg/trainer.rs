//! The segmenter training loop: frames from the background renderer, class
//! weights estimated from the first frames' pixel counts, class-weighted
//! cross-entropy, Adam with a cosine learning-rate decay over the planned
//! budget, an `indicatif` progress bar, a plain-text log, resumable
//! checkpoints, and a final held-out validation (mIoU, per-class IoU) through
//! the inference engine, written into the weight file's metadata.
//!
//! Checkpoints hold weights and the step/sample counters (Adam's moments
//! restart on resume, as in the pose trainer).

use std::io::Write;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use burn::optim::{AdamConfig, GradientsParams};
use burn::prelude::{Device, Tensor, TensorData};
use fusepose_estimator::net::meta::{TrainRecord, object_entries};
use fusepose_estimator::seg::{SegConfig, SegEngine};
use fusepose_scene::ObjectSet;
use fusepose_scene::builtin::builtin_objects;

use super::adapt::AdaptFrames;
use super::data::{SegSample, SegStream};
use super::loss::{class_weights, contact_bce, offset_l1, small_region_weights, weighted_cross_entropy_scaled};
use super::model::SegNet;
use super::store;
use super::validate::{self, SegValidation};
use crate::seeded_workers::RecvError;
use crate::warm_start::WarmStart;

/// Everything a segmenter training run needs. `Default` trains the built-in
/// objects for 30 minutes into `seg.safetensors`.
#[derive(Clone, Debug)]
pub struct SegTrainConfig {
    /// Objects to segment (class ids 1.. in this order).
    pub objects: Arc<ObjectSet>,
    /// The weight file written at the end.
    pub out: PathBuf,
    /// Stop after this much training wall time (validation comes after).
    pub minutes: Option<f64>,
    /// Stop after this many steps (counted from the first run, resumed steps included).
    pub steps: Option<u64>,
    /// Continue from a checkpoint or weight file (its architecture wins over `arch`).
    pub resume: Option<PathBuf>,
    /// A fresh run for other objects starts from this trained segmenter (a
    /// segmenter file or a pose-network file with one embedded): its
    /// architecture and every tensor whose shape does not depend on the
    /// number of classes; the class head starts fresh ([`warm_start`]).
    pub warm_start: Option<PathBuf>,
    /// Architecture of a fresh run; `None`: [`SegConfig::new`] for the object count.
    pub arch: Option<SegConfig>,
    /// Frames per step.
    pub batch: usize,
    /// Peak Adam learning rate (cosine decay to a tenth).
    pub lr: f64,
    pub seed: u64,
    /// Class weight = (1 / pixel frequency)^power, estimated from the first `weight_frames`
    /// frames of a fresh run (a resumed run keeps the weights stored in its file).
    pub class_weight_power: f64,
    /// Cap on largest / smallest class weight.
    pub class_weight_max_ratio: f64,
    pub weight_frames: usize,
    pub checkpoint_dir: PathBuf,
    pub checkpoint_every: Duration,
    /// Held-out frames for the final validation.
    pub val_frames: usize,
    /// Append-only text log.
    pub log: Option<PathBuf>,
    /// Show an `indicatif` progress bar.
    pub progress: bool,
    /// Train the centre-offset head (added to a resumed file that lacks it).
    pub offsets: bool,
    /// Weight of the offset loss beside the cross-entropy.
    pub offset_weight: f64,
    /// The offset head reads its own layer `o1` ([`SegConfig::offset_branch`]);
    /// a resumed file without the branch gets one, copied from `d1`.
    pub offset_branch: bool,
    /// Train the offset head (and branch) alone on a resumed segmenter: the
    /// loss is the offset loss, every other layer is `no_grad`
    /// ([`SegNet::frozen_trunk`]) and stays bit for bit as it was (its class
    /// outputs unchanged).
    pub freeze_trunk: bool,
    /// Train the contact branch and head ([`SegConfig::contacts`]; added to a
    /// resumed file that lacks them, `b1` copied from `d1`). With
    /// `freeze_trunk` they learn alone, on the contact loss.
    pub contacts: bool,
    /// Widths `(enc, dec)` a resumed segmenter is widened to before training
    /// ([`SegNet::widened`]: the same function, new channels starting at zero
    /// influence); `None` keeps the file's.
    pub widen: Option<([usize; 4], [usize; 3])>,
    /// Weight of a contact cell against a cell without one in the contact loss.
    pub contact_positive_weight: f32,
    /// Largest lift of a small object region's cells in the cross-entropy
    /// ([`small_region_weights`], reference [`SMALL_REGION_CELLS`]); 1 = off.
    pub small_region_boost: f32,
    /// How training scenes are drawn (validation uses the plain default scenes).
    pub sampler: fusepose_scene::sampler::SamplerConfig,
    /// Share of training frames given a camera cast ([`super::data::camera_cast`]); 0 = none.
    pub cast_augment: f64,
    /// Threads rendering training frames. Rendering, not the network, bounds
    /// the segmenter's speed; the frames are the same for any count.
    pub data_threads: usize,
    /// Where the network trains ([`crate::device`]).
    pub device: crate::device::TrainDevice,
    /// Pseudo-label folders of the camera to adapt to ([`super::adapt`]); empty = none.
    pub adapt_labels: Vec<PathBuf>,
    /// Share of training frames drawn from them.
    pub adapt_share: f64,
}

impl Default for SegTrainConfig {
    fn default() -> Self {
        Self {
            objects: Arc::new(builtin_objects()),
            out: PathBuf::from("seg.safetensors"),
            minutes: Some(30.0),
            steps: None,
            resume: None,
            warm_start: None,
            arch: None,
            batch: 8,
            lr: 2e-3,
            seed: 1,
            class_weight_power: 0.5,
            class_weight_max_ratio: 50.0,
            weight_frames: 32,
            checkpoint_dir: PathBuf::from("checkpoints/seg"),
            checkpoint_every: Duration::from_secs(300),
            val_frames: 32,
            log: None,
            progress: true,
            offsets: true,
            offset_weight: 1.0,
            offset_branch: false,
            freeze_trunk: false,
            contacts: false,
            widen: None,
            contact_positive_weight: 5.0,
            small_region_boost: 1.0,
            sampler: fusepose_scene::sampler::SamplerConfig::training(),
            cast_augment: 0.0,
            data_threads: crate::seeded_workers::default_threads(),
            device: crate::device::TrainDevice::Cpu,
            adapt_labels: Vec::new(),
            adapt_share: 0.5,
        }
    }
}

/// Output cells of an object region that [`SegTrainConfig::small_region_boost`]
/// leaves at weight 1: about a 10 cm object 0.8 m away fully in view on the
/// 80x60 grid; a half-hidden one gets √2, a region of 22 cells 3.
pub const SMALL_REGION_CELLS: f32 = 200.0;

/// What a finished run reports.
#[derive(Clone, Debug)]
pub struct SegTrainReport {
    pub out: PathBuf,
    pub config: SegConfig,
    pub record: TrainRecord,
    pub validation: SegValidation,
    pub class_weights: Vec<f32>,
    /// `(step, smoothed loss)` every 10 steps of this run.
    pub loss_curve: Vec<(u64, f64)>,
    /// Mean loss over this run's first 10 steps and last 10 steps.
    pub first_loss: f64,
    pub last_loss: f64,
    /// Smoothed training step time, milliseconds.
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

fn hyper_json(cfg: &SegTrainConfig, weights: &[f32]) -> serde_json::Value {
    serde_json::json!({
        "batch": cfg.batch,
        "lr": cfg.lr,
        "seed": cfg.seed,
        "class_weight_power": cfg.class_weight_power,
        "class_weight_max_ratio": cfg.class_weight_max_ratio,
        "class_weights": weights,
        "augment": "colour gain 0.8-1.2, bias +-0.15, brightness +-0.3; horizontal flip 0.5",
        "camera_cast": cfg.cast_augment,
        "offsets": cfg.offsets,
        "offset_weight": cfg.offset_weight,
        "offset_branch": cfg.offset_branch,
        "freeze_trunk": cfg.freeze_trunk,
        "contacts": cfg.contacts,
        "contact_positive_weight": cfg.contact_positive_weight,
        "small_region_boost": cfg.small_region_boost,
        "small_region_cells": SMALL_REGION_CELLS,
        "data": format!(
            "scene sampler (randomize {}, plain share {}, depth sensor {}, copies per class {:?}, pairs {}, heaps {}), rendered on the fly",
            cfg.sampler.randomize,
            cfg.sampler.plain_share,
            cfg.sampler.depth_sensor,
            cfg.sampler.instances_per_class,
            cfg.sampler.pair_probability,
            cfg.sampler.heap_probability
        ),
        "optimizer": "adam, cosine decay to 0.1 x lr",
    })
}

/// The next training frame. A slow frame is waited for, not an error: a
/// process paused with SIGSTOP (to benchmark beside it) must resume; a data
/// thread that died is.
fn recv(stream: &mut SegStream) -> anyhow::Result<SegSample> {
    recv_patiently(stream, Duration::from_secs(120))
}

fn recv_patiently(stream: &mut SegStream, warn_after: Duration) -> anyhow::Result<SegSample> {
    loop {
        match stream.recv_timeout(warn_after) {
            Err(RecvError::Timeout(t)) => tracing::warn!("no segmenter training frame for {t:?}; waiting on"),
            other => return Ok(other?),
        }
    }
}

/// A segmenter for `num_classes` classes with the architecture of the one
/// in `path` (a segmenter file or a pose-network file with one embedded) and
/// every tensor of it whose name and shape fit copied
/// ([`crate::warm_start::copy_fitting`]); the class head stays fresh. The
/// offset head (with `offsets`) reads `d1`, or the branch with `branch`; a
/// source head of the other kind is not copied, so it starts at zero.
pub fn warm_start(
    path: &std::path::Path,
    num_classes: usize,
    offsets: bool,
    branch: bool,
    device: &Device,
) -> anyhow::Result<(SegNet, SegConfig, WarmStart)> {
    let source =
        store::load(path, device).with_context(|| format!("reading the warm-start segmenter {}", path.display()))?;
    let mut source_net = source.net;
    let mut arch = SegConfig { num_classes, ..source.file.config.clone() };
    if arch.offsets && arch.offset_branch != branch {
        source_net.o1 = None;
        source_net.offset = None;
        arch.offsets = false;
        arch.offset_branch = false;
    }
    if offsets && !arch.offsets {
        arch.offsets = true;
        source_net = source_net.with_offset_head(&arch, device);
    }
    if offsets && branch && !arch.offset_branch {
        arch.offset_branch = true;
        source_net = source_net.with_offset_branch(&arch, device);
    }
    arch.offsets = offsets;
    arch.offset_branch = offsets && branch;
    arch.validate().map_err(|m| anyhow::anyhow!("architecture: {m}"))?;
    let mut net = SegNet::new(&arch, device);
    let copied = crate::warm_start::copy_fitting(&mut net, &source_net, path)?;
    Ok((net, arch, copied))
}

/// Trains the segmenter, validates it through the engine and writes `cfg.out`.
pub fn train_segmenter(cfg: SegTrainConfig) -> anyhow::Result<SegTrainReport> {
    let set = cfg.objects.clone();
    if set.is_empty() {
        bail!("the object set is empty");
    }
    if cfg.batch == 0 {
        bail!("batch must be at least 1");
    }
    if cfg.minutes.is_none() && cfg.steps.is_none() {
        bail!("give a time (minutes) or step budget");
    }
    if cfg.freeze_trunk && (!(cfg.offsets || cfg.contacts) || cfg.resume.is_none()) {
        bail!(
            "freezing the trunk trains the centre-offset or contact head alone: it needs one of them on and a \
             trained segmenter to resume (--resume FILE)"
        );
    }
    // Frozen with the contacts on, only the contact branch learns.
    let contacts_only = cfg.freeze_trunk && cfg.contacts;
    let device = cfg.device.autodiff()?;
    device.seed(cfg.seed);
    let objects = object_entries(&set);
    if let Some(dir) = cfg.log.as_deref().and_then(|p| p.parent()).filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let mut log = Log(match &cfg.log {
        Some(p) => Some(
            std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(p)
                .with_context(|| format!("opening {}", p.display()))?,
        ),
        None => None,
    });
    // On resume, the class weights stored in the file are kept (when readable).
    let mut stored_weights: Option<Vec<f32>> = None;
    let (mut net, arch, mut record) = match &cfg.resume {
        Some(path) => {
            let loaded = store::load(path, &device)?;
            loaded
                .file
                .check_objects(&set)
                .with_context(|| format!("{} does not fit the object set", path.display()))?;
            let record = loaded.file.train.clone().unwrap_or_default();
            stored_weights = loaded
                .file
                .metadata
                .get(fusepose_estimator::seg::file::KEY_HYPER)
                .and_then(|h| serde_json::from_str::<serde_json::Value>(h).ok())
                .and_then(|h| serde_json::from_value::<Vec<f32>>(h["class_weights"].clone()).ok())
                .filter(|w| w.len() == loaded.file.config.outputs());
            let mut arch = loaded.file.config.clone();
            let mut net = loaded.net;
            // A run that trains (not `--steps 0`, which only re-validates or embeds) adds the head.
            let trains = cfg.steps.is_none_or(|s| s > record.steps);
            if cfg.offsets && !arch.offsets && trains {
                arch.offsets = true;
                net = net.with_offset_head(&arch, &device);
            }
            if cfg.offsets && cfg.offset_branch && !arch.offset_branch && trains {
                arch.offset_branch = true;
                net = net.with_offset_branch(&arch, &device);
            }
            if cfg.contacts && !arch.contacts && trains {
                arch.contacts = true;
                net = net.with_contact_branch(&arch, &device);
            }
            if let Some((enc, dec)) = cfg.widen.filter(|&(e, d)| trains && (e, d) != (arch.enc, arch.dec)) {
                let wide = SegConfig { enc, dec, ..arch.clone() };
                wide.validate().map_err(|m| anyhow::anyhow!("architecture: {m}"))?;
                net = net.widened(&arch, &wide, &device)?;
                log.line(&format!("# widened from {:?} / {:?} to {enc:?} / {dec:?}", arch.enc, arch.dec));
                arch = wide;
            }
            (net, arch, record)
        }
        None if cfg.warm_start.is_some() => {
            let path = cfg.warm_start.as_ref().expect("checked");
            let (mut net, mut arch, w) = warm_start(path, set.len(), cfg.offsets, cfg.offset_branch, &device)?;
            log.line(&w.log_line(path));
            if cfg.contacts && !arch.contacts {
                arch.contacts = true;
                net = net.with_contact_branch(&arch, &device);
            }
            (net, arch, TrainRecord { seed: cfg.seed, ..TrainRecord::default() })
        }
        None => {
            let mut arch = cfg.arch.clone().unwrap_or_else(|| SegConfig::new(set.len()));
            arch.offsets = cfg.offsets;
            arch.offset_branch = cfg.offsets && cfg.offset_branch;
            arch.contacts = cfg.contacts;
            arch.validate().map_err(|m| anyhow::anyhow!("architecture: {m}"))?;
            if arch.num_classes != set.len() {
                bail!("architecture has {} classes, the object set {}", arch.num_classes, set.len());
            }
            (SegNet::new(&arch, &device), arch, TrainRecord { seed: cfg.seed, ..TrainRecord::default() })
        }
    };
    if cfg.freeze_trunk {
        net = net.frozen_trunk(contacts_only);
    }
    record.batch = cfg.batch;
    record.data = "builtin scene sampler, rendered on the fly with sensor noise".into();
    let start_steps = record.steps;
    log.line(&format!(
        "# seg start on {} | batch {} lr {} seed {} | resume {:?} at step {} | params {} | {:.1} MMAC/frame | {} data threads",
        cfg.device,
        cfg.batch,
        cfg.lr,
        cfg.seed,
        cfg.resume,
        start_steps,
        arch.parameter_count(),
        arch.macs() as f64 / 1e6,
        cfg.data_threads.max(1)
    ));

    // Training scenes: far from the pose trainer's and the validation seeds; a resume continues.
    let first_seed = 0x5e90_0000_0000 + (cfg.seed % 1000) * 1_000_000_000 + record.samples + 1;
    let adapt = if cfg.adapt_labels.is_empty() {
        None
    } else {
        let frames = AdaptFrames::load(&cfg.adapt_labels, set.len())?;
        log.line(&format!(
            "# adapting: {} pseudo-labelled frames from {:?}, {:.0} % of the frames",
            frames.len(),
            cfg.adapt_labels,
            100.0 * cfg.adapt_share
        ));
        record.data += &format!(
            "; {:.0} % pseudo-labelled frames ({} from {})",
            100.0 * cfg.adapt_share,
            frames.len(),
            cfg.adapt_labels.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ")
        );
        Some((Arc::new(frames), cfg.adapt_share))
    };
    let mut stream = SegStream::spawn(
        set.clone(),
        arch.clone(),
        cfg.sampler.clone(),
        cfg.cast_augment,
        first_seed,
        4 * cfg.batch,
        cfg.data_threads,
        adapt,
    )?;

    // Class weights from the first frames (those frames are trained on too).
    let mut pending: Vec<SegSample> = Vec::new();
    let mut counts = vec![0u64; arch.outputs()];
    for _ in 0..cfg.weight_frames.max(1) {
        let s = recv(&mut stream)?;
        for &t in &s.target {
            if let Some(c) = counts.get_mut(t as usize) {
                *c += 1;
            }
        }
        pending.push(s);
    }
    let weights =
        stored_weights.unwrap_or_else(|| class_weights(&counts, cfg.class_weight_power, cfg.class_weight_max_ratio));
    log.line(&format!("# pixel counts {counts:?} -> class weights {weights:?}"));
    let hyper = hyper_json(&cfg, &weights);

    let budget = cfg.minutes.map(|m| Duration::from_secs_f64(m * 60.0));
    let bar = if cfg.progress {
        let len = cfg.steps.map(|s| s.saturating_sub(start_steps)).unwrap_or_else(|| budget.map_or(0, |d| d.as_secs()));
        let b = indicatif::ProgressBar::new(len);
        b.set_style(
            indicatif::ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} ETA {eta} {msg}")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        b
    } else {
        indicatif::ProgressBar::hidden()
    };

    let (h0, w0) = (arch.input_height, arch.input_width);
    let b = cfg.batch;
    let mut optim = AdamConfig::new().init();
    let t_start = Instant::now();
    let mut last_ckpt = Instant::now();
    let mut ema = f64::NAN;
    let mut step_time = 0.0f64;
    let mut losses: Vec<f64> = Vec::new();
    let mut curve = Vec::new();
    loop {
        let elapsed = t_start.elapsed();
        let done = record.steps - start_steps;
        let frac = match (budget, cfg.steps) {
            (Some(d), _) if elapsed >= d => break,
            (_, Some(l)) if record.steps >= l => break,
            (Some(d), Some(l)) => {
                (elapsed.as_secs_f64() / d.as_secs_f64()).max(done as f64 / (l - start_steps).max(1) as f64)
            }
            (Some(d), None) => elapsed.as_secs_f64() / d.as_secs_f64(),
            (None, Some(l)) => done as f64 / (l - start_steps).max(1) as f64,
            (None, None) => 1.0,
        };
        let mut batch = Vec::with_capacity(b);
        while batch.len() < b {
            batch.push(match pending.pop() {
                Some(s) => s,
                None => recv(&mut stream)?,
            });
        }
        let t_step = Instant::now();
        let lr = cfg.lr * (0.1 + 0.9 * 0.5 * (1.0 + (std::f64::consts::PI * frac.min(1.0)).cos()));
        let input = Tensor::<4>::from_data(
            TensorData::new(batch.iter().flat_map(|s| s.input.iter().copied()).collect::<Vec<_>>(), [b, 4, h0, w0]),
            &device,
        );
        let target: Vec<u16> = batch.iter().flat_map(|s| s.target.iter().copied()).collect();
        let out = net.forward_outputs(input);
        let (logits, offsets) = (out.logits, out.offsets.filter(|_| !contacts_only));
        let [_, _, h1, w1] = logits.dims();
        let contact_loss = out.contacts.filter(|_| cfg.contacts).map(|pred| {
            let t: Vec<f32> = batch.iter().flat_map(|s| s.contacts.iter().copied()).collect();
            let m: Vec<f32> = target.iter().map(|&c| f32::from(u8::from(c != 0))).collect();
            contact_bce(pred, &t, &m, cfg.contact_positive_weight)
        });
        let offset_loss = offsets.map(|pred| {
            let t: Vec<f32> = batch.iter().flat_map(|s| s.offsets.iter().copied()).collect();
            let m: Vec<f32> = batch.iter().flat_map(|s| s.offset_mask.iter().copied()).collect();
            offset_l1(pred, &t, &m).mul_scalar(cfg.offset_weight)
        });
        // Frozen, the trunk and class head learn nothing: no class loss to compute.
        let class_loss = (!cfg.freeze_trunk).then(|| {
            let scale = (cfg.small_region_boost > 1.0)
                .then(|| small_region_weights(&target, w1, h1, SMALL_REGION_CELLS, cfg.small_region_boost));
            weighted_cross_entropy_scaled(logits, &target, &weights, scale.as_deref())
        });
        let Some(loss) = [class_loss, offset_loss, contact_loss].into_iter().flatten().reduce(|a, b| a + b) else {
            bail!("a frozen trunk leaves only the offset or contact head to train, and there is none");
        };
        let lv = loss.clone().into_data().try_to_vec::<f32>().ok().and_then(|v| v.first().copied()).unwrap_or(f32::NAN)
            as f64;
        if !lv.is_finite() {
            bail!("loss is {lv} at step {}", record.steps);
        }
        let grads = GradientsParams::from_grads(loss.backward(), &net);
        net = optim.step(lr, net, grads);
        record.steps += 1;
        record.samples += b as u64;
        losses.push(lv);
        ema = if ema.is_nan() { lv } else { 0.95 * ema + 0.05 * lv };
        let dt = t_step.elapsed().as_secs_f64();
        step_time = if step_time == 0.0 { dt } else { 0.9 * step_time + 0.1 * dt };
        let msg = format!("loss {ema:.4} | {:.0} ms/step lr {lr:.1e}", step_time * 1000.0);
        bar.set_position(if cfg.steps.is_some() { record.steps - start_steps } else { t_start.elapsed().as_secs() });
        bar.set_message(msg.clone());
        if record.steps % 10 == 0 {
            curve.push((record.steps, ema));
            log.line(&format!(
                "step {} frames {} t {:.0}s | {msg}",
                record.steps,
                record.samples,
                t_start.elapsed().as_secs_f64()
            ));
        }
        if last_ckpt.elapsed() >= cfg.checkpoint_every {
            record.seconds += last_ckpt.elapsed().as_secs_f64();
            last_ckpt = Instant::now();
            let p = cfg.checkpoint_dir.join("seg-checkpoint.safetensors");
            store::save(&net, &arch, &objects, &record, &hyper, &p)?;
            log.line(&format!("# checkpoint {} at step {}", p.display(), record.steps));
        }
    }
    bar.finish_and_clear();
    record.seconds += last_ckpt.elapsed().as_secs_f64();
    drop(stream);

    // Final weights, validation through the engine, then the record with metrics.
    let ckpt = cfg.checkpoint_dir.join("seg-checkpoint.safetensors");
    store::save(&net, &arch, &objects, &record, &hyper, &ckpt)?;
    let mut engine = SegEngine::load(&ckpt, &set).with_context(|| format!("loading {}", ckpt.display()))?;
    let validation = validate::validate(&mut engine, &set, cfg.val_frames)?;
    log.line(&format!("# {}", validation.summary()));
    record.metrics = validation.metrics();
    store::save(&net, &arch, &objects, &record, &hyper, &cfg.out)?;
    store::save(&net, &arch, &objects, &record, &hyper, &ckpt)?;
    log.line(&format!("# wrote {}", cfg.out.display()));
    let mean = |v: &[f64]| if v.is_empty() { f64::NAN } else { v.iter().sum::<f64>() / v.len() as f64 };
    let k = losses.len().min(10);
    Ok(SegTrainReport {
        out: cfg.out.clone(),
        config: arch,
        first_loss: mean(&losses[..k]),
        last_loss: mean(&losses[losses.len() - k..]),
        record,
        validation,
        class_weights: weights,
        loss_curve: curve,
        step_ms: step_time * 1000.0,
    })
}

#[cfg(test)]
mod tests {
    use burn::store::ModuleSnapshot;

    use super::*;

    #[test]
    fn a_frame_slower_than_the_wait_is_waited_for() {
        let set = Arc::new(builtin_objects());
        let sampler = fusepose_scene::sampler::SamplerConfig::training();
        let mut stream = SegStream::spawn(set.clone(), SegConfig::new(set.len()), sampler, 0.0, 1, 2, 1, None).unwrap();
        // A rendered frame takes tens of milliseconds: every wait of 1 ms times out first.
        let s = recv_patiently(&mut stream, Duration::from_millis(1)).unwrap();
        assert!(!s.input.is_empty());
    }

    #[test]
    fn warm_start_copies_the_trunk_and_leaves_the_class_head_fresh() {
        let device = Device::default();
        let eight = SegConfig { offsets: true, ..SegConfig::new(8) };
        let source = SegNet::new(&eight, &device);
        let dir = std::env::temp_dir().join(format!("fusepose-seg-warm-{}", std::process::id()));
        let path = dir.join("seg8.safetensors");
        let objects = object_entries(&builtin_objects());
        store::save(&source, &eight, &objects, &TrainRecord::default(), &serde_json::json!({}), &path).unwrap();

        let (net, arch, w) = warm_start(&path, 3, true, false, &device).unwrap();
        let (copied, fresh) = (w.copied, w.fresh);
        assert_eq!((arch.num_classes, arch.offsets), (3, true));
        assert!(copied > 0 && !fresh.is_empty(), "copied {copied}, fresh {fresh:?}");
        assert!(fresh.iter().all(|n| n.starts_with("head")), "only the class head is class-sized: {fresh:?}");
        let src: std::collections::HashMap<String, Vec<u8>> = source
            .collect(None, None, false)
            .into_iter()
            .map(|t| (t.name.clone(), t.to_bytes().unwrap().to_vec()))
            .collect();
        for t in net.collect(None, None, false) {
            let now = t.to_bytes().unwrap().to_vec();
            if fresh.contains(&t.name) {
                assert_ne!(src.get(&t.name).map(Vec::len), Some(now.len()), "{} is class-sized", t.name);
            } else {
                assert_eq!(Some(&now), src.get(&t.name), "{} copied", t.name);
            }
        }
        let _ = std::fs::remove_dir_all(dir);
    }

    /// A source whose offset head reads the branch (the shipped segmenter's
    /// kind) warm-starts a plain head at zero, as a source without a head
    /// does, and a branch run with its branch and head copied.
    #[test]
    fn warm_start_copies_an_offset_head_only_of_the_same_kind() {
        let device = Device::default();
        let branched = SegConfig { offset_branch: true, ..SegConfig::new(8) };
        let mut source = SegNet::new(&branched, &device);
        source.offset = Some(burn::nn::conv::Conv2dConfig::new([branched.dec[2], 2], [1, 1]).init(&device));
        let dir = std::env::temp_dir().join(format!("fusepose-seg-warm-branch-{}", std::process::id()));
        let path = dir.join("seg8.safetensors");
        let objects = object_entries(&builtin_objects());
        store::save(&source, &branched, &objects, &TrainRecord::default(), &serde_json::json!({}), &path).unwrap();
        let values = |c: &burn::nn::conv::Conv2d| c.weight.val().into_data().try_to_vec::<f32>().unwrap();
        let (plain, arch, _) = warm_start(&path, 3, true, false, &device).unwrap();
        assert!(arch.offsets && !arch.offset_branch && plain.o1.is_none());
        assert!(values(plain.offset.as_ref().unwrap()).iter().all(|&w| w == 0.0), "a fresh head starts at zero");
        let (with, arch, _) = warm_start(&path, 3, true, true, &device).unwrap();
        assert!(arch.offsets && arch.offset_branch);
        assert_eq!(values(with.o1.as_ref().unwrap()), values(source.o1.as_ref().unwrap()));
        assert_eq!(values(with.offset.as_ref().unwrap()), values(source.offset.as_ref().unwrap()));
        let _ = std::fs::remove_dir_all(dir);
    }
}
