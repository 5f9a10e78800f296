//! Per-instance scores of the masks an estimator got: each predicted
//! instance region against the dataset's ground-truth instance masks.
//!
//! A prediction and a ground-truth instance match when their IoU exceeds
//! 0.5 (then the pairing is unique). A ground-truth instance is *merged* when
//! the prediction covering most of it also covers at least half of another
//! ground-truth instance, and *split* when two or more predictions each cover
//! at least a fifth of it. Ground-truth instances with fewer than
//! [`MIN_TRUTH_PIXELS`] visible pixels are left out (no mask could find them).

use std::collections::HashMap;

/// Smallest ground-truth instance counted, visible pixels.
pub const MIN_TRUTH_PIXELS: u32 = 100;

/// Accumulated instance counts over frames.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct InstanceCounts {
    pub truth: usize,
    pub predicted: usize,
    pub matched: usize,
    pub merged: usize,
    pub split: usize,
}

impl InstanceCounts {
    /// Adds one frame: `truth` and `pred` are per-pixel instance ids (0 = none)
    /// of the ground truth and of the predicted regions; `predicted` lists the
    /// predicted region ids that became instances.
    pub fn add_frame(&mut self, truth: &[u16], pred: &[u32], predicted: &[u32]) {
        let mut truth_px: HashMap<u16, u32> = HashMap::new();
        let mut pred_px: HashMap<u32, u32> = HashMap::new();
        let mut overlap: HashMap<(u32, u16), u32> = HashMap::new();
        for (&t, &p) in truth.iter().zip(pred) {
            let p = if p != 0 && predicted.contains(&p) { p } else { 0 };
            if t != 0 {
                *truth_px.entry(t).or_default() += 1;
            }
            if p != 0 {
                *pred_px.entry(p).or_default() += 1;
                if t != 0 {
                    *overlap.entry((p, t)).or_default() += 1;
                }
            }
        }
        let counted: Vec<u16> = truth_px.iter().filter(|&(_, &n)| n >= MIN_TRUTH_PIXELS).map(|(&t, _)| t).collect();
        self.truth += counted.len();
        self.predicted += pred_px.len();
        let ov = |p: u32, t: u16| overlap.get(&(p, t)).copied().unwrap_or(0);
        for &p in pred_px.keys() {
            let matched = counted.iter().any(|&t| {
                let inter = ov(p, t);
                let union = pred_px[&p] + truth_px[&t] - inter;
                inter as f64 > 0.5 * union as f64
            });
            self.matched += matched as usize;
        }
        for &t in &counted {
            let tp = truth_px[&t] as f64;
            let covering: Vec<(u32, u32)> =
                pred_px.keys().map(|&p| (p, ov(p, t))).filter(|&(_, n)| n as f64 >= 0.2 * tp).collect();
            if covering.len() >= 2 {
                self.split += 1;
            }
            let Some(&(main, _)) = covering.iter().max_by_key(|&&(_, n)| n) else { continue };
            let merged = counted.iter().any(|&o| o != t && ov(main, o) as f64 >= 0.5 * truth_px[&o] as f64);
            self.merged += merged as usize;
        }
    }

    pub fn precision(&self) -> f64 {
        self.matched as f64 / self.predicted.max(1) as f64
    }

    pub fn recall(&self) -> f64 {
        self.matched as f64 / self.truth.max(1) as f64
    }

    /// One line for the report.
    pub fn summary(&self) -> String {
        format!(
            "instances: {} true, {} predicted, {} matched (IoU > 0.5): precision {:.3}, recall {:.3}; merged {} ({:.1} %), split {} ({:.1} %)",
            self.truth,
            self.predicted,
            self.matched,
            self.precision(),
            self.recall(),
            self.merged,
            100.0 * self.merged as f64 / self.truth.max(1) as f64,
            self.split,
            100.0 * self.split as f64 / self.truth.max(1) as f64
        )
    }

    pub fn json(&self) -> serde_json::Value {
        serde_json::json!({
            "truth": self.truth, "predicted": self.predicted, "matched": self.matched,
            "precision": self.precision(), "recall": self.recall(), "merged": self.merged, "split": self.split,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 40x10 frame: truth instances 1 (x < 20) and 2 (x >= 20), 200 px each.
    fn truth() -> Vec<u16> {
        (0..400).map(|i| if i % 40 < 20 { 1 } else { 2 }).collect()
    }

    #[test]
    fn two_predictions_for_two_objects_match_both() {
        let pred: Vec<u32> = truth().iter().map(|&t| t as u32 + 10).collect();
        let mut c = InstanceCounts::default();
        c.add_frame(&truth(), &pred, &[11, 12]);
        assert_eq!(c, InstanceCounts { truth: 2, predicted: 2, matched: 2, merged: 0, split: 0 });
    }

    #[test]
    fn one_prediction_over_two_touching_objects_is_a_merge() {
        let pred = vec![7u32; 400];
        let mut c = InstanceCounts::default();
        c.add_frame(&truth(), &pred, &[7]);
        assert_eq!(c, InstanceCounts { truth: 2, predicted: 1, matched: 0, merged: 2, split: 0 });
    }

    #[test]
    fn an_object_cut_in_two_predictions_is_a_split_and_unlisted_regions_do_not_count() {
        // Object 1 split into 3 (x < 10) and 4 (10 <= x < 20); object 2 found as 5.
        let pred: Vec<u32> = (0..400)
            .map(|i| {
                if i % 40 < 10 {
                    3
                } else if i % 40 < 20 {
                    4
                } else {
                    5
                }
            })
            .collect();
        let mut c = InstanceCounts::default();
        c.add_frame(&truth(), &pred, &[3, 4, 5]);
        assert_eq!(c, InstanceCounts { truth: 2, predicted: 3, matched: 1, merged: 0, split: 1 });
        let mut d = InstanceCounts::default();
        d.add_frame(&truth(), &pred, &[5]);
        assert_eq!(d, InstanceCounts { truth: 2, predicted: 1, matched: 1, merged: 0, split: 0 });
    }
}
