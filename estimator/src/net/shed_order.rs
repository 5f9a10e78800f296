//! Which of a frame's instances a late frame poses first.
//!
//! A frame whose deadline pays for fewer instances than the segmenter found
//! sheds the rest ([`super::budget::affordable`], and the check before each
//! instance). Shedding the smallest every time starves them: on a loaded
//! machine where one object of five fits a frame, the same four never got a
//! pose (measured in the two-minute network soak: 0.85 poses per answer,
//! always the largest object). So the order rotates:
//! - classes whose instances were all shed for the most frames in a row go
//!   first (a class absent from a frame keeps its count);
//! - among one class's instances, the turn moves on by as many as were posed,
//!   so copies of one object take turns too;
//! - ties keep the instances' own order (largest first).
//!
//! A frame that poses every instance resets both counts, so a machine that
//! keeps up runs the instances in their own order, as before. Buffers are
//! sized at construction and by [`ShedOrder::reserve`]; a frame allocates nothing.

/// Rotation state across frames, per class.
#[derive(Clone, Debug)]
pub struct ShedOrder {
    /// Frames in a row in which the class was present and none of its instances posed.
    starved: Vec<u32>,
    /// Rank (within the class, largest first) of the instance whose turn it is.
    turn: Vec<u32>,
    /// Per instance of the frame: its rank within its class.
    rank: Vec<u32>,
    /// Per class: instances in this frame, and how many got a pose.
    present: Vec<u32>,
    posed: Vec<u32>,
}

impl ShedOrder {
    /// For class indices `0..classes` and up to `capacity` instances per frame.
    pub fn new(classes: usize, capacity: usize) -> Self {
        Self {
            starved: vec![0; classes],
            turn: vec![0; classes],
            rank: Vec::with_capacity(capacity),
            present: vec![0; classes],
            posed: vec![0; classes],
        }
    }

    /// Room for `capacity` instances per frame.
    pub fn reserve(&mut self, capacity: usize) {
        self.rank.reserve(capacity.saturating_sub(self.rank.len()));
    }

    /// Writes into `order` the instances `0..class_of.len()` in the order to
    /// try them; `class_of[i]` is instance `i`'s class index (0-based, below
    /// the class count given to [`ShedOrder::new`]).
    pub fn order(&mut self, class_of: impl Fn(usize) -> usize, count: usize, order: &mut Vec<u16>) {
        self.present.iter_mut().for_each(|p| *p = 0);
        self.rank.clear();
        for i in 0..count {
            let k = class_of(i);
            self.rank.push(self.present[k]);
            self.present[k] += 1;
        }
        order.clear();
        order.extend((0..count).map(|i| i as u16));
        let (starved, turn, rank, present) = (&self.starved, &self.turn, &self.rank, &self.present);
        order.sort_unstable_by_key(|&i| {
            let i = usize::from(i);
            let k = class_of(i);
            let n = present[k].max(1);
            let behind = (rank[i] + n - turn[k] % n) % n;
            (std::cmp::Reverse(starved[k]), behind, i)
        });
    }

    /// After the frame: `posed(i)` says whether instance `i` (of the
    /// `count` given to [`ShedOrder::order`]) got a pose.
    pub fn finish(&mut self, class_of: impl Fn(usize) -> usize, count: usize, posed: impl Fn(usize) -> bool) {
        self.posed.iter_mut().for_each(|p| *p = 0);
        for i in 0..count {
            self.posed[class_of(i)] += u32::from(posed(i));
        }
        for k in 0..self.present.len() {
            let (present, posed) = (self.present[k], self.posed[k]);
            if present == 0 {
                continue;
            }
            self.starved[k] = if posed == 0 { self.starved[k].saturating_add(1) } else { 0 };
            self.turn[k] = if posed >= present { 0 } else { (self.turn[k] + posed) % present };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs `frames` frames in which only the first `fit` of the order get a
    /// pose; returns how often each instance was posed and the longest run of
    /// frames any instance waited for its pose.
    fn rotate(classes: &[usize], fit: usize, frames: usize) -> (Vec<usize>, usize) {
        let mut s = ShedOrder::new(8, classes.len());
        let mut order = Vec::with_capacity(classes.len());
        let mut counts = vec![0; classes.len()];
        let mut waiting = vec![0; classes.len()];
        let mut longest = 0;
        for _ in 0..frames {
            s.order(|i| classes[i], classes.len(), &mut order);
            let posed: Vec<bool> = (0..classes.len()).map(|i| order[..fit].contains(&(i as u16))).collect();
            for i in 0..classes.len() {
                counts[i] += usize::from(posed[i]);
                waiting[i] = if posed[i] { 0 } else { waiting[i] + 1 };
                longest = longest.max(waiting[i]);
            }
            s.finish(|i| classes[i], classes.len(), |i| posed[i]);
        }
        (counts, longest)
    }

    #[test]
    fn a_machine_that_keeps_up_keeps_the_instances_own_order() {
        let mut s = ShedOrder::new(4, 4);
        let mut order = Vec::new();
        for _ in 0..3 {
            s.order(|i| [2, 0, 3, 1][i], 4, &mut order);
            assert_eq!(order, [0, 1, 2, 3]);
            s.finish(|i| [2, 0, 3, 1][i], 4, |_| true);
        }
    }

    #[test]
    fn five_classes_one_pose_per_frame_take_turns() {
        // Before: instance 0 (the largest) every frame, the others never.
        assert_eq!(rotate(&[0, 1, 2, 3, 4], 1, 10), (vec![2, 2, 2, 2, 2], 4));
        // Two of five per frame: nobody waits more than two frames.
        let (counts, longest) = rotate(&[3, 1, 4, 0, 2], 2, 20);
        assert!(longest <= 2 && counts.iter().all(|&c| c >= 6), "{counts:?} {longest}");
    }

    #[test]
    fn copies_of_one_class_take_turns_too() {
        assert_eq!(rotate(&[5, 5, 5], 1, 9), (vec![3, 3, 3], 2));
        // Two classes, three copies of one: the classes alternate, the copies take turns.
        assert_eq!(rotate(&[1, 1, 1, 2], 1, 12), (vec![2, 2, 2, 6], 5));
    }

    #[test]
    fn the_longest_starved_class_goes_first() {
        let mut s = ShedOrder::new(3, 3);
        let mut order = Vec::new();
        let classes = [0, 1, 2];
        s.order(|i| classes[i], 3, &mut order);
        s.finish(|i| classes[i], 3, |i| i == 0);
        // Class 0 posed; 1 and 2 starved one frame: 1 then 2 then 0.
        s.order(|i| classes[i], 3, &mut order);
        assert_eq!(order, [1, 2, 0]);
        s.finish(|i| classes[i], 3, |i| i == 1);
        s.order(|i| classes[i], 3, &mut order);
        assert_eq!(order, [2, 0, 1]);
        // A frame where class 2 is absent keeps its count; when it is back it goes first.
        s.finish(|i| classes[i], 3, |i| i == 0);
        s.order(|i| [0, 1][i], 2, &mut order);
        assert_eq!(order, [1, 0]);
        s.finish(|i| [0, 1][i], 2, |_| true);
        s.order(|i| classes[i], 3, &mut order);
        assert_eq!(order[0], 2);
    }
}
