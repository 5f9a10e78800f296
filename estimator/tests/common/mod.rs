//! Synthetic test scenes without the renderer: objects made of axis-aligned
//! boxes (object frame, metres), ray-cast into depth and label planes.

#![allow(dead_code)]

use std::collections::HashMap;

use fusepose_estimator::net::meta::{self, object_entries};
use fusepose_estimator::seg::SegConfig;
use fusepose_estimator::seg::file::{FORMAT, KEY_CONFIG};
use fusepose_estimator::{ColorFormat, DepthPlane, Estimator, FrameView, LabelPlane, ObjectPose, PoseSet, Workspace};
use fusepose_scene::{Intrinsics, Mesh, ObjectModel, ObjectSet, Pose, Symmetry};
use nalgebra::{Point3, Vector3};
use safetensors::tensor::{Dtype, TensorView};

/// An object as a union of boxes `[min, max]` (object frame, metres).
#[derive(Clone, Debug)]
pub struct BoxObject {
    pub name: &'static str,
    pub boxes: Vec<([f64; 3], [f64; 3])>,
}

/// An asymmetric L-shaped block with a nub (about 8 × 7 × 4 cm).
pub fn l_block() -> BoxObject {
    BoxObject {
        name: "l_block",
        boxes: vec![
            ([-0.04, -0.03, -0.02], [0.04, -0.01, 0.02]),
            ([-0.04, -0.01, -0.02], [-0.02, 0.04, 0.02]),
            ([0.02, -0.01, -0.02], [0.04, 0.01, 0.0]),
        ],
    }
}

/// A squat step shape (two boxes), different from the L block.
pub fn step_block() -> BoxObject {
    BoxObject {
        name: "step_block",
        boxes: vec![([-0.03, -0.02, -0.015], [0.03, 0.02, 0.0]), ([-0.03, -0.02, 0.0], [0.0, 0.02, 0.025])],
    }
}

impl BoxObject {
    /// The object's bounding box (min, max corners), object frame.
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for (a, b) in &self.boxes {
            for k in 0..3 {
                lo[k] = lo[k].min(a[k]);
                hi[k] = hi[k].max(b[k]);
            }
        }
        (lo, hi)
    }

    fn inside_other(&self, p: &Vector3<f64>, skip: usize) -> bool {
        self.boxes
            .iter()
            .enumerate()
            .any(|(i, (lo, hi))| i != skip && (0..3).all(|a| p[a] > lo[a] + 1e-9 && p[a] < hi[a] - 1e-9))
    }

    /// Surface samples on a grid of `spacing` metres over every box face,
    /// without points buried inside another box.
    pub fn samples(&self, spacing: f64) -> Vec<Point3<f64>> {
        let mut out = Vec::new();
        for (bi, (lo, hi)) in self.boxes.iter().enumerate() {
            for axis in 0..3 {
                let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
                let na = ((hi[a] - lo[a]) / spacing).round().max(1.0) as usize;
                let nb = ((hi[b] - lo[b]) / spacing).round().max(1.0) as usize;
                for side in [lo[axis], hi[axis]] {
                    for i in 0..na {
                        for j in 0..nb {
                            let mut p = Vector3::zeros();
                            p[axis] = side;
                            p[a] = lo[a] + (i as f64 + 0.5) * (hi[a] - lo[a]) / na as f64;
                            p[b] = lo[b] + (j as f64 + 0.5) * (hi[b] - lo[b]) / nb as f64;
                            // A face point is buried when just outside the face
                            // (along its outward normal) lies inside another box.
                            let mut probe = p;
                            probe[axis] += if side == hi[axis] { 1e-6 } else { -1e-6 };
                            if !self.inside_other(&probe, bi) {
                                out.push(Point3::from(p));
                            }
                        }
                    }
                }
            }
        }
        out
    }

    pub fn model(&self) -> ObjectModel {
        let samples = self.samples(0.003);
        let lo = self.boxes.iter().fold([f64::MAX; 3], |m, (l, _)| [m[0].min(l[0]), m[1].min(l[1]), m[2].min(l[2])]);
        let hi = self.boxes.iter().fold([f64::MIN; 3], |m, (_, h)| [m[0].max(h[0]), m[1].max(h[1]), m[2].max(h[2])]);
        let diameter = (Vector3::from(hi) - Vector3::from(lo)).norm();
        ObjectModel {
            name: self.name.into(),
            mesh: Mesh::default(),
            symmetry: Symmetry::None,
            samples,
            diameter,
            bbox_min: Point3::from(lo),
            bbox_max: Point3::from(hi),
            shadow_mesh: None,
        }
    }

    /// Distance along a camera ray (origin 0, direction `d` with d.z = 1) to
    /// the first hit, i.e. the depth z; `None` on a miss.
    pub fn ray_depth(&self, pose: &Pose, d: &Vector3<f64>) -> Option<f64> {
        let inv = pose.inverse();
        let o = inv.translation.vector;
        let dir = inv.rotation * d;
        let mut best: Option<f64> = None;
        for (lo, hi) in &self.boxes {
            let (mut t0, mut t1) = (0.0f64, f64::MAX);
            let mut hit = true;
            for a in 0..3 {
                if dir[a].abs() < 1e-12 {
                    if o[a] < lo[a] || o[a] > hi[a] {
                        hit = false;
                        break;
                    }
                    continue;
                }
                let (ta, tb) = ((lo[a] - o[a]) / dir[a], (hi[a] - o[a]) / dir[a]);
                t0 = t0.max(ta.min(tb));
                t1 = t1.min(ta.max(tb));
            }
            if hit && t0 <= t1 && t0 > 0.0 {
                best = Some(best.map_or(t0, |b: f64| b.min(t0)));
            }
        }
        best
    }
}

pub fn object_set(objects: &[BoxObject]) -> ObjectSet {
    ObjectSet { objects: objects.iter().map(BoxObject::model).collect() }
}

/// An owned synthetic RGB-D frame.
pub struct SyntheticFrame {
    pub intrinsics: Intrinsics,
    pub color: Vec<u8>,
    pub depth: Vec<u16>,
    pub labels: Vec<u8>,
}

impl SyntheticFrame {
    pub fn view(&self) -> FrameView<'_> {
        FrameView {
            intrinsics: self.intrinsics,
            color_format: ColorFormat::Rgb8,
            color: &self.color,
            depth: DepthPlane::U16 { data: &self.depth, scale: 0.0001 },
            labels: Some(LabelPlane::U8(&self.labels)),
        }
    }
}

pub fn intrinsics() -> Intrinsics {
    Intrinsics { fx: 300.0, fy: 300.0, cx: 160.0, cy: 120.0, width: 320, height: 240 }
}

/// Ray-casts `objects` (class id = position + 1) at their poses in front of
/// a tilted background plane; depth in 0.1 mm units.
pub fn render(objects: &[(u8, &BoxObject, Pose)]) -> SyntheticFrame {
    let k = intrinsics();
    let (w, h) = (k.width as usize, k.height as usize);
    let mut f =
        SyntheticFrame { intrinsics: k, color: vec![0; w * h * 3], depth: vec![0; w * h], labels: vec![0; w * h] };
    for v in 0..h {
        for u in 0..w {
            let p = v * w + u;
            let d = Vector3::new((u as f64 - k.cx) / k.fx, (v as f64 - k.cy) / k.fy, 1.0);
            // Background: plane z = 0.9 + 0.3 y (tilted table), beyond the objects.
            let mut z = 0.9 / (1.0 - 0.3 * d.y);
            let mut label = 0u8;
            for (class, obj, pose) in objects {
                if let Some(t) = obj.ray_depth(pose, &d)
                    && t < z
                {
                    z = t;
                    label = *class;
                }
            }
            f.depth[p] = (z * 10_000.0).round() as u16;
            f.labels[p] = label;
            f.color[p * 3..p * 3 + 3].copy_from_slice(&[(u % 256) as u8, (v % 256) as u8, label.wrapping_mul(60)]);
        }
    }
    f
}

/// Every labelled pixel one colour (the synthetic frames' colours follow the
/// pixel position, which would make two copies look like two objects).
#[allow(dead_code)] // not every test binary paints
pub fn painted(mut frame: SyntheticFrame) -> SyntheticFrame {
    for (p, &l) in frame.labels.iter().enumerate() {
        if l != 0 {
            frame.color[p * 3..p * 3 + 3].copy_from_slice(&[150, 110, 60]);
        }
    }
    frame
}

/// Rotation angle between two rotations, degrees.
pub fn angle_deg(a: &nalgebra::UnitQuaternion<f64>, b: &nalgebra::UnitQuaternion<f64>) -> f64 {
    a.angle_to(b).to_degrees()
}

/// A segmenter file with deterministic pseudo-random weights (no trainer needed).
pub fn seg_weight_bytes(cfg: &SegConfig, set: &ObjectSet) -> Vec<u8> {
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32 - 0.5
    };
    let shapes = cfg.tensor_shapes();
    let data: Vec<Vec<u8>> = shapes
        .iter()
        .map(|(_, s)| {
            let fan_in: usize = s.iter().skip(1).product::<usize>().max(1);
            let scale = (6.0 / fan_in as f32).sqrt();
            (0..s.iter().product::<usize>()).flat_map(|_| (next() * scale).to_le_bytes()).collect()
        })
        .collect();
    let views: Vec<(String, TensorView<'_>)> = shapes
        .iter()
        .zip(&data)
        .map(|((n, s), d)| (n.clone(), TensorView::new(Dtype::F32, s.clone(), d).unwrap()))
        .collect();
    let metadata = HashMap::from([
        (meta::KEY_FORMAT.to_string(), FORMAT.to_string()),
        (KEY_CONFIG.to_string(), serde_json::to_string(cfg).unwrap()),
        (meta::KEY_OBJECTS.to_string(), serde_json::to_string(&object_entries(set)).unwrap()),
    ]);
    safetensors::serialize(views, Some(metadata)).unwrap()
}

/// How far the partial oracle's pose lies off the truth, metres along x.
pub const OFF_M: f64 = 0.015;

/// A test estimator that poses each prepared instance where `pose_of` says,
/// from the instance and its distinct sampled points (camera frame): a
/// [`Pose`] (confidence 1), or a pose with the network's confidence.
pub struct PoseEach<F>(pub F);

/// What a [`PoseEach`] closure gives.
pub trait Posed {
    /// The pose and its confidence (0..1).
    fn posed(self) -> (Pose, f32);
}

impl Posed for Pose {
    fn posed(self) -> (Pose, f32) {
        (self, 1.0)
    }
}

impl Posed for (Pose, f32) {
    fn posed(self) -> (Pose, f32) {
        self
    }
}

impl<F, R> Estimator for PoseEach<F>
where
    F: FnMut(&fusepose_estimator::Instance, &[[f32; 3]]) -> R + Send,
    R: Posed,
{
    fn name(&self) -> &str {
        "pose-each"
    }

    fn estimate(
        &mut self,
        _frame: &FrameView<'_>,
        ws: &mut Workspace,
        out: &mut PoseSet,
    ) -> Result<(), fusepose_estimator::EstimateError> {
        out.clear();
        for (i, inst) in ws.instances.iter().enumerate() {
            let (pose, confidence) =
                (self.0)(inst, &ws.instance_points(i)[..inst.distinct_points(ws.config.num_points)]).posed();
            out.push(ObjectPose {
                class_id: inst.class_id,
                instance_id: i as u16,
                rotation: pose.rotation,
                translation: pose.translation.vector,
                confidence,
                mask_pixels: inst.pixels,
                bbox: inst.bbox,
                iterations: 0,
            });
        }
        Ok(())
    }
}

/// Mean of `points` (metres).
pub fn centroid(points: &[[f32; 3]]) -> Vector3<f64> {
    let n = points.len().max(1) as f64;
    points.iter().fold(Vector3::zeros(), |a, p| a + Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64) / n)
}

/// Poses an instance at `truth` when its mask holds at least 70 % of the
/// object's `object_pixels`, else `OFF_M` to the side: the network's
/// behaviour on a mask that lost part of its object.
pub fn partial(
    truth: Pose,
    object_pixels: u32,
) -> PoseEach<impl FnMut(&fusepose_estimator::Instance, &[[f32; 3]]) -> Pose + Send> {
    PoseEach(move |inst: &fusepose_estimator::Instance, _: &[[f32; 3]]| {
        let whole = inst.pixels as f64 >= 0.7 * object_pixels as f64;
        let off = if whole { 0.0 } else { OFF_M };
        Pose::from_parts((truth.translation.vector + Vector3::new(off, 0.0, 0.0)).into(), truth.rotation)
    })
}

/// Keeps class labels only left of the object's 35th percentile column:
/// the region of an object the segmenter found in part.
pub fn left_part(mut frame: SyntheticFrame) -> (SyntheticFrame, u32) {
    let w = frame.intrinsics.width as usize;
    let object_pixels = frame.labels.iter().filter(|&&l| l != 0).count() as u32;
    let cols = || frame.labels.iter().enumerate().filter(|(_, l)| **l != 0).map(|(p, _)| p % w);
    let (lo, hi) = (cols().min().unwrap(), cols().max().unwrap());
    let cut = lo + (hi - lo) * 35 / 100;
    for (p, l) in frame.labels.iter_mut().enumerate() {
        if p % w > cut {
            *l = 0;
        }
    }
    (frame, object_pixels)
}
