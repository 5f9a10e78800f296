//! Class-weighted per-pixel cross-entropy, and the class weights: inverse
//! pixel frequency raised to a power (0.5 by default), so small objects are not
//! drowned by the background; optionally each object region's cells are
//! weighted up the fewer they are, so a partly hidden object is not traded
//! away for a cleaner background.

use burn::prelude::{Int, Tensor, TensorData};
use burn::tensor::activation::{log_sigmoid, log_softmax};

pub use super::adapt::IGNORE;

/// Per-class weights `(1 / freq_c)^power` from pixel counts (one per output
/// channel, background first), scaled so the pixel-weighted mean is 1; every
/// class gets at least one pseudo-count and the ratio of largest to smallest
/// weight is capped at `max_ratio`.
pub fn class_weights(counts: &[u64], power: f64, max_ratio: f64) -> Vec<f32> {
    let total: f64 = counts.iter().map(|&c| c as f64 + 1.0).sum();
    let freq: Vec<f64> = counts.iter().map(|&c| (c as f64 + 1.0) / total).collect();
    let raw: Vec<f64> = freq.iter().map(|f| f.powf(-power)).collect();
    let min = raw.iter().cloned().fold(f64::INFINITY, f64::min);
    let capped: Vec<f64> = raw.iter().map(|&w| w.min(min * max_ratio.max(1.0))).collect();
    let mean: f64 = capped.iter().zip(&freq).map(|(w, f)| w * f).sum();
    capped.iter().map(|w| (w / mean) as f32).collect()
}

/// Per-cell weight multipliers that lift small object regions: every
/// 4-connected region of one non-zero class in each `w`×`h` target image gets
/// `clamp(sqrt(reference_cells / cells), 1, max_boost)` on each of its cells;
/// background cells get 1. `max_boost <= 1` gives all ones.
pub fn small_region_weights(target: &[u16], w: usize, h: usize, reference_cells: f32, max_boost: f32) -> Vec<f32> {
    let mut out = vec![1.0f32; target.len()];
    if max_boost <= 1.0 || w == 0 || h == 0 {
        return out;
    }
    let mut seen = vec![false; target.len()];
    let (mut stack, mut members) = (Vec::new(), Vec::new());
    for start in 0..target.len() {
        let class = target[start];
        if class == 0 || seen[start] {
            continue;
        }
        // Images are stacked: neighbours never cross into the next image.
        let image = start / (w * h);
        let base = image * w * h;
        members.clear();
        stack.push(start);
        seen[start] = true;
        while let Some(i) = stack.pop() {
            members.push(i);
            let (x, y) = ((i - base) % w, (i - base) / w);
            let mut visit = |j: usize| {
                if target[j] == class && !seen[j] {
                    seen[j] = true;
                    stack.push(j);
                }
            };
            if x > 0 {
                visit(i - 1);
            }
            if x + 1 < w {
                visit(i + 1);
            }
            if y > 0 {
                visit(i - w);
            }
            if y + 1 < h {
                visit(i + w);
            }
        }
        let boost = (reference_cells / members.len() as f32).sqrt().clamp(1.0, max_boost);
        for &i in &members {
            out[i] = boost;
        }
    }
    out
}

/// Weighted cross-entropy: `-Σ w[t_i] log softmax(logits)_i[t_i] / Σ w[t_i]` over all cells
/// but those of class [`IGNORE`].
/// `logits [B, C, H, W]`, `target` `B*H*W` class ids (`< C`), `weights` `C` values.
pub fn weighted_cross_entropy(logits: Tensor<4>, target: &[u16], weights: &[f32]) -> Tensor<1> {
    weighted_cross_entropy_scaled(logits, target, weights, None)
}

/// [`weighted_cross_entropy`] with each cell's class weight multiplied by
/// `scale[i]` (`B*H*W` values, e.g. [`small_region_weights`]).
pub fn weighted_cross_entropy_scaled(
    logits: Tensor<4>,
    target: &[u16],
    weights: &[f32],
    scale: Option<&[f32]>,
) -> Tensor<1> {
    let [b, _, h, w] = logits.dims();
    let device = logits.device();
    // Cells of unknown class (pseudo-labels) gather class 0 at weight 0.
    let idx = Tensor::<4, Int>::from_data(
        TensorData::new(
            target.iter().map(|&t| if t == IGNORE { 0 } else { t as i64 }).collect::<Vec<_>>(),
            [b, 1, h, w],
        ),
        &device,
    );
    let mut pw: Vec<f32> = target
        .iter()
        .map(|&t| if t == IGNORE { 0.0 } else { weights.get(t as usize).copied().unwrap_or(1.0) })
        .collect();
    if let Some(scale) = scale {
        pw.iter_mut().zip(scale).for_each(|(p, s)| *p *= s);
    }
    let norm: f32 = pw.iter().sum::<f32>().max(1e-6);
    let pw = Tensor::<4>::from_data(TensorData::new(pw, [b, 1, h, w]), &device);
    let picked = log_softmax(logits, 1).gather(1, idx);
    (picked * pw).sum().mul_scalar(-1.0 / norm)
}

/// Centre-offset regression: mean L1 distance between predicted and target
/// offsets over the cells that belong to an object (`mask` 1, else 0).
/// `pred [B, 2, H, W]`; `target` and `mask` in the same layout (`B*2*H*W`, `B*H*W`).
pub fn offset_l1(pred: Tensor<4>, target: &[f32], mask: &[f32]) -> Tensor<1> {
    let [b, _, h, w] = pred.dims();
    let device = pred.device();
    let t = Tensor::<4>::from_data(TensorData::new(target.to_vec(), [b, 2, h, w]), &device);
    let m = Tensor::<4>::from_data(TensorData::new(mask.to_vec(), [b, 1, h, w]), &device);
    let norm = mask.iter().sum::<f32>().max(1.0) * 2.0;
    ((pred - t).abs() * m).sum().mul_scalar(1.0 / norm)
}

/// Contact classification: binary cross-entropy of the contact logits
/// `pred [B, 1, H, W]` against `target` (0 or 1 per cell) over the cells
/// with `mask` 1 (object cells; background cells are cut by the class
/// head, not by contacts), contact cells weighted `positive_weight` (they
/// are a few in a hundred), normalised by the summed weights.
pub fn contact_bce(pred: Tensor<4>, target: &[f32], mask: &[f32], positive_weight: f32) -> Tensor<1> {
    let [b, _, h, w] = pred.dims();
    let device = pred.device();
    let weights: Vec<f32> =
        target.iter().zip(mask).map(|(&t, &m)| m * if t > 0.5 { positive_weight } else { 1.0 }).collect();
    let norm = weights.iter().sum::<f32>().max(1.0);
    let t = Tensor::<4>::from_data(TensorData::new(target.to_vec(), [b, 1, h, w]), &device);
    let wt = Tensor::<4>::from_data(TensorData::new(weights, [b, 1, h, w]), &device);
    let per_cell = t.clone() * log_sigmoid(pred.clone()) + t.neg().add_scalar(1.0) * log_sigmoid(pred.neg());
    (per_cell * wt).sum().mul_scalar(-1.0 / norm)
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::prelude::Device;

    #[test]
    fn weights_favour_rare_classes() {
        let w = class_weights(&[9000, 900, 90, 0], 0.5, 20.0);
        assert!(w[0] < w[1] && w[1] < w[2] && w[2] <= w[3]);
        assert!((w[3] / w[0] - 20.0).abs() < 1e-3, "cap: {w:?}");
        let flat = class_weights(&[10, 10], 0.5, 10.0);
        assert!((flat[0] - 1.0).abs() < 1e-6 && (flat[1] - 1.0).abs() < 1e-6);
    }

    #[test]
    fn cross_entropy_matches_hand_computation() {
        let device = Device::flex();
        // One image, 2 classes, 1x2 cells: logits (0, ln 3) and (0, 0).
        let l = Tensor::<4>::from_data(TensorData::new(vec![0.0f32, 0.0, 3f32.ln(), 0.0], [1, 2, 1, 2]), &device);
        let loss = weighted_cross_entropy(l, &[1, 0], &[1.0, 3.0]);
        let v = loss.into_data().try_to_vec::<f32>().unwrap()[0];
        // cell 0: target 1, p = 3/4, weight 3; cell 1: target 0, p = 1/2, weight 1.
        let expect = -(3.0 * (0.75f32).ln() + (0.5f32).ln()) / 4.0;
        assert!((v - expect).abs() < 1e-5, "{v} vs {expect}");
    }

    #[test]
    fn small_regions_are_lifted_large_ones_and_background_are_not() {
        // Two 4x3 images: image 0 has a 1-cell class-1 region and a 6-cell class-2
        // region; image 1 a class-1 region touching image 0's last row only by index.
        #[rustfmt::skip]
        let t: Vec<u16> = vec![
            1, 0, 2, 2,
            0, 0, 2, 2,
            0, 0, 2, 2,

            2, 2, 2, 2,
            0, 0, 0, 0,
            0, 0, 0, 0,
        ];
        let s = small_region_weights(&t, 4, 3, 16.0, 3.0);
        assert_eq!(s[0], 3.0, "1 cell: sqrt(16) = 4, capped at 3");
        assert!((s[2] - (16.0f32 / 6.0).sqrt()).abs() < 1e-6, "6 cells: {}", s[2]);
        assert_eq!(s[12], 2.0, "image 1's 4-cell region is its own region, not joined across images");
        assert!(s.iter().zip(&t).all(|(w, &c)| c != 0 || *w == 1.0), "background stays 1");
        assert!(small_region_weights(&t, 4, 3, 16.0, 1.0).iter().all(|&w| w == 1.0), "off");
        // A region larger than the reference is never weighted down.
        assert!(small_region_weights(&t, 4, 3, 1.0, 3.0).iter().all(|&w| w == 1.0));
    }

    #[test]
    fn scaled_cross_entropy_weights_cells() {
        let device = Device::flex();
        let l = Tensor::<4>::from_data(TensorData::new(vec![0.0f32, 0.0, 3f32.ln(), 0.0], [1, 2, 1, 2]), &device);
        let loss = weighted_cross_entropy_scaled(l, &[1, 0], &[1.0, 3.0], Some(&[2.0, 1.0]));
        let v = loss.into_data().try_to_vec::<f32>().unwrap()[0];
        let expect = -(6.0 * (0.75f32).ln() + (0.5f32).ln()) / 7.0;
        assert!((v - expect).abs() < 1e-5, "{v} vs {expect}");
    }

    #[test]
    fn cells_of_unknown_class_take_no_loss() {
        let device = Device::flex();
        // Cells 0 and 1 as in the hand computation above; cell 2 unknown, with a logit that would cost a lot.
        let l = Tensor::<4>::from_data(
            TensorData::new(vec![0.0f32, 0.0, 40.0, 3f32.ln(), 0.0, -40.0], [1, 2, 1, 3]),
            &device,
        );
        let loss = weighted_cross_entropy(l, &[1, 0, IGNORE], &[1.0, 3.0]);
        let v = loss.into_data().try_to_vec::<f32>().unwrap()[0];
        let expect = -(3.0 * (0.75f32).ln() + (0.5f32).ln()) / 4.0;
        assert!((v - expect).abs() < 1e-5, "{v} vs {expect}");
    }

    #[test]
    fn contact_loss_matches_hand_computation() {
        let device = Device::flex();
        // Three cells: a contact at logit ln 3 (p = 3/4), no contact at 0 (p = 1/2), a masked cell.
        let p = Tensor::<4>::from_data(TensorData::new(vec![3f32.ln(), 0.0, 50.0], [1, 1, 1, 3]), &device);
        let loss = contact_bce(p, &[1.0, 0.0, 0.0], &[1.0, 1.0, 0.0], 4.0);
        let v = loss.into_data().try_to_vec::<f32>().unwrap()[0];
        let expect = -(4.0 * 0.75f32.ln() + 0.5f32.ln()) / 5.0;
        assert!((v - expect).abs() < 1e-5, "{v} vs {expect}");
    }

    #[test]
    fn offset_loss_counts_object_cells_only() {
        let device = Device::flex();
        // 1x2 cells; cell 0 is an object (errors 0.5 and 1.0), cell 1 background (error ignored).
        let p = Tensor::<4>::from_data(TensorData::new(vec![0.5f32, 9.0, -1.0, 9.0], [1, 2, 1, 2]), &device);
        let loss = offset_l1(p, &[0.0, 0.0, 0.0, 0.0], &[1.0, 0.0]);
        let v = loss.into_data().try_to_vec::<f32>().unwrap()[0];
        assert!((v - 0.75).abs() < 1e-6, "{v}");
    }
}
