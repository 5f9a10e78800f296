//! Poses seen twice: [`PoseFlags::CONFIRMED`] marks a published pose when a
//! pose of its class lay within a distance of it in one of the camera's last
//! processed frames (camera frame; the previous one by default). On a heap of identical objects a pose that
//! lies between two copies rarely repeats there, where a pose of a copy
//! does, so a grasp controller that acts only on confirmed poses grasps at
//! nothing far less often, one frame later (docs/BENCHMARKS.md, session 32).
//! Preallocated: no allocation per frame.

use fusepose_client::{MAX_OBJECTS, PoseFlags, WireObjectPose};

/// Most frames a camera may look back over (`estimator.confirm_frames`).
pub const MAX_CONFIRM_FRAMES: u32 = 24;

/// One camera's memory of its last frames' poses.
pub struct Confirmations {
    within_m: f64,
    frames: u32,
    /// Frames marked so far.
    frame: u64,
    /// (frame, class id, translation m) of the poses of the last `frames` frames.
    seen: Vec<(u64, u16, [f64; 3])>,
}

impl Confirmations {
    /// `within_m`: how near a pose must lie (metres; 0 = never confirmed);
    /// `frames`: in how many of the last processed frames (1 = the previous
    /// one only, at most [`MAX_CONFIRM_FRAMES`]).
    pub fn new(within_m: f64, frames: u32) -> Self {
        let frames = frames.clamp(1, MAX_CONFIRM_FRAMES);
        Self { within_m, frames, frame: 0, seen: Vec::with_capacity(frames as usize * MAX_OBJECTS) }
    }

    /// Sets [`PoseFlags::CONFIRMED`] on each of `objects` (this frame's
    /// published poses) that an earlier frame confirms, then remembers them.
    pub fn mark(&mut self, objects: &mut [WireObjectPose]) {
        let r2 = self.within_m * self.within_m;
        for o in objects.iter_mut() {
            let t = o.translation_m;
            let near = self
                .seen
                .iter()
                .any(|(_, c, p)| *c == o.class_id && (0..3).map(|a| (p[a] - t[a]).powi(2)).sum::<f64>() < r2);
            if near {
                o.flags |= PoseFlags::CONFIRMED;
            }
        }
        self.frame += 1;
        // Keep the last `frames - 1` frames and add this one.
        let oldest = self.frame.saturating_sub(self.frames as u64);
        self.seen.retain(|(f, _, _)| *f > oldest);
        let room = self.seen.capacity() - self.seen.len();
        let frame = self.frame;
        self.seen.extend(objects.iter().take(room.min(MAX_OBJECTS)).map(|o| (frame, o.class_id, o.translation_m)));
    }

    /// A frame without poses (refused, or the estimator failed): it counts
    /// as one of the frames looked back over, with nothing seen.
    pub fn forget(&mut self) {
        self.mark(&mut []);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(class_id: u16, x: f64) -> WireObjectPose {
        WireObjectPose { class_id, translation_m: [x, 0.0, 0.6], ..Default::default() }
    }

    fn confirmed(c: &mut Confirmations, frame: &[WireObjectPose]) -> Vec<bool> {
        let mut objects = frame.to_vec();
        c.mark(&mut objects);
        objects.iter().map(WireObjectPose::is_confirmed).collect()
    }

    #[test]
    fn a_pose_is_confirmed_by_one_of_its_class_near_it_in_the_previous_frame() {
        let mut c = Confirmations::new(0.01, 1);
        assert_eq!(confirmed(&mut c, &[at(1, 0.0), at(2, 0.1)]), [false, false], "a first frame confirms nothing");
        // Class 1 moved 5 mm, class 2 moved 15 mm, a class-3 pose where class 1 was.
        assert_eq!(confirmed(&mut c, &[at(1, 0.005), at(2, 0.115), at(3, 0.0)]), [true, false, false]);
        // Only the frame just before counts.
        assert_eq!(confirmed(&mut c, &[at(2, 0.1)]), [false]);
        c.forget();
        assert_eq!(confirmed(&mut c, &[at(2, 0.1)]), [false], "a frame without poses in between");
        assert_eq!(confirmed(&mut c, &[at(2, 0.1)]), [true]);
    }

    #[test]
    fn looking_back_over_three_frames_bridges_two_without_the_object() {
        let mut c = Confirmations::new(0.01, 3);
        confirmed(&mut c, &[at(1, 0.0)]);
        confirmed(&mut c, &[]);
        c.forget();
        assert_eq!(confirmed(&mut c, &[at(1, 0.002)]), [true], "seen three frames ago");
        confirmed(&mut c, &[]);
        confirmed(&mut c, &[]);
        confirmed(&mut c, &[]);
        assert_eq!(confirmed(&mut c, &[at(1, 0.002)]), [false], "four frames ago is too long");
        // A full memory: 32 poses a frame for many frames stays within its room.
        let many: Vec<WireObjectPose> = (0..MAX_OBJECTS).map(|i| at(1, i as f64)).collect();
        for _ in 0..10 {
            assert!(confirmed(&mut c, &many).len() == MAX_OBJECTS);
        }
        assert!(c.seen.len() <= 3 * MAX_OBJECTS && c.seen.capacity() == 3 * MAX_OBJECTS);
    }

    #[test]
    fn zero_distance_confirms_nothing_and_other_flags_stay() {
        let mut c = Confirmations::new(0.0, 1);
        confirmed(&mut c, &[at(1, 0.0)]);
        assert_eq!(confirmed(&mut c, &[at(1, 0.0)]), [false]);
        let mut c = Confirmations::new(0.01, 1);
        let verified = WireObjectPose { flags: PoseFlags::VERIFIED, ..at(1, 0.0) };
        c.mark(&mut [verified]);
        let mut again = [verified];
        c.mark(&mut again);
        assert_eq!(again[0].flags, PoseFlags::VERIFIED | PoseFlags::CONFIRMED);
    }
}
