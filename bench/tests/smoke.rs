//! The `estimator --smoke` path, run in-process: it must produce a table of
//! finite positive numbers, and zero allocations per steady-state frame for
//! every stage the estimator crate promises allocation-free. No timing
//! thresholds.

use fusepose_bench::alloc_count::CountingAlloc;
use fusepose_bench::estimator::{self, EstimatorArgs, Which};

#[global_allocator]
static ALLOC: CountingAlloc = CountingAlloc;

#[test]
fn smoke_produces_finite_positive_table_without_steady_state_allocations() {
    let out = std::env::temp_dir().join(format!("fusepose-bench-smoke-{}", std::process::id()));
    let args = EstimatorArgs {
        estimator: Which::Both,
        random_weights: true,
        objects_per_frame: vec![1, 3],
        smoke: true,
        out: out.clone(),
        ..EstimatorArgs::default()
    };
    let report = estimator::run(&args).expect("smoke run");
    let text = estimator::table::render(&report);
    println!("{text}");

    assert!(report.alloc_counting, "the counting allocator is installed in this test");
    let stages: Vec<&str> = report.rows.iter().map(|r| r.stage.as_str()).collect();
    for want in ["net pose", "net pose+refine", "icp"] {
        assert!(stages.contains(&want), "{want} missing from {stages:?}");
    }
    for row in &report.rows {
        assert!(row.frame_ms.is_finite() && row.object_ms.is_finite() && row.cpu_frame_ms.is_finite(), "{row:?}");
        assert!(row.instances > 0.0, "{row:?}");
        // The refiner row is a difference of two timings and may dip to 0 or below.
        if !row.stage.starts_with("net refiner") {
            assert!(row.frame_ms.min > 0.0 && row.object_ms.min > 0.0, "{row:?}");
        }
        if row.zero_alloc_promised {
            assert_eq!(row.allocs_per_frame, Some(0.0), "{} at K={} allocates", row.stage, row.objects);
        }
        if let Some(g) = row.gflops() {
            assert!(g.is_finite() && g > 0.0 || row.stage.starts_with("net refiner"), "{row:?}");
        }
    }
    assert!(report.peak_gflops.is_finite() && report.peak_gflops > 0.0);
    assert!(report.gemm.iter().all(|g| g.gflops.is_finite() && g.gflops.min > 0.0));
    assert_eq!(report.engine.len(), 3);
    assert!(report.engine.iter().all(|e| e.ms.is_finite() && e.ms.min > 0.0 && e.cpu_ms.is_finite() && e.flops > 0.0));
    assert!(report.png.as_ref().is_some_and(|p| p.exists()), "PNG written");
    assert!(text.contains("loadavg before") && text.contains("loadavg after"));
    let _ = std::fs::remove_dir_all(out);
}
