//! Pose metrics: ADD, ADD-S and ADD(S) per estimate, the YCB-Video area under
//! the accuracy–threshold curve (AUC up to 0.1 m, computed as the
//! YCB_Video_toolbox `VOCap` does), accuracy below 2 cm, per-object tables, and
//! the BOP results CSV.
//!
//! All distances are in metres; AUC and accuracies are reported in percent.
//!
//! Typical use:
//! ```
//! use fusepose_scene::metrics::{ObjectMetric, MetricsTable};
//! use fusepose_scene::Pose;
//! use nalgebra::{Point3, Translation3};
//!
//! let points = vec![Point3::new(0.0, 0.0, 0.0), Point3::new(0.1, 0.0, 0.0)];
//! let metric = ObjectMetric::new(&points, false).unwrap();
//! let truth = Pose::identity();
//! let estimate = Pose::from_parts(Translation3::new(0.01, 0.0, 0.0), Default::default());
//! let mut table = MetricsTable::new(vec![(1, "bar".to_string())]);
//! table.record(1, Some(metric.errors(&estimate, &truth)));
//! table.record(1, None); // a missed detection counts as a failure
//! assert_eq!(table.overall().count, 2);
//! ```

mod accuracy;
mod bop_results;
mod error;
mod plot;
mod pose_error;
mod table;

pub use accuracy::{ADD_S_THRESHOLD_2CM, AUC_MAX_THRESHOLD, accuracy_below_percent, accuracy_curve, vocap_auc_percent};
pub use bop_results::{BopResult, BopResultsWriter};
pub use error::MetricsError;
pub use plot::plot_accuracy_curves;
pub use pose_error::{ObjectMetric, PoseErrors, add, add_s};
pub use table::{MetricsRow, MetricsTable};
