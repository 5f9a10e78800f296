//! `fusepose-bench estimator`: per-stage latency of the estimator on
//! rendered frames with K objects each.
//!
//! 1. Renders a fixed set of frames per K ([`frames`]) once up front.
//! 2. For each K: sampling (`Workspace::prepare`), the network (pose net
//!    alone, then with the refiner) and ICP, each timed per frame and per
//!    object, allocations counted per frame ([`frame_loop`]).
//! 3. The engine's GEMM at network shapes and a large square one
//!    ([`gemm_peak`]), and the network stages timed one by one on one thread
//!    ([`engine_stages`]): achieved GFLOP/s against that peak.
//! 4. Prints the tables ([`table`]) and writes a PNG ([`plot`]).
//!
//! The network needs a weight file: a missing one is reported and the net
//! path skipped, unless `--random-weights` asks for randomly initialised
//! weights of the default architecture ([`random_weights`]), which time the
//! same as trained ones of that architecture.

pub mod engine_stages;
pub mod frame_loop;
pub mod frames;
pub mod gemm_peak;
pub mod plot;
pub mod random_weights;
pub mod table;

use std::path::PathBuf;
use std::time::Duration;

use fusepose_estimator::net::{NetEstimator, NetOptions, WeightFile};
use fusepose_estimator::{IcpConfig, IcpEstimator, Workspace, WorkspaceConfig};
use fusepose_scene::builtin::builtin_objects;

use crate::{alloc_count, loadavg};
use engine_stages::EngineStage;
use frame_loop::{IcpPipe, NetPipe, StageRow};
use gemm_peak::GemmPoint;

/// Which estimators to time.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Which {
    Icp,
    Net,
    Both,
}

/// Options of `fusepose-bench estimator`.
#[derive(Clone, Debug, clap::Args)]
pub struct EstimatorArgs {
    /// Estimators to time.
    #[arg(long, value_enum, default_value_t = Which::Both)]
    pub estimator: Which,
    /// Network weight file (the trainer's safetensors).
    #[arg(long, default_value = "models/builtin.safetensors")]
    pub weights: PathBuf,
    /// Time the network on randomly initialised weights of the default
    /// architecture instead of `--weights` (same cost; meaningless poses).
    #[arg(long)]
    pub random_weights: bool,
    /// Objects per frame (K), comma separated.
    #[arg(long, value_delimiter = ',', default_value = "1,3,5,8")]
    pub objects_per_frame: Vec<usize>,
    /// Timed frames per K (after one warm-up pass over the distinct frames).
    #[arg(long, default_value_t = 30)]
    pub frames: usize,
    /// Distinct rendered frames per K (cycled through).
    #[arg(long, default_value_t = 4)]
    pub scenes: usize,
    /// Network threads per frame (1 or 2; the daemon's default is 2 on 2+ cores).
    #[arg(long, default_value_t = 1)]
    pub threads: usize,
    /// A few frames only, short GEMM runs (seconds; for CI).
    #[arg(long)]
    pub smoke: bool,
    /// Folder for the PNG and the table.
    #[arg(long, default_value = "scratch/bench/estimator")]
    pub out: PathBuf,
}

impl Default for EstimatorArgs {
    fn default() -> Self {
        Self {
            estimator: Which::Both,
            weights: "models/builtin.safetensors".into(),
            random_weights: false,
            objects_per_frame: vec![1, 3, 5, 8],
            frames: 30,
            scenes: 4,
            threads: 1,
            smoke: false,
            out: "scratch/bench/estimator".into(),
        }
    }
}

/// Everything one run measured.
#[derive(Clone, Debug)]
pub struct Report {
    pub rows: Vec<StageRow>,
    pub gemm: Vec<GemmPoint>,
    /// Highest median single-thread GEMM GFLOP/s.
    pub peak_gflops: f64,
    /// Network stages on one thread (empty without the network).
    pub engine: Vec<EngineStage>,
    /// Network threads per frame in the frame loop.
    pub net_threads: usize,
    /// What was skipped or substituted, and why.
    pub notes: Vec<String>,
    /// Whether allocations were counted (the counting allocator is installed).
    pub alloc_counting: bool,
    pub load_before: String,
    pub load_after: String,
    pub cpus: usize,
    pub png: Option<PathBuf>,
}

/// Loads the network as asked, or says why not.
fn load_net(args: &EstimatorArgs, set: &fusepose_scene::ObjectSet, notes: &mut Vec<String>) -> Option<NetEstimator> {
    let file = if args.random_weights {
        notes.push(
            "net: randomly initialised weights of the default architecture (--random-weights); timings only".into(),
        );
        match random_weights::random_weights(set, 7) {
            Ok(f) => f,
            Err(e) => {
                notes.push(format!("net: could not build random weights ({e}); net path skipped"));
                return None;
            }
        }
    } else if !args.weights.exists() {
        notes.push(format!(
            "net: {} does not exist yet (the training run writes it); net path SKIPPED \
             (pass --random-weights to time the engine on untrained weights)",
            args.weights.display()
        ));
        return None;
    } else {
        match WeightFile::read(&args.weights) {
            Ok(f) => f,
            Err(e) => {
                notes.push(format!("net: {} unusable ({e}); net path skipped", args.weights.display()));
                return None;
            }
        }
    };
    let options = NetOptions { refine_iterations: None, threads: args.threads.clamp(1, 2), ..NetOptions::default() };
    match NetEstimator::from_file(file, set, options) {
        Ok(est) => Some(est),
        Err(e) => {
            notes.push(format!("net: weights do not fit the built-in objects ({e}); net path skipped"));
            None
        }
    }
}

/// Runs the benchmark, printing progress to stderr; the caller prints the report.
pub fn run(args: &EstimatorArgs) -> anyhow::Result<Report> {
    let load_before = loadavg::loadavg();
    let alloc_counting = alloc_count::installed();
    let set = builtin_objects();
    let (frames_to_time, scenes) =
        if args.smoke { (args.frames.min(3), 1) } else { (args.frames.max(1), args.scenes.max(1)) };
    let mut ks = args.objects_per_frame.clone();
    ks.retain(|&k| k >= 1);
    anyhow::ensure!(!ks.is_empty(), "--objects-per-frame needs at least one K >= 1");
    let max_instances = *ks.iter().max().expect("non-empty");
    let mut notes = Vec::new();
    if !alloc_counting {
        notes.push("allocations not counted: the counting allocator is not the global allocator".into());
    }

    let mut net = match args.estimator {
        Which::Net | Which::Both => load_net(args, &set, &mut notes).map(|est| {
            let ws = Workspace::new(est.workspace_config(max_instances)).expect("network workspace config");
            let iters = est.refine_iterations();
            NetPipe { est, ws, iters }
        }),
        Which::Icp => None,
    };
    let mut icp = match args.estimator {
        Which::Icp | Which::Both => {
            let est = IcpEstimator::new(&set, IcpConfig::default()).map_err(|e| anyhow::anyhow!("{e}"))?;
            let ws = Workspace::new(WorkspaceConfig {
                max_instances,
                num_classes: set.len() as u16,
                ..WorkspaceConfig::default()
            })
            .map_err(|e| anyhow::anyhow!("{e}"))?;
            Some(IcpPipe { est, ws })
        }
        Which::Net => None,
    };

    eprintln!("rendering {scenes} frame(s) per K for K in {ks:?} (640x480, noise on) ...");
    let mut all_frames = Vec::new();
    for &k in &ks {
        let frames = frames::render_frames(&set, k, scenes)?;
        for f in &frames {
            if f.instances != k {
                notes.push(format!("K={k}: scene seed {} shows {} of {k} objects", f.seed, f.instances));
            }
        }
        all_frames.push((k, frames));
    }

    let mut rows = Vec::new();
    for (k, frames) in &all_frames {
        eprintln!("timing K={k}: {frames_to_time} frames ...");
        rows.extend(frame_loop::run_k(net.as_mut(), icp.as_mut(), frames, *k, frames_to_time, alloc_counting)?);
    }

    eprintln!("GEMM peak ...");
    let budget = Duration::from_millis(if args.smoke { 20 } else { 400 });
    let gemm = gemm_peak::measure(&gemm_peak::SHAPES, budget);
    let peak_gflops = gemm_peak::peak(&gemm);

    let engine = match net.as_mut() {
        Some(p) => {
            eprintln!("network stages on one thread ...");
            let largest: Vec<&frames::TestFrame> =
                all_frames.last().map(|(_, f)| f.iter().collect()).unwrap_or_default();
            engine_stages::time_stages(p.est.engine(), &mut p.ws, &largest, p.iters, if args.smoke { 1 } else { 3 })
        }
        None => Vec::new(),
    };

    std::fs::create_dir_all(&args.out)?;
    let png = args.out.join("estimator.png");
    let png = match plot::plot_stages(&rows, &png) {
        Ok(()) => Some(png),
        Err(e) => {
            notes.push(format!("plot not written: {e}"));
            None
        }
    };
    let net_threads = net.as_ref().map_or(0, |p| p.est.threads());
    Ok(Report {
        rows,
        gemm,
        peak_gflops,
        engine,
        net_threads,
        notes,
        alloc_counting,
        load_before,
        load_after: loadavg::loadavg(),
        cpus: loadavg::cpus(),
        png,
    })
}
