//! Held-out segmentation metrics through the inference engine (the daemon's
//! code path): per-class IoU at full frame resolution, their mean over the
//! objects (mIoU), background IoU and pixel accuracy, on rendered scenes from
//! [`SEG_VAL_SEED_BASE`] (disjoint from training seeds), without augmentation.

use std::collections::BTreeMap;
use std::time::Instant;

use fusepose_estimator::seg::SegEngine;
use fusepose_scene::Intrinsics;
use fusepose_scene::ObjectSet;
use fusepose_scene::render::RenderTarget;

use super::data::{frame_view, render_frame};

/// First scene seed of the segmentation validation split.
pub const SEG_VAL_SEED_BASE: u64 = 0x7a12_0000_0000;

/// Held-out results.
#[derive(Clone, Debug, Default)]
pub struct SegValidation {
    pub frames: usize,
    /// Mean IoU over the object classes seen (in truth or prediction), 0..1.
    pub miou: f64,
    pub background_iou: f64,
    pub pixel_accuracy: f64,
    /// `(object name, IoU)`; `None` for a class neither present nor predicted.
    pub class_iou: Vec<(String, Option<f64>)>,
    /// Median engine time per frame (segment, full frame), milliseconds.
    pub engine_ms: f64,
}

impl SegValidation {
    /// Metrics for the weight file's record (`seg.miou`, `seg.iou.<name>`, …).
    pub fn metrics(&self) -> BTreeMap<String, f64> {
        let mut m = BTreeMap::new();
        m.insert("seg.miou".into(), self.miou);
        m.insert("seg.background_iou".into(), self.background_iou);
        m.insert("seg.pixel_accuracy".into(), self.pixel_accuracy);
        m.insert("seg.val_frames".into(), self.frames as f64);
        for (name, iou) in &self.class_iou {
            if let Some(v) = iou {
                m.insert(format!("seg.iou.{name}"), *v);
            }
        }
        m
    }

    /// One line for logs.
    pub fn summary(&self) -> String {
        let per: Vec<String> = self
            .class_iou
            .iter()
            .map(|(n, v)| format!("{n} {}", v.map_or("-".into(), |v| format!("{:.3}", v))))
            .collect();
        format!(
            "val {} frames: mIoU {:.3}, background IoU {:.3}, pixel acc {:.3} | {} | engine {:.1} ms/frame",
            self.frames,
            self.miou,
            self.background_iou,
            self.pixel_accuracy,
            per.join(", "),
            self.engine_ms
        )
    }
}

/// Intersection and union counts per class, and where each class's pixels went.
#[derive(Clone, Debug)]
pub struct Confusion {
    inter: Vec<u64>,
    union: Vec<u64>,
    /// `[truth * classes + predicted]` pixel counts.
    matrix: Vec<u64>,
    correct: u64,
    total: u64,
}

impl Confusion {
    pub fn new(classes: usize) -> Self {
        Self {
            inter: vec![0; classes],
            union: vec![0; classes],
            matrix: vec![0; classes * classes],
            correct: 0,
            total: 0,
        }
    }

    /// Share of the pixels of true class `truth` labelled `predicted`; `None`
    /// when the class has no pixels.
    pub fn share(&self, truth: usize, predicted: usize) -> Option<f64> {
        let n = self.inter.len();
        let row = self.matrix.get(truth * n..(truth + 1) * n)?;
        let total: u64 = row.iter().sum();
        (total > 0).then(|| row.get(predicted).copied().unwrap_or(0) as f64 / total as f64)
    }

    /// Adds one frame's prediction and truth (class ids; ids beyond the range are ignored).
    pub fn add(&mut self, pred: &[u16], truth: &[u16]) {
        let n = self.inter.len();
        for (&p, &t) in pred.iter().zip(truth) {
            let (p, t) = (p as usize, t as usize);
            self.total += 1;
            if p < n && t < n {
                self.matrix[t * n + p] += 1;
            }
            if p == t {
                self.correct += 1;
                if t < n {
                    self.inter[t] += 1;
                    self.union[t] += 1;
                }
            } else {
                if p < n {
                    self.union[p] += 1;
                }
                if t < n {
                    self.union[t] += 1;
                }
            }
        }
    }

    /// IoU of class `c`, `None` when it has no union.
    pub fn iou(&self, c: usize) -> Option<f64> {
        (self.union[c] > 0).then(|| self.inter[c] as f64 / self.union[c] as f64)
    }

    /// Mean IoU over classes `1..` with a union.
    pub fn miou(&self) -> f64 {
        let v: Vec<f64> = (1..self.inter.len()).filter_map(|c| self.iou(c)).collect();
        if v.is_empty() { 0.0 } else { v.iter().sum::<f64>() / v.len() as f64 }
    }

    pub fn pixel_accuracy(&self) -> f64 {
        self.correct as f64 / self.total.max(1) as f64
    }
}

/// Renders `frames` held-out scenes and scores `engine` on them: the network's
/// labels after small-fragment and strip removal, as plain cells
/// (`SegEngine::set_boundary`) and without the interior-cell rule (session 7),
/// so runs stay comparable with the earlier ones.
pub fn validate(engine: &mut SegEngine, set: &ObjectSet, frames: usize) -> anyhow::Result<SegValidation> {
    engine.set_boundary(fusepose_estimator::seg::Boundary::Cells);
    engine.set_min_interior_cells(0);
    let k = Intrinsics::YCB_VIDEO;
    let mut target = RenderTarget::for_intrinsics(&k);
    let mut pred = vec![0u16; k.width as usize * k.height as usize];
    let mut conf = Confusion::new(set.len() + 1);
    let mut times = Vec::new();
    let mut done = 0;
    let mut seed = SEG_VAL_SEED_BASE;
    while done < frames && seed < SEG_VAL_SEED_BASE + 4 * frames as u64 + 16 {
        seed += 1;
        let Some(k) = render_frame(set, seed - 1, &mut target)? else { continue };
        let t = Instant::now();
        engine.segment(&frame_view(k, &target), &mut pred)?;
        times.push(t.elapsed().as_secs_f64() * 1000.0);
        conf.add(&pred, target.labels());
        done += 1;
    }
    times.sort_by(f64::total_cmp);
    Ok(SegValidation {
        frames: done,
        miou: conf.miou(),
        background_iou: conf.iou(0).unwrap_or(0.0),
        pixel_accuracy: conf.pixel_accuracy(),
        class_iou: set.objects.iter().enumerate().map(|(i, o)| (o.name.clone(), conf.iou(i + 1))).collect(),
        engine_ms: times.get(times.len() / 2).copied().unwrap_or(0.0),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn confusion_counts_iou() {
        let mut c = Confusion::new(3);
        c.add(&[0, 1, 1, 2, 0], &[0, 1, 2, 2, 1]);
        // class 1: inter 1, union {1,2,4} = 3; class 2: inter 1, union {2,3} = 2; class 0: inter 1, union {0,4} = 2.
        assert_eq!(c.iou(1), Some(1.0 / 3.0));
        assert_eq!(c.iou(2), Some(0.5));
        assert_eq!(c.iou(0), Some(0.5));
        assert!((c.miou() - (1.0 / 3.0 + 0.5) / 2.0).abs() < 1e-12);
        assert!((c.pixel_accuracy() - 0.6).abs() < 1e-12);
        assert_eq!(Confusion::new(2).iou(1), None);
        // Truth 2's two pixels: one labelled 1, one 2; truth 1's two: one 1, one background.
        assert_eq!((c.share(2, 1), c.share(2, 2), c.share(2, 0)), (Some(0.5), Some(0.5), Some(0.0)));
        assert_eq!((c.share(1, 0), c.share(1, 1)), (Some(0.5), Some(0.5)));
        assert_eq!(Confusion::new(3).share(1, 1), None);
    }
}
