//! The report as text: the stage table (ms per frame and per object:
//! median / p90 / p99, allocations per frame, GFLOP/s), the GEMM table and
//! the one-thread network stage table, with the machine load.

use std::fmt::Write;

use super::Report;

/// The whole report as printable text.
pub fn render(r: &Report) -> String {
    let mut s = String::new();
    let pct = |g: f64, threads: usize| 100.0 * g / (r.peak_gflops * threads.max(1) as f64);
    let _ = writeln!(s, "fusepose-bench estimator — {} CPUs; loadavg before: {}", r.cpus, r.load_before);
    if r.net_threads > 0 {
        let _ = writeln!(s, "network threads per frame: {}", r.net_threads);
    }
    let _ = writeln!(s);
    let _ = writeln!(
        s,
        "{:<22} {:>2} {:>4} | {:>9} {:>8} {:>8} | {:>9} {:>8} {:>8} | {:>8} | {:>6} | {:>7} {:>5} | {:>7} {:>5}",
        "stage",
        "K",
        "inst",
        "frame ms",
        "p90",
        "p99",
        "object ms",
        "p90",
        "p99",
        "cpu ms",
        "allocs",
        "GFLOP/s",
        "%peak",
        "cpu GF/s",
        "%peak"
    );
    let _ = writeln!(s, "{}", "-".repeat(146));
    let mut last_k = None;
    for row in &r.rows {
        if last_k.is_some_and(|k| k != row.objects) {
            let _ = writeln!(s);
        }
        last_k = Some(row.objects);
        let allocs = match row.allocs_per_frame {
            Some(a) => format!("{a:.1}{}", if row.zero_alloc_promised && a > 0.0 { "!" } else { "" }),
            None => "-".into(),
        };
        let net = row.stage.starts_with("net");
        let threads = if net { r.net_threads } else { 1 };
        let (g, p) = match row.gflops() {
            Some(g) => (format!("{g:.1}"), format!("{:.0}%", pct(g, threads))),
            None => ("-".into(), "-".into()),
        };
        // Thread CPU time covers the caller only: meaningful for one network thread.
        let (cg, cp) = match row.cpu_gflops().filter(|_| threads == 1) {
            Some(g) => (format!("{g:.1}"), format!("{:.0}%", pct(g, 1))),
            None => ("-".into(), "-".into()),
        };
        let _ = writeln!(
            s,
            "{:<22} {:>2} {:>4.1} | {:>9.3} {:>8.3} {:>8.3} | {:>9.3} {:>8.3} {:>8.3} | {:>8.3} | {:>6} | {:>7} {:>5} | {:>7} {:>5}",
            row.stage,
            row.objects,
            row.instances,
            row.frame_ms.median,
            row.frame_ms.p90,
            row.frame_ms.p99,
            row.object_ms.median,
            row.object_ms.p90,
            row.object_ms.p99,
            row.cpu_frame_ms.median,
            allocs,
            g,
            p,
            cg,
            cp
        );
    }
    let _ = writeln!(
        s,
        "(frames per row: {}; ms are wall time, cpu ms = median thread CPU time per frame (caller thread); allocs = mean per frame;\n \
         refiner = per-frame difference pose+refine − pose; %peak against GEMM peak × network threads)",
        r.rows.first().map_or(0, |row| row.frame_ms.count)
    );
    let _ = writeln!(s);
    let _ = writeln!(s, "GEMM (engine kernel gemm_acc, 1 thread)      {:>8} {:>8} {:>8}", "GFLOP/s", "min", "max");
    for g in &r.gemm {
        let sh = g.shape;
        let _ = writeln!(
            s,
            "{:>4}x{:>4}x{:>4}  {:<40} {:>8.1} {:>8.1} {:>8.1}",
            sh.m, sh.k, sh.n, sh.what, g.gflops.median, g.gflops.min, g.gflops.max
        );
    }
    let _ = writeln!(s, "peak (highest median): {:.1} GFLOP/s", r.peak_gflops);
    if !r.engine.is_empty() {
        let _ = writeln!(s);
        let _ = writeln!(
            s,
            "network stages, 1 thread, per object  {:>8} | {:>7} {:>7} {:>7} | {:>7} | {:>7} {:>5} | {:>8} {:>5}",
            "MFLOP", "ms", "p90", "p99", "cpu ms", "GFLOP/s", "%peak", "cpu GF/s", "%peak"
        );
        for e in &r.engine {
            let _ = writeln!(
                s,
                "{:<37} {:>8.1} | {:>7.3} {:>7.3} {:>7.3} | {:>7.3} | {:>7.1} {:>4.0}% | {:>8.1} {:>4.0}%",
                e.name,
                e.flops / 1e6,
                e.ms.median,
                e.ms.p90,
                e.ms.p99,
                e.cpu_ms.median,
                e.gflops(),
                pct(e.gflops(), 1),
                e.cpu_gflops(),
                pct(e.cpu_gflops(), 1)
            );
        }
    }
    if !r.notes.is_empty() {
        let _ = writeln!(s);
        for n in &r.notes {
            let _ = writeln!(s, "note: {n}");
        }
    }
    if let Some(p) = &r.png {
        let _ = writeln!(s, "plot: {}", p.display());
    }
    let _ = writeln!(s, "loadavg after: {}", r.load_after);
    s
}
