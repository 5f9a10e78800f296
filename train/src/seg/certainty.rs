//! How sure a segmenter is of real objects, measured once after training so
//! that the daemon's segmenter-certainty verification term
//! (`VerifyConfig::min_region_probability`) can be set per model: a
//! segmenter trained for 14 minutes is rarely 80 % sure of anything, the
//! shipped one nearly always is (docs/BENCHMARKS.md, session 19).
//!
//! The measure is the one the verifier judges: the peak softmax probability
//! of an object's class over the segmenter cells under its region
//! (`SegEngine::region_probability`), here over the TRUE region of every
//! object at least [`MIN_PIXELS`] pixels large in frames rendered from the
//! segmenter's validation seeds ([`super::validate::SEG_VAL_SEED_BASE`],
//! never a training, tuning or test seed) with the sampler the caller gives
//! (`fusepose train --stage calibrate`: the randomised training sampler by
//! default, whatever the segmenter trained on). The percentiles of those
//! peaks are stored in the weight file (`fusepose_estimator::seg::file::Certainty`).
//!
//! Randomised frames are the measure because a segmenter is surest on the
//! frames it trained on: on plain frames the shipped segmenter's 5 % is
//! 0.984 against 0.765 on randomised ones, and that floor refused true
//! objects of path-traced frames with their ghosts (−2.35 ADD(S) on
//! `pt_tune12`; docs/BENCHMARKS.md, session 50).

use fusepose_estimator::seg::SegEngine;
use fusepose_estimator::seg::file::Certainty;
use fusepose_estimator::{FrameView, LabelPlane, Workspace, WorkspaceConfig};
use fusepose_scene::ObjectSet;
use fusepose_scene::render::RenderTarget;
use fusepose_scene::sampler::{LabelKind, SamplerConfig};

use super::data::{frame_view, render_camera, render_with};
use super::validate::SEG_VAL_SEED_BASE;

/// Smallest true region measured, in pixels of the rendered frame.
pub const MIN_PIXELS: usize = 100;

/// Offset into the segmenter validation seeds, past the frames
/// [`super::validate::validate`] scores, so the two never share a scene.
const SEED_OFFSET: u64 = 1 << 20;

/// Renders `frames` scenes with `sampler`, segments each with `engine` and
/// returns the percentiles of its peak certainty over the true object regions.
pub fn calibrate(
    engine: &mut SegEngine,
    set: &ObjectSet,
    sampler: &SamplerConfig,
    frames: usize,
) -> anyhow::Result<Certainty> {
    let k = render_camera(sampler);
    let mut target = RenderTarget::for_intrinsics(&k);
    let mut pred = vec![0u16; k.width as usize * k.height as usize];
    let mut ws = Workspace::new(WorkspaceConfig {
        num_classes: set.len() as u16,
        max_instances: 64,
        min_pixels: MIN_PIXELS,
        ..WorkspaceConfig::default()
    })?;
    let mut peaks = Vec::new();
    let (mut done, mut seed) = (0, SEG_VAL_SEED_BASE + SEED_OFFSET);
    while done < frames && seed < SEG_VAL_SEED_BASE + SEED_OFFSET + 4 * frames as u64 + 16 {
        seed += 1;
        let Some((k, lut)) = render_with(set, sampler, seed - 1, LabelKind::Instance, &mut target)? else { continue };
        engine.segment(&frame_view(k, &target), &mut pred)?;
        let truth = FrameView {
            labels: Some(LabelPlane::Instances { ids: target.labels(), classes: &lut }),
            ..frame_view(k, &target)
        };
        let n = ws.prepare(&truth, seed)?;
        for i in 0..n {
            let inst = ws.instances[i];
            let Some(id) = ws.component_id(i) else { continue };
            let p = engine.region_probability(ws.component_ids(), id, inst.class_id, inst.bbox);
            if p.is_finite() {
                peaks.push(p);
            }
        }
        done += 1;
    }
    anyhow::ensure!(!peaks.is_empty(), "no object region in {done} calibration frames");
    Ok(Certainty::from_peaks(&mut peaks, done, &sampler_summary(sampler)))
}

/// What the calibration frames were, for the file's record.
fn sampler_summary(s: &SamplerConfig) -> String {
    let k = render_camera(s);
    format!(
        "segmenter validation seeds from {:#x}, randomize {:?}, depth sensor {:?}, {}x{} camera",
        SEG_VAL_SEED_BASE + SEED_OFFSET,
        s.randomize,
        s.depth_sensor,
        k.width,
        k.height
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The record in the shipped file is what this code measures: `fusepose
    /// train --stage calibrate` with its defaults (400 frames drawn by the
    /// training sampler), reproduced exactly (rendering is seeded).
    #[test]
    fn the_shipped_record_is_what_calibration_measures() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/builtin.safetensors");
        let set = fusepose_scene::builtin::builtin_objects();
        let recorded = fusepose_estimator::seg::SegFile::read(&path).unwrap().certainty.expect("a record");
        let mut engine = SegEngine::load(&path, &set).unwrap();
        let measured = calibrate(&mut engine, &set, &SamplerConfig::training(), recorded.frames).unwrap();
        assert_eq!(measured, recorded);
        // Sure of most real objects, far less of its least visible ones.
        assert!(measured.quantile(0.5).unwrap() > 0.99 && measured.quantile(0.01).unwrap() < 0.5, "{measured:?}");
    }
}
