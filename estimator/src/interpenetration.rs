//! Interpenetration: two solid objects cannot share space. A segmenter that
//! gives part of one object another class (a cracker box's red top read as
//! the tomato can) yields a pose that depth verification cannot refuse — the
//! top's depth is explained by a can standing there — but that can stands
//! inside the box, whose own pose the rest of the box gave. Of two poses
//! whose solids overlap by more than a share, the one more inside the other
//! is dropped (a grasp at it would hit the other object).
//!
//! Solids are voxel grids in each object's frame: the voxels its surface
//! passes through, plus those the outside cannot reach (6-connected flood
//! fill from the grid's border). A bowl or a mug stays hollow where it is
//! open, so an object standing in a bowl does not overlap it. Probe points
//! (voxel centres of the solid, at most [`PROBES`] per object) are tested
//! against the other object's grid; built at construction, no allocation per
//! frame.

use fusepose_scene::ObjectSet;
use fusepose_scene::surface::sample_surface;
use nalgebra::{Point3, Vector3};

use crate::poses::PoseSet;

/// Voxels along an object's longest bounding-box side.
const VOXELS: f64 = 20.0;
/// Surface samples per object when voxelising (dense enough that the surface
/// leaves no gap the flood fill could pass through).
const SURFACE_SAMPLES: usize = 40_000;
/// Default of `estimator.max_interpenetration` (chosen on the tuning splits, docs/BENCHMARKS.md).
pub const DEFAULT_MAX_SHARE: f32 = 0.5;
/// Most probe points per object.
pub const PROBES: usize = 96;

/// One object's solid: occupancy on a padded voxel grid in its own frame.
#[derive(Clone, Debug)]
struct Solid {
    origin: Vector3<f64>,
    voxel: f64,
    dims: [usize; 3],
    occupied: Vec<bool>,
    probes: Vec<Point3<f64>>,
}

impl Solid {
    fn index(&self, p: &Point3<f64>) -> Option<usize> {
        let q = (p.coords - self.origin) / self.voxel;
        let (x, y, z) = (q.x.floor(), q.y.floor(), q.z.floor());
        let [nx, ny, nz] = self.dims;
        (x >= 0.0 && y >= 0.0 && z >= 0.0 && (x as usize) < nx && (y as usize) < ny && (z as usize) < nz)
            .then(|| (z as usize * ny + y as usize) * nx + x as usize)
    }

    fn contains(&self, p: &Point3<f64>) -> bool {
        self.index(p).is_some_and(|i| self.occupied[i])
    }

    /// Voxelises `samples` (object frame) over the box `lo..hi`.
    fn from_surface(samples: &[Point3<f64>], lo: Point3<f64>, hi: Point3<f64>) -> Self {
        let side = (hi - lo).max().max(1e-3);
        let voxel = side / VOXELS;
        // One empty voxel of padding on every side: the flood fill starts there.
        let origin = lo.coords - Vector3::repeat(voxel);
        let dims = [0, 1, 2].map(|k| ((hi[k] - lo[k]) / voxel).ceil() as usize + 2);
        let mut solid =
            Self { origin, voxel, dims, occupied: vec![false; dims[0] * dims[1] * dims[2]], probes: vec![] };
        let mut surface = vec![false; solid.occupied.len()];
        for p in samples {
            if let Some(i) = solid.index(p) {
                surface[i] = true;
            }
        }
        // Outside: reachable from the border without crossing the surface.
        let [nx, ny, nz] = dims;
        let mut outside = vec![false; surface.len()];
        let mut stack: Vec<usize> = Vec::new();
        for z in 0..nz {
            for y in 0..ny {
                for x in 0..nx {
                    if x == 0 || y == 0 || z == 0 || x == nx - 1 || y == ny - 1 || z == nz - 1 {
                        let i = (z * ny + y) * nx + x;
                        if !surface[i] && !outside[i] {
                            outside[i] = true;
                            stack.push(i);
                        }
                    }
                }
            }
        }
        while let Some(i) = stack.pop() {
            let (x, y, z) = (i % nx, i / nx % ny, i / (nx * ny));
            let mut visit = |j: usize| {
                if !surface[j] && !outside[j] {
                    outside[j] = true;
                    stack.push(j);
                }
            };
            if x > 0 {
                visit(i - 1);
            }
            if x + 1 < nx {
                visit(i + 1);
            }
            if y > 0 {
                visit(i - nx);
            }
            if y + 1 < ny {
                visit(i + nx);
            }
            if z > 0 {
                visit(i - nx * ny);
            }
            if z + 1 < nz {
                visit(i + nx * ny);
            }
        }
        for (o, out) in solid.occupied.iter_mut().zip(&outside) {
            *o = !out;
        }
        let filled: Vec<usize> = (0..solid.occupied.len()).filter(|&i| solid.occupied[i]).collect();
        let stride = filled.len().div_ceil(PROBES).max(1);
        solid.probes = filled
            .iter()
            .step_by(stride)
            .map(|&i| {
                let c = Vector3::new((i % nx) as f64, (i / nx % ny) as f64, (i / (nx * ny)) as f64);
                Point3::from(origin + (c + Vector3::repeat(0.5)) * voxel)
            })
            .collect();
        solid
    }
}

/// The solids of one object set (class id − 1 indexes them).
#[derive(Clone, Debug)]
pub struct Solids {
    solids: Vec<Solid>,
}

impl Solids {
    pub fn new(objects: &ObjectSet) -> Self {
        let solids = objects
            .objects
            .iter()
            .map(|o| {
                // A mesh that cannot be sampled (no area) falls back to the stored samples.
                let dense = sample_surface(&o.mesh, SURFACE_SAMPLES, 0x501d).unwrap_or_else(|_| o.samples.clone());
                Solid::from_surface(&dense, o.bbox_min, o.bbox_max)
            })
            .collect();
        Self { solids }
    }

    /// Share of class `class`'s solid that lies in the solid of class
    /// `other`, the two at their poses (camera frame). 0 for unknown classes.
    pub fn share_inside(
        &self,
        class: u16,
        pose: &nalgebra::Isometry3<f64>,
        other: u16,
        other_pose: &nalgebra::Isometry3<f64>,
    ) -> f32 {
        let (Some(a), Some(b)) = (self.solid(class), self.solid(other)) else { return 0.0 };
        if a.probes.is_empty() {
            return 0.0;
        }
        let to_other = other_pose.inverse() * pose;
        let inside = a.probes.iter().filter(|p| b.contains(&(to_other * *p))).count();
        inside as f32 / a.probes.len() as f32
    }

    /// Share of class `class`'s own solid voxels in its grid (tests, docs).
    pub fn fill(&self, class: u16) -> f32 {
        self.solid(class).map_or(0.0, |s| s.occupied.iter().filter(|&&o| o).count() as f32 / s.occupied.len() as f32)
    }

    fn solid(&self, class: u16) -> Option<&Solid> {
        (class as usize).checked_sub(1).and_then(|i| self.solids.get(i))
    }

    /// Of every two poses whose solids overlap by more than `max_share`
    /// (of either one), marks the one more inside the other (equal shares
    /// within 0.1: the lower `scores`, NaN lowest) in `dropped` (resized to the
    /// pose count; no allocation within its capacity), removes them from
    /// `poses` and returns how many. `max_share` ≥ 1 never drops.
    pub fn suppress(&self, poses: &mut PoseSet, max_share: f32, scores: &[f32], dropped: &mut Vec<bool>) -> usize {
        let iso = |p: &crate::poses::ObjectPose| {
            nalgebra::Isometry3::from_parts(nalgebra::Translation3::from(p.translation), p.rotation)
        };
        crate::poses::drop_pairwise(poses, max_share, scores, dropped, false, |a, b| {
            let (pa, pb) = (iso(a), iso(b));
            Some((
                self.share_inside(a.class_id, &pa, b.class_id, &pb),
                self.share_inside(b.class_id, &pb, a.class_id, &pa),
            ))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::poses::ObjectPose;
    use fusepose_scene::builtin::builtin_objects;
    use nalgebra::{Isometry3, UnitQuaternion};

    fn at(x: f64, y: f64, z: f64) -> Isometry3<f64> {
        Isometry3::translation(x, y, z)
    }

    fn pose(class_id: u16, iso: Isometry3<f64>) -> ObjectPose {
        ObjectPose {
            class_id,
            instance_id: 0,
            rotation: iso.rotation,
            translation: iso.translation.vector,
            confidence: 0.5,
            mask_pixels: 100,
            bbox: [0; 4],
            iterations: 0,
        }
    }

    #[test]
    fn boxes_are_solid_and_bowls_and_mugs_stay_hollow() {
        let set = builtin_objects();
        let solids = Solids::new(&set);
        let class = |n: &str| set.class_of(n).unwrap();
        // A closed box fills its padded grid but for the padding.
        assert!(solids.fill(class("cracker_box")) > 0.6, "{}", solids.fill(class("cracker_box")));
        // A can at the bowl's centre, standing in it: the bowl's inside is not solid.
        let bowl = set.by_class(class("bowl")).unwrap();
        let inner = at(0.0, 0.0, bowl.bbox_min.z + 0.04);
        let share = solids.share_inside(class("tomato_soup_can"), &inner, class("bowl"), &at(0.0, 0.0, 0.0));
        assert!(share < 0.2, "a can standing in the bowl overlaps it by {share}");
        assert!(solids.fill(class("bowl")) < 0.3, "{}", solids.fill(class("bowl")));
    }

    #[test]
    fn a_can_inside_a_box_goes_and_touching_neighbours_stay() {
        let set = builtin_objects();
        let solids = Solids::new(&set);
        let (boxc, can, block) = (
            set.class_of("cracker_box").unwrap(),
            set.class_of("tomato_soup_can").unwrap(),
            set.class_of("wood_block").unwrap(),
        );
        let box_model = set.by_class(boxc).unwrap();
        let can_model = set.by_class(can).unwrap();
        let base = at(0.0, 0.0, 0.8);
        // The can inside the box (the box's top read as a can), a block
        // touching the box's side (its bbox edge against the box's).
        let block_model = set.by_class(block).unwrap();
        let beside = base * at(box_model.bbox_max.x - block_model.bbox_min.x + 0.002, 0.0, 0.0);
        let inside = base * at(0.0, 0.0, box_model.bbox_max.z - can_model.bbox_max.z - 0.01);
        let mut poses = PoseSet::with_capacity(4);
        for p in [pose(boxc, base), pose(can, inside), pose(block, beside)] {
            assert!(poses.push(p));
        }
        // The can scores higher: the rule goes by who is inside whom, not by score.
        let scores = [0.5, 0.9, 0.5];
        let mut dropped = Vec::with_capacity(4);
        assert_eq!(solids.suppress(&mut poses, 0.4, &scores, &mut dropped), 1);
        assert_eq!(dropped, vec![false, true, false]);
        assert_eq!(poses.as_slice().iter().map(|p| p.class_id).collect::<Vec<_>>(), vec![boxc, block]);
        // Off (1.0): nothing dropped; a rotated pose of the same box in the
        // same place: one of the two goes (the lower score).
        let mut again = PoseSet::with_capacity(4);
        let turned = base * Isometry3::rotation(Vector3::z() * 0.3);
        for p in [pose(boxc, base), pose(boxc, turned)] {
            assert!(again.push(p));
        }
        assert_eq!(solids.suppress(&mut again.clone(), 1.0, &[0.5, 0.6], &mut dropped), 0);
        assert_eq!(solids.suppress(&mut again, 0.4, &[0.5, 0.6], &mut dropped), 1);
        assert_eq!(again.as_slice()[0].rotation, UnitQuaternion::from_scaled_axis(Vector3::z() * 0.3));
    }
}
