//! Helpers shared by the train crate's integration tests.

use std::path::Path;

use fusepose_scene::bop::{BopWriter, FrameToWrite, InstanceToWrite, ObjectSource};
use fusepose_scene::render::{DEPTH_U16_PER_METRE, NoiseConfig, RenderTarget};
use fusepose_scene::sampler::{LabelKind, SamplerConfig, render_view_labelled, sample_scene};
use fusepose_scene::{Intrinsics, ObjectSet};

/// Writes `frames` rendered default scenes (sampler seeds `first_seed..`, the
/// YCB-Video camera) as scene 0 of BOP split `split` under `root`.
pub fn write_rendered_split(root: &Path, split: &str, set: &ObjectSet, frames: u32, first_seed: u64) {
    let mut writer = BopWriter::create(root, split, set, &ObjectSource::Builtin).unwrap();
    let k = Intrinsics::YCB_VIDEO;
    let mut target = RenderTarget::for_intrinsics(&k);
    for im in 0..frames {
        let scene = sample_scene(set, &SamplerConfig::default(), first_seed + im as u64).unwrap();
        let truth = render_view_labelled(&scene, set, 0, &k, &NoiseConfig::default(), LabelKind::Instance, &mut target)
            .unwrap();
        let instances = InstanceToWrite::of_truth(&truth);
        writer
            .write_frame(&FrameToWrite {
                scene_id: 0,
                im_id: im,
                intrinsics: k,
                rgb: target.rgb(),
                depth: target.depth_u16(),
                depth_unit_m: 1.0 / DEPTH_U16_PER_METRE,
                instance_labels: target.labels(),
                instances: &instances,
            })
            .unwrap();
    }
}
