//! One surface, one object: a region that lies on another posed object's
//! visible surface is a second reading of that object, whatever class the
//! segmenter gave it.
//!
//! A segmenter that labels part of one object as another class (a cracker
//! box's red top read as the tomato can, a mustard bottle's side read as the
//! sugar box) yields a pose that depth verification passes: the region's
//! depth is explained by an object standing there. If the region is not a
//! separate object, the pose of the object it belongs to explains the same
//! measured surface. Of two poses where one explains more than a share of
//! the other's region ([`crate::verify::Verifier::explained_share`]), the one
//! more explained by the other is dropped (equal within 0.1: the lower
//! score). Objects in front of or behind each other do not explain each
//! other: a model's surface agrees with the measured depth only where it is
//! the surface the camera sees.
//!
//! Works on the poses left after verification; no allocation within the
//! capacity of `dropped`.

use crate::frame::FrameView;
use crate::poses::{ObjectPose, PoseSet, drop_pairwise};
use crate::verify::{MaskRef, Verifier};

/// Default of `estimator.max_explained_share`: off. On the tuning splits it
/// removed few ghosts beyond those interpenetration already removes, and
/// cost heaps of identical objects real poses (docs/BENCHMARKS.md, session 19).
pub const DEFAULT_MAX_SHARE: f32 = 1.0;

/// Marks in `dropped` (resized to the pose count) every pose whose region
/// another pose explains by more than `max_share` and more than it explains
/// the other's (within 0.1: the lower `scores`, NaN lowest), removes them
/// from `poses` and returns how many. `mask_of` gives a pose's region (None:
/// the pose is neither judged nor used to judge). A pose already dropped does
/// not explain others. `max_share` ≥ 1 never drops.
pub fn suppress<'a>(
    verifier: &mut Verifier,
    frame: &FrameView<'_>,
    mask_of: impl Fn(&ObjectPose) -> Option<MaskRef<'a>>,
    poses: &mut PoseSet,
    max_share: f32,
    scores: &[f32],
    dropped: &mut Vec<bool>,
) -> usize {
    drop_pairwise(poses, max_share, scores, dropped, true, |a, b| {
        let (ma, mb) = (mask_of(a)?, mask_of(b)?);
        Some((verifier.explained_share(frame, ma, b), verifier.explained_share(frame, mb, a)))
    })
}
