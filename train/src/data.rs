//! Training samples rendered on the fly: tabletop scenes from
//! `scene::sampler`, rendered with sensor noise by `scene::render`, turned into
//! network inputs by `estimator::Workspace::prepare` — exactly the inference
//! path. A background thread fills a bounded crossbeam channel.
//!
//! One rendered frame gives one sample per instance the workspace finds in its
//! label plane, matched to the ground-truth instance that covers most of its
//! pixels (rendered frames carry instance labels, so several copies of one
//! class are told apart); an instance of which no single object covers
//! [`MIN_OWN_SHARE`] — two touching copies merged into one region, or a
//! segmenter region straying onto another object — is not a sample. Augmentation (training only): per-channel colour gain
//! and bias on the normalised crop, 1 mm Gaussian point jitter, and a uniform
//! ±2 cm shift of the whole cloud applied to the ground truth as well.
//! Occluders come from the cluttered scenes; depth noise from the renderer.
//!
//! Rendered frames may take their masks from the built-in segmenter instead of
//! the ground-truth label map ([`SegMasks`], a seeded share of the frames), so
//! the pose network learns the ragged, partly wrong masks it gets at run time.
//! A segmenter instance whose points lie farther than one object diameter from
//! the matched object is dropped (a false positive, not a view of it).
//!
//! Alternatively ([`Source::Bop`]) frames come from a BOP dataset whose obj_ids
//! are the object set's class ids: frames with index % 10 != 0 train, the rest
//! validate; instances are matched to the ground truth of their class whose
//! visible box centre is nearest.

use std::collections::VecDeque;
use std::sync::Arc;

use self::rand_distr_free::gauss;
use crate::seeded_workers::{RecvError, SeededWorkers};
use anyhow::Context;
use fusepose_estimator::seg::{SegEngine, SegFile};
use fusepose_estimator::{ColorFormat, DepthPlane, FrameView, LabelPlane, Workspace, WorkspaceConfig};
use fusepose_scene::bop::BopDataset;
use fusepose_scene::render::{NoiseConfig, RenderTarget};
use fusepose_scene::sampler::{LabelKind, SamplerConfig, render_view_labelled, sample_scene};
use fusepose_scene::{ObjectSet, Pose};
use nalgebra::{Translation3, Vector3};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// Share of an instance's pixels one ground-truth object must cover for the
/// instance to be trained on as a view of that object.
pub const MIN_OWN_SHARE: f64 = 0.8;

/// One object instance, as the network sees it, with its ground truth.
#[derive(Clone, Debug)]
pub struct Sample {
    /// `[3,S,S]` normalised crop.
    pub crop: Vec<f32>,
    /// `[N,3]` camera-frame points, metres.
    pub points: Vec<f32>,
    /// `[N]` crop pixel index of each point.
    pub choose: Vec<u32>,
    /// 0-based class index.
    pub class: usize,
    /// Object → camera.
    pub pose: Pose,
}

/// What the generator produces.
#[derive(Clone, Debug)]
pub struct DataConfig {
    pub num_points: usize,
    pub crop_size: usize,
    /// Instances with fewer distinct valid-depth points are skipped.
    pub min_points: usize,
    /// Instances less visible than this are skipped.
    pub min_visible: f64,
    pub augment: bool,
    /// How rendered scenes are drawn (randomisation, depth sensor, copies per class).
    pub sampler: SamplerConfig,
    /// Samples per object per rendered frame (1 = one). Each further one
    /// draws its own point subset and augmentation from the same render, so
    /// the render's cost is shared by `views_per_frame` samples.
    pub views_per_frame: usize,
    /// Further samples per rendered frame of each object whose box touches
    /// the image border ([`cut_by_edge`]): close views of objects cut by the
    /// image edge lose most of what touching pairs lose with true masks
    /// (docs/BENCHMARKS.md, session 45), so they can be drawn more often
    /// without rendering more.
    pub edge_views: usize,
    /// Share (0..=1) of ground-truth-mask frames whose object masks are cut
    /// to a random part ([`cut_masks`]): on images it did not render, the
    /// segmenter finds only part of many objects (docs/BENCHMARKS.md,
    /// session 40), a view the ground truth never shows the network.
    pub partial_masks: f64,
}

impl DataConfig {
    /// Plain default scenes, one sample per object, no augmentation: the
    /// network inputs exactly as the estimator prepares them.
    pub fn unaugmented(num_points: usize, crop_size: usize) -> Self {
        Self {
            num_points,
            crop_size,
            min_points: 32,
            min_visible: 0.2,
            augment: false,
            sampler: SamplerConfig::default(),
            views_per_frame: 1,
            edge_views: 0,
            partial_masks: 0.0,
        }
    }
}

/// Smallest object mask (pixels) [`cut_masks`] cuts.
pub const MIN_CUT_PIXELS: usize = 200;

/// Cuts each object's mask in `class_plane` to a random part: the pixels on
/// one side of a line in a random direction, keeping 30–90 % of them (the
/// rest become background). `instances` is the frame's instance label plane;
/// masks under [`MIN_CUT_PIXELS`] stay whole.
pub fn cut_masks<R: Rng>(class_plane: &mut [u16], instances: &[u16], width: usize, rng: &mut R) {
    let mut pixels: Vec<Vec<u32>> = Vec::new();
    for (p, &l) in instances.iter().enumerate() {
        if l != 0 && class_plane.get(p).is_some_and(|&c| c != 0) {
            let l = l as usize;
            if pixels.len() <= l {
                pixels.resize_with(l + 1, Vec::new);
            }
            pixels[l].push(p as u32);
        }
    }
    let w = width.max(1);
    for own in pixels.iter().filter(|o| o.len() >= MIN_CUT_PIXELS) {
        let angle: f64 = rng.random_range(0.0..std::f64::consts::TAU);
        let keep: f64 = rng.random_range(0.3..0.9);
        let (c, s) = (angle.cos(), angle.sin());
        let along = |p: u32| (p as usize % w) as f64 * c + (p as usize / w) as f64 * s;
        let mut order: Vec<f64> = own.iter().map(|&p| along(p)).collect();
        let k = ((order.len() as f64 * keep) as usize).min(order.len() - 1);
        let limit = *order.select_nth_unstable_by(k, f64::total_cmp).1;
        for &p in own {
            if along(p) > limit {
                class_plane[p as usize] = 0;
            }
        }
    }
}

/// Tiny Gaussian helper (Box–Muller), so no extra dependency is needed.
mod rand_distr_free {
    use rand::Rng;
    pub fn gauss<R: Rng>(rng: &mut R) -> f32 {
        let u1: f64 = rng.random_range(1e-12..1.0);
        let u2: f64 = rng.random::<f64>();
        ((-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()) as f32
    }
}

/// Where frames come from.
#[derive(Clone, Debug)]
pub enum Source {
    /// Tabletop scenes rendered on the fly (seeded).
    Rendered,
    /// A BOP dataset split (class ids = obj_ids).
    Bop(Arc<BopDataset>),
}

impl Source {
    /// Opens `DIR` (a split folder such as `out/train`) and checks its classes against `set`.
    pub fn bop(dir: &std::path::Path, set: &ObjectSet) -> anyhow::Result<Self> {
        let ds = BopDataset::open(dir).with_context(|| format!("opening BOP split {}", dir.display()))?;
        if ds.is_empty() {
            anyhow::bail!("{} has no frames", dir.display());
        }
        if let Some(m) = ds.manifest() {
            for c in &m.classes {
                let ours = set.by_class(c.obj_id).map(|o| o.name.as_str());
                if ours != Some(c.name.as_str()) {
                    anyhow::bail!("dataset class {} is `{}`, the object set has {:?}", c.obj_id, c.name, ours);
                }
            }
        }
        Ok(Source::Bop(Arc::new(ds)))
    }
}

/// Frames of a BOP dataset used for training (`val = false`) or validation.
pub fn bop_indices(ds: &BopDataset, val: bool) -> Vec<usize> {
    (0..ds.len()).filter(|i| (i % 10 == 0) == val).collect()
}

/// The built-in segmenter as a mask source for a share of the rendered frames.
pub struct SegMasks {
    engine: SegEngine,
    /// Label plane of the current frame (grown to the frame size once).
    labels: Vec<u16>,
    /// Share of frames, 0..=1, whose masks come from the segmenter.
    fraction: f64,
}

impl SegMasks {
    pub fn new(engine: SegEngine, fraction: f64) -> Self {
        Self { engine, labels: Vec::new(), fraction: fraction.clamp(0.0, 1.0) }
    }
}

/// Ground truth of one object in a frame, for matching instances.
struct Truth {
    class_id: u16,
    /// Label of the object in the frame's instance label map (0 = unknown: match by box centre).
    instance_label: u16,
    pose: Pose,
    visible: f64,
    /// Centre of the visible box (pixels), if any.
    centre: Option<(f64, f64)>,
    /// Object diameter (m) when instances may be false positives (segmenter masks).
    max_offset: Option<f64>,
}

/// Renders scene `seed` and returns its samples. `ws` and `target` are reused.
pub fn frame_samples(
    set: &ObjectSet,
    cfg: &DataConfig,
    seed: u64,
    ws: &mut Workspace,
    target: &mut RenderTarget,
    seg: Option<&mut SegMasks>,
) -> anyhow::Result<Vec<Sample>> {
    let sampler = &cfg.sampler;
    let k = sampler.intrinsics;
    let scene = match sample_scene(set, sampler, seed) {
        Ok(s) => s,
        Err(fusepose_scene::sampler::SamplerError::Placement { .. }) => return Ok(Vec::new()),
        Err(e) => return Err(e).context("sampling a scene"),
    };
    let truth = render_view_labelled(&scene, set, 0, &k, &NoiseConfig::default(), LabelKind::Instance, target)
        .context("rendering a scene")?;
    let k = truth.intrinsics;
    let mut class_plane = Vec::new();
    let mut frame = FrameView {
        intrinsics: k,
        color_format: ColorFormat::Rgb8,
        color: target.rgb(),
        depth: DepthPlane::F32(target.depth_m()),
        labels: None,
    };
    // A seeded per-frame draw, independent of the other random streams.
    let seg = seg.filter(|s| Pcg64::seed_from_u64(seed ^ 0x5e6_3a5c).random::<f64>() < s.fraction);
    let from_segmenter = seg.is_some();
    match seg {
        Some(s) => {
            s.labels.resize(k.width as usize * k.height as usize, 0);
            s.engine.segment(&frame, &mut s.labels).context("segmenting a training frame")?;
            frame.labels = Some(LabelPlane::U16(&s.labels));
        }
        None => {
            target.map_labels(&truth.class_lut(), &mut class_plane);
            // A seeded per-frame draw of its own, as the segmenter's above.
            let mut cut = Pcg64::seed_from_u64(seed ^ 0xc07_3a5c);
            if cut.random::<f64>() < cfg.partial_masks {
                cut_masks(&mut class_plane, target.labels(), k.width as usize, &mut cut);
            }
            frame.labels = Some(LabelPlane::U16(&class_plane));
        }
    }
    let truths: Vec<Truth> = truth
        .objects
        .iter()
        .map(|o| Truth {
            class_id: o.class_id,
            instance_label: o.instance_label,
            pose: o.pose,
            visible: o.visible_fraction,
            centre: o.bbox.map(|b| ((b.u_min + b.u_max) as f64 / 2.0, (b.v_min + b.v_max) as f64 / 2.0)),
            max_offset: from_segmenter.then(|| set.by_class(o.class_id).map(|m| m.diameter)).flatten(),
        })
        .collect();
    let labels = Some(target.labels());
    let mut out = samples_from_frame(&frame, &truths, labels, cfg, seed, ws, Objects::All)?;
    for view in 1..cfg.views_per_frame.max(1) as u64 {
        // Seeds of further views stay clear of the frame seeds (consecutive integers).
        let view_seed = seed ^ view.wrapping_mul(0x9e37_79b9_7f4a_7c15);
        out.extend(samples_from_frame(&frame, &truths, labels, cfg, view_seed, ws, Objects::All)?);
    }
    for view in 0..cfg.edge_views as u64 {
        // A stream of seeds of their own, apart from the views' above.
        let view_seed = seed ^ (view + 1).wrapping_mul(0xd1b5_4a32_d192_ed03);
        out.extend(samples_from_frame(&frame, &truths, labels, cfg, view_seed, ws, Objects::CutByEdge)?);
    }
    Ok(out)
}

/// Loads BOP frame `index` and returns its samples.
pub fn bop_frame_samples(
    ds: &BopDataset,
    index: usize,
    cfg: &DataConfig,
    seed: u64,
    ws: &mut Workspace,
) -> anyhow::Result<Vec<Sample>> {
    let f = ds.load(index).with_context(|| format!("loading BOP frame {index}"))?;
    let frame = FrameView {
        intrinsics: f.intrinsics,
        color_format: ColorFormat::Rgb8,
        color: &f.rgb,
        depth: DepthPlane::U16 { data: &f.depth, scale: f.depth_unit_m as f32 },
        labels: Some(LabelPlane::U16(&f.labels)),
    };
    let truths: Vec<Truth> =
        f.gt.iter()
            .map(|g| Truth {
                class_id: g.obj_id,
                instance_label: 0,
                pose: g.pose,
                visible: g.visib_fract,
                centre: (g.bbox_visib[2] > 0).then(|| {
                    (
                        g.bbox_visib[0] as f64 + g.bbox_visib[2] as f64 / 2.0,
                        g.bbox_visib[1] as f64 + g.bbox_visib[3] as f64 / 2.0,
                    )
                }),
                max_offset: None,
            })
            .collect();
    samples_from_frame(&frame, &truths, None, cfg, seed, ws, Objects::All)
}

/// Which of a frame's objects [`samples_from_frame`] takes.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Objects {
    All,
    /// Those whose box touches the image border ([`cut_by_edge`]).
    CutByEdge,
}

/// Whether an instance's box `[u0, v0, u1, v1]` (pixels, inclusive) touches
/// the border of a `width` × `height` image: the object runs out of the view.
pub fn cut_by_edge(bbox: [u16; 4], width: usize, height: usize) -> bool {
    let [u0, v0, u1, v1] = bbox.map(usize::from);
    u0 == 0 || v0 == 0 || u1 + 1 >= width || v1 + 1 >= height
}

/// The ground-truth object that covers at least [`MIN_OWN_SHARE`] of
/// instance `i`'s pixels in `instance_labels` (the frame's true instance map).
fn owner<'t>(ws: &Workspace, i: usize, w: usize, instance_labels: &[u16], truths: &'t [Truth]) -> Option<&'t Truth> {
    let inst = ws.instances[i];
    let id = ws.component_id(i)?;
    let ids = ws.component_ids();
    let [u0, v0, u1, v1] = inst.bbox.map(|x| x as usize);
    let mut counts: Vec<(u16, u32)> = Vec::with_capacity(4);
    let mut total = 0u32;
    for v in v0..=v1 {
        for u in u0..=u1 {
            let p = v * w + u;
            if ids.get(p) != Some(&id) {
                continue;
            }
            total += 1;
            let l = instance_labels.get(p).copied().unwrap_or(0);
            match counts.iter_mut().find(|(k, _)| *k == l) {
                Some((_, c)) => *c += 1,
                None => counts.push((l, 1)),
            }
        }
    }
    let (label, n) = counts.into_iter().filter(|&(l, _)| l != 0).max_by_key(|&(_, c)| c)?;
    if (n as f64) < MIN_OWN_SHARE * total.max(1) as f64 {
        return None;
    }
    truths.iter().find(|t| t.instance_label == label && t.class_id == inst.class_id)
}

fn samples_from_frame(
    frame: &FrameView<'_>,
    truths: &[Truth],
    instance_labels: Option<&[u16]>,
    cfg: &DataConfig,
    seed: u64,
    ws: &mut Workspace,
    objects: Objects,
) -> anyhow::Result<Vec<Sample>> {
    let count = ws.prepare(frame, seed).context("preparing the workspace")?;
    let mut rng = Pcg64::seed_from_u64(seed ^ 0x5eed_da7a);
    let (n, s) = (cfg.num_points, cfg.crop_size);
    let mut out = Vec::with_capacity(count);
    for i in 0..count {
        let inst = ws.instances[i];
        if objects == Objects::CutByEdge && !cut_by_edge(inst.bbox, frame.width(), frame.height()) {
            continue;
        }
        let (cu, cv) =
            ((inst.bbox[0] as f64 + inst.bbox[2] as f64) / 2.0, (inst.bbox[1] as f64 + inst.bbox[3] as f64) / 2.0);
        let dist = |t: &Truth| t.centre.map_or(f64::INFINITY, |(u, v)| (u - cu).powi(2) + (v - cv).powi(2));
        let matched = match instance_labels {
            Some(labels) => owner(ws, i, frame.width(), labels, truths),
            None => truths.iter().filter(|t| t.class_id == inst.class_id).min_by(|a, b| dist(a).total_cmp(&dist(b))),
        };
        let Some(t) = matched else {
            continue;
        };
        if t.visible < cfg.min_visible || inst.distinct_points(n) < cfg.min_points {
            continue;
        }
        let mut crop: Vec<f32> = ws.crops.slice(ndarray::s![i, .., .., ..]).iter().copied().collect();
        let mut points: Vec<f32> = ws.points.slice(ndarray::s![i, .., ..]).iter().copied().collect();
        if let Some(max) = t.max_offset {
            let mut mean = Vector3::<f64>::zeros();
            for p in points.chunks_exact(3) {
                mean += Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            }
            mean /= (points.len() / 3).max(1) as f64;
            if (mean - t.pose.translation.vector).norm() > max {
                continue;
            }
        }
        let choose: Vec<u32> = ws.choose.row(i).to_vec();
        let mut pose = t.pose;
        if cfg.augment {
            for c in 0..3 {
                let gain: f32 = rng.random_range(0.8..1.2);
                let bias: f32 = rng.random_range(-0.2..0.2);
                for v in &mut crop[c * s * s..(c + 1) * s * s] {
                    *v = *v * gain + bias;
                }
            }
            let shift = Vector3::new(
                rng.random_range(-0.02..0.02),
                rng.random_range(-0.02..0.02),
                rng.random_range(-0.02..0.02),
            );
            for p in points.chunks_exact_mut(3) {
                for j in 0..3 {
                    p[j] += shift[j] as f32 + 0.001 * gauss(&mut rng);
                }
            }
            pose = Translation3::from(shift) * pose;
        }
        out.push(Sample { crop, points, choose, class: inst.class_id as usize - 1, pose });
    }
    Ok(out)
}

/// Workspace for the generator: the network's N and S, every class of the set.
pub fn workspace(set: &ObjectSet, cfg: &DataConfig) -> anyhow::Result<Workspace> {
    Workspace::new(WorkspaceConfig {
        max_instances: 16,
        num_points: cfg.num_points,
        crop_size: cfg.crop_size,
        num_classes: set.len() as u16,
        ..WorkspaceConfig::default()
    })
    .map_err(|e| anyhow::anyhow!("workspace: {e}"))
}

/// Training samples from background threads: rendered scenes `first_seed,
/// first_seed + 1, …` from `threads` render threads merged back into seed
/// order (the same samples for any count, [`SeededWorkers`]), or BOP training
/// frames in a fresh seeded shuffle per pass from one thread.
pub struct Stream {
    frames: SeededWorkers<Vec<Sample>>,
    /// Samples of the last frame not handed out yet.
    pending: VecDeque<Sample>,
}

/// The segmenter whose masks a share of rendered training frames get; each
/// render thread builds its own engine from the file.
#[derive(Clone)]
pub struct SegMaskSource {
    pub file: Arc<SegFile>,
    /// Share of frames, 0..=1, whose masks come from the segmenter.
    pub fraction: f64,
}

/// Where a BOP reader is in its shuffled pass over the training frames.
struct BopPass {
    order: Vec<usize>,
    next: usize,
    rng: Pcg64,
}

impl Stream {
    /// Starts the data threads; `capacity` samples (in frames: a tenth) are buffered.
    pub fn spawn(
        set: Arc<ObjectSet>,
        cfg: DataConfig,
        source: Source,
        first_seed: u64,
        capacity: usize,
        seg: Option<SegMaskSource>,
        threads: usize,
    ) -> anyhow::Result<Self> {
        // A frame holds a few samples.
        let frames = (capacity / 10).max(threads.max(1) * 2);
        let frames = match source {
            Source::Rendered => {
                let (set2, cfg2) = (set.clone(), cfg.clone());
                let init = move || -> anyhow::Result<_> {
                    let seg = match &seg {
                        Some(s) => Some(SegMasks::new(
                            SegEngine::new(&s.file).context("building a data thread's segmenter")?,
                            s.fraction,
                        )),
                        None => None,
                    };
                    Ok((workspace(&set2, &cfg2)?, RenderTarget::for_intrinsics(&cfg2.sampler.intrinsics), seg))
                };
                let produce = move |(ws, target, seg): &mut (Workspace, RenderTarget, Option<SegMasks>), seed| {
                    frame_samples(&set, &cfg, seed, ws, target, seg.as_mut()).map(Some)
                };
                SeededWorkers::spawn("fusepose-data", threads, first_seed, frames, init, produce)?
            }
            // One thread: the shuffled pass is sequential state.
            Source::Bop(ds) => {
                let (ds2, cfg2) = (ds.clone(), cfg.clone());
                let init = move || -> anyhow::Result<_> {
                    let order = bop_indices(&ds2, false);
                    if order.is_empty() {
                        anyhow::bail!("the BOP dataset has no training frames");
                    }
                    let pass = BopPass { next: order.len(), order, rng: Pcg64::seed_from_u64(first_seed) };
                    Ok((workspace(&set, &cfg2)?, pass))
                };
                let produce = move |(ws, pass): &mut (Workspace, BopPass), seed| {
                    if pass.next >= pass.order.len() {
                        pass.order.shuffle(&mut pass.rng);
                        pass.next = 0;
                    }
                    pass.next += 1;
                    bop_frame_samples(&ds, pass.order[pass.next - 1], &cfg, seed, ws).map(Some)
                };
                SeededWorkers::spawn("fusepose-data", 1, first_seed, frames, init, produce)?
            }
        };
        Ok(Self { frames, pending: VecDeque::new() })
    }

    /// The next sample, waiting at most `timeout` for it.
    pub fn recv_timeout(&mut self, timeout: std::time::Duration) -> Result<Sample, RecvError> {
        let deadline = std::time::Instant::now() + timeout;
        loop {
            if let Some(s) = self.pending.pop_front() {
                return Ok(s);
            }
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            self.pending.extend(self.frames.recv_timeout(left)?);
        }
    }

    /// A sample that is ready now, if any.
    pub fn try_recv(&mut self) -> Option<Sample> {
        self.recv_timeout(std::time::Duration::ZERO).ok()
    }

    /// A data thread's error, if one has died.
    pub fn check(&mut self) -> Result<(), RecvError> {
        self.frames.check()
    }
}
