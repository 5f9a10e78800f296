//! The second look (`fusepose_estimator::recut`): two touching copies of one
//! object in one class region, which the size-based cut leaves whole, get a
//! pose each once the region's single pose is found to cover only part of
//! it; one object alone keeps its one pose, and each of the terms that tell
//! one object's halves from two copies refuses its cut on its own; instance
//! planes are never cut.

mod common;

use std::sync::Arc;

use common::{BoxObject, SyntheticFrame, l_block, object_set, painted, render};
use fusepose_estimator::contact_cut::ContactMap;
use fusepose_estimator::icp::{IcpConfig, IcpEstimator};
use fusepose_estimator::interpenetration::Solids;
use fusepose_estimator::recut::{
    CentreVotes, CutProposal, REVIVE_MIN_FIT, Recut, RecutConfig, RecutPoses, RecutStats, pieces_for,
};
use fusepose_estimator::seg::{SegConfig, SegEngine, SegFile};
use fusepose_estimator::verify::{Verification, Verifier, VerifyConfig};
use fusepose_estimator::{CutHint, Estimator, FrameView, LabelPlane, PoseSet, Workspace, WorkspaceConfig};
use fusepose_scene::Pose;
use nalgebra::{Translation3, UnitQuaternion, Vector3};

fn pose(deg: f64, t: [f64; 3]) -> Pose {
    let r = UnitQuaternion::from_scaled_axis(Vector3::z() * deg.to_radians());
    Pose::from_parts(Translation3::new(t[0], t[1], t[2]), r)
}

/// Two L blocks side by side, touching, painted alike: one class-1 region.
fn pair(l: &BoxObject) -> SyntheticFrame {
    painted(render(&[(1, l, pose(10.0, [-0.04, 0.0, 0.5])), (1, l, pose(10.0, [0.04, 0.0, 0.5]))]))
}

struct Outcome {
    poses: PoseSet,
    verdicts: Vec<Verification>,
    stats: RecutStats,
    ws: Workspace,
    before: usize,
}

/// Prepares (no size-based cut), estimates with ICP, verifies, then runs the
/// second look with ICP for the pieces.
fn second_look(view: &FrameView<'_>, config: RecutConfig) -> Outcome {
    let objects = object_set(&[l_block()]);
    second_look_with(view, config, &mut IcpEstimator::new(&objects, IcpConfig::default()).unwrap())
}

/// As [`second_look`], with `estimator` for the first estimate and the pieces.
fn second_look_with(view: &FrameView<'_>, config: RecutConfig, estimator: &mut dyn Estimator) -> Outcome {
    second_look_voted(view, config, estimator, None, None)
}

/// As [`second_look_with`], with centre votes for the cut, or a segmenter
/// that made the regions.
fn second_look_voted(
    view: &FrameView<'_>,
    config: RecutConfig,
    estimator: &mut dyn Estimator,
    votes: Option<Votes>,
    segmenter: Option<&mut SegEngine>,
) -> Outcome {
    second_look_set(view, config, estimator, segmenter, |recut| {
        if let Some(votes) = votes {
            recut.set_votes(Box::new(votes));
        }
    })
}

/// As [`second_look_voted`], with `setup` given the second look before it runs.
fn second_look_set(
    view: &FrameView<'_>,
    config: RecutConfig,
    estimator: &mut dyn Estimator,
    segmenter: Option<&mut SegEngine>,
    setup: impl FnOnce(&mut Recut),
) -> Outcome {
    let objects = object_set(&[l_block()]);
    let ws_config = WorkspaceConfig { num_classes: 1, ..Default::default() };
    let mut ws = Workspace::new(ws_config).unwrap();
    let mut poses = PoseSet::with_capacity(2 * ws_config.max_instances);
    ws.prepare(view, 7).unwrap();
    estimator.estimate(view, &mut ws, &mut poses).unwrap();
    let mut verifier = Verifier::new(&objects, VerifyConfig::default());
    let mut verdicts: Vec<Verification> = poses
        .as_slice()
        .iter()
        .map(|p| {
            let id = ws.component_id(p.instance_id as usize).unwrap();
            verifier.verify(view, ws.mask_ref(id, p.bbox), p)
        })
        .collect();
    let before = poses.len();
    let mut recut = Recut::new(&objects, Arc::new(Solids::new(&objects)), ws_config, config).unwrap();
    setup(&mut recut);
    let stats = recut.run(view, &mut ws, &mut poses, &mut verdicts, estimator, &mut verifier, segmenter, 7).unwrap();
    Outcome { poses, verdicts, stats, ws, before }
}

#[test]
fn two_touching_copies_in_one_region_get_a_pose_each() {
    let l = l_block();
    let frame = pair(&l);
    let out = second_look(&frame.view(), RecutConfig::DEFAULT);
    assert_eq!(out.before, 1, "one region, one pose before the second look");
    assert_eq!((out.stats.tried, out.stats.kept), (1, 1), "the region is cut and the cut kept");
    assert_eq!(out.poses.len(), 2);
    assert_eq!(out.verdicts.len(), 2, "a verdict per pose, in step");
    assert!(out.verdicts.iter().all(|v| v.passed));
    assert_eq!(out.ws.instances.len(), 2, "the workspace holds the two pieces");
    assert_poses_across(&out, [-0.04, 0.04]);
    for p in out.poses.as_slice() {
        // Each pose's published box and mask are its own piece's.
        let inst = out.ws.instances[p.instance_id as usize];
        assert_eq!((p.bbox, p.mask_pixels), (inst.bbox, inst.pixels));
        let centre_u = (inst.bbox[0] + inst.bbox[2]) as f64 / 2.0;
        let k = frame.intrinsics;
        assert_eq!(centre_u < k.cx, p.translation.x < 0.0, "pose and mask on the same side");
    }
}

/// Centre votes as a segmenter's offset head would give them, in cells of
/// 4 frame pixels (a 160x120 segmenter input on the 320x240 test frame).
struct Votes(fn(usize, usize) -> [f32; 2]);

impl CentreVotes for Votes {
    fn vote_at(&self, u: usize, v: usize) -> Option<[f32; 2]> {
        Some((self.0)(u, v))
    }
}

/// The cell of the projection of camera point `(x, 0, 0.5)` on the test frame.
fn centre_cell(x: f64) -> [f32; 2] {
    let k = common::intrinsics();
    [((k.fx * x / 0.5 + k.cx) / 4.0) as f32, (k.cy / 4.0) as f32]
}

#[test]
fn votes_for_two_centres_cut_the_region_along_them() {
    let l = l_block();
    let frame = pair(&l);
    // Each copy's pixels vote for its own centre (the blocks meet at the image centre).
    let votes = Votes(|u, _| centre_cell(if (u as f64) < common::intrinsics().cx { -0.04 } else { 0.04 }));
    let objects = object_set(&[l_block()]);
    let mut icp = IcpEstimator::new(&objects, IcpConfig::default()).unwrap();
    // The votes' own cut (refit would move it to the pieces' poses).
    let config = RecutConfig { proposal: CutProposal::VotesOnly, refit: false, ..RecutConfig::DEFAULT };
    let out = second_look_voted(&frame.view(), config, &mut icp, Some(votes), None);
    assert_eq!((out.before, out.stats.tried, out.stats.by_votes, out.stats.kept), (1, 1, 1, 1));
    assert_poses_across(&out, [-0.04, 0.04]);
    // The pieces meet where the votes change sides.
    let cx = common::intrinsics().cx as u16;
    let mut boxes: Vec<[u16; 4]> = out.ws.instances.iter().map(|i| i.bbox).collect();
    boxes.sort();
    assert_eq!((boxes[0][2], boxes[1][0]), (cx - 1, cx), "piece boxes {boxes:?}");
}

/// Two pieces whose boxes meet within 3 pixels of frame column `cx`.
fn assert_pieces_meet_at(out: &Outcome, cx: usize) {
    let mut boxes: Vec<[u16; 4]> = out.ws.instances.iter().map(|i| i.bbox).collect();
    boxes.sort();
    let (left_end, right_start) = (boxes[0][2] as usize, boxes[1][0] as usize);
    assert!(left_end.abs_diff(cx) <= 3 && right_start.abs_diff(cx) <= 3, "piece boxes {boxes:?}");
}

/// Poses within 2 cm across of their blocks at `truths` (x, metres, left to right).
fn assert_poses_across(out: &Outcome, truths: [f64; 2]) {
    let mut xs: Vec<f64> = out.poses.as_slice().iter().map(|p| p.translation.x).collect();
    xs.sort_by(f64::total_cmp);
    for (x, truth) in xs.iter().zip(truths) {
        assert!((x - truth).abs() < 0.02, "a pose {x:.3} m across, its block at {truth} m");
    }
}

/// A contact band as a segmenter's contact branch would give it: probability
/// 0.9 on the frame columns within the band, 0.05 elsewhere.
struct Band(std::ops::RangeInclusive<usize>);

impl ContactMap for Band {
    fn contact_at(&self, u: usize, _: usize) -> Option<f32> {
        Some(if self.0.contains(&u) { 0.9 } else { 0.05 })
    }
}

#[test]
fn a_contact_band_between_two_copies_cuts_the_region_along_it() {
    let l = l_block();
    let frame = pair(&l);
    let cx = common::intrinsics().cx as usize;
    let objects = object_set(&[l_block()]);
    let mut icp = IcpEstimator::new(&objects, IcpConfig::default()).unwrap();
    // The band's own cut (refit would move it to the pieces' poses).
    let config = RecutConfig { proposal: CutProposal::Contacts, refit: false, ..RecutConfig::DEFAULT };
    let band = Band(cx - 4..=cx + 3);
    let out = second_look_set(&frame.view(), config, &mut icp, None, |r| r.set_contacts(Box::new(band)));
    assert_eq!((out.before, out.stats.tried, out.stats.by_contacts, out.stats.by_votes), (1, 1, 1, 0));
    assert_eq!(out.stats.kept, 1, "the cut stands");
    assert_poses_across(&out, [-0.04, 0.04]);
    // The band is shared (each band pixel joins the nearer part within the
    // region): the pieces meet within a few pixels of the blocks' contact.
    assert_pieces_meet_at(&out, cx);

    // A band off the region does not part it: k-means on the 3D points
    // cuts it, and the pieces grow from their centres over the contacts.
    let off = Band(0..=3);
    let config = RecutConfig { proposal: CutProposal::Contacts, ..RecutConfig::DEFAULT };
    let out = second_look_set(&frame.view(), config, &mut icp, None, |r| r.set_contacts(Box::new(off)));
    assert_eq!((out.stats.tried, out.stats.by_contacts, out.stats.kept), (1, 1, 1), "cut by points, grown");
}

#[test]
fn votes_for_one_centre_leave_the_region_whole_or_fall_back_to_the_points() {
    // One block whose pose is looked at again (coverage forced), every pixel
    // voting for its centre: the votes do not cut it; `Votes` then tries the
    // 3D points, whose cut the two-copy terms refuse.
    let l = l_block();
    let truth = pose(10.0, [0.0, 0.0, 0.5]);
    let frame = painted(render(&[(1, &l, truth)]));
    let looked = RecutConfig { max_coverage: 1.01, ..RecutConfig::DEFAULT };
    let run = |proposal| {
        let config = RecutConfig { proposal, ..looked };
        second_look_voted(&frame.view(), config, &mut oracle(vec![truth]), Some(Votes(|_, _| centre_cell(0.0))), None)
            .stats
    };
    let only = run(CutProposal::VotesOnly);
    assert_eq!((only.tried, only.by_votes, only.kept), (0, 0, 0), "votes-only: not cut");
    let fallback = run(CutProposal::Votes);
    assert_eq!((fallback.tried, fallback.by_votes, fallback.kept), (1, 0, 0), "votes: cut by points, refused");
    assert_eq!(fallback.refused.iter().sum::<usize>(), 1, "the refusal is counted: {:?}", fallback.refused);
}

/// A segmenter file with the offset branch computes its votes on demand: the
/// second look asks for them where it cuts a region by votes, and only there.
#[test]
fn the_segmenters_votes_are_computed_where_a_region_is_cut() {
    let l = l_block();
    let objects = object_set(&[l_block()]);
    let cfg = SegConfig { offset_branch: true, ..SegConfig::new(1) };
    let file = SegFile::from_bytes(&common::seg_weight_bytes(&cfg, &objects)).unwrap();
    let computed = |frame: &common::SyntheticFrame, proposal| {
        let mut engine = SegEngine::new(&file).unwrap();
        let mut labels = vec![0u16; frame.view().width() * frame.view().height()];
        engine.segment(&frame.view(), &mut labels).unwrap();
        assert!(engine.offsets().is_empty());
        let config = RecutConfig { proposal, ..RecutConfig::DEFAULT };
        let mut icp = IcpEstimator::new(&objects, IcpConfig::default()).unwrap();
        let out = second_look_voted(&frame.view(), config, &mut icp, None, Some(&mut engine));
        (out.stats.tried, !engine.offsets().is_empty())
    };
    let two = pair(&l);
    assert_eq!(computed(&two, CutProposal::Votes), (1, true), "a region cut: votes computed");
    assert_eq!(computed(&two, CutProposal::Points), (1, false), "cut by points: not computed");
    let one = painted(render(&[(1, &l, pose(10.0, [0.0, 0.0, 0.5]))]));
    assert_eq!(computed(&one, CutProposal::Votes), (0, false), "nothing to cut: not computed");
}

#[test]
fn cut_proposals_parse_and_a_bad_one_names_the_choices() {
    assert_eq!("votes".parse::<CutProposal>(), Ok(CutProposal::Votes));
    assert_eq!("votes-only".parse::<CutProposal>(), Ok(CutProposal::VotesOnly));
    assert_eq!("points".parse::<CutProposal>(), Ok(CutProposal::Points));
    assert_eq!("contacts".parse::<CutProposal>(), Ok(CutProposal::Contacts));
    assert_eq!("creases".parse::<CutProposal>(), Ok(CutProposal::Creases));
    for p in
        [CutProposal::Votes, CutProposal::VotesOnly, CutProposal::Points, CutProposal::Contacts, CutProposal::Creases]
    {
        assert_eq!(p.to_string().parse::<CutProposal>(), Ok(p), "round trip");
    }
    let err = "vote".parse::<CutProposal>().unwrap_err();
    assert!(err.contains("points, votes, votes-only, contacts or creases"), "{err}");
}

/// Two L blocks turned 35° about the vertical towards each other: their
/// fronts fold away from the camera where they meet (a V), as touching
/// copies in a heap do.
fn folded_pair(l: &BoxObject) -> SyntheticFrame {
    let turned = |deg: f64, x: f64| {
        Pose::from_parts(
            Translation3::new(x, 0.0, 0.5),
            UnitQuaternion::from_scaled_axis(Vector3::y() * deg.to_radians()),
        )
    };
    painted(render(&[(1, l, turned(-35.0, -0.044)), (1, l, turned(35.0, 0.044))]))
}

#[test]
fn the_depth_images_crease_between_two_copies_cuts_the_region_along_it() {
    let l = l_block();
    let frame = folded_pair(&l);
    let cx = common::intrinsics().cx as usize;
    let objects = object_set(&[l_block()]);
    let mut icp = IcpEstimator::new(&objects, IcpConfig::default()).unwrap();
    // The crease's own cut (refit would move it to the pieces' poses).
    let config = RecutConfig { proposal: CutProposal::Creases, refit: false, ..RecutConfig::DEFAULT };
    let out = second_look_set(&frame.view(), config, &mut icp, None, |_| ());
    assert_eq!((out.before, out.stats.tried, out.stats.by_contacts, out.stats.by_votes), (1, 1, 1, 0));
    assert_eq!(out.stats.kept, 1, "the cut stands");
    assert_eq!(out.poses.len(), 2);
    // The pieces meet at the fold, within a few pixels of the frame's centre column.
    assert_pieces_meet_at(&out, cx);
    // Each pose is its own block's.
    assert_poses_across(&out, [-0.044, 0.044]);

    // The default, votes, falls back to the creases where there are no votes.
    let default = RecutConfig { refit: false, ..RecutConfig::DEFAULT };
    assert_eq!(default.proposal, CutProposal::Votes);
    let out = second_look_set(&frame.view(), default, &mut icp, None, |_| ());
    assert_eq!((out.stats.by_contacts, out.stats.kept), (1, 1), "cut along the fold");

    // The same fold between pieces of two colours is where another object
    // the segmenter gave this class meets the first: the points cut it.
    let mut two_colours = folded_pair(&l);
    let w = common::intrinsics().width as usize;
    for (p, &label) in two_colours.labels.iter().enumerate() {
        if label != 0 && p % w > cx {
            two_colours.color[p * 3..p * 3 + 3].copy_from_slice(&[60, 110, 150]);
        }
    }
    let out = second_look_set(&two_colours.view(), config, &mut icp, None, |_| ());
    assert_eq!((out.stats.tried, out.stats.by_contacts), (1, 0), "cut by points");

    // Side by side with flush fronts the depth shows no fold between them:
    // the 3D points cut the region (not grown over the creases).
    let frame = pair(&l);
    let out = second_look_set(&frame.view(), config, &mut icp, None, |_| ());
    assert_eq!((out.stats.tried, out.stats.by_contacts, out.stats.kept), (1, 0, 1), "cut by points");
}

#[test]
fn one_object_keeps_one_pose() {
    let l = l_block();
    let frame = painted(render(&[(1, &l, pose(10.0, [0.0, 0.0, 0.5]))]));
    let out = second_look(&frame.view(), RecutConfig::DEFAULT);
    assert_eq!((out.before, out.poses.len(), out.stats.kept), (1, 1, 0));
    assert_eq!(out.ws.instances.len(), 1);
}

/// Poses every instance at the true pose nearest its points: the network's
/// behaviour on a piece of one object (its points vote for that object's
/// centre), without ICP's own errors on half a block.
fn oracle(truths: Vec<Pose>) -> impl Estimator {
    common::PoseEach(move |_: &fusepose_estimator::Instance, points: &[[f32; 3]]| {
        let c = common::centroid(points);
        let nearest = |a: &&Pose| (a.translation.vector - c).norm();
        *truths.iter().min_by(|a, b| nearest(a).total_cmp(&nearest(b))).unwrap()
    })
}

#[test]
fn one_object_cut_in_two_is_kept_whole_by_each_two_copy_term() {
    // Coverage forced above any pose's so the second look runs; the pieces of
    // one block both get its true pose, which passes verification on each.
    let l = l_block();
    let truth = pose(10.0, [0.0, 0.0, 0.5]);
    let frame = painted(render(&[(1, &l, truth)]));
    let view = frame.view();
    let looked = RecutConfig { max_coverage: 1.01, refit: false, ..RecutConfig::DEFAULT };
    let all_off = RecutConfig { min_separation: 0.0, max_cross_explained: 9.0, max_overlap: 9.0, ..looked };
    let run = |config| second_look_with(&view, config, &mut oracle(vec![truth]));
    // Each term alone refuses the cut; with none of them it would stand.
    assert_eq!(run(all_off).stats.kept, 1, "without the terms, one block becomes two poses");
    for (term, config) in [
        ("separation", RecutConfig { min_separation: looked.min_separation, ..all_off }),
        ("cross-explanation", RecutConfig { max_cross_explained: looked.max_cross_explained, ..all_off }),
        ("overlap", RecutConfig { max_overlap: looked.max_overlap, ..all_off }),
        // Both pieces posed as the one block: its box takes every pixel.
        ("refit", RecutConfig { refit: true, ..all_off }),
        ("all", looked),
        ("the default", RecutConfig { max_coverage: 1.01, ..RecutConfig::DEFAULT }),
    ] {
        let out = run(config);
        assert_eq!(out.stats.tried, 1, "{term}: the region was looked at again");
        assert_eq!((out.poses.len(), out.stats.kept), (1, 0), "{term}: its halves are one object");
    }
}

#[test]
fn two_copies_posed_exactly_pass_every_term() {
    let l = l_block();
    let truths = vec![pose(10.0, [-0.04, 0.0, 0.5]), pose(10.0, [0.04, 0.0, 0.5])];
    let frame = pair(&l);
    let looked = RecutConfig { max_coverage: 1.01, ..RecutConfig::DEFAULT };
    let out = second_look_with(&frame.view(), looked, &mut oracle(truths));
    assert_eq!((out.before, out.poses.len(), out.stats.kept), (1, 2, 1));
}

#[test]
fn instance_planes_and_the_off_setting_are_left_alone() {
    let l = l_block();
    let frame = pair(&l);
    let off = second_look(&frame.view(), RecutConfig { max_coverage: 0.0, ..RecutConfig::DEFAULT });
    assert_eq!((off.poses.len(), off.stats.tried), (1, 0));
    let ids: Vec<u16> = frame.labels.iter().map(|&l| l as u16).collect();
    let classes = [0u16, 1];
    let view = FrameView { labels: Some(LabelPlane::Instances { ids: &ids, classes: &classes }), ..frame.view() };
    let out = second_look(&view, RecutConfig::DEFAULT);
    assert_eq!((out.poses.len(), out.stats.tried), (1, 0), "a producer's instance is its own");
}

/// One camera's stream: the workspace, ICP, verifier and second look kept
/// from frame to frame, the kept cuts passed on as the daemon does.
struct Stream {
    ws: Workspace,
    icp: IcpEstimator,
    pieces: IcpEstimator,
    verifier: Verifier,
    recut: Recut,
    poses: PoseSet,
    verdicts: Vec<Verification>,
}

impl Stream {
    fn new() -> Self {
        Self::with(RecutConfig::DEFAULT)
    }

    fn with(recut: RecutConfig) -> Self {
        let objects = object_set(&[l_block()]);
        let config = WorkspaceConfig { num_classes: 1, ..Default::default() };
        let solids = Arc::new(Solids::new(&objects));
        Self {
            ws: Workspace::new(config).unwrap(),
            icp: IcpEstimator::new(&objects, IcpConfig::default()).unwrap(),
            pieces: IcpEstimator::new(&objects, IcpConfig::default()).unwrap(),
            verifier: Verifier::new(&objects, VerifyConfig::default()),
            recut: Recut::new(&objects, solids, config, recut).unwrap(),
            poses: PoseSet::with_capacity(2 * config.max_instances),
            verdicts: Vec::new(),
        }
    }

    /// (instances before the estimate, the second look's stats).
    fn frame(&mut self, frame: &SyntheticFrame, seed: u64) -> (usize, RecutStats) {
        let view = frame.view();
        self.ws.set_cut_hints(self.recut.hints());
        let prepared = self.ws.prepare(&view, seed).unwrap();
        self.icp.estimate(&view, &mut self.ws, &mut self.poses).unwrap();
        self.verdicts.clear();
        for p in self.poses.as_slice() {
            let id = self.ws.component_id(p.instance_id as usize).unwrap();
            let mask = self.ws.mask_ref(id, p.bbox);
            self.verdicts.push(self.verifier.verify(&view, mask, p));
        }
        let (ws, poses, verdicts) = (&mut self.ws, &mut self.poses, &mut self.verdicts);
        let stats = self.recut.run(&view, ws, poses, verdicts, &mut self.pieces, &mut self.verifier, None, seed);
        (prepared, stats.unwrap())
    }

    fn xs(&self) -> Vec<f64> {
        let mut xs: Vec<f64> = self.poses.as_slice().iter().map(|p| p.translation.x).collect();
        xs.sort_by(f64::total_cmp);
        xs
    }
}

#[test]
fn a_kept_cut_is_made_again_in_the_next_frame_before_the_estimate() {
    let l = l_block();
    let mut stream = Stream::new();
    let (prepared, stats) = stream.frame(&pair(&l), 7);
    assert_eq!((prepared, stats.kept), (1, 1), "the second look separates the pair");
    assert_eq!(stream.recut.hints().len(), 1);
    // The pair 5 mm further right: cut before the estimate, both halves posed, the cut held again.
    let shift = 0.005;
    let moved = painted(render(&[
        (1, &l, pose(10.0, [-0.04 + shift, 0.0, 0.5])),
        (1, &l, pose(10.0, [0.04 + shift, 0.0, 0.5])),
    ]));
    let (prepared, stats) = stream.frame(&moved, 8);
    assert_eq!(prepared, 2, "two instances enter the estimate");
    assert_eq!(stream.ws.hinted_pieces().len(), 1);
    assert_eq!((stats.carried, stats.kept), (1, 0));
    for (x, truth) in stream.xs().iter().zip([-0.04 + shift, 0.04 + shift]) {
        assert!((x - truth).abs() < 0.02, "a pose {x:.3} m across, its block at {truth:.3} m");
    }
    assert_eq!(stream.recut.hints().len(), 1, "and is carried on");
}

#[test]
fn a_carried_cut_that_no_longer_holds_is_forgotten_and_one_pose_stays() {
    let l = l_block();
    let mut stream = Stream::new();
    assert_eq!(stream.frame(&pair(&l), 7).1.kept, 1);
    // One block where the pair stood: the carried cut halves it, the halves
    // are one object by the depth image, and only one pose stays.
    let single = painted(render(&[(1, &l, pose(10.0, [0.0, 0.0, 0.5]))]));
    let (prepared, stats) = stream.frame(&single, 8);
    assert_eq!(prepared, 2, "the stale cut was made");
    assert_eq!((stats.carried, stream.poses.len()), (0, 1));
    assert!(stream.recut.hints().is_empty(), "the cut is forgotten");
    let (prepared, _) = stream.frame(&single, 9);
    assert_eq!((prepared, stream.poses.len()), (1, 1), "the next frame is the block whole");
}

#[test]
fn a_cut_without_time_for_its_pieces_is_deferred_to_the_next_frames_estimate() {
    let l = l_block();
    let mut stream = Stream::new();
    stream.recut.defer_next_frame();
    let (_, stats) = stream.frame(&pair(&l), 7);
    assert_eq!((stats.tried, stats.deferred, stats.kept), (1, 1, 0), "cut, not estimated");
    assert_eq!(stream.poses.len(), 1, "this frame keeps the region's pose");
    assert_eq!(stream.recut.hints().len(), 1);
    let (prepared, stats) = stream.frame(&pair(&l), 8);
    assert_eq!((prepared, stats.carried), (2, 1), "the next frame estimates the pieces, and the cut holds");
    for (x, truth) in stream.xs().iter().zip([-0.04, 0.04]) {
        assert!((x - truth).abs() < 0.02, "a pose {x:.3} m across, its block at {truth} m");
    }
}

#[test]
fn a_deferred_cut_the_next_frame_refuses_is_not_deferred_again_for_a_while() {
    // Every region qualifies; one block, deferred: the next frame halves it,
    // the halves are one object, and that place is left whole for REFUSED_FRAMES.
    let l = l_block();
    let mut stream = Stream::with(RecutConfig { max_coverage: 1.01, ..RecutConfig::DEFAULT });
    let single = painted(render(&[(1, &l, pose(10.0, [0.0, 0.0, 0.5]))]));
    stream.recut.defer_next_frame();
    assert_eq!(stream.frame(&single, 7).1.deferred, 1);
    let (prepared, stats) = stream.frame(&single, 8);
    assert_eq!((prepared, stats.carried, stream.poses.len()), (2, 0, 1), "refused: one pose stays");
    for seed in 9..9 + fusepose_estimator::recut::REFUSED_FRAMES as u64 - 1 {
        stream.recut.defer_next_frame();
        let (prepared, stats) = stream.frame(&single, seed);
        assert_eq!((prepared, stats.deferred), (1, 0), "frame {seed}: not deferred again yet");
    }
    stream.recut.defer_next_frame();
    assert_eq!(stream.frame(&single, 40).1.deferred, 1, "after REFUSED_FRAMES it may be tried again");
}

/// Cuts into up to four pieces, any pose's region looked at.
const UP_TO_FOUR: RecutConfig = RecutConfig { max_pieces: 4, poses: RecutPoses::Any, ..RecutConfig::DEFAULT };

/// Three L blocks in a row, 5 mm apart, painted alike: one class-1 region.
/// (Touching, the cut between them misses their contacts: k-means places
/// it midway between the blocks' centroids, which lie off their boxes'
/// centres in an L, and one piece's pose then fails.)
fn row_of_three(l: &BoxObject) -> SyntheticFrame {
    let at = |x: f64| (1, l, pose(10.0, [x, 0.0, 0.5]));
    painted(render(&[at(-0.085), at(0.0), at(0.085)]))
}

#[test]
fn three_touching_copies_are_cut_into_three_when_the_pieces_allow() {
    let l = l_block();
    let frame = row_of_three(&l);
    let config = UP_TO_FOUR;
    let out = second_look(&frame.view(), config);
    assert_eq!(out.before, 1, "one region, one pose before the second look");
    assert_eq!((out.stats.tried, out.stats.kept), (1, 1), "the region is cut and the cut kept");
    assert_eq!(out.poses.len(), 3, "a pose per copy");
    assert_eq!(out.ws.instances.len(), 3, "the workspace holds the three pieces");
    assert!(out.verdicts.iter().all(|v| v.passed));
    let mut xs: Vec<f64> = out.poses.as_slice().iter().map(|p| p.translation.x).collect();
    xs.sort_by(f64::total_cmp);
    for (x, truth) in xs.iter().zip([-0.08, 0.0, 0.08]) {
        assert!((x - truth).abs() < 0.02, "a pose {x:.3} m across, its block at {truth} m");
    }
    for p in out.poses.as_slice() {
        let inst = out.ws.instances[p.instance_id as usize];
        assert_eq!((p.bbox, p.mask_pixels), (inst.bbox, inst.pixels), "each pose carries its own piece");
    }
    // Cut in two at most, the region cannot become three copies.
    let two = second_look(&frame.view(), RecutConfig { max_pieces: 2, ..config });
    assert!(two.poses.len() < 3, "{} poses from a cut in two", two.poses.len());
}

#[test]
fn a_piece_whose_pose_fits_below_the_floor_is_no_copy() {
    let l = l_block();
    let frame = row_of_three(&l);
    let config = UP_TO_FOUR;
    let all = second_look(&frame.view(), config);
    assert_eq!(all.poses.len(), 3);
    let mut fits: Vec<f32> = all.verdicts.iter().map(|v| v.fit).collect();
    fits.sort_by(f32::total_cmp);
    assert!(fits[0] < 0.99, "the test needs a piece fitting below 1: {fits:?}");
    // At the lowest piece's fit every piece still counts.
    let at = second_look(&frame.view(), RecutConfig { min_piece_fit: fits[0], ..config });
    assert_eq!(at.poses.len(), 3, "a floor equal to the lowest fit keeps every piece");
    // Just above it, that piece is not a copy: two blocks keep their poses.
    let above = second_look(&frame.view(), RecutConfig { min_piece_fit: fits[0] + 0.005, ..config });
    assert_eq!((above.stats.kept, above.poses.len()), (1, 2), "the lowest-fit piece is no copy");
    assert!(above.verdicts.iter().all(|v| v.fit > fits[0]), "{:?}", above.verdicts);
    // Above every piece: no copy at all, the cut is refused and the region keeps one pose.
    let none = second_look(&frame.view(), RecutConfig { min_piece_fit: 1.01, ..config });
    assert_eq!((none.stats.kept, none.poses.len()), (0, 1), "no piece counts: the cut is refused");
}

#[test]
fn the_region_of_a_failed_pose_is_looked_at_unless_only_passed_poses_are() {
    let l = l_block();
    let frame = row_of_three(&l);
    let config = RecutConfig { poses: RecutPoses::Passed, ..RecutConfig::DEFAULT };
    let passed = second_look(&frame.view(), config);
    assert!(!passed.verdicts[0].passed, "one pose cannot explain three blocks");
    assert_eq!(passed.stats.tried, 0, "with `passed`, a failed pose's region is not cut");
    assert_eq!(passed.poses.len(), 1);
    let any = second_look(&frame.view(), RecutConfig::DEFAULT);
    assert_eq!((any.stats.tried, any.poses.len()), (1, 3), "the default looks at it: a pose per block");
}

/// Two touching blocks whose region is posed between them, where a piece
/// of copy A gets A's pose and a piece of copy B one 5 cm too far: B never
/// passes, so the cut is refused.
fn one_copy_posed(truths: [Pose; 2]) -> impl Estimator {
    common::PoseEach(move |_: &fusepose_estimator::Instance, points: &[[f32; 3]]| {
        let x = common::centroid(points).x;
        match x {
            x if x < -0.02 => truths[0],
            x if x > 0.02 => {
                let t = truths[1].translation.vector + Vector3::new(0.0, 0.0, 0.05);
                Pose::from_parts(Translation3::from(t), truths[1].rotation)
            }
            _ => pose(10.0, [x as f64, 0.0, 0.5]),
        }
    })
}

#[test]
fn a_refused_cut_gives_its_region_the_pose_of_its_best_fitting_piece() {
    let l = l_block();
    let truths = [pose(10.0, [-0.04, 0.0, 0.5]), pose(10.0, [0.04, 0.0, 0.5])];
    let frame = pair(&l);
    let view = frame.view();
    // Two pieces and no refit: the region's pose, between the copies, covers
    // too little of it for three, and B's box, posed behind B, would hand B's
    // pixels to A's piece (either way A's piece holds part of B and fits less).
    let config = RecutConfig { max_pieces: 2, refit: false, ..RecutConfig::DEFAULT };
    let run = |best_piece| second_look_with(&view, RecutConfig { best_piece, ..config }, &mut one_copy_posed(truths));
    let off = run(false);
    assert_eq!((off.before, off.stats.tried, off.stats.kept), (1, 1, 0), "the cut is refused");
    assert_eq!(off.stats.replaced, 0);
    let between = off.poses.as_slice()[0].translation;
    assert!(between.x.abs() < 0.02, "without it the region keeps its pose between the copies: {between:?}");
    assert!(!off.verdicts[0].passed, "that pose fails: the piece must fit at least REVIVE_MIN_FIT to revive it");
    let on = run(true);
    assert_eq!((on.stats.kept, on.stats.replaced, on.poses.len()), (0, 1, 1), "one pose, now copy A's");
    let p = on.poses.as_slice()[0];
    assert!((p.translation - truths[0].translation.vector).norm() < 1e-9, "{p:?}");
    let inst = on.ws.instances[p.instance_id as usize];
    assert_eq!((p.bbox, p.mask_pixels), (inst.bbox, inst.pixels), "the region's box and pixels stay");
    assert!(
        on.verdicts[0].passed && on.verdicts[0].fit >= REVIVE_MIN_FIT,
        "the piece's verdict comes with it: {:?}",
        on.verdicts[0]
    );
}

#[test]
fn a_refused_cut_whose_pieces_all_fail_leaves_the_region_alone() {
    let l = l_block();
    let frame = pair(&l);
    let view = frame.view();
    // Every pose 5 cm behind its points: nothing passes, nothing is taken.
    let mut far = common::PoseEach(|_: &fusepose_estimator::Instance, points: &[[f32; 3]]| {
        let c = common::centroid(points);
        pose(10.0, [c.x as f64, 0.0, 0.55])
    });
    let out = second_look_with(&view, RecutConfig { max_coverage: 1.01, ..RecutConfig::DEFAULT }, &mut far);
    assert_eq!((out.stats.tried, out.stats.kept, out.stats.replaced), (1, 0, 0));
    assert!((out.poses.as_slice()[0].translation.z - 0.55).abs() < 1e-9);
}

#[test]
fn pieces_follow_the_share_one_pose_covers() {
    assert_eq!(pieces_for(0.9, 6), 2, "at least two");
    assert_eq!(pieces_for(0.5, 6), 2);
    assert_eq!(pieces_for(0.45, 6), 3, "rounded up: a pose between copies covers more than one");
    assert_eq!(pieces_for(0.34, 6), 3);
    assert_eq!(pieces_for(0.3, 6), 4);
    assert_eq!(pieces_for(0.3, 3), 3, "at most the configured count");
    assert_eq!(pieces_for(0.0, 6), 6, "no coverage: the most");
    for (s, poses) in [("passed", RecutPoses::Passed), ("coverage", RecutPoses::Coverage), ("any", RecutPoses::Any)] {
        assert_eq!(s.parse::<RecutPoses>(), Ok(poses));
        assert_eq!(poses.to_string(), s);
    }
    let err = "all".parse::<RecutPoses>().unwrap_err();
    assert!(err.contains("passed, coverage or any"), "{err}");
}

#[test]
fn refitting_the_cut_to_the_pieces_poses_separates_touching_l_blocks() {
    let l = l_block();
    let at = |x: f64| (1, &l, pose(10.0, [x, 0.0, 0.5]));
    let frame = painted(render(&[at(-0.08), at(0.0), at(0.08)]));
    let config = RecutConfig { refit: false, ..UP_TO_FOUR };
    let plain = second_look(&frame.view(), config);
    assert!(plain.poses.len() < 3, "between point clusters the cut misses the contacts: {} poses", plain.poses.len());
    let out = second_look(&frame.view(), RecutConfig { refit: true, ..config });
    assert_eq!((out.stats.tried, out.stats.kept), (1, 1));
    assert_eq!(out.poses.len(), 3, "a pose per block once the pixels follow the pieces' poses");
    let mut xs: Vec<f64> = out.poses.as_slice().iter().map(|p| p.translation.x).collect();
    xs.sort_by(f64::total_cmp);
    for (x, truth) in xs.iter().zip([-0.08, 0.0, 0.08]) {
        assert!((x - truth).abs() < 0.02, "a pose {x:.3} m across, its block at {truth} m");
    }
}

/// The network's behaviour on tune_pairs (docs/BENCHMARKS.md, session 35):
/// a piece holding nine tenths or more of one copy's points (by the copies'
/// true boxes, within 2 mm) is posed exactly as that copy; a piece holding
/// parts of two gets a pose between them.
fn mixing(truths: [Pose; 2]) -> impl Estimator {
    let l = l_block();
    let (lo, hi) = l.bounds();
    common::PoseEach(move |_: &fusepose_estimator::Instance, points: &[[f32; 3]]| {
        let holds = |t: &Pose, p: &[f32; 3]| {
            let q = t.inverse_transform_point(&nalgebra::Point3::new(p[0] as f64, p[1] as f64, p[2] as f64));
            (0..3).all(|a| q[a] > lo[a] - 0.002 && q[a] < hi[a] + 0.002)
        };
        let share = |t: &Pose| points.iter().filter(|p| holds(t, p)).count() as f64 / points.len().max(1) as f64;
        match truths.iter().find(|t| share(t) >= 0.9) {
            Some(t) => *t,
            None => {
                let mid = (truths[0].translation.vector + truths[1].translation.vector) / 2.0;
                Pose::from_parts(Translation3::from(mid), truths[0].rotation)
            }
        }
    })
}

#[test]
fn refitting_by_verdict_gives_the_pixels_a_well_posed_copy_holds_to_it_first() {
    // The votes cut a pair of L blocks a quarter into the right block: the
    // left piece holds parts of both and is posed between them, the right
    // one is posed exactly. By nearest box centre the right block's pixels
    // stay split between the two poses and the left piece never comes
    // clean; by verdict they go first to the better-verified pose's box, so
    // the left piece loses them and is posed exactly in turn.
    let l = l_block();
    let truths = [pose(10.0, [-0.04, 0.0, 0.5]), pose(10.0, [0.04, 0.0, 0.5])];
    let frame = pair(&l);
    let boundary = |u: usize, _: usize| {
        let k = common::intrinsics();
        centre_cell(if (u as f64) < k.fx * 0.02 / 0.5 + k.cx { -0.04 } else { 0.04 })
    };
    let nearest = RecutConfig { proposal: CutProposal::VotesOnly, refit: true, ..RecutConfig::DEFAULT };
    let out = second_look_voted(&frame.view(), nearest, &mut mixing(truths), Some(Votes(boundary)), None);
    assert_eq!((out.before, out.stats.tried, out.stats.by_votes), (1, 1, 1), "one region, cut along the votes");
    assert_eq!(out.stats.kept, 0, "by nearest box the left piece stays mixed, posed between the blocks");
    let by_verdict = RecutConfig { refit_by_verdict: true, ..nearest };
    let out = second_look_voted(&frame.view(), by_verdict, &mut mixing(truths), Some(Votes(boundary)), None);
    assert_eq!((out.before, out.stats.tried, out.stats.by_votes), (1, 1, 1), "one region, cut along the votes");
    assert_eq!(out.stats.kept, 1, "the cut stands once each piece holds one block; refused: {:?}", out.stats.refused);
    let mut xs: Vec<f64> = out.poses.as_slice().iter().map(|p| p.translation.x).collect();
    xs.sort_by(f64::total_cmp);
    assert_eq!(xs.len(), 2, "poses at {xs:.3?}");
    for (x, truth) in xs.iter().zip([-0.04, 0.04]) {
        assert!((x - truth).abs() < 1e-6, "a pose {x:.3} m across, its block at {truth} m");
    }
}

/// The poses' x, checked against the blocks' `truths` (sorted).
fn assert_across(stream: &Stream, truths: &[f64]) {
    let xs = stream.xs();
    assert_eq!(xs.len(), truths.len(), "poses at {xs:.3?}");
    for (x, truth) in xs.iter().zip(truths) {
        assert!((x - truth).abs() < 0.02, "a pose {x:.3} m across, its block at {truth:.3} m");
    }
}

#[test]
fn a_kept_cut_into_three_is_carried_with_a_centre_per_copy() {
    let l = l_block();
    let mut stream = Stream::with(RecutConfig { max_pieces: 4, ..RecutConfig::DEFAULT });
    let (prepared, stats) = stream.frame(&row_of_three(&l), 7);
    assert_eq!((prepared, stats.kept), (1, 1), "the second look cuts the row into three");
    let hints = stream.recut.hints();
    assert_eq!((hints.len(), hints[0].centres().len()), (1, 3), "carried with three centres");
    // The row 5 mm further right: cut into three before the estimate, each posed, the cut held.
    let shift = 0.005;
    let at = |x: f64| (1, &l, pose(10.0, [x + shift, 0.0, 0.5]));
    let moved = painted(render(&[at(-0.085), at(0.0), at(0.085)]));
    let (prepared, stats) = stream.frame(&moved, 8);
    assert_eq!(prepared, 3, "three instances enter the estimate");
    assert_eq!(stream.ws.hinted_pieces().len(), 1);
    assert_eq!(stream.ws.hinted_pieces()[0].ids().len(), 3);
    assert_eq!((stats.carried, stats.tried), (1, 0), "the cut holds; nothing is left to look at again");
    assert_across(&stream, &[-0.08 + shift, shift, 0.08 + shift]);
    assert_eq!(stream.recut.hints()[0].centres().len(), 3, "and is carried on whole");
}

#[test]
fn a_deferred_cut_into_three_is_made_whole_in_the_next_frames_estimate() {
    let l = l_block();
    let mut stream = Stream::with(RecutConfig { max_pieces: 4, ..RecutConfig::DEFAULT });
    stream.recut.defer_next_frame();
    let (_, stats) = stream.frame(&row_of_three(&l), 7);
    assert_eq!((stats.tried, stats.deferred, stats.kept), (1, 1, 0), "cut, not estimated");
    assert_eq!(stream.poses.len(), 1, "this frame keeps the region's pose");
    assert_eq!(stream.recut.hints()[0].centres().len(), 3, "the deferred cut keeps its three pieces");
    let (prepared, stats) = stream.frame(&row_of_three(&l), 8);
    assert_eq!((prepared, stats.carried), (3, 1), "the next frame estimates the three pieces, and the cut holds");
    assert_across(&stream, &[-0.08, 0.0, 0.08]);
}

#[test]
fn a_copy_that_leaves_a_carried_cut_drops_out_of_it() {
    let l = l_block();
    let mut stream = Stream::with(RecutConfig { max_pieces: 4, ..RecutConfig::DEFAULT });
    assert_eq!(stream.frame(&row_of_three(&l), 7).1.kept, 1);
    // The right block taken away: its centre falls on the table, the other
    // two still fall on one region, which is cut in two between them.
    let at = |x: f64| (1, &l, pose(10.0, [x, 0.0, 0.5]));
    let two = painted(render(&[at(-0.085), at(0.0)]));
    let (prepared, stats) = stream.frame(&two, 8);
    assert_eq!(prepared, 2, "cut between the two centres still on it");
    assert_eq!(stream.ws.hinted_pieces()[0].ids().len(), 2);
    assert_eq!(stats.carried, 1);
    assert_across(&stream, &[-0.08, 0.0]);
    assert_eq!(stream.recut.hints()[0].centres().len(), 2);
}

#[test]
fn a_cut_hint_holds_two_to_six_centres() {
    let c = [[0.0f32, 0.0, 0.5]; 7];
    assert!(CutHint::new(1, &c[..1]).is_none(), "one centre is no cut");
    assert!(CutHint::new(1, &c[..7]).is_none(), "more than MAX_CUT_PIECES");
    for k in 2..=fusepose_estimator::recut::MAX_CUT_PIECES {
        assert_eq!(CutHint::new(1, &c[..k]).map(|h| h.centres().len()), Some(k));
    }
}

#[test]
fn a_budget_of_piece_estimates_bounds_the_second_look() {
    let l = l_block();
    let frame = row_of_three(&l);
    let config = RecutConfig { max_pieces: 4, ..RecutConfig::DEFAULT };
    let run = |budget: Option<usize>| {
        let mut stream = Stream::with(config);
        if let Some(b) = budget {
            stream.recut.budget_next_frame(b);
        }
        let (_, stats) = stream.frame(&frame, 7);
        (stats, stream.recut.hints().iter().map(|h| h.centres().len()).collect::<Vec<_>>())
    };
    // Fewer than the region's three pieces and their two refit rounds:
    // nothing estimated, the cut deferred to the next frame with its three centres.
    let (stats, hints) = run(Some(8));
    assert_eq!((stats.tried, stats.deferred, stats.estimates, stats.kept), (1, 1, 0, 0));
    assert_eq!(hints, [3]);
    // Unbounded: the pieces and each refit round that moves pixels, at most two.
    let (free, _) = run(None);
    assert!(free.estimates >= 3 && free.estimates <= 9 && free.estimates % 3 == 0, "{free:?}");
    assert_eq!(free.deferred, 0);
    assert_eq!(run(Some(9)).0, free, "a budget that pays for every round changes nothing");
    // Without refit the pieces alone are the cost.
    let mut plain = Stream::with(RecutConfig { refit: false, ..config });
    plain.recut.budget_next_frame(3);
    let (_, stats) = plain.frame(&frame, 7);
    assert_eq!((stats.deferred, stats.estimates), (0, 3));
}

#[test]
fn a_budget_takes_the_regions_whose_pieces_fit_lowest_coverage_first() {
    // Two pairs far apart: two regions to cut in two.
    let l = l_block();
    let at = |x: f64| (1, &l, pose(10.0, [x, 0.0, 0.8]));
    let frame = painted(render(&[at(-0.24), at(-0.16), at(0.16), at(0.24)]));
    let config = RecutConfig { refit: false, ..RecutConfig::DEFAULT };
    let mut both = Stream::with(config);
    let (prepared, stats) = both.frame(&frame, 7);
    assert_eq!((prepared, stats.tried, stats.estimates), (2, 2, 4), "both pairs cut and estimated");
    let mut one = Stream::with(config);
    one.recut.budget_next_frame(3);
    let (_, stats) = one.frame(&frame, 7);
    assert_eq!((stats.tried, stats.estimates), (1, 2), "the second pair's pieces do not fit");
    assert_eq!(one.poses.len(), stats.kept + 2, "the other region keeps its one pose");
}
