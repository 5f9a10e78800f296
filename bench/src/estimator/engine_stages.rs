//! The network's stages timed one by one on the engine's public API, one
//! thread, per object: colour branch (CNN + per-point embedding), pose net
//! (PointNet fusion + heads), refiner (colour features + `iters` iterations),
//! each with its FLOPs (from the hyper-parameters in the weight file's
//! metadata, [`NetConfig::flops_per_object`]) and achieved GFLOP/s.

use std::time::Instant;

use fusepose_estimator::Workspace;
use fusepose_estimator::net::{Engine, NetConfig, Scratch};
use nalgebra::{Matrix3, Vector3};
use ndarray::s;

use super::frames::TestFrame;
use crate::cpu_time::thread_cpu_ms;
use crate::summary::Summary;

/// One stage of the network, per object.
#[derive(Clone, Debug)]
pub struct EngineStage {
    pub name: &'static str,
    /// FLOPs per object (2 per multiply-add).
    pub flops: f64,
    /// Milliseconds per object (wall).
    pub ms: Summary,
    /// Milliseconds of thread CPU time per object.
    pub cpu_ms: Summary,
}

impl EngineStage {
    /// Achieved GFLOP/s at the median time.
    pub fn gflops(&self) -> f64 {
        self.flops / (self.ms.median * 1e-3) / 1e9
    }

    /// Achieved GFLOP/s at the median CPU time.
    pub fn cpu_gflops(&self) -> f64 {
        self.flops / (self.cpu_ms.median * 1e-3) / 1e9
    }
}

/// FLOPs of the colour branch alone (the `cnn` term of [`NetConfig::flops_per_object`]).
pub fn colour_flops(c: &NetConfig, n: usize, s: usize) -> f64 {
    let [c1, c2, c3] = c.cnn;
    let (s1, s2, s4) = ((s * s) as f64, ((s / 2) * (s / 2)) as f64, ((s / 4) * (s / 4)) as f64);
    let f = |v: usize| v as f64;
    2.0 * (s1 * f(c1 * 27)
        + s2 * f(c2 * c1 * 9)
        + s4 * f(c3 * c2 * 9 + c3 * c3 * 9)
        + s2 * f(c.emb * (c3 + c2) * 9)
        + n as f64 * f((c.emb + c1) * c.emb))
}

/// Runs every instance of `frames` (prepared into `ws`) through the stages
/// `rounds` times; `iters` refiner iterations.
pub fn time_stages(
    engine: &Engine,
    ws: &mut Workspace,
    frames: &[&TestFrame],
    iters: usize,
    rounds: usize,
) -> Vec<EngineStage> {
    let c = &engine.config;
    let (n, s) = (ws.config.num_points, ws.config.crop_size);
    let mut sc = Scratch::new(c, n, s);
    // (wall ms, cpu ms) per object and stage.
    let (mut colour, mut pose, mut refine) = (Vec::new(), Vec::new(), Vec::new());
    for round in 0..rounds + 1 {
        for (f, frame) in frames.iter().enumerate() {
            if ws.prepare(&frame.view(), f as u64).is_err() {
                continue;
            }
            for i in 0..ws.instances.len() {
                let k = ws.instances[i].class_id as usize - 1;
                engine.set_inputs(
                    &mut sc,
                    ws.crops.slice(s![i, .., .., ..]),
                    ws.points.slice(s![i, .., ..]),
                    ws.choose.slice(s![i, ..]),
                );
                let (c0, t0) = (thread_cpu_ms(), Instant::now());
                engine.color(&mut sc);
                let (c1, t1) = (thread_cpu_ms(), Instant::now());
                let best = engine.pose(&mut sc, k);
                let (c2, t2) = (thread_cpu_ms(), Instant::now());
                let mut rot = Matrix3::identity();
                let mut t = Vector3::new(sc.trans[[best, 0]], sc.trans[[best, 1]], sc.trans[[best, 2]]);
                if iters > 0 {
                    engine.refine_color(&mut sc);
                    for _ in 0..iters {
                        (rot, t) = engine.refine(&mut sc, k, &rot, &t);
                    }
                }
                let (c3, t3) = (thread_cpu_ms(), Instant::now());
                std::hint::black_box((rot, t));
                if round > 0 {
                    colour.push(((t1 - t0).as_secs_f64() * 1e3, c1 - c0));
                    pose.push(((t2 - t1).as_secs_f64() * 1e3, c2 - c1));
                    refine.push(((t3 - t2).as_secs_f64() * 1e3, c3 - c2));
                }
            }
        }
    }
    let f_colour = colour_flops(c, n, s);
    let f_pose_net = c.flops_per_object(n, s, 0);
    let f_full = c.flops_per_object(n, s, iters);
    let stage = |name, flops, v: &[(f64, f64)]| {
        let wall: Vec<f64> = v.iter().map(|x| x.0).collect();
        let cpu: Vec<f64> = v.iter().map(|x| x.1).collect();
        Some(EngineStage { name, flops, ms: Summary::of(&wall)?, cpu_ms: Summary::of(&cpu)? })
    };
    [
        stage("colour branch", f_colour, &colour),
        stage("pose net", f_pose_net - f_colour, &pose),
        stage("refiner", f_full - f_pose_net, &refine),
    ]
    .into_iter()
    .flatten()
    .collect()
}
