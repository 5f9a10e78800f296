//! Stable instance ids in tracking mode: a published pose keeps the id it
//! had in the camera's previous frames while its object stays in view, so a
//! consumer can follow one of several identical objects. Matching is by class
//! and position: each pose takes the id of the nearest remembered object of
//! its class within half that class's diameter (nearest pairs first, one pose
//! per id); the others get new ids. An object unseen for more than
//! [`MAX_MISSED_FRAMES`] frames that looked at its class is forgotten: a
//! frame that shed an instance of the class to keep its deadline did not
//! look, and on a machine that poses one of five objects per frame each
//! object waits four frames or more for its turn (as for the `CONFIRMED`
//! flag, [`crate::confirm`]). Unseen for [`MAX_UNSEEN_FRAMES`] frames in
//! all, it is forgotten anyway. Preallocated: no allocation per frame.

use fusepose_client::WireObjectPose;
use nalgebra::Vector3;

/// Frames that looked at its class in which an object may go unseen (a
/// missed detection) and keep its id.
pub const MAX_MISSED_FRAMES: u32 = 5;
/// Frames in all (shed ones included) an object may go unseen and keep its
/// id: one second at 24 FPS.
pub const MAX_UNSEEN_FRAMES: u32 = 24;
/// Most objects remembered at once.
const CAPACITY: usize = 128;

#[derive(Clone, Copy, Debug)]
struct Remembered {
    class_id: u16,
    id: u16,
    translation: Vector3<f64>,
    /// Frames unseen that looked at its class, and frames unseen in all.
    missed: u32,
    unseen: u32,
}

/// One camera's id memory.
pub struct StableIds {
    /// Per class id − 1: largest distance between frames of one object, metres.
    radius_m: Vec<f64>,
    known: Vec<Remembered>,
    /// (distance, pose index, known index) candidates of one frame.
    pairs: Vec<(f64, u16, u16)>,
    taken_pose: Vec<bool>,
    taken_known: Vec<bool>,
    next_id: u16,
}

impl StableIds {
    /// `radius_m[class − 1]`: how far an object may move between frames and keep its id.
    pub fn new(radius_m: Vec<f64>) -> Self {
        Self {
            radius_m,
            known: Vec::with_capacity(CAPACITY),
            pairs: Vec::with_capacity(fusepose_client::MAX_OBJECTS * CAPACITY),
            taken_pose: Vec::with_capacity(fusepose_client::MAX_OBJECTS),
            taken_known: Vec::with_capacity(CAPACITY),
            next_id: 0,
        }
    }

    fn fresh_id(&mut self) -> u16 {
        // Skip ids still in use after the counter wraps.
        loop {
            let id = self.next_id;
            self.next_id = self.next_id.wrapping_add(1);
            if !self.known.iter().any(|k| k.id == id) {
                return id;
            }
        }
    }

    /// Rewrites the `instance_id` of this frame's poses to stable ids;
    /// `shed(class_id)`: whether this frame shed an instance of the class.
    pub fn assign(&mut self, poses: &mut [WireObjectPose], shed: impl Fn(u16) -> bool) {
        self.pairs.clear();
        for (p, pose) in poses.iter().enumerate() {
            let t = Vector3::from(pose.translation_m);
            let radius = self.radius_m.get((pose.class_id as usize).wrapping_sub(1)).copied().unwrap_or(0.0);
            for (k, known) in self.known.iter().enumerate() {
                let d = (known.translation - t).norm();
                if known.class_id == pose.class_id && d <= radius {
                    self.pairs.push((d, p as u16, k as u16));
                }
            }
        }
        self.pairs.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        self.taken_pose.clear();
        self.taken_pose.resize(poses.len(), false);
        self.taken_known.clear();
        self.taken_known.resize(self.known.len(), false);
        for &(_, p, k) in &self.pairs {
            let (p, k) = (p as usize, k as usize);
            if self.taken_pose[p] || self.taken_known[k] {
                continue;
            }
            self.taken_pose[p] = true;
            self.taken_known[k] = true;
            poses[p].instance_id = self.known[k].id;
            self.known[k].translation = Vector3::from(poses[p].translation_m);
            self.known[k].missed = 0;
            self.known[k].unseen = 0;
        }
        // Unmatched remembered objects age (where their class was looked
        // at); the too old are forgotten.
        for (k, known) in self.known.iter_mut().enumerate() {
            if !self.taken_known[k] {
                known.missed += u32::from(!shed(known.class_id));
                known.unseen += 1;
            }
        }
        self.known.retain(|k| k.missed <= MAX_MISSED_FRAMES && k.unseen <= MAX_UNSEEN_FRAMES);
        for (p, pose) in poses.iter_mut().enumerate() {
            if self.taken_pose[p] {
                continue;
            }
            let id = self.fresh_id();
            pose.instance_id = id;
            if self.known.len() < CAPACITY {
                let translation = Vector3::from(pose.translation_m);
                self.known.push(Remembered { class_id: pose.class_id, id, translation, missed: 0, unseen: 0 });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pose(class_id: u16, instance_id: u16, x: f64) -> WireObjectPose {
        WireObjectPose { class_id, instance_id, translation_m: [x, 0.0, 0.8], ..WireObjectPose::default() }
    }

    #[test]
    fn identical_objects_keep_their_ids_when_the_frame_order_changes() {
        let mut ids = StableIds::new(vec![0.05; 8]);
        let mut frame = [pose(3, 0, 0.00), pose(3, 1, 0.10), pose(5, 2, -0.2)];
        ids.assign(&mut frame, |_| false);
        let (left, right, other) = (frame[0].instance_id, frame[1].instance_id, frame[2].instance_id);
        assert!(left != right && right != other && left != other);
        // Next frame: the right copy is now the larger mask (listed first), both moved a little.
        let mut next = [pose(3, 0, 0.11), pose(3, 1, 0.01), pose(5, 2, -0.19)];
        ids.assign(&mut next, |_| false);
        assert_eq!((next[0].instance_id, next[1].instance_id, next[2].instance_id), (right, left, other));
    }

    #[test]
    fn a_new_object_gets_a_new_id_and_a_lost_one_is_forgotten_after_a_few_frames() {
        let mut ids = StableIds::new(vec![0.05; 8]);
        let mut frame = [pose(3, 0, 0.0)];
        ids.assign(&mut frame, |_| false);
        let first = frame[0].instance_id;
        // Unseen for a few frames: the id survives.
        for _ in 0..MAX_MISSED_FRAMES {
            ids.assign(&mut [], |_| false);
        }
        let mut back = [pose(3, 0, 0.01)];
        ids.assign(&mut back, |_| false);
        assert_eq!(back[0].instance_id, first);
        // Too far to be the same object: another id, and the old one is not reused while remembered.
        let mut jump = [pose(3, 0, 0.01), pose(3, 1, 0.3)];
        ids.assign(&mut jump, |_| false);
        assert_eq!(jump[0].instance_id, first);
        assert_ne!(jump[1].instance_id, first);
        // Gone longer than the limit: forgotten, so it comes back with a new id.
        for _ in 0..=MAX_MISSED_FRAMES {
            ids.assign(&mut [], |_| false);
        }
        let mut again = [pose(3, 0, 0.01)];
        ids.assign(&mut again, |_| false);
        assert_ne!(again[0].instance_id, first);
    }

    #[test]
    fn frames_that_shed_a_class_do_not_age_its_objects() {
        let mut ids = StableIds::new(vec![0.05; 8]);
        let mut frame = [pose(3, 0, 0.0), pose(5, 1, 0.3)];
        ids.assign(&mut frame, |_| false);
        let (can, other) = (frame[0].instance_id, frame[1].instance_id);
        // Class 3 shed for twice the missed-frame limit, class 5 posed: the can keeps its id.
        for _ in 0..2 * MAX_MISSED_FRAMES {
            let mut only_other = [pose(5, 0, 0.3)];
            ids.assign(&mut only_other, |c| c == 3);
            assert_eq!(only_other[0].instance_id, other);
        }
        let mut back = [pose(3, 0, 0.01)];
        ids.assign(&mut back, |_| false);
        assert_eq!(back[0].instance_id, can, "shed frames are not missed frames");
        // Shed for longer than a second in all: forgotten.
        for _ in 0..=MAX_UNSEEN_FRAMES {
            ids.assign(&mut [], |c| c == 3);
        }
        let mut late = [pose(3, 0, 0.01)];
        ids.assign(&mut late, |_| false);
        assert_ne!(late[0].instance_id, can, "unseen for {MAX_UNSEEN_FRAMES} frames and more");
    }
}
