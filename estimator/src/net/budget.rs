//! Deadline-aware degradation of the network estimator: a cost model learned
//! from the frames themselves, and the plan for one frame — as many refiner
//! iterations as the remaining time allows (0..max), and when even the pose
//! net alone does not fit, fewer points per object; when even that does not
//! fit every instance, only as many as it pays for (see [`affordable`]; which
//! ones rotates across frames, [`super::shed_order`]).
//!
//! Costs are per object on one thread, ns, at the full N points; the pose net
//! and the refiner scale with the points used, the colour CNN does not.

use std::time::{Duration, Instant};

/// Fewest points a degraded frame uses, as a fraction of N.
pub const MIN_POINT_FRACTION: f64 = 0.25;
/// Share of the remaining time the plan may fill (the rest absorbs noise).
const FILL: f64 = 0.85;
/// Weight of a new measurement in the moving averages.
const GAIN: f64 = 0.2;

/// Moving averages of the per-object stage costs, ns at N points.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CostModel {
    /// Colour CNN + gather (independent of the points used).
    pub color_ns: Option<f64>,
    /// Pose net at N points.
    pub pose_ns: Option<f64>,
    /// The refiner's colour features, once per refined object, at N points.
    pub refine_setup_ns: Option<f64>,
    /// One refiner iteration at N points.
    pub refine_iter_ns: Option<f64>,
}

fn update(slot: &mut Option<f64>, value: f64) {
    *slot = Some(match *slot {
        None => value,
        Some(old) => old + GAIN * (value - old),
    });
}

/// Measured durations of one object's stages (what [`CostModel::observe`] takes).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ObjectTimes {
    pub color: Duration,
    pub pose: Duration,
    pub refine_setup: Duration,
    /// All refiner iterations together, and how many ran.
    pub refine: Duration,
    pub refine_iterations: usize,
    /// Points used of `full_points`.
    pub points: usize,
    pub full_points: usize,
}

impl CostModel {
    /// Folds in one object's measured times (scaled to N points).
    pub fn observe(&mut self, t: &ObjectTimes) {
        if t.points == 0 || t.full_points == 0 {
            return;
        }
        let scale = t.full_points as f64 / t.points as f64;
        update(&mut self.color_ns, t.color.as_nanos() as f64);
        // Zero: the pose net did not run (a tracked object).
        if !t.pose.is_zero() {
            update(&mut self.pose_ns, t.pose.as_nanos() as f64 * scale);
        }
        if t.refine_iterations > 0 {
            update(&mut self.refine_setup_ns, t.refine_setup.as_nanos() as f64 * scale);
            update(&mut self.refine_iter_ns, t.refine.as_nanos() as f64 * scale / t.refine_iterations as f64);
        }
    }

    /// One object's colour CNN and pose net at `points` of `full_points`, ns
    /// (0 before both were measured).
    pub fn object_ns(&self, points: usize, full_points: usize) -> f64 {
        match (self.color_ns, self.pose_ns) {
            (Some(c), Some(p)) => c + p * points as f64 / full_points.max(1) as f64,
            _ => 0.0,
        }
    }

    /// The refiner's colour features at `points` of `full_points`, ns (0 before measured).
    pub fn refine_setup_ns(&self, points: usize, full_points: usize) -> f64 {
        self.refine_setup_ns.unwrap_or(0.0) * points as f64 / full_points.max(1) as f64
    }

    /// One refiner iteration at `points` of `full_points`, ns (0 before any was measured).
    pub fn refine_iter_ns(&self, points: usize, full_points: usize) -> f64 {
        self.refine_iter_ns.unwrap_or(0.0) * points as f64 / full_points.max(1) as f64
    }
}

/// What one frame may spend.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FramePlan {
    /// Refiner iterations per object.
    pub refine_iterations: usize,
    /// Points per object (N when not degraded).
    pub points: usize,
}

impl FramePlan {
    pub fn full(max_iterations: usize, full_points: usize) -> Self {
        Self { refine_iterations: max_iterations, points: full_points }
    }

    /// Whether this plan gives up anything against the full one.
    pub fn is_degraded(&self, max_iterations: usize, full_points: usize) -> bool {
        self.refine_iterations < max_iterations || self.points < full_points
    }
}

/// The plan for `objects_per_thread` objects (the most any thread runs) with
/// `remaining` time left; the full plan when no deadline or no costs are known yet.
pub fn plan(
    model: &CostModel,
    remaining: Option<Duration>,
    objects_per_thread: usize,
    max_iterations: usize,
    full_points: usize,
) -> FramePlan {
    let full = FramePlan::full(max_iterations, full_points);
    let (Some(remaining), Some(color), Some(pose)) = (remaining, model.color_ns, model.pose_ns) else {
        return full;
    };
    if objects_per_thread == 0 {
        return full;
    }
    let per_object = remaining.as_nanos() as f64 * FILL / objects_per_thread as f64;
    let setup = model.refine_setup_ns.unwrap_or(0.0);
    let iter = model.refine_iter_ns.unwrap_or(0.0);
    for iterations in (1..=max_iterations).rev() {
        if color + pose + setup + iterations as f64 * iter <= per_object {
            return FramePlan { refine_iterations: iterations, points: full_points };
        }
    }
    if color + pose <= per_object {
        return FramePlan { refine_iterations: 0, points: full_points };
    }
    // Not even the pose net fits: fewer points (its cost scales with them).
    let fraction = ((per_object - color) / pose).clamp(MIN_POINT_FRACTION, 1.0);
    let points = ((full_points as f64 * fraction).ceil() as usize).clamp(1, full_points);
    FramePlan { refine_iterations: 0, points }
}

/// How many of a frame's `count` instances the remaining time
/// pays for at the cheapest plan (pose net on a quarter of the points, no
/// refiner) on `threads` threads: all of them without a deadline or before
/// costs are known, otherwise as many as fit, but at least one. The rest get
/// no pose this frame: a segmenter that finds more regions than the budget
/// holds (clutter, or regions of an unfamiliar camera) would otherwise make
/// every frame late.
pub fn affordable(model: &CostModel, remaining: Option<Duration>, count: usize, threads: usize) -> usize {
    let (Some(remaining), Some(color), Some(pose)) = (remaining, model.color_ns, model.pose_ns) else {
        return count;
    };
    let cheapest = color + pose * MIN_POINT_FRACTION;
    if count == 0 || cheapest <= 0.0 {
        return count;
    }
    let per_thread = (remaining.as_nanos() as f64 * FILL / cheapest).floor() as usize;
    per_thread.saturating_mul(threads.max(1)).clamp(1, count)
}

/// Safety factor on a step's average cost when deciding, just before it,
/// whether it still ends before the deadline: single steps vary (the other
/// thread, cache misses, the scheduler) and one that overruns makes the frame late.
const STEP_MARGIN: f64 = 1.25;

/// Whether a step of average cost `cost_ns` (a refiner iteration, an
/// object's pose net) started now still ends before `deadline`.
pub fn step_fits(deadline: Option<Instant>, cost_ns: f64) -> bool {
    deadline.is_none_or(|d| Instant::now() + Duration::from_nanos((cost_ns * STEP_MARGIN) as u64) <= d)
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: f64 = 1e6;

    fn model() -> CostModel {
        // 1 ms colour, 2 ms pose, 0.2 ms refiner set-up, 0.5 ms per iteration.
        CostModel {
            color_ns: Some(MS),
            pose_ns: Some(2.0 * MS),
            refine_setup_ns: Some(0.2 * MS),
            refine_iter_ns: Some(0.5 * MS),
        }
    }

    #[test]
    fn full_plan_without_deadline_or_costs() {
        assert_eq!(plan(&model(), None, 3, 4, 256), FramePlan::full(4, 256));
        assert_eq!(plan(&CostModel::default(), Some(Duration::from_millis(1)), 3, 4, 256), FramePlan::full(4, 256));
    }

    #[test]
    fn iterations_shrink_before_points() {
        let ms = |x: f64| Some(Duration::from_secs_f64(x / 1e3));
        // 2 objects per thread; per object 0.85 * budget / 2.
        assert_eq!(plan(&model(), ms(100.0), 2, 4, 256), FramePlan { refine_iterations: 4, points: 256 });
        // per object 0.85 * 10 / 2 = 4.25 ms: 3 + 0.2 + 2 * 0.5 = 4.2 fits, 3 iterations (4.7) do not.
        assert_eq!(plan(&model(), ms(10.0), 2, 4, 256), FramePlan { refine_iterations: 2, points: 256 });
        // 3.4 ms per object: pose only.
        assert_eq!(plan(&model(), ms(8.0), 2, 4, 256), FramePlan { refine_iterations: 0, points: 256 });
        // 2.55 ms per object: (2.55 - 1) / 2 = 0.775 of the points.
        assert_eq!(plan(&model(), ms(6.0), 2, 4, 256), FramePlan { refine_iterations: 0, points: 199 });
        // Hopeless: the floor of a quarter of the points.
        assert_eq!(plan(&model(), ms(0.1), 2, 4, 256), FramePlan { refine_iterations: 0, points: 64 });
        assert!(plan(&model(), ms(6.0), 2, 4, 256).is_degraded(4, 256));
        assert!(!plan(&model(), ms(100.0), 2, 4, 256).is_degraded(4, 256));
    }

    #[test]
    fn instances_beyond_the_cheapest_plan_are_shed() {
        let ms = |x: f64| Some(Duration::from_secs_f64(x / 1e3));
        // Cheapest object: 1 + 2 / 4 = 1.5 ms; 0.85 * 10 ms holds 5 per thread.
        assert_eq!(affordable(&model(), ms(10.0), 12, 1), 5);
        assert_eq!(affordable(&model(), ms(10.0), 12, 2), 10);
        assert_eq!(affordable(&model(), ms(10.0), 4, 2), 4);
        // Hopeless still keeps the largest instance; no deadline or costs keep all.
        assert_eq!(affordable(&model(), ms(0.0), 6, 2), 1);
        assert_eq!(affordable(&model(), None, 6, 2), 6);
        assert_eq!(affordable(&CostModel::default(), ms(0.0), 6, 2), 6);
        assert_eq!(affordable(&model(), ms(0.0), 0, 2), 0);
    }

    #[test]
    fn costs_are_learned_per_full_point_count() {
        let mut m = CostModel::default();
        let t = ObjectTimes {
            color: Duration::from_millis(1),
            pose: Duration::from_millis(1),
            refine_setup: Duration::from_micros(100),
            refine: Duration::from_millis(1),
            refine_iterations: 2,
            points: 128,
            full_points: 256,
        };
        m.observe(&t);
        assert_eq!(m.color_ns, Some(1e6));
        assert_eq!(m.pose_ns, Some(2e6), "half the points took 1 ms: 2 ms at N");
        assert_eq!(m.refine_iter_ns, Some(1e6));
        assert_eq!(m.refine_iter_ns(64, 256), 0.25e6);
    }
}
