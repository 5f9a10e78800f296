//! The timed frame loop for one objects-per-frame count K: every stage of
//! every frame timed and its allocations counted, after one warm-up pass
//! over the distinct frames.
//!
//! Stages per frame, in order: `prepare` (sampling, [`Workspace::prepare`],
//! for the network's workspace), `net pose` (refiner iterations set to 0),
//! `net pose+refine` (the file's refiner iterations); `refiner` is the
//! per-frame difference of those two; then `prepare` for the ICP workspace
//! (its N differs) and `icp`.

use std::time::Instant;

use fusepose_estimator::net::NetEstimator;
use fusepose_estimator::{Estimator, IcpEstimator, PoseSet, Workspace};

use super::frames::TestFrame;
use crate::summary::Summary;
use crate::{alloc_count, cpu_time};

/// The network and its workspace.
pub struct NetPipe {
    pub est: NetEstimator,
    pub ws: Workspace,
    /// Refiner iterations of the full run.
    pub iters: usize,
}

/// The ICP baseline and its workspace.
pub struct IcpPipe {
    pub est: IcpEstimator,
    pub ws: Workspace,
}

/// One row of the result table: a stage at one K.
#[derive(Clone, Debug)]
pub struct StageRow {
    pub stage: String,
    /// Objects per frame (K).
    pub objects: usize,
    /// Mean instances the workspace found per frame.
    pub instances: f64,
    pub frame_ms: Summary,
    pub object_ms: Summary,
    /// CPU time of the calling thread per frame, ms (excludes time other
    /// processes held the core; with 2 network threads, the caller's share only).
    pub cpu_frame_ms: Summary,
    /// Mean allocations per steady-state frame (`None`: not counted).
    pub allocs_per_frame: Option<f64>,
    /// Whether the estimator crate promises zero allocations for this stage.
    pub zero_alloc_promised: bool,
    /// FLOPs per object, for the network stages.
    pub flops_per_object: Option<f64>,
}

impl StageRow {
    /// Achieved GFLOP/s at the median per-object time (`None` when that
    /// median is not positive: a difference row lost in noise).
    pub fn gflops(&self) -> Option<f64> {
        let ms = self.object_ms.median;
        self.flops_per_object.filter(|_| ms > 0.0).map(|f| f / (ms * 1e-3) / 1e9)
    }

    /// Achieved GFLOP/s at the median CPU time per frame.
    pub fn cpu_gflops(&self) -> Option<f64> {
        let ms = self.cpu_frame_ms.median;
        self.flops_per_object.filter(|_| ms > 0.0).map(|f| f * self.instances / (ms * 1e-3) / 1e9)
    }
}

#[derive(Default)]
struct Samples {
    frame_ms: Vec<f64>,
    object_ms: Vec<f64>,
    cpu_ms: Vec<f64>,
    allocs: Vec<u64>,
    instances: Vec<usize>,
}

impl Samples {
    fn push(&mut self, (ms, cpu_ms): (f64, f64), instances: usize, allocs: Option<u64>) {
        self.frame_ms.push(ms);
        self.cpu_ms.push(cpu_ms);
        if instances > 0 {
            self.object_ms.push(ms / instances as f64);
        }
        self.allocs.extend(allocs);
        self.instances.push(instances);
    }

    fn row(&self, stage: &str, objects: usize, zero_alloc_promised: bool, flops: Option<f64>) -> Option<StageRow> {
        Some(StageRow {
            stage: stage.into(),
            objects,
            instances: self.instances.iter().sum::<usize>() as f64 / self.instances.len().max(1) as f64,
            frame_ms: Summary::of(&self.frame_ms)?,
            object_ms: Summary::of(&self.object_ms)?,
            cpu_frame_ms: Summary::of(&self.cpu_ms)?,
            allocs_per_frame: (!self.allocs.is_empty())
                .then(|| self.allocs.iter().sum::<u64>() as f64 / self.allocs.len() as f64),
            zero_alloc_promised,
            flops_per_object: flops,
        })
    }
}

/// Times `f` (wall and thread CPU ms), counting its allocations when `count` is set.
fn timed<T>(count: bool, f: impl FnOnce() -> T) -> (T, (f64, f64), Option<u64>) {
    let a = alloc_count::allocations();
    let c = cpu_time::thread_cpu_ms();
    let t = Instant::now();
    let r = f();
    let ms = t.elapsed().as_secs_f64() * 1e3;
    let cpu = cpu_time::thread_cpu_ms() - c;
    let allocs = count.then(|| alloc_count::allocations() - a);
    (r, (ms, cpu), allocs)
}

/// Runs `frames_to_time` frames (cycling through `frames`) for K = `objects`.
pub fn run_k(
    net: Option<&mut NetPipe>,
    icp: Option<&mut IcpPipe>,
    frames: &[TestFrame],
    objects: usize,
    frames_to_time: usize,
    count_allocs: bool,
) -> anyhow::Result<Vec<StageRow>> {
    let mut out = PoseSet::with_capacity(16);
    let [mut prep_net, mut pose, mut full, mut refine]: [Samples; 4] = Default::default();
    let (mut prep_icp, mut icp_s) = (Samples::default(), Samples::default());
    let (mut net, mut icp) = (net, icp);
    let warm = frames.len();
    for f in 0..warm + frames_to_time {
        let frame = frames[f % frames.len()].view();
        let record = f >= warm;
        let seed = f as u64;
        if let Some(p) = net.as_deref_mut() {
            let (n, ms, al) = timed(count_allocs, || p.ws.prepare(&frame, seed));
            let n = n?;
            p.est.set_refine_iterations(0);
            let (r0, ms0, al0) = timed(count_allocs, || p.est.estimate(&frame, &mut p.ws, &mut out));
            r0?;
            p.est.set_refine_iterations(p.iters);
            let (r1, ms1, al1) = timed(count_allocs, || p.est.estimate(&frame, &mut p.ws, &mut out));
            r1?;
            if record {
                prep_net.push(ms, n, al);
                pose.push(ms0, n, al0);
                full.push(ms1, n, al1);
                refine.push((ms1.0 - ms0.0, ms1.1 - ms0.1), n, None);
            }
        }
        if let Some(p) = icp.as_deref_mut() {
            let (n, ms, al) = timed(count_allocs, || p.ws.prepare(&frame, seed));
            let n = n?;
            let (r, ms1, al1) = timed(count_allocs, || p.est.estimate(&frame, &mut p.ws, &mut out));
            r?;
            if record {
                prep_icp.push(ms, n, al);
                icp_s.push(ms1, n, al1);
            }
        }
    }
    let mut rows = Vec::new();
    if let Some(p) = net.as_deref() {
        let c = &p.est.engine().config;
        let (n, s) = (p.ws.config.num_points, p.ws.config.crop_size);
        let f0 = c.flops_per_object(n, s, 0);
        let f1 = c.flops_per_object(n, s, p.iters);
        rows.extend(prep_net.row(&format!("prepare N={n} (net)"), objects, true, None));
        rows.extend(pose.row("net pose", objects, true, Some(f0)));
        rows.extend(refine.row(&format!("net refiner x{}", p.iters), objects, false, Some(f1 - f0)));
        rows.extend(full.row("net pose+refine", objects, true, Some(f1)));
    }
    if let Some(p) = icp.as_deref() {
        rows.extend(prep_icp.row(&format!("prepare N={} (icp)", p.ws.config.num_points), objects, true, None));
        rows.extend(icp_s.row("icp", objects, true, None));
    }
    Ok(rows)
}
