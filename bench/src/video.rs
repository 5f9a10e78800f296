//! Video sequences with their truth: class-id label planes and the
//! ground-truth object → camera poses of every frame.
//!
//! - Rendered ([`render_video_with`]): one tabletop scene with K objects, the
//!   camera orbiting it smoothly (constant height and distance, a fixed angle
//!   per frame, looking at the objects), sensor noise on; played back and
//!   forth, so the motion never jumps.
//! - Loaded from a BOP split ([`load_bop_video`]), such as the path-traced
//!   splits of `tools/blender/render_bop_split.py`: images fusepose did not
//!   render, each frame held for several steps (a still camera on each
//!   scene in turn), then the next.
//!
//! Used by `e2e` (the producer replays it; its consumer scores against the
//! same video, [`Source`]) and by `tracking` (accuracy against the truth).

use std::path::{Path, PathBuf};

use fusepose_estimator::{ColorFormat, DepthPlane, FrameView, LabelPlane};
use fusepose_scene::bop::BopDataset;
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

/// A sequence of frames and how steps map onto them.
pub struct Video {
    pub intrinsics: Intrinsics,
    pub frames: Vec<VideoFrame>,
    /// Camera motion per frame, degrees about the look-at point (0 for a loaded split).
    pub degrees_per_frame: f64,
    pub playback: Playback,
}

/// How a producer's step (the frame sequence number) picks a video frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Playback {
    /// 0, 1, …, n−1, n−2, …, 1, 0, … ([`ping_pong`]).
    PingPong,
    /// Each frame for this many steps in a row, then the next, looping.
    Hold(usize),
}

impl Video {
    /// The frame shown at step `step`.
    pub fn frame_at(&self, step: usize) -> &VideoFrame {
        let n = self.frames.len();
        let i = match self.playback {
            Playback::PingPong => ping_pong(step, n),
            Playback::Hold(hold) => (step / hold.max(1)) % n.max(1),
        };
        &self.frames[i]
    }
}

/// Where a producer's video comes from, written as one command-line word for
/// the producer and consumer processes: `N`, `N:pair` or `N:heap` (a rendered
/// scene of N classes; seed and frame count are their own arguments), or
/// `bop:HOLD:DIR` (the `test` split of the BOP dataset at DIR, each frame
/// held HOLD steps).
#[derive(Clone, Debug, PartialEq)]
pub enum Source {
    Rendered { objects: usize, copies: Copies },
    Bop { root: PathBuf, hold: usize },
}

impl Source {
    /// Parses the command-line word (see the type's doc).
    pub fn parse_arg(arg: &str) -> anyhow::Result<Self> {
        if let Some(rest) = arg.strip_prefix("bop:") {
            let (hold, dir) = rest
                .split_once(':')
                .ok_or_else(|| anyhow::anyhow!("{arg:?}: expected bop:HOLD:DIR (HOLD steps per frame)"))?;
            let hold: usize = hold.parse().map_err(|e| anyhow::anyhow!("{arg:?}: HOLD {hold:?}: {e}"))?;
            anyhow::ensure!(hold >= 1, "{arg:?}: HOLD must be at least 1 step per frame");
            return Ok(Self::Bop { root: dir.into(), hold });
        }
        let (objects, copies) = Copies::parse_arg(arg)?;
        Ok(Self::Rendered { objects, copies })
    }

    /// What the producer sends, for the benchmark's header.
    pub fn describe(&self) -> String {
        match self {
            Self::Rendered { objects, copies } => {
                let copies = match copies {
                    Copies::None => "",
                    Copies::Pair => ", one class twice",
                    Copies::Heap => ", one class as a heap",
                };
                format!("{objects} objects{copies}, rendered video")
            }
            Self::Bop { root, hold } => format!("BOP split {}/test, each image held {hold} frames", root.display()),
        }
    }

    /// The command-line word for this source.
    pub fn arg(&self) -> String {
        match self {
            Self::Rendered { objects, copies } => format!("{objects}{}", copies.suffix()),
            Self::Bop { root, hold } => format!("bop:{hold}:{}", root.display()),
        }
    }

    /// The video: rendered from `seed` with `frames` frames, or loaded.
    pub fn load(&self, set: &ObjectSet, seed: u64, frames: usize) -> anyhow::Result<Video> {
        match self {
            Self::Rendered { objects, copies } => render_video_with(set, *objects, *copies, frames, 0.5, seed),
            Self::Bop { root, hold } => load_bop_video(root, *hold, set),
        }
    }
}

/// The `test` split of the BOP dataset at `root` as a video, each frame held
/// `hold` steps. Depth is converted to [`DEPTH_SCALE_M`] units, labels are
/// class ids from the visible masks (`obj_id` = class id of `set`, as
/// `fusepose render` and the Blender script write them), visibility is BOP's
/// `visib_fract`. One camera sends it, so every frame must have the first
/// one's intrinsics and size.
pub fn load_bop_video(root: &Path, hold: usize, set: &ObjectSet) -> anyhow::Result<Video> {
    anyhow::ensure!(hold >= 1, "hold must be at least 1 step per frame");
    let ds = BopDataset::open_split(root, "test")
        .map_err(|e| anyhow::anyhow!("{}: not a BOP dataset with a test split: {e}", root.display()))?;
    anyhow::ensure!(!ds.is_empty(), "{}: the test split has no frames", root.display());
    let mut intrinsics = None;
    let mut frames = Vec::with_capacity(ds.len());
    for (i, f) in ds.iter().enumerate() {
        let f = f.map_err(|e| anyhow::anyhow!("{}: frame {i}: {e}", root.display()))?;
        let k = *intrinsics.get_or_insert(f.intrinsics);
        anyhow::ensure!(
            f.intrinsics == k,
            "{}: scene {} image {} has other intrinsics than the first frame ({:?} against {k:?}); \
             one producer sends one camera",
            root.display(),
            f.id.scene_id,
            f.id.im_id,
            f.intrinsics
        );
        if let Some(g) = f.gt.iter().find(|g| set.by_class(g.obj_id).is_none()) {
            anyhow::bail!(
                "{}: scene {} image {}: obj_id {} is not a class of the object set ({} classes)",
                root.display(),
                f.id.scene_id,
                f.id.im_id,
                g.obj_id,
                set.objects.len()
            );
        }
        let to_units = f.depth_unit_m / DEPTH_SCALE_M as f64;
        let depth = f.depth.iter().map(|&d| (d as f64 * to_units).round().min(u16::MAX as f64) as u16).collect();
        frames.push(VideoFrame {
            rgb: f.rgb,
            depth,
            labels: f.labels,
            truth: f.gt.iter().map(|g| (g.obj_id, g.pose)).collect(),
            visible: f.gt.iter().map(|g| g.visib_fract).collect(),
        });
    }
    let intrinsics = intrinsics.expect("a non-empty split has a first frame");
    Ok(Video { intrinsics, frames, degrees_per_frame: 0.0, playback: Playback::Hold(hold) })
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
    Ok(Video { intrinsics, frames: out, degrees_per_frame, playback: Playback::PingPong })
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

/// Writes a small BOP `test` split under `root`: `views` views of one
/// rendered three-object scene of the built-in objects, as `fusepose render`
/// writes one (for tests and the smoke benchmark of `e2e --source`); returns
/// each view's depth (0.1 mm units) and true class ids.
pub fn write_test_split(root: &Path, views: usize) -> anyhow::Result<Vec<(Vec<u16>, Vec<u16>)>> {
    use fusepose_scene::bop::{BopWriter, FrameToWrite, InstanceToWrite, ObjectSource};
    use fusepose_scene::sampler::render_view;
    let set = fusepose_scene::builtin::builtin_objects();
    let k = Intrinsics::YCB_VIDEO;
    let cfg = SamplerConfig { min_objects: 3, max_objects: 3, views, ..SamplerConfig::default() };
    let scene = sample_scene(&set, &cfg, 5).map_err(|e| anyhow::anyhow!("scene: {e}"))?;
    let mut writer = BopWriter::create(root, "test", &set, &ObjectSource::Builtin)?;
    let mut target = RenderTarget::for_intrinsics(&k);
    let mut written = Vec::new();
    for view in 0..views {
        let truth = render_view(&scene, &set, view, &k, &NoiseConfig::default(), &mut target)?;
        let instances = InstanceToWrite::of_truth(&truth);
        writer.write_frame(&FrameToWrite::rendered(0, view as u32, &truth, &target, &instances))?;
        written.push((target.depth_u16().to_vec(), truth.objects.iter().map(|o| o.class_id).collect()));
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A two-image split replayed with each image held three steps: the
    /// frames, depth in the video's units, class labels and truths are the
    /// split's, and bad source words and folders are refused by name.
    #[test]
    fn a_bop_split_plays_each_image_held_with_its_truth() {
        let root = std::env::temp_dir().join(format!("fusepose-bench-bop-video-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let written = write_test_split(&root, 2).unwrap();
        let set = fusepose_scene::builtin::builtin_objects();
        let source = Source::parse_arg(&format!("bop:3:{}", root.display())).unwrap();
        assert_eq!(source, Source::Bop { root: root.clone(), hold: 3 });
        assert_eq!(Source::parse_arg(&source.arg()).unwrap(), source);
        let video = source.load(&set, 0, 0).unwrap();
        assert_eq!(video.frames.len(), 2);
        assert_eq!(video.intrinsics, Intrinsics::YCB_VIDEO);
        for (step, shown) in [(0, 0), (2, 0), (3, 1), (5, 1), (6, 0)] {
            assert!(std::ptr::eq(video.frame_at(step), &video.frames[shown]), "step {step}");
        }
        for (f, (depth, classes)) in video.frames.iter().zip(&written) {
            assert_eq!(&f.depth, depth);
            assert_eq!(&f.truth.iter().map(|t| t.0).collect::<Vec<_>>(), classes);
            assert!(f.labels.iter().all(|&l| l == 0 || classes.contains(&l)));
            assert!(f.labels.iter().any(|&l| l != 0));
            assert!(f.visible.iter().all(|v| (0.0..=1.0).contains(v)) && f.visible.iter().any(|&v| v > 0.5));
        }
        // A rendered source's word round-trips too.
        let rendered = Source::Rendered { objects: 5, copies: Copies::Heap };
        assert_eq!(Source::parse_arg(&rendered.arg()).unwrap(), rendered);
        assert!(Source::parse_arg("bop:0:/x").unwrap_err().to_string().contains("at least 1"));
        assert!(Source::parse_arg("bop:/x").unwrap_err().to_string().contains("bop:HOLD:DIR"));
        let missing = Source::Bop { root: root.join("nothing"), hold: 1 }.load(&set, 0, 0).err().unwrap();
        assert!(missing.to_string().contains("not a BOP dataset with a test split"), "{missing}");
        std::fs::remove_dir_all(&root).ok();
    }

    #[test]
    fn ping_pong_never_jumps() {
        let seq: Vec<usize> = (0..9).map(|i| ping_pong(i, 4)).collect();
        assert_eq!(seq, [0, 1, 2, 3, 2, 1, 0, 1, 2]);
        assert_eq!(ping_pong(5, 1), 0);
    }
}
