//! Accuracy–threshold statistics over lists of pose errors (metres): the
//! YCB-Video AUC (`VOCap`), accuracy below a threshold, and curve points.
//!
//! A missed object is scored with error `f64::INFINITY`; NaN errors are
//! treated as failures too.

/// The largest threshold of the YCB-Video AUC (metres).
pub const AUC_MAX_THRESHOLD: f64 = 0.1;

/// The "< 2 cm" accuracy threshold (metres).
pub const ADD_S_THRESHOLD_2CM: f64 = 0.02;

/// Area under the accuracy–threshold curve for thresholds 0..0.1 m, in
/// percent, computed exactly as the YCB_Video_toolbox does
/// (`plot_accuracy_keyframe.m` + `VOCap`):
///
/// ```matlab
/// rec(rec > 0.1) = inf; rec = sort(rec); n = numel(rec); prec = (1:n)'/n;
/// index = find(rec <= 0.1); rec = rec(index); prec = prec(index);
/// mrec = [0; rec; 0.1]; mpre = [0; prec; prec(end)];
/// for i = 2:numel(mpre), mpre(i) = max(mpre(i), mpre(i-1)); end
/// i = find(mrec(2:end) ~= mrec(1:end-1)) + 1;
/// ap = sum((mrec(i) - mrec(i-1)) .* mpre(i)) * 10;
/// ```
///
/// Each step of the curve is weighted by the accuracy at its right end, so a
/// list of `n` errors scores up to `100 / n` points above the exact area (one
/// error of 0.05 m scores 100). Errors above 0.1 m, infinite or NaN count in
/// `n` as failures. An empty list, or one with no error ≤ 0.1 m, scores 0.
pub fn vocap_auc_percent(errors: &[f64]) -> f64 {
    let n = errors.len();
    // rec(rec > 0.1) = inf; rec = sort(rec); (NaN sorts last in MATLAB and
    // fails `rec <= 0.1`, exactly like inf.)
    let mut rec: Vec<f64> =
        errors.iter().map(|&e| if e.is_nan() || e > AUC_MAX_THRESHOLD { f64::INFINITY } else { e }).collect();
    rec.sort_by(f64::total_cmp);
    // prec = (1:n)'/n; index = find(rec <= 0.1);
    let kept: Vec<(f64, f64)> = rec
        .iter()
        .enumerate()
        .filter(|&(_, &r)| r <= AUC_MAX_THRESHOLD)
        .map(|(i, &r)| (r, (i + 1) as f64 / n as f64))
        .collect();
    let Some(&(_, last_prec)) = kept.last() else {
        return 0.0;
    };
    // mrec = [0; rec; 0.1]; mpre = [0; prec; prec(end)];
    let mut mrec = Vec::with_capacity(kept.len() + 2);
    let mut mpre = Vec::with_capacity(kept.len() + 2);
    mrec.push(0.0);
    mpre.push(0.0);
    for &(r, p) in &kept {
        mrec.push(r);
        mpre.push(p);
    }
    mrec.push(AUC_MAX_THRESHOLD);
    mpre.push(last_prec);
    // mpre(i) = max(mpre(i), mpre(i-1))
    for i in 1..mpre.len() {
        mpre[i] = mpre[i].max(mpre[i - 1]);
    }
    // i = find(mrec(2:end) ~= mrec(1:end-1)) + 1; ap = sum(...) * 10
    let mut ap = 0.0;
    for i in 1..mrec.len() {
        if mrec[i] != mrec[i - 1] {
            ap += (mrec[i] - mrec[i - 1]) * mpre[i];
        }
    }
    ap * 10.0 * 100.0
}

/// The percentage of errors strictly below `threshold` (metres), as the
/// toolbox's `numel(d(d < 0.02)) / n`. Misses (infinite) and NaN count as
/// failures; an empty list gives 0.
pub fn accuracy_below_percent(errors: &[f64], threshold: f64) -> f64 {
    if errors.is_empty() {
        return 0.0;
    }
    let hits = errors.iter().filter(|&&e| e < threshold).count();
    100.0 * hits as f64 / errors.len() as f64
}

/// Points of the accuracy–threshold curve for plotting: `samples + 1` pairs
/// `(threshold in metres, percent of errors ≤ threshold)` at evenly spaced
/// thresholds from 0 to `max_threshold` inclusive. An empty list gives 0 %
/// everywhere; `samples` of 0 is taken as 1.
pub fn accuracy_curve(errors: &[f64], max_threshold: f64, samples: usize) -> Vec<(f64, f64)> {
    let samples = samples.max(1);
    let mut sorted: Vec<f64> = errors.iter().map(|&e| if e.is_nan() { f64::INFINITY } else { e }).collect();
    sorted.sort_by(f64::total_cmp);
    (0..=samples)
        .map(|k| {
            let t = max_threshold * k as f64 / samples as f64;
            let hits = sorted.partition_point(|&e| e <= t);
            let acc = if sorted.is_empty() { 0.0 } else { 100.0 * hits as f64 / sorted.len() as f64 };
            (t, acc)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-9
    }

    #[test]
    fn all_zero_errors_score_100() {
        assert!(close(vocap_auc_percent(&[0.0, 0.0, 0.0]), 100.0));
    }

    #[test]
    fn all_failures_score_0() {
        assert_eq!(vocap_auc_percent(&[0.1000001, 0.5, f64::INFINITY]), 0.0);
        assert_eq!(vocap_auc_percent(&[f64::NAN]), 0.0);
    }

    #[test]
    fn empty_list_scores_0() {
        assert_eq!(vocap_auc_percent(&[]), 0.0);
        assert_eq!(accuracy_below_percent(&[], 0.02), 0.0);
    }

    #[test]
    fn two_errors_zero_and_five_cm() {
        // mrec = [0 0 .05 .1], mpre = [0 .5 1 1]; steps at i = 3, 4:
        // (.05 - 0) * 1 + (.1 - .05) * 1 = .1; * 10 -> 1 -> 100 %.
        assert!(close(vocap_auc_percent(&[0.05, 0.0]), 100.0));
    }

    #[test]
    fn four_errors_evenly_spaced() {
        // mrec = [0 .02 .04 .06 .08 .1], mpre = [0 .25 .5 .75 1 1]:
        // .02 * (.25 + .5 + .75 + 1 + 1) = .07 -> 70 %.
        assert!(close(vocap_auc_percent(&[0.08, 0.02, 0.06, 0.04]), 70.0));
        // Errors k * 0.1 / n for k = 1..n score 50 (n + 1) / n: here n = 4 -> 62.5,
        // with the last error exactly at 0.1 m counted as a success.
        assert!(close(vocap_auc_percent(&[0.025, 0.05, 0.075, 0.1]), 62.5));
    }

    #[test]
    fn uniform_errors_approach_50() {
        let n = 1000;
        let errors: Vec<f64> = (1..=n).map(|k| 0.1 * k as f64 / n as f64).collect();
        let expected = 50.0 * (n + 1) as f64 / n as f64;
        assert!((vocap_auc_percent(&errors) - expected).abs() < 1e-6);
    }

    #[test]
    fn a_miss_counts_as_a_failure() {
        // rec = [.05 inf]: n = 2, only .05 kept with prec .5;
        // mrec = [0 .05 .1], mpre = [0 .5 .5] -> (.05 + .05) * .5 * 10 = .5 -> 50 %.
        assert!(close(vocap_auc_percent(&[0.05, f64::INFINITY]), 50.0));
        assert!(close(vocap_auc_percent(&[0.05, 0.2]), 50.0));
        assert!(close(vocap_auc_percent(&[0.0, f64::INFINITY]), 50.0));
    }

    #[test]
    fn ties_take_the_precision_of_the_first_tied_entry() {
        // rec = [.05 .05]: mrec = [0 .05 .05 .1], mpre = [0 .5 1 1];
        // steps at i = 2 (width .05, mpre .5) and i = 4 (width .05, mpre 1):
        // .025 + .05 = .075 -> 75 %.
        assert!(close(vocap_auc_percent(&[0.05, 0.05]), 75.0));
    }

    #[test]
    fn accuracy_below_is_strict() {
        let e = [0.0, 0.019, 0.02, 0.03, f64::INFINITY];
        assert!(close(accuracy_below_percent(&e, 0.02), 40.0));
    }

    #[test]
    fn curve_counts_errors_at_or_below_each_threshold() {
        let c = accuracy_curve(&[0.0, 0.05, f64::INFINITY, f64::NAN], 0.1, 4);
        let expected = [(0.0, 25.0), (0.025, 25.0), (0.05, 50.0), (0.075, 50.0), (0.1, 50.0)];
        assert_eq!(c.len(), expected.len());
        for ((t, a), (et, ea)) in c.iter().zip(expected) {
            assert!(close(*t, et) && close(*a, ea), "{t} {a}");
        }
        assert!(accuracy_curve(&[], 0.1, 2).iter().all(|&(_, a)| a == 0.0));
    }
}
