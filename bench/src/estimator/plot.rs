//! PNG plot: median milliseconds per frame against objects per frame, one
//! line per stage (the p90 as a thin second line), log-scale y so that the
//! sub-millisecond sampling and the ICP's hundreds of milliseconds share it.
//! Non-positive values (a refiner difference lost in noise) are left out.

use std::path::Path;

use plotters::prelude::*;

use super::frame_loop::StageRow;

/// Draws `rows` into a 900×600 PNG at `path`.
pub fn plot_stages(rows: &[StageRow], path: &Path) -> anyhow::Result<()> {
    let err = |e: &dyn std::fmt::Display| anyhow::anyhow!("{}: {e}", path.display());
    let mut stages: Vec<&str> = Vec::new();
    for r in rows {
        if !stages.contains(&r.stage.as_str()) {
            stages.push(&r.stage);
        }
    }
    let k_max = rows.iter().map(|r| r.objects).max().unwrap_or(1) as f64;
    let positive = rows.iter().flat_map(|r| [r.frame_ms.median, r.frame_ms.p90]).filter(|&v| v > 0.0);
    let y_min = positive.clone().fold(f64::INFINITY, f64::min).clamp(1e-3, 1.0) * 0.5;
    let y_max = positive.fold(0.0, f64::max).max(y_min * 10.0) * 2.0;
    let root = BitMapBackend::new(path, (900, 600)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption("estimator stages: ms per frame vs objects per frame", ("sans-serif", 22))
        .margin(16)
        .x_label_area_size(44)
        .y_label_area_size(64)
        .build_cartesian_2d(0.0..k_max + 0.5, (y_min..y_max).log_scale())
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc("objects per frame")
        .y_desc("ms per frame (median; thin: p90; log scale)")
        .draw()
        .map_err(|e| err(&e))?;
    for (i, stage) in stages.iter().enumerate() {
        let colour = Palette99::pick(i).to_rgba();
        let mine: Vec<&StageRow> = rows.iter().filter(|r| r.stage == *stage).collect();
        let points = |f: fn(&StageRow) -> f64| -> Vec<(f64, f64)> {
            mine.iter().map(|r| (r.objects as f64, f(r))).filter(|&(_, v)| v > 0.0).collect()
        };
        let median = points(|r| r.frame_ms.median);
        let p90 = points(|r| r.frame_ms.p90);
        chart
            .draw_series(LineSeries::new(median.clone(), colour.stroke_width(2)))
            .map_err(|e| err(&e))?
            .label(*stage)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2)));
        chart.draw_series(median.iter().map(|&p| Circle::new(p, 3, colour.filled()))).map_err(|e| err(&e))?;
        chart.draw_series(LineSeries::new(p90, colour.mix(0.5).stroke_width(1))).map_err(|e| err(&e))?;
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
