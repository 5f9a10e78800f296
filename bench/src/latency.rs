//! Latency samples in HdrHistograms (ns): percentiles for the tables, the
//! `.hlog` interval log (one tagged interval per series) and a percentile plot.

use std::path::Path;

use hdrhistogram::Histogram;
use plotters::prelude::*;

/// A new histogram for 1 ns .. 100 s at 3 significant digits.
pub fn histogram() -> Histogram<u64> {
    Histogram::new_with_bounds(1, 100_000_000_000, 3).expect("constant histogram bounds are valid")
}

/// The percentiles every latency table prints, ns.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Percentiles {
    pub count: u64,
    pub p50_ns: u64,
    pub p99_ns: u64,
    pub p999_ns: u64,
    pub max_ns: u64,
}

impl Percentiles {
    pub fn of(h: &Histogram<u64>) -> Self {
        Self {
            count: h.len(),
            p50_ns: h.value_at_quantile(0.5),
            p99_ns: h.value_at_quantile(0.99),
            p999_ns: h.value_at_quantile(0.999),
            max_ns: h.max(),
        }
    }

    /// The table values in the given unit (ns per unit, e.g. 1e3 for µs).
    pub fn scaled(&self, ns_per_unit: f64) -> [f64; 4] {
        [self.p50_ns, self.p99_ns, self.p999_ns, self.max_ns].map(|v| v as f64 / ns_per_unit)
    }
}

/// Writes one interval per `(tag, histogram)` to an HdrHistogram interval log.
pub fn write_hlog(
    path: &Path,
    comment: &str,
    series: &[(String, &Histogram<u64>)],
    duration_ns: u64,
) -> anyhow::Result<()> {
    let mut log = fusepose_daemon::interval_log::IntervalLog::create(path, 0, comment)
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    for (tag, h) in series {
        log.write(tag, 0, duration_ns, h).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    }
    Ok(())
}

/// Percentile plot (p50 … max on x, log latency in `unit` on y), one line per series.
pub fn plot_percentiles(
    path: &Path,
    title: &str,
    unit: &str,
    ns_per_unit: f64,
    series: &[(String, Percentiles)],
) -> anyhow::Result<()> {
    let err = |e: &dyn std::fmt::Display| anyhow::anyhow!("{}: {e}", path.display());
    let labels = ["p50", "p99", "p99.9", "max"];
    let values: Vec<f64> = series.iter().flat_map(|(_, p)| p.scaled(ns_per_unit)).filter(|v| *v > 0.0).collect();
    let y_min = values.iter().copied().fold(f64::INFINITY, f64::min).clamp(1e-3, 1.0) * 0.5;
    let y_max = values.iter().copied().fold(0.0, f64::max).max(y_min * 10.0) * 2.0;
    let root = BitMapBackend::new(path, (900, 600)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 22))
        .margin(16)
        .x_label_area_size(44)
        .y_label_area_size(70)
        .build_cartesian_2d(-0.3f64..3.3f64, (y_min..y_max).log_scale())
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_labels(4)
        .x_label_formatter(&|x| labels.get(x.round() as usize).map_or(String::new(), |s| s.to_string()))
        .x_desc("percentile")
        .y_desc(format!("latency ({unit}, log scale)"))
        .draw()
        .map_err(|e| err(&e))?;
    for (i, (name, p)) in series.iter().enumerate() {
        let colour = Palette99::pick(i).to_rgba();
        let points: Vec<(f64, f64)> =
            p.scaled(ns_per_unit).iter().enumerate().map(|(x, &v)| (x as f64, v.max(y_min))).collect();
        chart
            .draw_series(LineSeries::new(points.clone(), colour.stroke_width(2)))
            .map_err(|e| err(&e))?
            .label(name.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2)));
        chart.draw_series(points.iter().map(|&p| Circle::new(p, 3, colour.filled()))).map_err(|e| err(&e))?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))?;
    Ok(())
}
