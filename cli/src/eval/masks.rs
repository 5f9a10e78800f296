//! `--masks net`: the built-in segmenter run once per evaluated frame (shared
//! by every estimator under evaluation), timed, and scored against the
//! dataset's ground-truth class labels (mIoU, per-class IoU).

use std::path::Path;
use std::time::Instant;

use anyhow::Context;
use fusepose_estimator::seg::voting::VotingMode;
use fusepose_estimator::seg::{Boundary, DepthRegionParams, DepthRegions, SegEngine};
use fusepose_estimator::{ColorFormat, DepthPlane, FrameView};
use fusepose_scene::ObjectSet;
use fusepose_train::seg::validate::Confusion;

use super::dataset::EvalFrame;

/// `--seg-*` settings of the evaluated segmenter; `None` keeps the engine's
/// default (see the `SegEngine` setter of each).
#[derive(Clone, Copy, Debug, Default)]
pub struct SegSettings {
    pub min_cells: Option<usize>,
    pub max_elongation: Option<f32>,
    pub boundary: Option<Boundary>,
    pub min_interior: Option<usize>,
    pub voting: Option<VotingMode>,
    pub background_offset: Option<f32>,
    /// Logits averaged with the mirror image's (`SegEngine::set_flip_average`).
    pub flip_average: Option<fusepose_estimator::seg::FlipAverage>,
    /// Cell labels regrouped by depth (`None` = off).
    pub depth_regions: Option<DepthRegionParams>,
}

/// The segmenter with its label buffer and accumulated scores.
pub struct NetMasks {
    engine: SegEngine,
    /// The segmenter's plane of the last frame: instance ids when it separates
    /// instances (classes in `classes`), else class ids.
    labels: Vec<u16>,
    /// Instance id → class id of the last frame (empty for a class plane).
    classes: Vec<u16>,
    /// Class ids of the last segmented frame.
    pub class_labels: Vec<u16>,
    /// Milliseconds per frame.
    pub ms: Vec<f64>,
    confusion: Confusion,
    names: Vec<String>,
    /// Cells the depth regrouping relabelled, over all frames.
    depth_changed: usize,
}

impl NetMasks {
    /// See `SegEngine::set_instance_separation`.
    pub fn set_instance_separation(&mut self, separation: Vec<f32>) {
        self.engine.set_instance_separation(separation);
    }

    /// Averages the segmenter's logits with the one in `partner` (`SegEngine::set_partner`).
    pub fn set_partner(&mut self, partner: &Path, weight: f32, objects: &ObjectSet) -> anyhow::Result<()> {
        let engine = SegEngine::load(partner, objects)
            .with_context(|| format!("--seg-partner: loading the segmenter of {}", partner.display()))?;
        self.engine.set_partner(engine, weight).with_context(|| format!("--seg-partner {}", partner.display()))?;
        Ok(())
    }

    /// Loads the segmenter of `weights` (a network file with one embedded, or
    /// a segmenter file) with `settings` applied over the engine's defaults.
    pub fn load(weights: &Path, objects: &ObjectSet, settings: &SegSettings) -> anyhow::Result<Self> {
        let SegSettings {
            min_cells,
            max_elongation,
            boundary,
            min_interior,
            voting,
            background_offset,
            flip_average,
            depth_regions,
        } = *settings;
        let mut engine = SegEngine::load(weights, objects)
            .with_context(|| format!("--masks net: loading the segmenter of {}", weights.display()))?;
        if let Some(n) = min_cells {
            engine.set_min_component_cells(n);
        }
        if let Some(e) = max_elongation {
            engine.set_max_elongation(e);
        }
        if let Some(n) = min_interior {
            engine.set_min_interior_cells(n);
        }
        if let Some(b) = boundary {
            engine.set_boundary(b);
        }
        if let Some(v) = voting {
            engine.set_voting_mode(v);
        }
        if let Some(o) = background_offset {
            engine.set_background_offset(o);
        }
        if let Some(mode) = flip_average {
            engine.set_flip_average(mode);
        }
        if let Some(params) = depth_regions {
            let diameters = fusepose_estimator::parts::extents(objects, 1.0);
            engine.set_depth_regions(Some(DepthRegions::new(&diameters, params)));
        }
        Ok(Self {
            engine,
            labels: Vec::new(),
            classes: Vec::new(),
            class_labels: Vec::new(),
            ms: Vec::new(),
            confusion: Confusion::new(objects.len() + 1),
            names: objects.objects.iter().map(|o| o.name.clone()).collect(),
            depth_changed: 0,
        })
    }

    /// Segments `frame` into [`NetMasks::labels`] and scores it against the frame's labels.
    pub fn segment(&mut self, frame: &EvalFrame) -> anyhow::Result<()> {
        let view = FrameView {
            intrinsics: frame.intrinsics,
            color_format: ColorFormat::Rgb8,
            color: &frame.rgb,
            depth: DepthPlane::U16 { data: &frame.depth, scale: frame.depth_unit_m as f32 },
            labels: None,
        };
        let start = Instant::now();
        let plane = self.engine.segment_plane(&view, &mut self.labels)?;
        self.ms.push(start.elapsed().as_secs_f64() * 1e3);
        self.classes.clear();
        if let fusepose_estimator::LabelPlane::Instances { classes, .. } = plane {
            self.classes.extend_from_slice(classes);
        }
        self.depth_changed += self.engine.depth_changed_cells();
        let (labels, classes) = (&self.labels, &self.classes);
        self.class_labels.clear();
        if classes.is_empty() {
            self.class_labels.extend_from_slice(labels);
        } else {
            self.class_labels.extend(labels.iter().map(|&id| classes.get(id as usize).copied().unwrap_or(0)));
        }
        self.confusion.add(&self.class_labels, &frame.labels);
        Ok(())
    }

    /// The label plane of the last segmented frame, as the estimator takes
    /// it, and the engine after that frame (its logits describe it; the
    /// second look computes its votes on demand).
    pub fn plane_and_engine(&mut self) -> (fusepose_estimator::LabelPlane<'_>, &mut SegEngine) {
        let plane = if self.classes.is_empty() {
            fusepose_estimator::LabelPlane::U16(&self.labels)
        } else {
            fusepose_estimator::LabelPlane::Instances { ids: &self.labels, classes: &self.classes }
        };
        (plane, &mut self.engine)
    }

    /// Prints mIoU, per-class IoU and the time per frame.
    pub fn print(&self, median_ms: f64, p99_ms: f64) {
        println!(
            "\nsegmenter on {} frames: mIoU {:.3}, background IoU {:.3}, pixel accuracy {:.3}; time per frame median {median_ms:.2} ms, p99 {p99_ms:.2} ms",
            self.ms.len(),
            self.confusion.miou(),
            self.confusion.iou(0).unwrap_or(0.0),
            self.confusion.pixel_accuracy()
        );
        if self.engine.depth_regions().is_some() {
            println!(
                "  cells regrouped by depth: {} ({:.1} per frame)",
                self.depth_changed,
                self.depth_changed as f64 / self.ms.len().max(1) as f64
            );
        }
        for (i, name) in self.names.iter().enumerate() {
            // Where its pixels went, when the segmenter gave 5 % or more of them another label.
            let elsewhere: Vec<String> = (0..=self.names.len())
                .filter(|&p| p != i + 1)
                .filter_map(|p| self.confusion.share(i + 1, p).filter(|&s| s >= 0.05).map(|s| (p, s)))
                .map(|(p, s)| {
                    let label = if p == 0 { "background" } else { self.names[p - 1].as_str() };
                    format!("{:.0} % as {label}", 100.0 * s)
                })
                .collect();
            let elsewhere =
                if elsewhere.is_empty() { String::new() } else { format!("; its pixels: {}", elsewhere.join(", ")) };
            match self.confusion.iou(i + 1) {
                Some(v) => println!("  {name:<24} IoU {v:.3}{elsewhere}"),
                None => println!("  {name:<24} IoU -"),
            }
        }
    }

    /// `{"miou", "background_iou", "pixel_accuracy", "iou": {name: v}}`.
    pub fn summary(&self, median_ms: f64, p99_ms: f64) -> serde_json::Value {
        let iou: serde_json::Map<String, serde_json::Value> = self
            .names
            .iter()
            .enumerate()
            .filter_map(|(i, n)| self.confusion.iou(i + 1).map(|v| (n.clone(), v.into())))
            .collect();
        serde_json::json!({
            "miou": self.confusion.miou(),
            "background_iou": self.confusion.iou(0).unwrap_or(0.0),
            "pixel_accuracy": self.confusion.pixel_accuracy(),
            "ms_per_frame_median": median_ms,
            "ms_per_frame_p99": p99_ms,
            "frames": self.ms.len(),
            "iou": iou,
        })
    }
}
