//! The fixed test frames: tabletop scenes of the built-in objects with
//! exactly K objects each, rendered once up front (640×480, YCB-Video
//! intrinsics, sensor noise on) with class-id label planes as GT masks.
//!
//! A scene is kept only when the workspace finds K instances in its label
//! plane (no object fully hidden or out of view); seeds are tried in order,
//! so the set is the same on every run.

use fusepose_estimator::{ColorFormat, DepthPlane, FrameView, LabelPlane, Workspace, WorkspaceConfig};
use fusepose_scene::render::{NoiseConfig, RenderTarget};
use fusepose_scene::sampler::{LabelKind, SamplerConfig, render_view_labelled, sample_scene};
use fusepose_scene::{Intrinsics, ObjectSet};

/// Depth unit of [`RenderTarget::depth_u16`]: 0.1 mm.
const DEPTH_SCALE_M: f32 = 1e-4;
/// Seeds tried per frame before keeping the scene with the most instances.
const TRIES: u64 = 40;

/// One rendered frame, owned.
pub struct TestFrame {
    /// Objects placed in the scene (K).
    pub objects: usize,
    /// Instances the workspace finds in the label plane (K unless no seed gave K).
    pub instances: usize,
    pub seed: u64,
    pub intrinsics: Intrinsics,
    pub rgb: Vec<u8>,
    pub depth: Vec<u16>,
    pub labels: Vec<u16>,
}

impl TestFrame {
    /// The frame as the estimator sees it.
    pub fn view(&self) -> FrameView<'_> {
        FrameView {
            intrinsics: self.intrinsics,
            color_format: ColorFormat::Rgb8,
            color: &self.rgb,
            depth: DepthPlane::U16 { data: &self.depth, scale: DEPTH_SCALE_M },
            labels: Some(LabelPlane::U16(&self.labels)),
        }
    }
}

/// Renders `count` frames with exactly `k` objects of `set` each.
pub fn render_frames(set: &ObjectSet, k: usize, count: usize) -> anyhow::Result<Vec<TestFrame>> {
    let intrinsics = Intrinsics::YCB_VIDEO;
    let cfg = SamplerConfig { min_objects: k, max_objects: k, ..SamplerConfig::default() };
    let noise = NoiseConfig::default();
    let mut target = RenderTarget::for_intrinsics(&intrinsics);
    let mut ws = Workspace::new(WorkspaceConfig {
        max_instances: k.max(1),
        num_classes: set.len() as u16,
        ..WorkspaceConfig::default()
    })
    .map_err(|e| anyhow::anyhow!("{e}"))?;
    let mut frames = Vec::with_capacity(count);
    let mut seed = 1000 * k as u64;
    for _ in 0..count {
        let mut best: Option<TestFrame> = None;
        for _ in 0..TRIES {
            seed += 1;
            let Ok(scene) = sample_scene(set, &cfg, seed) else { continue };
            render_view_labelled(&scene, set, 0, &intrinsics, &noise, LabelKind::Class, &mut target)?;
            let frame = TestFrame {
                objects: k,
                instances: 0,
                seed,
                intrinsics,
                rgb: target.rgb().to_vec(),
                depth: target.depth_u16().to_vec(),
                labels: target.labels().to_vec(),
            };
            let found = ws.prepare(&frame.view(), 0).unwrap_or(0);
            if best.as_ref().is_none_or(|b| found > b.instances) {
                best = Some(TestFrame { instances: found, ..frame });
            }
            if found >= k {
                break;
            }
        }
        frames.extend(best);
    }
    anyhow::ensure!(!frames.is_empty(), "no scene with {k} objects could be rendered");
    Ok(frames)
}
