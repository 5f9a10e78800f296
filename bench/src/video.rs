//! Rendered video sequences: one tabletop scene with K objects, the camera
//! orbiting it smoothly (constant height and distance, a fixed angle per
//! frame, looking at the objects), sensor noise on, class-id label planes and
//! the ground-truth object → camera poses of every frame.
//!
//! Used by `e2e` (the producer replays it ping-pong, so the motion never
//! jumps) and by `tracking` (accuracy against the truth).

use fusepose_estimator::{ColorFormat, DepthPlane, FrameView, LabelPlane};
use fusepose_scene::render::{NoiseConfig, RenderTarget};
use fusepose_scene::sampler::viewpoint::look_at;
use fusepose_scene::sampler::{CameraView, LabelKind, SamplerConfig, render_view_labelled, sample_scene};
use fusepose_scene::{Intrinsics, ObjectSet, Pose};
use nalgebra::{Point3, Vector3};

/// Depth unit of [`RenderTarget::depth_u16`]: 0.1 mm.
pub const DEPTH_SCALE_M: f32 = 1e-4;

/// One rendered frame with its truth.
pub struct VideoFrame {
    pub rgb: Vec<u8>,
    pub depth: Vec<u16>,
    pub labels: Vec<u16>,
    /// (class id, object → camera pose) of every object in the scene.
    pub truth: Vec<(u16, Pose)>,
    /// Each truth's visible fraction in this frame (same order).
    pub visible: Vec<f64>,
}

impl VideoFrame {
    pub fn view(&self, intrinsics: Intrinsics) -> FrameView<'_> {
        FrameView {
            intrinsics,
            color_format: ColorFormat::Rgb8,
            color: &self.rgb,
            depth: DepthPlane::U16 { data: &self.depth, scale: DEPTH_SCALE_M },
            labels: Some(LabelPlane::U16(&self.labels)),
        }
    }
}

/// A rendered sequence.
pub struct Video {
    pub intrinsics: Intrinsics,
    pub frames: Vec<VideoFrame>,
    /// Camera motion per frame, degrees about the look-at point.
    pub degrees_per_frame: f64,
}

/// Renders `frames` frames of a `objects`-object scene drawn from `seed`,
/// the camera turning `degrees_per_frame` about the objects per frame.
pub fn render_video(
    set: &ObjectSet,
    objects: usize,
    frames: usize,
    degrees_per_frame: f64,
    seed: u64,
) -> anyhow::Result<Video> {
    render_video_with(set, objects, Copies::None, frames, degrees_per_frame, seed)
}

/// Several copies of one class in a video's scene ([`render_video_with`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Copies {
    /// One object per class.
    #[default]
    None,
    /// One of the drawn classes stands twice, the copies side by side and
    /// touching (0–3 mm apart).
    Pair,
    /// One of the drawn classes as a heap of 4–8 copies touching and lying
    /// on each other (the sampler's heap).
    Heap,
}

impl Copies {
    /// The producer argument's suffix (`5:pair`, `5:heap`).
    pub fn suffix(self) -> &'static str {
        match self {
            Self::None => "",
            Self::Pair => ":pair",
            Self::Heap => ":heap",
        }
    }

    /// `OBJECTS[:pair|:heap]` → (objects, copies).
    pub fn parse_arg(arg: &str) -> anyhow::Result<(usize, Self)> {
        let (n, copies) = match arg.split_once(':') {
            Some((n, "pair")) => (n, Self::Pair),
            Some((n, "heap")) => (n, Self::Heap),
            Some((_, other)) => anyhow::bail!("{arg:?}: expected OBJECTS, OBJECTS:pair or OBJECTS:heap, not {other:?}"),
            None => (arg, Self::None),
        };
        Ok((n.parse()?, copies))
    }
}

/// As [`render_video`], with `copies` of one drawn class.
pub fn render_video_with(
    set: &ObjectSet,
    objects: usize,
    copies: Copies,
    frames: usize,
    degrees_per_frame: f64,
    seed: u64,
) -> anyhow::Result<Video> {
    let intrinsics = Intrinsics::YCB_VIDEO;
    let cfg = SamplerConfig {
        pair_probability: if copies == Copies::Pair { 1.0 } else { 0.0 },
        heap_probability: if copies == Copies::Heap { 1.0 } else { 0.0 },
        min_objects: objects,
        max_objects: objects,
        camera_distance_m: (0.7, 0.9),
        camera_elevation_deg: (35.0, 50.0),
        ..SamplerConfig::default()
    };
    let mut scene = sample_scene(set, &cfg, seed).map_err(|e| anyhow::anyhow!("scene {seed}: {e}"))?;
    let centroid = scene.objects.iter().fold(Vector3::zeros(), |a, o| a + o.table_from_object.translation.vector)
        / scene.objects.len().max(1) as f64;
    let target = Point3::from(centroid + Vector3::new(0.0, 0.0, 0.05));
    let eye = Point3::from(scene.views[0].camera_from_table.inverse().translation.vector);
    let offset = eye - target;
    let (radius, height) = (offset.xy().norm(), offset.z);
    let start = offset.y.atan2(offset.x);
    scene.views = (0..frames)
        .map(|i| {
            let a = start + (i as f64 * degrees_per_frame).to_radians();
            let eye = target + Vector3::new(radius * a.cos(), radius * a.sin(), height);
            let camera_from_table = look_at(eye, target, 0.0).ok_or_else(|| anyhow::anyhow!("degenerate camera"))?;
            Ok(CameraView { camera_from_table, occlusion_target_met: true })
        })
        .collect::<anyhow::Result<_>>()?;
    let noise = NoiseConfig::default();
    let mut render_target = RenderTarget::for_intrinsics(&intrinsics);
    let mut out = Vec::with_capacity(frames);
    for view in 0..frames {
        let truth = render_view_labelled(&scene, set, view, &intrinsics, &noise, LabelKind::Class, &mut render_target)?;
        out.push(VideoFrame {
            rgb: render_target.rgb().to_vec(),
            depth: render_target.depth_u16().to_vec(),
            labels: render_target.labels().to_vec(),
            truth: truth.objects.iter().map(|o| (o.class_id, o.pose)).collect(),
            visible: truth.objects.iter().map(|o| o.visible_fraction).collect(),
        });
    }
    Ok(Video { intrinsics, frames: out, degrees_per_frame })
}

/// Frame index of step `i` when playing `len` frames back and forth (0, 1, …, len−1, len−2, …, 1, 0, …).
pub fn ping_pong(i: usize, len: usize) -> usize {
    if len <= 1 {
        return 0;
    }
    let period = 2 * (len - 1);
    let j = i % period;
    if j < len { j } else { period - j }
}

#[cfg(test)]
mod tests {
    #[test]
    fn ping_pong_never_jumps() {
        let seq: Vec<usize> = (0..9).map(|i| super::ping_pong(i, 4)).collect();
        assert_eq!(seq, [0, 1, 2, 3, 2, 1, 0, 1, 2]);
        assert_eq!(super::ping_pong(5, 1), 0);
    }
}
