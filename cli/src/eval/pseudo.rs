//! `fusepose eval --pseudo-labels DIR`: class labels for unlabelled frames from
//! the poses the estimator published for them, so that the segmenter can be
//! adapted to a camera without anyone drawing a mask (`fusepose train --stage
//! seg --adapt-labels DIR`; the folder's layout is
//! `fusepose_scene::bop::PseudoLabelWriter`'s). No ground truth is read.
//!
//! Each published pose's model is rendered at its pose. A pixel takes the
//! pose's class where the model covers it and the measured depth lies within
//! 1 cm + 1 % of the model's. It is background where no pose covers it, the
//! segmenter saw background and its point lies on the support plane (fitted
//! to the segmenter's background). Where the segmenter saw an object on the
//! plane that no pose explains it is unknown unless `table_patches` asks for
//! background (a patch of table that took a class is a ghost to unlearn, but
//! the lowest centimetre of an object whose pose failed lies there too; files
//! adapted with and without it scored alike, docs/BENCHMARKS.md session 49).
//! Everywhere else it is unknown and teaches nothing: pixels a pose covers
//! but the depth does not confirm (an occluder no pose explains, a slightly
//! wrong pose), and points off the plane that no pose explains (a copy nobody
//! posed, walls, other things): a missed object must not be taught as
//! background.

use std::path::{Path, PathBuf};

use anyhow::Context;
use fusepose_estimator::poses::ObjectPose;
use fusepose_estimator::support;
use fusepose_scene::bop::{PseudoLabelWriter, UNKNOWN_LABEL};
use fusepose_scene::render::{RenderItem, RenderSettings, RenderTarget, render_scene};
use fusepose_scene::{Intrinsics, ObjectSet};
use nalgebra::Vector3;

use super::dataset::EvalFrame;

/// A pixel's measured depth confirms the model's within this (metres, plus [`DEPTH_TOL_PER_M`] × depth).
const DEPTH_TOL_M: f32 = 0.01;
const DEPTH_TOL_PER_M: f32 = 0.01;
/// A point within this height of the support plane is table (metres).
const ON_PLANE_M: f32 = 0.01;
/// The support plane is fitted to every this-many-th pixel of the segmenter's background, along each axis.
const PLANE_STRIDE: usize = 4;

/// One frame's inputs to [`pseudo_labels`], all `width * height` and row-major.
pub struct LabelInputs<'a> {
    pub intrinsics: Intrinsics,
    /// Measured depth in metres (0 or non-finite = none).
    pub depth_m: &'a [f32],
    /// The segmenter's class per pixel (0 = background).
    pub segmenter: &'a [u16],
    /// Rendered posed models: item `i + 1` per pixel (0 = none) and its depth in metres.
    pub rendered_items: &'a [u16],
    pub rendered_depth_m: &'a [f32],
    /// Class of rendered item `i + 1` at index `i`.
    pub item_classes: &'a [u16],
    /// Whether a pixel on the table plane that the segmenter gave a class (and no pose explains) is background.
    pub table_patches: bool,
}

/// The labels of one frame (see the module doc); `out` gets `width * height` values.
pub fn pseudo_labels(inputs: &LabelInputs<'_>, out: &mut Vec<u8>) {
    let k = &inputs.intrinsics;
    let (w, h) = (k.width as usize, k.height as usize);
    let point = |p: usize, z: f32| {
        let (u, v) = ((p % w) as f64, (p / w) as f64);
        Vector3::new(((u - k.cx) * z as f64 / k.fx) as f32, ((v - k.cy) * z as f64 / k.fy) as f32, z)
    };
    let measured = |p: usize| inputs.depth_m.get(p).copied().filter(|z| z.is_finite() && *z > 0.0);
    let mut background = Vec::new();
    for v in (0..h).step_by(PLANE_STRIDE) {
        for u in (0..w).step_by(PLANE_STRIDE) {
            let p = v * w + u;
            if let Some(z) = measured(p).filter(|_| inputs.segmenter[p] == 0 && inputs.rendered_items[p] == 0) {
                background.push(point(p, z));
            }
        }
    }
    let plane = support::fit(&background);
    out.clear();
    out.extend((0..w * h).map(|p| {
        let item = inputs.rendered_items[p] as usize;
        let z = measured(p);
        if item > 0 {
            let zr = inputs.rendered_depth_m[p];
            let class = inputs.item_classes.get(item - 1).copied().unwrap_or(0);
            return match z {
                Some(z)
                    if class > 0
                        && class < u16::from(UNKNOWN_LABEL)
                        && (z - zr).abs() <= DEPTH_TOL_M + DEPTH_TOL_PER_M * zr =>
                {
                    class as u8
                }
                _ => UNKNOWN_LABEL,
            };
        }
        // On the table it is background; where the segmenter saw an object there, only with `table_patches`.
        match (z, &plane) {
            (Some(z), Some(plane))
                if (inputs.segmenter[p] == 0 || inputs.table_patches)
                    && plane.height(&point(p, z)).abs() <= ON_PLANE_M =>
            {
                0
            }
            _ => UNKNOWN_LABEL,
        }
    }));
}

/// Writes a pseudo-label folder over an evaluation's frames.
pub struct PseudoLabeller {
    writer: PseudoLabelWriter,
    target: RenderTarget,
    depth_m: Vec<f32>,
    labels: Vec<u8>,
    table_patches: bool,
    /// Against the dataset's own class labels, where it has them (a report,
    /// never an input): object pixels with the true class, of all labelled
    /// object; background pixels truly background, of all labelled background.
    agree: [u64; 4],
}

impl PseudoLabeller {
    pub fn create(dir: &Path, split: &Path, objects: &ObjectSet, table_patches: bool) -> anyhow::Result<Self> {
        let classes = u16::try_from(objects.len()).ok().filter(|&n| n < u16::from(UNKNOWN_LABEL));
        let Some(classes) = classes else {
            anyhow::bail!(
                "--pseudo-labels: 8-bit labels hold at most 254 classes, the object set has {}",
                objects.len()
            );
        };
        let writer = PseudoLabelWriter::create(dir, split, classes).context("--pseudo-labels")?;
        Ok(Self {
            writer,
            target: RenderTarget::new(1, 1),
            depth_m: Vec::new(),
            labels: Vec::new(),
            table_patches,
            agree: [0; 4],
        })
    }

    /// Labels `frame` from its published `poses` and the segmenter's class plane.
    pub fn add(
        &mut self,
        frame: &EvalFrame,
        segmenter: &[u16],
        poses: &[ObjectPose],
        objects: &ObjectSet,
    ) -> anyhow::Result<()> {
        let k = frame.intrinsics;
        let items: Vec<RenderItem<'_>> = poses
            .iter()
            .enumerate()
            .filter_map(|(i, p)| {
                Some(RenderItem {
                    mesh: &objects.by_class(p.class_id)?.mesh,
                    pose: super::pose_of(p),
                    instance_label: i as u16 + 1,
                    shadow_mesh: None,
                })
            })
            .collect();
        let item_classes: Vec<u16> = poses.iter().map(|p| p.class_id).collect();
        self.target.resize(k.width, k.height);
        render_scene(&items, &k, &RenderSettings::default(), &mut self.target)
            .with_context(|| format!("rendering the poses of frame {}/{}", frame.scene_id, frame.im_id))?;
        self.depth_m.clear();
        self.depth_m.extend(frame.depth.iter().map(|&d| (d as f64 * frame.depth_unit_m) as f32));
        let inputs = LabelInputs {
            intrinsics: k,
            depth_m: &self.depth_m,
            segmenter,
            rendered_items: self.target.labels(),
            rendered_depth_m: self.target.depth_m(),
            item_classes: &item_classes,
            table_patches: self.table_patches,
        };
        pseudo_labels(&inputs, &mut self.labels);
        if frame.labels.len() == self.labels.len() && frame.labels.iter().any(|&l| l != 0) {
            for (&l, &t) in self.labels.iter().zip(&frame.labels) {
                match l {
                    UNKNOWN_LABEL => {}
                    0 => {
                        self.agree[2] += 1;
                        self.agree[3] += (t == 0) as u64;
                    }
                    c => {
                        self.agree[0] += 1;
                        self.agree[1] += (u16::from(c) == t) as u64;
                    }
                }
            }
        }
        self.writer.write_frame(frame.scene_id, frame.im_id, k.width, k.height, &self.labels, items.len() as u32)?;
        Ok(())
    }

    /// Writes the manifest and prints what the labels hold.
    pub fn finish(self) -> anyhow::Result<PathBuf> {
        let frames = self.writer.frames();
        let sum = |f: fn(&fusepose_scene::bop::PseudoLabelFrame) -> u64| frames.iter().map(f).sum::<u64>();
        let (obj, bg, unk) = (sum(|f| f.object_px), sum(|f| f.background_px), sum(|f| f.unknown_px));
        let all = (obj + bg + unk).max(1) as f64;
        println!(
            "pseudo-labels: {} frames, {} poses; pixels {:.1} % object, {:.1} % background, {:.1} % unknown",
            frames.len(),
            frames.iter().map(|f| u64::from(f.poses)).sum::<u64>(),
            100.0 * obj as f64 / all,
            100.0 * bg as f64 / all,
            100.0 * unk as f64 / all
        );
        if self.agree[0] + self.agree[2] > 0 {
            println!(
                "pseudo-labels against the dataset's labels (report only): object pixels {:.2} % right, background pixels {:.2} % right",
                100.0 * self.agree[1] as f64 / self.agree[0].max(1) as f64,
                100.0 * self.agree[3] as f64 / self.agree[2].max(1) as f64
            );
        }
        Ok(self.writer.finish()?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 40x30 frame looking straight down at a table 1 m away: a posed box
    /// (item 1, class 2) over x 5..15, an unexplained segmenter region of
    /// class 4 standing 5 cm off the table at x 25..30, a table patch the
    /// segmenter gave class 5, a wall-like patch off the plane at x 32..36.
    #[test]
    fn labels_follow_confirmed_poses_the_table_and_nothing_else() {
        let k = Intrinsics { fx: 40.0, fy: 40.0, cx: 19.5, cy: 14.5, width: 40, height: 30 };
        let n = 40 * 30;
        let mut depth = vec![1.0f32; n];
        let (mut seg, mut items, mut rdepth) = (vec![0u16; n], vec![0u16; n], vec![0.0f32; n]);
        for p in 0..n {
            let (u, v) = (p % 40, p / 40);
            if (5..15).contains(&u) && (5..15).contains(&v) {
                depth[p] = 0.9;
                seg[p] = 2;
                items[p] = 1;
                // The posed model agrees with the depth except in its last column (an occluder 5 cm nearer).
                rdepth[p] = 0.9;
                if u == 14 {
                    depth[p] = 0.85;
                }
            }
            if (25..30).contains(&u) && (5..15).contains(&v) {
                depth[p] = 0.95;
                seg[p] = 4;
            }
            // A patch of table the segmenter took for class 5.
            if (20..24).contains(&u) && (20..25).contains(&v) {
                seg[p] = 5;
            }
            if (32..36).contains(&u) {
                depth[p] = 0.7;
            }
        }
        depth[n - 1] = 0.0;
        let mut inputs = LabelInputs {
            intrinsics: k,
            depth_m: &depth,
            segmenter: &seg,
            rendered_items: &items,
            rendered_depth_m: &rdepth,
            item_classes: &[2],
            table_patches: false,
        };
        let mut out = Vec::new();
        pseudo_labels(&inputs, &mut out);
        let at = |out: &[u8], u: usize, v: usize| out[v * 40 + u];
        let patch = at(&out, 22, 22);
        inputs.table_patches = true;
        let mut taught = Vec::new();
        pseudo_labels(&inputs, &mut taught);
        assert_eq!(patch, UNKNOWN_LABEL, "a table patch the segmenter took for an object: unknown by default");
        assert_eq!(at(&taught, 22, 22), 0, "with table_patches it is background");
        // Everything else is labelled alike either way.
        let differ = out.iter().zip(&taught).filter(|(a, b)| a != b).count();
        assert_eq!(differ, 4 * 5, "only the patch's pixels differ");
        let at = |u: usize, v: usize| out[v * 40 + u];
        assert_eq!(at(8, 8), 2, "a confirmed pose's pixel takes its class");
        assert_eq!(at(14, 8), UNKNOWN_LABEL, "depth that does not confirm the pose: unknown");
        assert_eq!(at(27, 8), UNKNOWN_LABEL, "an object no pose explains is not taught as background");
        assert_eq!(at(34, 20), UNKNOWN_LABEL, "off the table, unexplained: unknown");
        assert_eq!(at(20, 25), 0, "the table is background");
        assert_eq!(at(39, 29), UNKNOWN_LABEL, "no depth: unknown");
    }
}
