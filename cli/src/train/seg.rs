//! `fusepose train --stage seg`: trains the built-in instance segmenter
//! (`fusepose_train::seg`), validates it on held-out rendered scenes (mIoU,
//! per-class IoU) and writes it: embedded into `--out` when that is a
//! pose-network file for the same objects, else as a segmenter-only file.
//! With `--validate-only` it scores `--resume`; with `--bench-engine` it times
//! the inference engine per frame.

use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use fusepose_estimator::net::WeightFile;
use fusepose_estimator::seg::{Boundary, SegConfig, SegEngine, SegFile, file};
use fusepose_scene::ObjectSet;
use fusepose_train::seg::{SegTrainConfig, SegValidation, certainty, train_segmenter, validate};

use super::Args;

/// Parses `WxH` (e.g. `160x120`).
fn parse_size(s: &str) -> anyhow::Result<(usize, usize)> {
    let (w, h) = s.split_once(['x', 'X']).with_context(|| format!("--seg-size `{s}`: expected WxH"))?;
    Ok((w.trim().parse().context("--seg-size width")?, h.trim().parse().context("--seg-size height")?))
}

/// Parses `E1,E2,E3,E4/D3,D2,D1` (e.g. `24,48,96,96/48,24,24`).
fn parse_widths(s: &str) -> anyhow::Result<([usize; 4], [usize; 3])> {
    let bad =
        || anyhow::anyhow!("--seg-widths `{s}`: expected four encoder and three decoder widths, E1,E2,E3,E4/D3,D2,D1");
    let (e, d) = s.split_once('/').ok_or_else(bad)?;
    let list = |part: &str| -> anyhow::Result<Vec<usize>> {
        part.split(',').map(|w| w.trim().parse::<usize>().map_err(|_| bad())).collect()
    };
    let (e, d) = (list(e)?, list(d)?);
    Ok((e.try_into().map_err(|_| bad())?, d.try_into().map_err(|_| bad())?))
}

fn print_validation(v: &SegValidation) {
    println!(
        "segmentation, {} held-out frames: mIoU {:.3}, background IoU {:.3}, pixel accuracy {:.3}, engine {:.2} ms/frame (median)",
        v.frames, v.miou, v.background_iou, v.pixel_accuracy, v.engine_ms
    );
    for (name, iou) in &v.class_iou {
        match iou {
            Some(x) => println!("  {name:<24} IoU {x:.3}"),
            None => println!("  {name:<24} IoU -  (neither present nor predicted)"),
        }
    }
}

/// Whether `path` is an existing pose-network file (then the segmenter is embedded into it).
fn is_pose_file(path: &Path) -> bool {
    path.exists() && WeightFile::read(path).is_ok()
}

/// Writes the segmenter file `seg_path` into the pose-network file `pose_path` (objects must match).
pub fn embed_into(seg_path: &Path, pose_path: &Path) -> anyhow::Result<()> {
    let seg = SegFile::read(seg_path).with_context(|| format!("reading {}", seg_path.display()))?;
    let pose = std::fs::read(pose_path).with_context(|| format!("reading {}", pose_path.display()))?;
    let bytes = file::embed(&pose, &seg).with_context(|| {
        format!("the segmenter {} does not fit the network file {}", seg_path.display(), pose_path.display())
    })?;
    let tmp = pose_path.with_extension("safetensors.tmp");
    std::fs::write(&tmp, bytes).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, pose_path).with_context(|| format!("renaming to {}", pose_path.display()))?;
    Ok(())
}

/// Frames the segmenter's certainty is measured on (about 2 400 object
/// regions, 10-25 s on two cores).
pub const CALIBRATION_FRAMES: usize = 400;

/// Measures how sure the segmenter in `path` (either layout) is of real
/// objects on [`CALIBRATION_FRAMES`] rendered frames drawn like its training
/// data (`fusepose_train::seg::certainty`) and stores the result in the file.
pub fn calibrate_file(set: &ObjectSet, args: &Args, path: &Path) -> anyhow::Result<file::Certainty> {
    let mut engine =
        SegEngine::load(path, set).with_context(|| format!("loading the segmenter in {}", path.display()))?;
    let t = Instant::now();
    let sampler = super::training_sampler(args);
    if !sampler.randomize.is_on() {
        println!(
            "note: measuring the segmenter's certainty on plain frames (--randomize off), where it is surest; the \
             floor this sets refuses true objects on a camera's images (the shipped segmenter: 5 % at 0.984 on plain \
             frames, 0.765 on randomised ones; docs/TRAINING.md). Calibrate without --randomize off unless you mean it."
        );
    }
    let c = certainty::calibrate(&mut engine, set, &sampler, CALIBRATION_FRAMES)?;
    file::store_certainty(path, &c).with_context(|| format!("writing the calibration into {}", path.display()))?;
    let q = |p: f32| c.quantile(p).unwrap_or(f32::NAN);
    println!(
        "segmenter certainty of real objects, {} regions in {} frames ({:.0} s): peak probability percentiles \
         1 % {:.3}, 2 % {:.3}, 5 % {:.3}, 10 % {:.3}, 25 % {:.3}, median {:.3}; stored in {}",
        c.regions,
        c.frames,
        t.elapsed().as_secs_f64(),
        q(0.01),
        q(0.02),
        q(0.05),
        q(0.10),
        q(0.25),
        q(0.5),
        path.display()
    );
    Ok(c)
}

pub fn run(set: ObjectSet, args: &Args) -> anyhow::Result<()> {
    if args.dataset.is_some() {
        bail!(
            "--stage seg trains on rendered scenes, and with --adapt-labels on pseudo-labelled frames; --dataset is not \
             supported"
        );
    }
    if args.bench_engine {
        return bench(&set, args.resume.as_deref());
    }
    if args.validate_only {
        let path = args.resume.as_ref().context("--validate-only needs --resume FILE")?;
        let mut engine = SegEngine::load(path, &set).with_context(|| format!("loading {}", path.display()))?;
        print_validation(&validate::validate(&mut engine, &set, args.val_frames)?);
        return Ok(());
    }
    let widths = args.seg_widths.as_deref().map(parse_widths).transpose()?;
    let arch = match (&args.seg_size, widths) {
        (None, None) => None,
        (size, widths) => {
            let mut c = SegConfig::new(set.len());
            if let Some(s) = size {
                (c.input_width, c.input_height) = parse_size(s)?;
            }
            if let Some((enc, dec)) = widths {
                (c.enc, c.dec) = (enc, dec);
            }
            c.validate().map_err(|m| anyhow::anyhow!("--seg-size / --seg-widths: {m}"))?;
            Some(c)
        }
    };
    let embed = is_pose_file(&args.out);
    if !embed && args.out.exists() && SegFile::read(&args.out).is_err() {
        bail!(
            "{} exists and is neither a fusepose network nor a segmenter file; not overwriting it",
            args.out.display()
        );
    }
    // When embedding, the trainer writes a segmenter-only file beside the checkpoints first.
    let seg_out = if embed { args.checkpoint_dir.join("seg.safetensors") } else { args.out.clone() };
    let cfg = SegTrainConfig {
        objects: Arc::new(set),
        out: seg_out.clone(),
        minutes: args.minutes,
        steps: args.steps,
        resume: args.resume.clone(),
        warm_start: args.warm_start.clone(),
        arch,
        batch: args.batch,
        lr: args.lr,
        seed: args.seed,
        checkpoint_dir: args.checkpoint_dir.clone(),
        checkpoint_every: Duration::from_secs_f64(args.checkpoint_minutes * 60.0),
        val_frames: args.val_frames,
        log: args.log.clone(),
        progress: !args.quiet,
        sampler: super::training_sampler(args),
        small_region_boost: args.seg_small_boost,
        cast_augment: args.seg_cast,
        data_threads: args.seg_data_threads.map_or_else(fusepose_train::seeded_workers::default_threads, usize::from),
        offsets: args.seg_offsets,
        offset_weight: args.seg_offset_weight,
        offset_branch: args.seg_offset_branch,
        freeze_trunk: args.seg_freeze_trunk,
        contacts: args.seg_contacts,
        widen: widths,
        device: args.device,
        adapt_labels: args.adapt_labels.clone(),
        adapt_share: args.adapt_share,
        ..SegTrainConfig::default()
    };
    let report = train_segmenter(cfg)?;
    // A run with no steps of its own (e.g. `--steps 0` on a resumed file) has no loss to show.
    let loss = if report.first_loss.is_finite() {
        format!("; loss {:.3} -> {:.3}", report.first_loss, report.last_loss)
    } else {
        String::new()
    };
    println!(
        "segmenter: {} steps in all ({} frames, {:.0} s, {:.0} ms/step{loss}) -> {}",
        report.record.steps,
        report.record.samples,
        report.record.seconds,
        report.step_ms,
        seg_out.display()
    );
    print_validation(&report.validation);
    if embed {
        embed_into(&seg_out, &args.out)?;
        println!("embedded into {}", args.out.display());
    }
    Ok(())
}

/// `--bench-engine`: segmentation time per 640x480 frame (median and p99 of 200).
fn bench(set: &ObjectSet, weights: Option<&Path>) -> anyhow::Result<()> {
    let path = weights.context("--bench-engine with --stage seg needs --resume FILE")?;
    let mut engine = SegEngine::load(path, set).with_context(|| format!("loading {}", path.display()))?;
    let c = engine.config().clone();
    println!(
        "segmenter: {}x{} input, {} parameters, {:.1} MMAC per frame",
        c.input_width,
        c.input_height,
        c.parameter_count(),
        c.macs() as f64 / 1e6
    );
    let k = fusepose_scene::Intrinsics::YCB_VIDEO;
    let mut target = fusepose_scene::render::RenderTarget::for_intrinsics(&k);
    let mut seed = fusepose_train::seg::validate::SEG_VAL_SEED_BASE;
    let k = loop {
        if let Some(k) = fusepose_train::seg::data::render_frame(set, seed, &mut target)? {
            break k;
        }
        seed += 1;
    };
    let frame = fusepose_train::seg::data::frame_view(k, &target);
    let mut labels = vec![0u16; k.width as usize * k.height as usize];
    let default = engine.boundary();
    let modes = [Boundary::Cells, Boundary::ErodeCells, Boundary::Refine { erode_px: 3 }];
    for mode in std::iter::once(default).chain(modes.into_iter().filter(|m| *m != default)) {
        engine.set_boundary(mode);
        for _ in 0..5 {
            engine.segment(&frame, &mut labels)?;
        }
        let mut times: Vec<f64> = (0..200)
            .map(|_| {
                let t = Instant::now();
                engine.segment(&frame, &mut labels).map(|()| t.elapsed().as_secs_f64() * 1e3)
            })
            .collect::<Result<_, _>>()?;
        times.sort_by(f64::total_cmp);
        let tag = if mode == default { " (default)" } else { "" };
        println!(
            "segment {}x{}, boundary {mode}{tag}: median {:.2} ms, p99 {:.2} ms, max {:.2} ms (200 frames, one thread)",
            k.width, k.height, times[100], times[197], times[199]
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn widths_parse_as_encoder_then_decoder() {
        assert_eq!(parse_widths("24,48,96,96/48,24,24").unwrap(), ([24, 48, 96, 96], [48, 24, 24]));
        for bad in ["24,48,96,96", "24,48,96/48,24,24", "24,48,96,96/48,24", "a,48,96,96/48,24,24"] {
            let e = parse_widths(bad).unwrap_err().to_string();
            assert!(e.contains("--seg-widths") && e.contains("E1,E2,E3,E4/D3,D2,D1"), "{bad}: {e}");
        }
    }
}
