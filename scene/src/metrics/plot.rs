//! PNG plots of accuracy–threshold curves (plotters): accuracy in percent
//! against the error threshold from 0 to 10 cm, one line per error list,
//! each labelled with its YCB-Video AUC.

use std::path::Path;

use plotters::prelude::*;

use super::MetricsError;
use super::accuracy::{AUC_MAX_THRESHOLD, accuracy_curve, vocap_auc_percent};

/// Points per curve.
const CURVE_SAMPLES: usize = 400;

/// Draws one accuracy–threshold curve per `(label, errors in metres)` into a
/// 900x600 PNG at `path`. Misses (infinite errors) count as failures.
pub fn plot_accuracy_curves(curves: &[(&str, Vec<f64>)], path: &Path) -> Result<(), MetricsError> {
    let plot_err = |e: &dyn std::fmt::Display| MetricsError::Plot { path: path.to_owned(), message: e.to_string() };
    let root = BitMapBackend::new(path, (900, 600)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| plot_err(&e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption("accuracy vs. error threshold", ("sans-serif", 24))
        .margin(16)
        .x_label_area_size(44)
        .y_label_area_size(56)
        .build_cartesian_2d(0.0..AUC_MAX_THRESHOLD * 100.0, 0.0..100.0)
        .map_err(|e| plot_err(&e))?;
    chart.configure_mesh().x_desc("error threshold (cm)").y_desc("accuracy (%)").draw().map_err(|e| plot_err(&e))?;
    for (i, (label, errors)) in curves.iter().enumerate() {
        let colour = Palette99::pick(i).to_rgba();
        let points = accuracy_curve(errors, AUC_MAX_THRESHOLD, CURVE_SAMPLES).into_iter().map(|(t, a)| (t * 100.0, a));
        let auc = vocap_auc_percent(errors);
        chart
            .draw_series(LineSeries::new(points, colour.stroke_width(2)))
            .map_err(|e| plot_err(&e))?
            .label(format!("{label} (AUC {auc:.1})"))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2)));
    }
    if !curves.is_empty() {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerRight)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(|e| plot_err(&e))?;
    }
    root.present().map_err(|e| plot_err(&e))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_a_png_of_the_requested_size() {
        let dir = std::env::temp_dir().join(format!("fusepose-plot-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("curves.png");
        let a: Vec<f64> = (0..50).map(|i| i as f64 * 0.002).collect();
        let b = vec![0.01, 0.03, f64::INFINITY];
        plot_accuracy_curves(&[("mug", a), ("bowl", b)], &path).unwrap();
        let img = image::open(&path).unwrap();
        assert_eq!((img.width(), img.height()), (900, 600));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn unwritable_path_is_an_error() {
        let r = plot_accuracy_curves(&[("x", vec![0.0])], Path::new("/nonexistent-fusepose/x.png"));
        assert!(matches!(r, Err(MetricsError::Plot { .. })));
    }
}
