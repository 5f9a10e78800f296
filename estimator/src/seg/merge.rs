//! Instances of one class that are one object: the vote peaks of two
//! instances lie closer in 3D than two solid copies of the object can be
//! (their centres stay about its smallest side apart), so they are the
//! pieces of one object whose centre votes scattered, and become one
//! instance. Each instance's centre is its vote peak back-projected at the
//! mean measured depth of its cells; the per-class distance comes from
//! [`crate::duplicates::separations`], the same rule that drops duplicate
//! poses after estimation.
//!
//! Buffers are sized for [`MAX_INSTANCES`] at construction; merging never allocates.

use super::input::FrameMap;
use super::voting::{Centre, MAX_INSTANCES};
use crate::frame::FrameView;

/// Reusable buffers of the merge step.
#[derive(Clone, Debug)]
pub struct InstanceMerger {
    /// Per instance (index = id − 1): camera-frame centre, metres (NaN when no cell has depth).
    centres: Vec<[f64; 3]>,
    /// Per instance: sum of cell depths and their count.
    depth: Vec<(f64, u32)>,
    /// Union-find parent per instance.
    parent: Vec<u16>,
    /// Old id → new id (index 0 = background).
    renumber: Vec<u16>,
}

impl Default for InstanceMerger {
    fn default() -> Self {
        Self {
            centres: Vec::with_capacity(MAX_INSTANCES),
            depth: Vec::with_capacity(MAX_INSTANCES),
            parent: Vec::with_capacity(MAX_INSTANCES),
            renumber: Vec::with_capacity(MAX_INSTANCES + 1),
        }
    }
}

fn root(parent: &mut [u16], mut i: usize) -> usize {
    while parent[i] as usize != i {
        parent[i] = parent[parent[i] as usize];
        i = parent[i] as usize;
    }
    i
}

impl InstanceMerger {
    /// Merges the instances of `cell_ids` (ids 1..=`centres.len()`, class of
    /// id `k` = `centres[k − 1].class_id`) that are one object by
    /// `separation[class − 1]` (metres; classes beyond it never merge),
    /// renumbers the cells to consecutive ids and writes the class of each
    /// new id into `classes` (index 0 = background). Returns how many
    /// instances were merged away.
    pub fn merge(
        &mut self,
        frame: &FrameView<'_>,
        map: &FrameMap,
        centres: &[Centre],
        separation: &[f32],
        cell_ids: &mut [u16],
        classes: &mut Vec<u16>,
    ) -> usize {
        let n = centres.len().min(MAX_INSTANCES);
        if separation.is_empty() {
            // Off: the ids stay as voted.
            classes.clear();
            classes.push(0);
            classes.extend(centres.iter().take(n).map(|c| c.class_id));
            return 0;
        }
        let (grid_w, grid_h) = map.grid_size();
        let (frame_w, _) = map.frame_size();
        let mid = |r: std::ops::Range<usize>| (r.start + r.end.max(r.start + 1) - 1) as f64 / 2.0;
        // Mean measured depth per instance over its cells' centre pixels.
        self.depth.clear();
        self.depth.resize(n, (0.0, 0));
        for (cell, &id) in cell_ids.iter().enumerate() {
            if id == 0 || id as usize > n {
                continue;
            }
            let (cx, cy) = (cell % grid_w, cell / grid_w);
            let (u, v) = (mid(map.span_x(cx)) as usize, mid(map.span_y(cy)) as usize);
            if let Some(z) = frame.depth.metres(v * frame_w + u).filter(|z| *z > 0.0) {
                let d = &mut self.depth[id as usize - 1];
                *d = (d.0 + z as f64, d.1 + 1);
            }
        }
        let k = &frame.intrinsics;
        self.centres.clear();
        for (c, &(sum, count)) in centres.iter().take(n).zip(&self.depth) {
            let z = if count > 0 { sum / count as f64 } else { f64::NAN };
            let cx = (c.x.round().max(0.0) as usize).min(grid_w - 1);
            let cy = (c.y.round().max(0.0) as usize).min(grid_h - 1);
            let (u, v) = (mid(map.span_x(cx)), mid(map.span_y(cy)));
            self.centres.push([(u - k.cx) / k.fx * z, (v - k.cy) / k.fy * z, z]);
        }
        self.parent.clear();
        self.parent.extend((0..n).map(|i| i as u16));
        let mut merged = 0;
        for (a, ca) in centres.iter().enumerate().take(n) {
            let class = ca.class_id;
            let Some(&min) = separation.get(class as usize - 1) else { continue };
            for (b, cb) in centres.iter().enumerate().take(n).skip(a + 1) {
                if cb.class_id != class {
                    continue;
                }
                let (p, q) = (self.centres[a], self.centres[b]);
                let d2 = (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2);
                // NaN (an instance without depth) never merges.
                if d2 < (min as f64).powi(2) {
                    let (ra, rb) = (root(&mut self.parent, a), root(&mut self.parent, b));
                    if ra != rb {
                        // The lower id (the stronger peak of the class) stays.
                        let (keep, gone) = (ra.min(rb), ra.max(rb));
                        self.parent[gone] = keep as u16;
                        merged += 1;
                    }
                }
            }
        }
        self.renumber.clear();
        self.renumber.resize(n + 1, 0);
        classes.clear();
        classes.push(0);
        for (i, c) in centres.iter().enumerate().take(n) {
            if root(&mut self.parent, i) == i {
                self.renumber[i + 1] = classes.len() as u16;
                classes.push(c.class_id);
            }
        }
        for i in 0..n {
            let r = root(&mut self.parent, i);
            self.renumber[i + 1] = self.renumber[r + 1];
        }
        for id in cell_ids.iter_mut() {
            if (*id as usize) <= n {
                *id = self.renumber[*id as usize];
            }
        }
        merged
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{ColorFormat, DepthPlane};
    use crate::seg::SegConfig;
    use fusepose_scene::Intrinsics;

    const K: Intrinsics = Intrinsics { fx: 1066.0, fy: 1066.0, cx: 320.0, cy: 240.0, width: 640, height: 480 };

    fn centre(class_id: u16, x: f32, y: f32) -> Centre {
        Centre { class_id, x, y, strength: 10.0, cells: 0 }
    }

    /// Cells of ids 1, 2, 3 in three side-by-side 10x10 blocks of the 80x60 grid
    /// (8-pixel cells of a 640x480 frame, everything at 0.8 m).
    fn run(centres: &[Centre], separation: &[f32]) -> (usize, Vec<u16>, Vec<u16>) {
        let map = FrameMap::new(640, 480, &SegConfig::new(2));
        let (w, h) = map.grid_size();
        assert_eq!((w, h), (80, 60));
        let depth = vec![0.8f32; 640 * 480];
        let color = vec![0u8; 640 * 480 * 3];
        let frame = FrameView {
            intrinsics: K,
            color_format: ColorFormat::Rgb8,
            color: &color,
            depth: DepthPlane::F32(&depth),
            labels: None,
        };
        let mut ids = vec![0u16; w * h];
        for y in 10..20 {
            for x in 10..40 {
                ids[y * w + x] = ((x - 10) / 10 + 1) as u16;
            }
        }
        let mut classes = Vec::new();
        let merged = InstanceMerger::default().merge(&frame, &map, centres, separation, &mut ids, &mut classes);
        (merged, ids, classes)
    }

    #[test]
    fn pieces_closer_than_two_copies_can_be_become_one_and_the_rest_stay() {
        // Ids 1 and 2 (class 1) vote 1 cell = 6 mm apart at 0.8 m; id 3 is class 2.
        let (merged, ids, classes) =
            run(&[centre(1, 15.0, 15.0), centre(1, 16.0, 15.0), centre(2, 35.0, 15.0)], &[0.03, 0.03]);
        assert_eq!(merged, 1);
        assert_eq!(classes, vec![0, 1, 2]);
        assert!((10..30).all(|x| ids[15 * 80 + x] == 1) && ids[15 * 80 + 35] == 2);
        // 20 cells = 160 px = 12 cm apart: two objects.
        let (merged, ids, classes) =
            run(&[centre(1, 15.0, 15.0), centre(1, 35.0, 15.0), centre(2, 25.0, 15.0)], &[0.03, 0.03]);
        assert_eq!(merged, 0);
        assert_eq!(classes, vec![0, 1, 1, 2]);
        assert_eq!((ids[15 * 80 + 12], ids[15 * 80 + 22], ids[15 * 80 + 32]), (1, 2, 3));
        // Other classes at the same place never merge; no separation = never.
        let (merged, _, _) = run(&[centre(1, 15.0, 15.0), centre(2, 15.0, 15.0), centre(2, 15.0, 15.0)], &[0.03]);
        assert_eq!(merged, 0);
        let (merged, ids, classes) = run(&[centre(1, 15.0, 15.0), centre(1, 15.0, 15.0), centre(1, 15.0, 15.0)], &[]);
        assert_eq!((merged, classes), (0, vec![0, 1, 1, 1]));
        assert_eq!((ids[15 * 80 + 12], ids[15 * 80 + 22], ids[15 * 80 + 32]), (1, 2, 3));
        // Chains join into the first: three pieces of one object.
        let (merged, ids, classes) =
            run(&[centre(1, 15.0, 15.0), centre(1, 16.0, 15.0), centre(1, 17.0, 15.0)], &[0.03]);
        assert_eq!((merged, classes), (2, vec![0, 1]));
        assert!((10..40).all(|x| ids[15 * 80 + x] == 1));
    }
}
