//! Poses seen twice: [`PoseFlags::CONFIRMED`] marks a published pose when a
//! pose of its class lay within a distance of it in one of the camera's last
//! processed frames that looked at the class (camera frame; the previous one
//! by default). On a heap of identical objects a pose that lies between two
//! copies rarely repeats there, where a pose of a copy does, so a grasp
//! controller that acts only on confirmed poses grasps at nothing far less
//! often, one frame later (docs/BENCHMARKS.md, session 32).
//!
//! A frame that shed an instance of a class to keep its deadline did not
//! look at the class: its missing pose says nothing, so the frame is not
//! counted for that class and the memory reaches back to the frame before
//! (at most [`MAX_CONFIRM_FRAMES`] frames). On a machine that poses one of
//! five objects per frame, objects take turns and are rarely posed two
//! frames in a row (session 32); counting frames alone, they were almost
//! never confirmed (docs/BENCHMARKS.md, session 35).
//! Preallocated: no allocation per frame.

use fusepose_client::{MAX_OBJECTS, PoseFlags, WireObjectPose};

/// Most frames a camera may look back over (`estimator.confirm_frames`).
pub const MAX_CONFIRM_FRAMES: u32 = 24;

/// A pose remembered: when, of which class, where.
#[derive(Clone, Copy, Debug)]
struct Seen {
    frame: u64,
    /// Frames that had looked at its class before its own.
    look: u64,
    class_id: u16,
    translation_m: [f64; 3],
}

/// One camera's memory of its last frames' poses.
pub struct Confirmations {
    within_m: f64,
    frames: u32,
    /// Frames marked so far.
    frame: u64,
    /// Per class id: frames marked so far that looked at the class (did not
    /// shed an instance of it). Class ids beyond it are always looked at.
    looks: Vec<u64>,
    /// The poses of the last `frames` looks at their class, of the last
    /// [`MAX_CONFIRM_FRAMES`] frames at most.
    seen: Vec<Seen>,
}

impl Confirmations {
    /// `within_m`: how near a pose must lie (metres; 0 = never confirmed);
    /// `frames`: in how many of the last processed frames that looked at
    /// its class (1 = the last one only, at most [`MAX_CONFIRM_FRAMES`]);
    /// `classes`: the largest class id counted apart.
    pub fn new(within_m: f64, frames: u32, classes: u16) -> Self {
        let frames = frames.clamp(1, MAX_CONFIRM_FRAMES);
        Self {
            within_m,
            frames,
            frame: 0,
            looks: vec![0; usize::from(classes) + 1],
            seen: Vec::with_capacity(MAX_CONFIRM_FRAMES as usize * MAX_OBJECTS),
        }
    }

    /// Frames that looked at class `class_id` so far (ids beyond the table:
    /// every frame).
    fn looks(&self, class_id: u16) -> u64 {
        self.looks.get(usize::from(class_id)).copied().unwrap_or(self.frame)
    }

    /// Sets [`PoseFlags::CONFIRMED`] on each of `objects` (this frame's
    /// published poses) that an earlier frame confirms, then remembers them.
    /// `shed(class_id)`: whether this frame shed an instance of the class.
    pub fn mark(&mut self, objects: &mut [WireObjectPose], shed: impl Fn(u16) -> bool) {
        let r2 = self.within_m * self.within_m;
        let frames = u64::from(self.frames);
        for o in objects.iter_mut() {
            let (t, before) = (o.translation_m, self.looks(o.class_id));
            let near = self.seen.iter().any(|s| {
                s.class_id == o.class_id
                    && before - s.look <= frames
                    && (0..3).map(|a| (s.translation_m[a] - t[a]).powi(2)).sum::<f64>() < r2
            });
            if near {
                o.flags |= PoseFlags::CONFIRMED;
            }
        }
        let room = self.seen.capacity() - self.seen.len();
        for o in objects.iter().take(room.min(MAX_OBJECTS)) {
            let look = self.looks(o.class_id);
            self.seen.push(Seen { frame: self.frame, look, class_id: o.class_id, translation_m: o.translation_m });
        }
        self.frame += 1;
        for (class_id, looks) in self.looks.iter_mut().enumerate() {
            *looks += u64::from(!shed(class_id as u16));
        }
        // Keep what a later frame may still match: within `frames` looks at
        // its class, and the last `MAX_CONFIRM_FRAMES` frames.
        let (now, looks, max_age) = (self.frame, &self.looks, u64::from(MAX_CONFIRM_FRAMES));
        let looks_of = |c: u16| looks.get(usize::from(c)).copied().unwrap_or(now);
        self.seen.retain(|s| looks_of(s.class_id) - s.look <= frames && now - s.frame <= max_age);
    }

    /// A frame without poses (refused, or the estimator failed): it looked
    /// at every class and saw nothing.
    pub fn forget(&mut self) {
        self.mark(&mut [], |_| false);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(class_id: u16, x: f64) -> WireObjectPose {
        WireObjectPose { class_id, translation_m: [x, 0.0, 0.6], ..Default::default() }
    }

    fn confirmed(c: &mut Confirmations, frame: &[WireObjectPose]) -> Vec<bool> {
        confirmed_shedding(c, frame, |_| false)
    }

    /// As [`confirmed`], in a frame that shed the classes `shed` says.
    fn confirmed_shedding(c: &mut Confirmations, frame: &[WireObjectPose], shed: fn(u16) -> bool) -> Vec<bool> {
        let mut objects = frame.to_vec();
        c.mark(&mut objects, shed);
        objects.iter().map(WireObjectPose::is_confirmed).collect()
    }

    #[test]
    fn a_pose_is_confirmed_by_one_of_its_class_near_it_in_the_previous_frame() {
        let mut c = Confirmations::new(0.01, 1, 8);
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
        let mut c = Confirmations::new(0.01, 3, 8);
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
        assert!(c.seen.len() <= 3 * MAX_OBJECTS && c.seen.capacity() == MAX_CONFIRM_FRAMES as usize * MAX_OBJECTS);
    }

    #[test]
    fn frames_that_shed_a_class_are_not_counted_for_it() {
        let mut c = Confirmations::new(0.01, 1, 8);
        let shed_1 = |k: u16| k == 1;
        confirmed(&mut c, &[at(1, 0.0), at(2, 0.1)]);
        // Two late frames pose class 2 only: class 1 was shed, not missed.
        assert_eq!(confirmed_shedding(&mut c, &[at(2, 0.1)], shed_1), [true]);
        assert_eq!(confirmed_shedding(&mut c, &[at(2, 0.1)], shed_1), [true]);
        // Class 1's turn: the last frame that looked at it confirms it.
        assert_eq!(confirmed(&mut c, &[at(1, 0.002)]), [true], "bridged over the two frames that shed it");
        // Class 2 was looked at in that frame and not seen: no confirmation.
        assert_eq!(confirmed(&mut c, &[at(1, 0.002)]), [true]);
        assert_eq!(confirmed(&mut c, &[at(2, 0.1)]), [false], "looked at, not seen, in between");
        // Shed for 23 frames: still bridged; for 24: too long ago.
        for (shed_frames, bridged) in [(MAX_CONFIRM_FRAMES - 1, true), (MAX_CONFIRM_FRAMES, false)] {
            confirmed(&mut c, &[at(1, 0.0)]);
            for _ in 0..shed_frames {
                confirmed_shedding(&mut c, &[], shed_1);
            }
            assert_eq!(confirmed(&mut c, &[at(1, 0.0)]), [bridged], "{shed_frames} frames shed");
            confirmed(&mut c, &[]);
        }
        // A class id beyond the table is looked at in every frame.
        confirmed(&mut c, &[at(40, 0.0)]);
        assert!(confirmed_shedding(&mut c, &[], |_| true).is_empty());
        assert_eq!(confirmed(&mut c, &[at(40, 0.0)]), [false]);
    }

    #[test]
    fn zero_distance_confirms_nothing_and_other_flags_stay() {
        let mut c = Confirmations::new(0.0, 1, 8);
        confirmed(&mut c, &[at(1, 0.0)]);
        assert_eq!(confirmed(&mut c, &[at(1, 0.0)]), [false]);
        let mut c = Confirmations::new(0.01, 1, 8);
        let verified = WireObjectPose { flags: PoseFlags::VERIFIED, ..at(1, 0.0) };
        c.mark(&mut [verified], |_| false);
        let mut again = [verified];
        c.mark(&mut again, |_| false);
        assert_eq!(again[0].flags, PoseFlags::VERIFIED | PoseFlags::CONFIRMED);
    }
}
