//! `fusepose camera`: act as a live RGB-D camera on iceoryx2 — replay a BOP
//! split (frames preloaded, paced by a monotonic clock; `--dataset` is the
//! dataset root or the split folder, as for every command) or render tabletop
//! scenes of the built-in objects on the fly.
//!
//! The iceoryx2 namespace comes from `FUSEPOSE_IOX2_ROOT` / `FUSEPOSE_IOX2_PREFIX`.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use fusepose_client::{
    ColorFormat, DepthFormat, DepthMut, FrameLayout, Ipc, IpcOptions, LabelFormat, LabelsMut, Producer,
};

/// Where the label plane comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Labels {
    /// Ground-truth class ids.
    Gt,
    /// No label plane: the daemon segments with the built-in segmenter when
    /// its weight file has one (`estimator.masks = "auto"`).
    None,
}

#[derive(clap::Args)]
pub struct Args {
    /// Camera name: frames go to fusepose/camera/<name>/frames.
    #[arg(long, default_value = "cam0")]
    pub name: String,
    /// BOP dataset to replay: its root (the --split folder is used) or a
    /// split folder (e.g. data/synth or data/synth/test).
    #[arg(long, alias = "from", value_name = "DIR", conflicts_with = "synthetic")]
    pub dataset: Option<PathBuf>,
    /// Split of a dataset root to replay (ignored when --dataset is a split folder).
    #[arg(long, default_value = "test")]
    pub split: String,
    /// Render scenes of the built-in objects on the fly instead of replaying.
    #[arg(long)]
    pub synthetic: bool,
    /// Frame rate, frames per second (the renderer may be slower; then as fast as it renders).
    #[arg(long, default_value_t = 24.0)]
    pub fps: f64,
    /// Start over at the end of the dataset.
    #[arg(long = "loop")]
    pub repeat: bool,
    /// Label plane to send.
    #[arg(long, value_enum, default_value = "gt")]
    pub labels: Labels,
    /// Most frames to preload from the dataset / to send (default: all / forever).
    #[arg(long)]
    pub frames: Option<usize>,
    /// First scene seed (synthetic): scene i of the run uses seed + i.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Camera views rendered per synthetic scene.
    #[arg(long, default_value_t = 8)]
    pub views_per_scene: usize,
    /// Synthetic: render this many frames before sending, then replay them in
    /// a loop (0 = render every frame live). Keeps --fps when rendering is
    /// slower; costs about 2.2 MB of memory per 640x480 frame.
    #[arg(long, default_value_t = 0, value_name = "FRAMES")]
    pub preload: usize,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if !(args.fps.is_finite() && args.fps > 0.0) {
        bail!("--fps must be positive, got {}", args.fps);
    }
    let ipc = Ipc::new(&IpcOptions::from_env().with_node_name("fusepose-camera"))?;
    match (&args.dataset, args.synthetic) {
        (Some(dir), false) => replay_bop(&ipc, &args, dir),
        (None, true) => synthetic(&ipc, &args),
        _ => bail!("give either --dataset DIR or --synthetic"),
    }
}

/// Sleeps until frame `i`'s slot; returns false when the clock is already past it.
fn pace(t0: Instant, i: u64, period: Duration) -> bool {
    match (t0 + period.mul_f64(i as f64)).checked_duration_since(Instant::now()) {
        Some(wait) => {
            std::thread::sleep(wait);
            true
        }
        None => false,
    }
}

/// Progress line every 5 s.
struct Progress {
    start: Instant,
    last: Instant,
    sent: u64,
}

impl Progress {
    fn new() -> Self {
        Self { start: Instant::now(), last: Instant::now(), sent: 0 }
    }

    fn tick(&mut self, camera: &str) {
        self.sent += 1;
        if self.last.elapsed() >= Duration::from_secs(5) {
            self.last = Instant::now();
            let fps = self.sent as f64 / self.start.elapsed().as_secs_f64();
            tracing::info!(camera, sent = self.sent, "{fps:.1} frames/s");
        }
    }
}

fn replay_bop(ipc: &Ipc, args: &Args, dir: &Path) -> anyhow::Result<()> {
    let dir = crate::dataset_path::resolve_bop_split(dir, &args.split)?;
    let dataset = fusepose_scene::bop::BopDataset::open(&dir).with_context(|| format!("opening {}", dir.display()))?;
    let limit = args.frames.unwrap_or(usize::MAX);
    let t = Instant::now();
    let mut frames = Vec::new();
    for frame in dataset.iter().take(limit) {
        frames.push(frame?);
    }
    let Some(first) = frames.first() else { bail!("{}: no frames", dir.display()) };
    let layout = FrameLayout {
        width: first.width(),
        height: first.height(),
        color_format: ColorFormat::Rgb8,
        depth_format: DepthFormat::U16,
        depth_scale: first.depth_unit_m as f32,
        labels: (args.labels == Labels::Gt).then_some(LabelFormat::U16),
    };
    let before = frames.len();
    frames.retain(|f| {
        f.width() == layout.width && f.height() == layout.height && f.depth_unit_m as f32 == layout.depth_scale
    });
    if frames.len() < before {
        tracing::warn!(
            skipped = before - frames.len(),
            "frames with another size or depth unit than the first are skipped"
        );
    }
    tracing::info!(frames = frames.len(), seconds = t.elapsed().as_secs_f64(), "dataset preloaded");

    let mut producer = Producer::create(ipc, &args.name, layout)?;
    let period = Duration::from_secs_f64(1.0 / args.fps);
    let t0 = Instant::now();
    let mut progress = Progress::new();
    let mut i = 0u64;
    loop {
        for frame in &frames {
            pace(t0, i, period);
            let mut w = producer.loan()?;
            let k = frame.intrinsics;
            w.set_intrinsics(k.fx, k.fy, k.cx, k.cy);
            let planes = w.planes_mut();
            planes.color.copy_from_slice(&frame.rgb);
            if let DepthMut::U16(depth) = planes.depth {
                depth.copy_from_slice(&frame.depth);
            }
            if let Some(LabelsMut::U16(labels)) = planes.labels {
                labels.copy_from_slice(&frame.labels);
            }
            w.send()?;
            progress.tick(&args.name);
            i += 1;
        }
        if !args.repeat {
            break;
        }
    }
    tracing::info!(sent = i, "replay finished");
    Ok(())
}

/// The sampler of `--synthetic`: default tabletop scenes, `views_per_scene` camera views each.
pub fn synthetic_sampler(views_per_scene: usize) -> fusepose_scene::sampler::SamplerConfig {
    fusepose_scene::sampler::SamplerConfig { views: views_per_scene.max(1), ..Default::default() }
}

/// Which scene seed and view `--synthetic` renders as frame `sequence` (frames
/// go scene by scene from `--seed`, every view of a scene in order; with
/// `--preload N` the first N frames repeat), so a consumer can recompute the
/// ground truth of any frame it receives.
pub fn synthetic_frame_of(first_seed: u64, views_per_scene: usize, preload: usize, sequence: u64) -> (u64, usize) {
    let index = if preload > 0 { sequence % preload as u64 } else { sequence };
    let views = views_per_scene.max(1) as u64;
    (first_seed.wrapping_add(index / views), (index % views) as usize)
}

/// Copies one rendered frame into a loaned sample and sends it.
fn send_rendered(
    producer: &mut Producer,
    k: &fusepose_scene::Intrinsics,
    rgb: &[u8],
    depth: &[u16],
    labels: &[u16],
) -> anyhow::Result<()> {
    let mut w = producer.loan()?;
    w.set_intrinsics(k.fx, k.fy, k.cx, k.cy);
    let planes = w.planes_mut();
    planes.color.copy_from_slice(rgb);
    if let DepthMut::U16(plane) = planes.depth {
        plane.copy_from_slice(depth);
    }
    if let Some(LabelsMut::U16(plane)) = planes.labels {
        plane.copy_from_slice(labels);
    }
    w.send()?;
    Ok(())
}

fn synthetic(ipc: &Ipc, args: &Args) -> anyhow::Result<()> {
    use fusepose_scene::render::{NoiseConfig, RenderTarget};
    use fusepose_scene::sampler::{LabelKind, render_view_labelled, sample_scene};

    let objects = fusepose_scene::builtin::builtin_objects();
    let k = fusepose_scene::Intrinsics::YCB_VIDEO;
    let sampler = synthetic_sampler(args.views_per_scene);
    let noise = NoiseConfig::default();
    let mut target = RenderTarget::for_intrinsics(&k);
    let layout = FrameLayout {
        width: k.width,
        height: k.height,
        color_format: ColorFormat::Rgb8,
        depth_format: DepthFormat::U16,
        depth_scale: 1e-4, // RenderTarget::depth_u16 is in 0.1 mm
        labels: (args.labels == Labels::Gt).then_some(LabelFormat::U16),
    };
    let mut producer = Producer::create(ipc, &args.name, layout)?;
    let period = Duration::from_secs_f64(1.0 / args.fps);
    let limit = args.frames.map_or(u64::MAX, |n| n as u64);
    let t0 = Instant::now();
    let mut progress = Progress::new();
    let mut sent = 0u64;
    let mut scene: Option<(u64, fusepose_scene::sampler::Scene)> = None;
    let mut render = |index: u64, target: &mut RenderTarget| -> anyhow::Result<()> {
        let (seed, view) = synthetic_frame_of(args.seed, args.views_per_scene, 0, index);
        if scene.as_ref().is_none_or(|(s, _)| *s != seed) {
            let sampled = sample_scene(&objects, &sampler, seed).map_err(|e| anyhow::anyhow!("scene {seed}: {e}"))?;
            scene = Some((seed, sampled));
        }
        let Some((_, scene)) = scene.as_ref() else { unreachable!("sampled above") };
        render_view_labelled(scene, &objects, view, &k, &noise, LabelKind::Class, target)
            .map_err(|e| anyhow::anyhow!("scene {seed} view {view}: {e}"))?;
        Ok(())
    };
    if args.preload > 0 {
        tracing::info!(frames = args.preload, "pre-rendering");
        let mut frames = Vec::with_capacity(args.preload);
        for i in 0..args.preload as u64 {
            render(i, &mut target)?;
            frames.push((target.rgb().to_vec(), target.depth_u16().to_vec(), target.labels().to_vec()));
        }
        tracing::info!(seconds = t0.elapsed().as_secs_f64(), "pre-rendered; replaying in a loop");
        let t0 = Instant::now();
        progress = Progress::new(); // rate of sending, not of pre-rendering
        while sent < limit {
            let (rgb, depth, labels) = &frames[(sent % frames.len() as u64) as usize];
            pace(t0, sent, period);
            send_rendered(&mut producer, &k, rgb, depth, labels)?;
            progress.tick(&args.name);
            sent += 1;
        }
    } else {
        while sent < limit {
            render(sent, &mut target)?;
            pace(t0, sent, period);
            send_rendered(&mut producer, &k, target.rgb(), target.depth_u16(), target.labels())?;
            progress.tick(&args.name);
            sent += 1;
        }
    }
    tracing::info!(sent, "synthetic camera finished");
    Ok(())
}
