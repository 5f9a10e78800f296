//! After a warm-up frame, `Workspace::prepare` (joining pieces and cutting
//! regions of several copies included) and the ICP estimator's `estimate`
//! perform no heap allocation on further frames of the same size.
//!
//! A counting global allocator counts allocations made on the test's own
//! thread while counting is switched on (other test threads don't interfere).

mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use common::{l_block, object_set, painted, render, step_block};
use fusepose_estimator::icp::{IcpConfig, IcpEstimator};
use fusepose_estimator::{Estimator, FrameView, LabelPlane, PoseSet, Workspace, WorkspaceConfig};
use fusepose_scene::Pose;
use nalgebra::{Translation3, UnitQuaternion, Vector3};

struct CountingAllocator;

thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

fn note_allocation() {
    let counting = COUNTING.try_with(Cell::get).unwrap_or(false);
    if counting {
        let _ = ALLOCATIONS.try_with(|a| a.set(a.get() + 1));
    }
}

unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note_allocation();
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note_allocation();
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note_allocation();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

/// Allocations made by `f` on this thread.
fn allocations_in(f: impl FnOnce()) -> usize {
    ALLOCATIONS.with(|a| a.set(0));
    COUNTING.with(|c| c.set(true));
    f();
    COUNTING.with(|c| c.set(false));
    ALLOCATIONS.with(Cell::get)
}

fn pose(axis: [f64; 3], deg: f64, t: [f64; 3]) -> Pose {
    let r = UnitQuaternion::from_scaled_axis(Vector3::from(axis).normalize() * deg.to_radians());
    Pose::from_parts(Translation3::new(t[0], t[1], t[2]), r)
}

#[test]
fn prepare_and_icp_estimate_do_not_allocate_after_warm_up() {
    // The counter itself works.
    assert!(allocations_in(|| drop(std::hint::black_box(vec![1u8; 16]))) >= 1);

    let (l, s) = (l_block(), step_block());
    let objects = object_set(&[l.clone(), s.clone()]);
    let mut icp = IcpEstimator::new(&objects, IcpConfig::default()).unwrap();
    // The support floor fits the tilted table behind the blocks every frame.
    let config = WorkspaceConfig { num_classes: 2, support_floor_m: 0.004, ..Default::default() };
    let mut ws = Workspace::new(config).unwrap();
    ws.join_parts(&fusepose_estimator::parts::extents(&objects, 1.0));
    ws.split_regions(&fusepose_estimator::split::CutLimits::new(&objects, 1.0));
    let mut out = PoseSet::with_capacity(8);

    let warm = render(&[(1, &l, pose([1.0, 0.0, 0.0], 30.0, [-0.05, 0.0, 0.5]))]);
    assert_eq!(ws.prepare(&warm.view(), 0).unwrap(), 1);
    assert!(ws.support_plane().is_some(), "the table behind the block is found");
    icp.estimate(&warm.view(), &mut ws, &mut out).unwrap();

    // Different frames: two objects, other poses, then one object again.
    let frames = [
        render(&[
            (1, &l, pose([0.2, 1.0, 0.0], 80.0, [-0.06, 0.02, 0.55])),
            (2, &s, pose([1.0, 1.0, 0.0], 140.0, [0.06, -0.01, 0.5])),
        ]),
        render(&[(2, &s, pose([0.0, 0.0, 1.0], 45.0, [0.0, 0.0, 0.4]))]),
        split(render(&[(1, &l, pose([0.0, 1.0, 0.0], 20.0, [0.0, 0.0, 0.5]))])),
        // Two L blocks side by side, touching: one class-1 region of two
        // objects (painted alike, as copies are).
        painted(render(&[
            (1, &l, pose([0.0, 0.0, 1.0], 10.0, [-0.04, 0.0, 0.5])),
            (1, &l, pose([0.0, 0.0, 1.0], 10.0, [0.04, 0.0, 0.5])),
        ])),
    ];
    for (i, frame) in frames.iter().enumerate() {
        let view = frame.view();
        let mut prepared = 0;
        let n = allocations_in(|| {
            prepared = ws.prepare(&view, 100 + i as u64).unwrap();
            icp.estimate(&view, &mut ws, &mut out).unwrap();
        });
        assert!(prepared >= 1);
        assert_eq!(out.len(), prepared, "every instance got a pose");
        assert_eq!(n, 0, "frame {i}: {n} allocations in prepare + estimate");
        if i == 2 {
            assert_eq!((prepared, ws.stats().joined_parts), (1, 1), "the split object is one instance");
        }
        if i == 3 {
            assert_eq!((prepared, ws.stats().split_regions), (2, 1), "the touching pair is two instances");
            for pose in out.as_slice() {
                let x = pose.translation.x;
                assert!((x.abs() - 0.04).abs() < 0.02, "a pose between the pair: x = {x:.3} m");
            }
        }
    }
}

/// Clears the labels of a 3-pixel-wide column through the middle of the
/// labelled pixels, so the object shows up as two regions.
fn split(mut frame: common::SyntheticFrame) -> common::SyntheticFrame {
    let w = frame.intrinsics.width as usize;
    let columns: Vec<usize> = (0..frame.labels.len()).filter(|&p| frame.labels[p] != 0).map(|p| p % w).collect();
    let mid = (columns.iter().min().unwrap() + columns.iter().max().unwrap()) / 2;
    for p in 0..frame.labels.len() {
        if (mid - 1..=mid + 1).contains(&(p % w)) {
            frame.labels[p] = 0;
        }
    }
    frame
}

/// The frame's labels as an instance plane: label value k becomes instance id k.
fn instance_ids(frame: &common::SyntheticFrame) -> Vec<u16> {
    frame.labels.iter().map(|&l| l as u16).collect()
}

#[test]
fn instance_planes_do_not_allocate_after_warm_up() {
    let (l, s) = (l_block(), step_block());
    let objects = object_set(&[l.clone(), s.clone()]);
    let mut icp = IcpEstimator::new(&objects, IcpConfig::default()).unwrap();
    let mut ws = Workspace::new(WorkspaceConfig { num_classes: 2, ..Default::default() }).unwrap();
    ws.join_parts(&fusepose_estimator::parts::extents(&objects, 1.0));
    let mut out = PoseSet::with_capacity(8);
    // Instances 1 and 2 are both L blocks (class 1); 3 is the step block.
    let classes = [0u16, 1, 1, 2];

    let warm = render(&[(1, &l, pose([1.0, 0.0, 0.0], 30.0, [-0.05, 0.0, 0.5]))]);
    let warm_ids = instance_ids(&warm);
    let view = FrameView { labels: Some(LabelPlane::Instances { ids: &warm_ids, classes: &classes }), ..warm.view() };
    assert_eq!(ws.prepare(&view, 0).unwrap(), 1);
    icp.estimate(&view, &mut ws, &mut out).unwrap();

    // Two identical objects side by side (touching in the image), then all three,
    // then one L block cut in two by a cleared column: still one instance.
    let frames = [
        render(&[
            (1, &l, pose([0.0, 0.0, 1.0], 10.0, [-0.04, 0.0, 0.5])),
            (2, &l, pose([0.0, 0.0, 1.0], 10.0, [0.04, 0.0, 0.5])),
        ]),
        render(&[
            (1, &l, pose([0.2, 1.0, 0.0], 80.0, [-0.08, 0.02, 0.55])),
            (2, &l, pose([1.0, 0.0, 0.0], 40.0, [0.0, -0.03, 0.5])),
            (3, &s, pose([1.0, 1.0, 0.0], 140.0, [0.08, -0.01, 0.5])),
        ]),
        split(render(&[(2, &l, pose([0.0, 1.0, 0.0], 20.0, [0.0, 0.0, 0.5]))])),
    ];
    let expected = [2, 3, 1];
    for (i, frame) in frames.iter().enumerate() {
        let ids = instance_ids(frame);
        let view = FrameView { labels: Some(LabelPlane::Instances { ids: &ids, classes: &classes }), ..frame.view() };
        let mut prepared = 0;
        let n = allocations_in(|| {
            prepared = ws.prepare(&view, 100 + i as u64).unwrap();
            icp.estimate(&view, &mut ws, &mut out).unwrap();
        });
        assert_eq!(n, 0, "frame {i}: {n} allocations in prepare + estimate");
        assert_eq!(prepared, expected[i], "frame {i}");
        assert_eq!(out.len(), prepared, "every instance got a pose");
        assert_eq!(ws.stats().joined_parts, 0, "instance planes are never joined");
        if i == 0 {
            // The touching pair: same class, two instances.
            assert!(ws.instances.iter().all(|inst| inst.class_id == 1));
        }
    }
}

#[test]
fn the_second_look_does_not_allocate_after_warm_up() {
    use fusepose_estimator::recut::{RecutConfig, RecutPoses};
    second_look_without_allocations(RecutConfig::DEFAULT, false, false);
    // Cuts into three, the regions of failed poses looked at too, cuts refitted to the pieces' poses.
    let heaps = RecutConfig { max_pieces: 4, poses: RecutPoses::Any, refit: true, ..RecutConfig::DEFAULT };
    second_look_without_allocations(heaps, true, false);
    // Cut along a contact map (pieces grown over it from their centres).
    let contacts = RecutConfig { proposal: fusepose_estimator::recut::CutProposal::Contacts, ..RecutConfig::DEFAULT };
    second_look_without_allocations(contacts, false, true);
    // Along the depth image's creases alone (the default's votes fall back to them too).
    let creases = RecutConfig { proposal: fusepose_estimator::recut::CutProposal::Creases, ..RecutConfig::DEFAULT };
    second_look_without_allocations(creases, false, false);
}

/// A contact map that sees no contact anywhere.
struct NoContact;

impl fusepose_estimator::contact_cut::ContactMap for NoContact {
    fn contact_at(&self, _: usize, _: usize) -> Option<f32> {
        Some(0.05)
    }
}

fn second_look_without_allocations(
    recut_config: fusepose_estimator::recut::RecutConfig,
    rows_of_three: bool,
    contacts: bool,
) {
    use fusepose_estimator::interpenetration::Solids;
    use fusepose_estimator::recut::Recut;
    use fusepose_estimator::verify::{Verifier, VerifyConfig, verify_on_region};

    let l = l_block();
    let objects = object_set(std::slice::from_ref(&l));
    let config = WorkspaceConfig { num_classes: 1, ..Default::default() };
    let mut ws = Workspace::new(config).unwrap();
    let mut icp = IcpEstimator::new(&objects, IcpConfig::default()).unwrap();
    let mut pieces = IcpEstimator::new(&objects, IcpConfig::default()).unwrap();
    let mut verifier = Verifier::new(&objects, VerifyConfig::default());
    let solids = std::sync::Arc::new(Solids::new(&objects));
    let mut recut = Recut::new(&objects, solids, config, recut_config).unwrap();
    if contacts {
        recut.set_contacts(Box::new(NoContact));
    }
    let mut poses = PoseSet::with_capacity(2 * config.max_instances);
    let mut verdicts = Vec::with_capacity(2 * config.max_instances);
    let mut frame_of = |frame: &common::SyntheticFrame, seed: u64| {
        let view = frame.view();
        ws.prepare(&view, seed).unwrap();
        icp.estimate(&view, &mut ws, &mut poses).unwrap();
        verdicts.clear();
        for p in poses.as_slice() {
            verdicts.push(verify_on_region(&mut verifier, &view, &ws, None, p).unwrap());
        }
        let stats =
            recut.run(&view, &mut ws, &mut poses, &mut verdicts, &mut pieces, &mut verifier, None, seed).unwrap();
        (stats.kept, poses.len())
    };
    // Warm-up on a frame where no region qualifies: the first pair comes later.
    let single = painted(render(&[(1, &l, pose([0.0, 0.0, 1.0], 10.0, [0.0, 0.0, 0.5]))]));
    assert_eq!(frame_of(&single, 0), (0, 1));
    let row = |deg: f64, y: f64, xs: &[f64]| {
        let objects: Vec<_> = xs.iter().map(|&x| (1, &l, pose([0.0, 0.0, 1.0], deg, [x, y, 0.5]))).collect();
        painted(render(&objects))
    };
    let (copies, xs): (usize, &[f64]) = if rows_of_three { (3, &[-0.085, 0.0, 0.085]) } else { (2, &[-0.04, 0.04]) };
    let frames = [row(10.0, 0.0, xs), single, row(10.0, 0.02, xs)];
    for (i, frame) in frames.iter().enumerate() {
        let mut outcome = (0, 0);
        let n = allocations_in(|| outcome = frame_of(frame, 10 + i as u64));
        assert_eq!(n, 0, "frame {i}: {n} allocations in prepare, estimate, verification and the second look");
        // A cut into three needs the region's first pose to cover a third
        // of it or less; ICP's pose there depends on the seed.
        let expected = if i == 1 { (0, 1..=1) } else { (1, 2..=copies) };
        assert!(
            outcome.0 == expected.0 && expected.1.contains(&outcome.1),
            "frame {i}: (cuts kept, poses) {outcome:?}"
        );
    }
}

/// An L block on the table and two frames of it, its region whole and cut
/// to its left part (`common::left_part`, whose pose fails), and a run of one
/// frame: prepare, estimate, verify (as the daemon does) and second masks.
/// `hanging` moves the failed pose 20 cm in front of its object, with a made-up
/// failed verdict: the box it places holds no measured point, so its second
/// mask is too thin to estimate.
fn second_mask_rig() -> (
    common::SyntheticFrame,
    common::SyntheticFrame,
    impl FnMut(&common::SyntheticFrame, u64, Option<bool>) -> fusepose_estimator::remask::RemaskStats,
) {
    use fusepose_estimator::remask::{Remask, RemaskConfig};
    use fusepose_estimator::verify::{Verification, Verifier, VerifyConfig, verify_on_region};
    use fusepose_estimator::workspace::DEFAULT_SUPPORT_FLOOR_M;

    let l = l_block();
    let objects = object_set(std::slice::from_ref(&l));
    let config = WorkspaceConfig { num_classes: 1, support_floor_m: DEFAULT_SUPPORT_FLOOR_M, ..Default::default() };
    let mut ws = Workspace::new(config).unwrap();
    let mut verifier = Verifier::new(&objects, VerifyConfig::default());
    let mut remask = Remask::new(&objects, config, RemaskConfig::DEFAULT).unwrap();
    let mut poses = PoseSet::with_capacity(2 * config.max_instances);
    let mut verdicts = Vec::with_capacity(2 * config.max_instances);
    let truth = pose([0.0, 0.0, 1.0], 10.0, [0.0, 0.0, 0.5]);
    let whole = painted(render(&[(1, &l, truth)]));
    let (part, object_pixels) = common::left_part(painted(render(&[(1, &l, truth)])));
    let mut estimator = common::partial(truth, object_pixels);
    // `hanging`: None = only warm the second masks up (`Remask::warm_up_for`).
    let frame_of = move |frame: &common::SyntheticFrame, seed: u64, hanging: Option<bool>| {
        let view = frame.view();
        ws.prepare(&view, seed).unwrap();
        estimator.estimate(&view, &mut ws, &mut poses).unwrap();
        verdicts.clear();
        for p in poses.as_slice() {
            verdicts.push(verify_on_region(&mut verifier, &view, &ws, None, p).unwrap());
        }
        if hanging == Some(true) {
            let mut p = poses.as_slice()[0];
            p.translation.z -= 0.2;
            poses.replace(0, p);
            verdicts[0] = Verification { passed: false, inlier_fraction: 0.5, ..verdicts[0] };
        }
        let mut pieces = common::partial(truth, object_pixels);
        if hanging.is_none() {
            remask.warm_up_for(&view, &mut pieces, seed).unwrap();
            return Default::default();
        }
        remask.run(&view, &ws, &mut poses, &mut verdicts, &mut pieces, &mut verifier, None, seed).unwrap()
    };
    (whole, part, frame_of)
}

/// Second masks (`fusepose_estimator::remask`): after the warm-up frame,
/// giving a failed pose a second mask, estimating and judging it allocates
/// nothing.
#[test]
fn second_masks_do_not_allocate_after_warm_up() {
    let (whole, part, mut run) = second_mask_rig();
    let mut frame_of = |frame: &common::SyntheticFrame, seed: u64| run(frame, seed, Some(false)).kept;
    // Warm-up on a frame whose pose passes: no second mask yet.
    assert_eq!(frame_of(&whole, 0), 0);
    for (i, frame) in [&part, &whole, &part].into_iter().enumerate() {
        let mut kept = 0;
        let n = allocations_in(|| kept = frame_of(frame, 10 + i as u64));
        assert_eq!(n, 0, "frame {i}: {n} allocations in prepare, estimate, verification and the second masks");
        assert_eq!(kept, (i != 1) as usize, "frame {i}: failed poses replaced");
    }
}

/// A caller that runs the second masks only in some frames (the daemon)
/// warms them up on its first frame: their first run, frames later,
/// allocates nothing.
#[test]
fn second_masks_warmed_up_ahead_do_not_allocate_in_their_first_run() {
    let (whole, part, mut run) = second_mask_rig();
    // The frame's own workspace and estimator meet the frame; the second masks are only warmed up.
    run(&whole, 0, None);
    let mut stats = Default::default();
    let n = allocations_in(|| stats = run(&part, 10, Some(false)));
    assert_eq!(n, 0, "{n} allocations in the first run of the second masks");
    assert_eq!(stats.kept, 1, "the failed pose replaced");
}

#[test]
fn second_masks_too_thin_to_estimate_leave_nothing_behind() {
    use fusepose_estimator::remask::RemaskConfig;

    let (whole, part, mut frame_of) = second_mask_rig();
    assert_eq!(frame_of(&whole, 0, Some(false)).tried, 0);
    assert_eq!(frame_of(&part, 1, Some(false)).kept, 1, "warm-up: the second mask works");
    // More frames than the remask keeps boxes for: a box left behind by
    // each would outgrow its list.
    for i in 0..2 * RemaskConfig::DEFAULT.max_regions + 2 {
        let mut stats = Default::default();
        let n = allocations_in(|| stats = frame_of(&part, 10 + i as u64, Some(true)));
        assert_eq!(n, 0, "frame {i}: {n} allocations with every second mask too thin");
        assert_eq!((stats.tried, stats.kept, stats.estimates), (1, 0, 0), "frame {i}: tried, nothing estimated");
    }
    // The plane was left clear: the next frame's second mask is whole again.
    assert_eq!(frame_of(&part, 99, Some(false)).kept, 1, "after the thin frames");
}

#[test]
fn auto_exposure_does_not_allocate_after_the_first_frame_of_a_size() {
    use fusepose_estimator::exposure::{AutoExposure, ExposureConfig};
    let l = l_block();
    let bright = render(&[(1, &l, pose([1.0, 0.0, 0.0], 30.0, [0.0, 0.0, 0.5]))]);
    let mut dim = render(&[(1, &l, pose([0.0, 1.0, 0.0], 50.0, [0.02, 0.0, 0.6]))]);
    for v in dim.color.iter_mut() {
        *v /= 4;
    }
    let mut ae = AutoExposure::new(ExposureConfig::default());
    // The first frame is bright: nothing to copy, but the buffer is sized.
    assert!(ae.apply(&bright.view()).is_none());
    let mut gained = false;
    let n = allocations_in(|| gained = ae.apply(&dim.view()).is_some());
    assert_eq!(n, 0, "the first dim frame copies into the buffer sized by the bright one");
    assert!(gained && ae.last_gain() > 1.0, "the dim frame is brightened (gain {})", ae.last_gain());
    for frame in [&dim, &bright, &dim] {
        let n = allocations_in(|| {
            let _ = ae.apply(&frame.view());
        });
        assert_eq!(n, 0);
    }
}

#[test]
fn white_balance_does_not_allocate_after_the_first_frame_of_a_size() {
    use fusepose_estimator::white_balance::{WhiteBalance, WhiteBalanceConfig};
    let l = l_block();
    let plain = render(&[(1, &l, pose([1.0, 0.0, 0.0], 30.0, [0.0, 0.0, 0.5]))]);
    let mut warm = render(&[(1, &l, pose([0.0, 1.0, 0.0], 50.0, [0.02, 0.0, 0.6]))]);
    // Blue down to 60 % of its code: far beyond the band.
    for px in warm.color.chunks_exact_mut(3) {
        px[2] = (px[2] as f32 * 0.6) as u8;
    }
    let mut wb = WhiteBalance::new(WhiteBalanceConfig::default());
    // The first frame sizes the buffer, corrected or not.
    let _ = wb.apply(&plain.view());
    let mut corrected = false;
    let n = allocations_in(|| corrected = wb.apply(&warm.view()).is_some());
    assert_eq!(n, 0, "the first tinted frame copies into the buffer sized by the first one");
    assert!(corrected && wb.last_gains()[2] > 1.0, "blue is raised: {:?}", wb.last_gains());
    for frame in [&warm, &plain, &warm] {
        let n = allocations_in(|| {
            let _ = wb.apply(&frame.view());
        });
        assert_eq!(n, 0);
    }
}
