//! Single-precision GEMM throughput of the engine's own kernel
//! ([`fusepose_estimator::net::gemm::gemm_acc`], one thread) at the shapes
//! the network runs and one large square shape: the peak the network's
//! achieved GFLOP/s is compared against.

use std::time::{Duration, Instant};

use fusepose_estimator::net::gemm::gemm_acc;
use ndarray::Array2;

use crate::summary::Summary;

/// One GEMM shape `C[m,n] += A[m,k] · B[k,n]` and where the network runs it.
#[derive(Clone, Copy, Debug)]
pub struct GemmShape {
    pub m: usize,
    pub k: usize,
    pub n: usize,
    pub what: &'static str,
}

/// The shapes measured: network layers at N = 256 points, S = 64 crop
/// (the default architecture), then a large square one. Two diagnostics
/// repeat a shape with 1040 instead of 1024 columns: a B row stride of
/// 4160 B instead of exactly 4 KiB, which the unpacked kernel is sensitive
/// to (cache-set aliasing of the streamed B panel).
pub const SHAPES: [GemmShape; 8] = [
    GemmShape { m: 256, k: 896, n: 256, what: "reference 256x896x256" },
    GemmShape { m: 256, k: 384, n: 256, what: "pose.h1_local (N x local x trunk0)" },
    GemmShape { m: 256, k: 256, n: 512, what: "pose.l2 (N x lift0 x lift1)" },
    GemmShape { m: 256, k: 64, n: 128, what: "pose.g2 (N x geo0 x geo1)" },
    GemmShape { m: 32, k: 864, n: 1024, what: "cnn.d1 conv (emb x 96*9 x 32*32)" },
    GemmShape { m: 32, k: 864, n: 1040, what: "cnn.d1 shape, B row stride 4160 B" },
    GemmShape { m: 1024, k: 1024, n: 1024, what: "large square" },
    GemmShape { m: 1024, k: 1024, n: 1040, what: "large, B row stride 4160 B" },
];

/// Throughput of one shape.
#[derive(Clone, Debug)]
pub struct GemmPoint {
    pub shape: GemmShape,
    /// GFLOP/s per call (2·m·k·n FLOPs).
    pub gflops: Summary,
}

/// Times each shape for about `budget` (at least 3 calls after one warm-up call).
pub fn measure(shapes: &[GemmShape], budget: Duration) -> Vec<GemmPoint> {
    shapes
        .iter()
        .map(|&shape| {
            let GemmShape { m, k, n, .. } = shape;
            let a = Array2::from_shape_fn((m, k), |(i, j)| ((i * 7 + j * 3) % 11) as f32 * 1e-3);
            let b = Array2::from_shape_fn((k, n), |(i, j)| ((i * 5 + j) % 13) as f32 * 1e-3);
            let mut c = Array2::<f32>::zeros((m, n));
            let flops = 2.0 * (m * k * n) as f64;
            gemm_acc(a.view(), b.view(), &mut c.view_mut());
            let mut rates = Vec::new();
            let start = Instant::now();
            while rates.len() < 3 || start.elapsed() < budget {
                let t = Instant::now();
                gemm_acc(a.view(), b.view(), &mut c.view_mut());
                rates.push(flops / t.elapsed().as_secs_f64() / 1e9);
            }
            std::hint::black_box(&c);
            GemmPoint { shape, gflops: Summary::of(&rates).expect("at least 3 calls") }
        })
        .collect()
}

/// The peak: the highest median GFLOP/s over the measured shapes.
pub fn peak(points: &[GemmPoint]) -> f64 {
    points.iter().map(|p| p.gflops.median).fold(0.0, f64::max)
}
