//! Speeds the trainer depends on: milliseconds per object and achieved
//! GFLOP/s of the shipped inference engine (`NetEstimator`) on synthetic
//! inputs of the network's N and S, and the cost of one rendered training
//! frame (scene draw, render, sample extraction) for an object set.

use std::time::Instant;

use fusepose_estimator::net::{NetEstimator, NetOptions, WeightFile};
use fusepose_estimator::workspace::Instance;
use fusepose_estimator::{ColorFormat, DepthPlane, Estimator, FrameView, PoseSet, Workspace};
use fusepose_scene::{Intrinsics, ObjectSet};
use rand::{Rng, SeedableRng};

/// One measurement.
#[derive(Clone, Debug)]
pub struct EngineSpeed {
    pub threads: usize,
    pub instances: usize,
    pub refine_iterations: usize,
    /// Median over frames of frame time / instances.
    pub ms_per_object: f64,
    pub gflops: f64,
}

/// Times `frames` frames of `instances` objects each (after 3 warm-up frames).
pub fn engine_speed(
    file: &WeightFile,
    set: &ObjectSet,
    instances: usize,
    threads: usize,
    frames: usize,
) -> anyhow::Result<EngineSpeed> {
    let mut est = NetEstimator::from_file(
        file.clone(),
        set,
        NetOptions { refine_iterations: None, threads, ..NetOptions::default() },
    )?;
    let c = file.config.clone();
    let mut ws = Workspace::new(est.workspace_config(instances.max(1))).map_err(|e| anyhow::anyhow!("{e}"))?;
    let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
    let (n, s) = (c.num_points, c.crop_size);
    ws.crops.mapv_inplace(|_| rng.random_range(-2.0..2.0));
    ws.points.mapv_inplace(|_| rng.random_range(-0.05..0.05));
    ws.points.slice_mut(ndarray::s![.., .., 2]).mapv_inplace(|v| v + 0.8);
    ws.choose.mapv_inplace(|_| rng.random_range(0..(s * s) as u32));
    ws.instances.clear();
    for i in 0..instances {
        ws.instances.push(Instance {
            class_id: (i % c.num_classes) as u16 + 1,
            pixels: n as u32,
            valid_depth_pixels: n as u32,
            ..Instance::default()
        });
    }
    let k = Intrinsics::YCB_VIDEO;
    let px = (k.width * k.height) as usize;
    let color = vec![0u8; px * 3];
    let depth = vec![0f32; px];
    let frame = FrameView {
        intrinsics: k,
        color_format: ColorFormat::Rgb8,
        color: &color,
        depth: DepthPlane::F32(&depth),
        labels: None,
    };
    let mut out = PoseSet::with_capacity(instances.max(1));
    let mut times = Vec::with_capacity(frames);
    for f in 0..frames + 3 {
        let t0 = Instant::now();
        est.estimate(&frame, &mut ws, &mut out)?;
        if f >= 3 {
            times.push(t0.elapsed().as_secs_f64());
        }
    }
    times.sort_by(f64::total_cmp);
    let per_obj = times[times.len() / 2] / instances.max(1) as f64;
    let iters = est.refine_iterations();
    Ok(EngineSpeed {
        threads: est.threads(),
        instances,
        refine_iterations: iters,
        ms_per_object: per_obj * 1000.0,
        gflops: c.flops_per_object(n, s, iters) / per_obj / 1e9,
    })
}

/// What one rendered training frame costs on the calling thread.
#[derive(Clone, Debug)]
pub struct DataSpeed {
    pub frames: usize,
    /// Training samples (object views) per frame, mean.
    pub samples_per_frame: f64,
    /// Median ms per frame: drawing the scene (`sample_scene`).
    pub scene_ms: f64,
    /// Median ms per frame: rendering it with the training sensor model.
    pub render_ms: f64,
    /// Median ms per frame: the whole of [`crate::data::frame_samples`]
    /// (draw + render + crops and point clouds).
    pub frame_ms: f64,
}

impl DataSpeed {
    /// CPU ms of data generation per training sample.
    pub fn ms_per_sample(&self) -> f64 {
        self.frame_ms / self.samples_per_frame.max(1e-9)
    }
}

/// Times `frames` training frames (seeds `first_seed..`) as the trainer's data
/// thread makes them: the whole frame, and its scene draw and render alone
/// (run again on the same seed, so the shares are of the same work).
pub fn data_speed(
    set: &ObjectSet,
    cfg: &crate::data::DataConfig,
    first_seed: u64,
    frames: usize,
) -> anyhow::Result<DataSpeed> {
    use fusepose_scene::render::{NoiseConfig, RenderTarget};
    use fusepose_scene::sampler::{LabelKind, render_view_labelled, sample_scene};
    let mut ws = crate::data::workspace(set, cfg)?;
    let mut target = RenderTarget::for_intrinsics(&cfg.sampler.intrinsics);
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(f64::NAN) * 1000.0
    };
    let (mut scene_t, mut render_t, mut frame_t) = (Vec::new(), Vec::new(), Vec::new());
    let mut samples = 0usize;
    for seed in first_seed..first_seed + frames as u64 {
        let t0 = Instant::now();
        samples += crate::data::frame_samples(set, cfg, seed, &mut ws, &mut target, None)?.len();
        frame_t.push(t0.elapsed().as_secs_f64());
        let t0 = Instant::now();
        let Ok(scene) = sample_scene(set, &cfg.sampler, seed) else { continue };
        scene_t.push(t0.elapsed().as_secs_f64());
        let t0 = Instant::now();
        let k = cfg.sampler.intrinsics;
        render_view_labelled(&scene, set, 0, &k, &NoiseConfig::default(), LabelKind::Instance, &mut target)?;
        render_t.push(t0.elapsed().as_secs_f64());
    }
    Ok(DataSpeed {
        frames,
        samples_per_frame: samples as f64 / frames.max(1) as f64,
        scene_ms: median(scene_t),
        render_ms: median(render_t),
        frame_ms: median(frame_t),
    })
}

/// A weight file with freshly initialised (untrained) weights for `set`, for timing.
pub fn random_weights(set: &ObjectSet) -> anyhow::Result<WeightFile> {
    let cfg = fusepose_estimator::net::NetConfig::new(set.len());
    let net = crate::model::FusionNet::new(&cfg, &burn::prelude::Device::flex());
    let dir = std::env::temp_dir().join(format!("fusepose-bench-{}", std::process::id()));
    let p = dir.join("random.safetensors");
    let entries = fusepose_estimator::net::meta::object_entries(set);
    crate::store::save(&net, &cfg, &entries, &Default::default(), &p)?;
    let f = WeightFile::read(&p)?;
    let _ = std::fs::remove_dir_all(dir);
    Ok(f)
}
