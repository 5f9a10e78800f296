//! `fusepose-bench tracking`: the network estimator with and without
//! tracking mode on rendered video sequences (camera orbiting a tabletop
//! scene smoothly): time per object (wall and thread CPU, one thread),
//! poses per second, accuracy (ADD(S) and ADD-S against the rendered truth),
//! the share of objects kept by tracking, and allocations per frame.
//!
//! Both modes run the same frames in the same order on the same weights;
//! the workspace sampling (`prepare`) is timed separately and is the same for
//! both. No deadline is set (full refinement every frame).

use std::path::PathBuf;
use std::time::Instant;

use fusepose_estimator::net::{NetEstimator, NetOptions};
use fusepose_estimator::tracking::TrackingConfig;
use fusepose_estimator::{Estimator, PoseSet, Workspace};
use fusepose_scene::metrics::ObjectMetric;
use fusepose_scene::{ObjectSet, Pose};
use nalgebra::{Isometry3, Translation3};

use crate::summary::Summary;
use crate::video::{self, Video};
use crate::{alloc_count, cpu_time, loadavg};

/// Options of `fusepose-bench tracking`.
#[derive(Clone, Debug, clap::Args)]
pub struct TrackingArgs {
    /// Objects per scene, comma separated (1 gives the single-object poses/s).
    #[arg(long, alias = "objects", value_delimiter = ',', default_value = "1,5")]
    pub objects_per_frame: Vec<usize>,
    /// Video sequences per object count.
    #[arg(long, default_value_t = 3)]
    pub sequences: usize,
    /// Frames per sequence.
    #[arg(long, default_value_t = 60)]
    pub frames: usize,
    /// Camera motion per frame, degrees about the objects (0.5° at 30 FPS = 15°/s).
    #[arg(long, default_value_t = 0.5)]
    pub degrees_per_frame: f64,
    /// Network weights.
    #[arg(long, default_value = "models/builtin.safetensors")]
    pub weights: PathBuf,
    /// Tracking: largest fit kept, mm.
    #[arg(long, default_value_t = 8.0)]
    pub max_fit_mm: f64,
    /// Tracking: a full estimate at least every this many frames.
    #[arg(long, default_value_t = 5)]
    pub full_estimate_every: u32,
    /// Tracking: refiner iterations from the previous pose.
    #[arg(long, default_value_t = 2)]
    pub tracking_iterations: usize,
    /// A short run (seconds; for CI).
    #[arg(long)]
    pub smoke: bool,
    /// Folder for the table.
    #[arg(long, default_value = "scratch/bench/tracking")]
    pub out: PathBuf,
}

impl Default for TrackingArgs {
    fn default() -> Self {
        Self {
            objects_per_frame: vec![1, 5],
            sequences: 3,
            frames: 60,
            degrees_per_frame: 0.5,
            weights: "models/builtin.safetensors".into(),
            max_fit_mm: 8.0,
            full_estimate_every: 5,
            tracking_iterations: 2,
            smoke: false,
            out: "scratch/bench/tracking".into(),
        }
    }
}

/// One mode at one object count.
#[derive(Clone, Debug)]
pub struct ModeRow {
    pub objects: usize,
    pub tracking: bool,
    pub frames: usize,
    pub poses: u64,
    /// Wall and thread-CPU ms per object (estimate only).
    pub wall_ms_per_object: Summary,
    pub cpu_ms_per_object: f64,
    /// Sampling (`prepare`) ms per frame, median.
    pub prepare_ms: f64,
    /// Objects whose tracked pose was kept.
    pub tracked: u64,
    /// Mean ADD(S) error, mm; share with ADD-S < 2 cm, %; share with ADD(S) < 10 % of the diameter, %.
    pub add_or_add_s_mm: f64,
    pub add_s_below_2cm: f64,
    pub add_or_add_s_below_10pct: f64,
    /// Allocations per frame after the first sequence's first frames (None: not counted).
    pub allocs_per_frame: Option<f64>,
}

impl ModeRow {
    /// Poses per second on one thread (estimate only): 1000 / median ms per object.
    pub fn poses_per_s(&self) -> f64 {
        1000.0 / self.wall_ms_per_object.median
    }
}

/// Everything one run measured.
#[derive(Clone, Debug)]
pub struct TrackingReport {
    pub args: TrackingArgs,
    pub rows: Vec<ModeRow>,
    pub load_before: String,
    pub load_after: String,
}

fn pose_of(p: &fusepose_estimator::ObjectPose) -> Pose {
    Isometry3::from_parts(Translation3::from(p.translation), p.rotation)
}

fn run_mode(
    set: &ObjectSet,
    metrics: &[ObjectMetric],
    videos: &[Video],
    args: &TrackingArgs,
    objects: usize,
    tracking: bool,
) -> anyhow::Result<ModeRow> {
    let tracking_config = tracking.then(|| TrackingConfig {
        max_fit_m: args.max_fit_mm / 1000.0,
        full_estimate_every: args.full_estimate_every,
        refine_iterations: args.tracking_iterations,
    });
    let options = NetOptions { refine_iterations: None, threads: 1, tracking: tracking_config, pin_worker_cpu: None };
    let mut est = NetEstimator::load(&args.weights, set, options)?;
    let mut ws = Workspace::new(est.workspace_config(objects.max(1) + 2)).map_err(|e| anyhow::anyhow!("{e}"))?;
    let mut out = PoseSet::with_capacity(objects.max(1) + 2);
    let (mut wall, mut cpu_total, mut prepare) = (Vec::new(), 0.0, Vec::new());
    let (mut poses, mut add_sum, mut below_2cm, mut below_10pct) = (0u64, 0.0, 0u64, 0u64);
    let counting = alloc_count::installed();
    let (mut alloc_frames, mut allocs) = (0u64, 0u64);
    for (v, video) in videos.iter().enumerate() {
        est.reset_tracks();
        for (f, frame) in video.frames.iter().enumerate() {
            let view = frame.view(video.intrinsics);
            let t0 = Instant::now();
            ws.prepare(&view, (v * 10_000 + f) as u64)?;
            prepare.push(t0.elapsed().as_secs_f64() * 1e3);
            let a0 = alloc_count::allocations();
            let (t1, c1) = (Instant::now(), cpu_time::thread_cpu_ms());
            est.estimate(&view, &mut ws, &mut out)?;
            let (ms, cpu) = (t1.elapsed().as_secs_f64() * 1e3, cpu_time::thread_cpu_ms() - c1);
            // Steady state: after the first frames of the first sequence.
            if v > 0 || f >= 3 {
                allocs += alloc_count::allocations() - a0;
                alloc_frames += 1;
            }
            let n = out.len();
            if n > 0 {
                wall.push(ms / n as f64);
                cpu_total += cpu;
            }
            for p in out.as_slice() {
                let Some((_, truth)) = frame.truth.iter().find(|(c, _)| *c == p.class_id) else {
                    continue;
                };
                let m = &metrics[p.class_id as usize - 1];
                let est_pose = pose_of(p);
                let e = m.add_or_add_s(&est_pose, truth);
                let diameter = set.by_class(p.class_id).map_or(f64::INFINITY, |o| o.diameter);
                poses += 1;
                add_sum += e;
                below_2cm += (m.add_s(&est_pose, truth) < 0.02) as u64;
                below_10pct += (e < 0.1 * diameter) as u64;
            }
        }
    }
    let counters = est.counters();
    let wall_summary =
        Summary::of(&wall).ok_or_else(|| anyhow::anyhow!("no object was posed ({objects} objects per scene)"))?;
    let pct = |x: u64| 100.0 * x as f64 / poses.max(1) as f64;
    Ok(ModeRow {
        objects,
        tracking,
        frames: videos.iter().map(|v| v.frames.len()).sum(),
        poses,
        wall_ms_per_object: wall_summary,
        cpu_ms_per_object: cpu_total / poses.max(1) as f64,
        prepare_ms: Summary::of(&prepare).map_or(f64::NAN, |s| s.median),
        tracked: counters.tracked,
        add_or_add_s_mm: add_sum / poses.max(1) as f64 * 1e3,
        add_s_below_2cm: pct(below_2cm),
        add_or_add_s_below_10pct: pct(below_10pct),
        allocs_per_frame: (counting && alloc_frames > 0).then(|| allocs as f64 / alloc_frames as f64),
    })
}

/// Renders the sequences and runs both modes per object count; progress on stderr.
pub fn run(args: &TrackingArgs) -> anyhow::Result<TrackingReport> {
    anyhow::ensure!(args.weights.exists(), "{} does not exist (the network weights)", args.weights.display());
    let load_before = loadavg::loadavg();
    let set = fusepose_scene::builtin::builtin_objects();
    let metrics: Vec<ObjectMetric> = set.objects.iter().map(ObjectMetric::for_model).collect::<Result<_, _>>()?;
    let (sequences, frames) =
        if args.smoke { (1, args.frames.min(8)) } else { (args.sequences.max(1), args.frames.max(2)) };
    let mut rows = Vec::new();
    for &k in &args.objects_per_frame {
        eprintln!("tracking: rendering {sequences} sequence(s) of {frames} frames with {k} object(s) ...");
        let videos: Vec<Video> = (0..sequences)
            .map(|s| {
                video::render_video(&set, k, frames, args.degrees_per_frame, 500 + 37 * s as u64 + 1000 * k as u64)
            })
            .collect::<anyhow::Result<_>>()?;
        for tracking in [false, true] {
            eprintln!("tracking: {k} object(s), tracking {tracking} ...");
            rows.push(run_mode(&set, &metrics, &videos, args, k, tracking)?);
        }
    }
    Ok(TrackingReport { args: args.clone(), rows, load_before, load_after: loadavg::loadavg() })
}

/// The printed table.
pub fn render(r: &TrackingReport) -> String {
    let a = &r.args;
    let mut s = format!(
        "tracking: net estimator, 1 thread, rendered videos (camera orbiting {}°/frame), tracking: fit <= {} mm, full estimate every {} frames, {} refiner iterations\n",
        a.degrees_per_frame, a.max_fit_mm, a.full_estimate_every, a.tracking_iterations
    );
    s.push_str(&format!("loadavg before: {}   cpus: {}\n\n", r.load_before, loadavg::cpus()));
    s.push_str(&format!(
        "{:>7} {:>9} {:>6} {:>6} {:>11} {:>11} {:>11} {:>9} {:>8} {:>11} {:>10} {:>11} {:>10} {:>11}\n",
        "objects",
        "tracking",
        "frames",
        "poses",
        "ms/obj p50",
        "ms/obj p90",
        "CPU ms/obj",
        "poses/s",
        "tracked",
        "ADD(S) mm",
        "ADD-S<2cm",
        "ADD(S)<0.1d",
        "prepare ms",
        "allocs/frm"
    ));
    for x in &r.rows {
        s.push_str(&format!(
            "{:>7} {:>9} {:>6} {:>6} {:>11.3} {:>11.3} {:>11.3} {:>9.0} {:>7.0}% {:>11.1} {:>9.1}% {:>10.1}% {:>10.2} {:>11}\n",
            x.objects,
            if x.tracking { "on" } else { "off" },
            x.frames,
            x.poses,
            x.wall_ms_per_object.median,
            x.wall_ms_per_object.p90,
            x.cpu_ms_per_object,
            x.poses_per_s(),
            100.0 * x.tracked as f64 / x.poses.max(1) as f64,
            x.add_or_add_s_mm,
            x.add_s_below_2cm,
            x.add_or_add_s_below_10pct,
            x.prepare_ms,
            x.allocs_per_frame.map_or("n/a".into(), |v| format!("{v:.2}")),
        ));
    }
    s.push_str("\nms/obj = estimate wall time per posed object (sampling excluded, see prepare ms per frame); poses/s = 1000 / ms/obj p50;\n");
    s.push_str("tracked = objects whose tracked pose was kept (no pose net); ADD(S) = mean error against the rendered truth.\n");
    s.push_str(&format!("loadavg after: {}\n", r.load_after));
    s
}
