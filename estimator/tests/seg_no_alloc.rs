//! After a warm-up frame, `SegEngine::segment` performs no heap allocation on
//! further frames of the same size, and its output feeds `Workspace::prepare`.
//! Also measures the engine's time per frame (ignored test; run in release).
//!
//! A counting global allocator counts allocations made on the test's own
//! thread while counting is switched on (other test threads don't interfere).

mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use common::{l_block, object_set, seg_weight_bytes as weight_bytes, step_block};
use fusepose_estimator::seg::{DepthRegionParams, DepthRegions, FrameMap, SegConfig, SegEngine, SegFile};
use fusepose_estimator::{ColorFormat, DepthPlane, FrameView, LabelPlane, Workspace, WorkspaceConfig};
use fusepose_scene::{Intrinsics, ObjectSet};

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

fn engine(set: &ObjectSet) -> SegEngine {
    engine_with(&SegConfig::new(set.len()), set)
}

/// An engine of architecture `cfg` with random weights.
fn engine_with(cfg: &SegConfig, set: &ObjectSet) -> SegEngine {
    let file = SegFile::from_bytes(&weight_bytes(cfg, set)).unwrap();
    file.check_objects(set).unwrap();
    SegEngine::new(&file).unwrap()
}

/// A 640x480 frame with structure (gradients, a near box, missing depth).
fn frame_planes(shift: usize) -> (Vec<u8>, Vec<u16>) {
    let (w, h) = (640usize, 480usize);
    let mut color = vec![0u8; w * h * 3];
    let mut depth = vec![0u16; w * h];
    for p in 0..w * h {
        let (u, v) = (p % w, p / w);
        let near = (200 + shift..360 + shift).contains(&u) && (150..300).contains(&v);
        color[3 * p..3 * p + 3].copy_from_slice(&[(u / 3) as u8, (v / 2) as u8, if near { 220 } else { 40 }]);
        depth[p] = if p % 53 == 0 {
            0
        } else if near {
            6000
        } else {
            9000 + v as u16 * 4
        };
    }
    (color, depth)
}

fn view<'a>(color: &'a [u8], depth: &'a [u16]) -> FrameView<'a> {
    FrameView {
        intrinsics: Intrinsics::YCB_VIDEO,
        color_format: ColorFormat::Rgb8,
        color,
        depth: DepthPlane::U16 { data: depth, scale: 1e-4 },
        labels: None,
    }
}

#[test]
fn segment_does_not_allocate_after_warm_up_and_feeds_the_workspace() {
    let set = object_set(&[l_block(), step_block()]);
    let mut engine = engine(&set);
    // As the daemon runs it: cells regrouped by depth (the box stands 30 cm off the background plane).
    engine.set_depth_regions(Some(DepthRegions::new(&[0.3, 0.3], DepthRegionParams::default())));
    let (c0, d0) = frame_planes(0);
    let (c1, d1) = frame_planes(40);
    let mut labels = vec![0u16; 640 * 480];
    engine.segment(&view(&c0, &d0), &mut labels).unwrap();
    let first = labels.clone();
    let n = allocations_in(|| {
        engine.segment(&view(&c1, &d1), &mut labels).unwrap();
        engine.segment(&view(&c0, &d0), &mut labels).unwrap();
    });
    assert_eq!(n, 0, "segment allocated {n} times after warm-up");
    assert_eq!(labels, first, "same frame, same labels");
    assert!(labels.iter().all(|&l| (l as usize) <= set.len()));

    // The label plane is what Workspace::prepare consumes.
    let mut ws =
        Workspace::new(WorkspaceConfig { num_classes: set.len() as u16, ..WorkspaceConfig::default() }).unwrap();
    let frame = FrameView { labels: Some(LabelPlane::U16(&labels)), ..view(&c0, &d0) };
    let count = ws.prepare(&frame, 1).unwrap();
    let distinct: std::collections::BTreeSet<u16> = labels.iter().copied().filter(|&l| l > 0).collect();
    assert!(count <= distinct.len() * WorkspaceConfig::default().max_instances);
    for i in 0..count {
        assert!(distinct.contains(&ws.instances[i].class_id));
    }
}

#[test]
fn depth_regrouping_does_not_allocate_after_warm_up() {
    // The near box of `frame_planes` labelled class 1 but for its left half
    // (background), and logits to match: every frame relabels that half.
    let (c0, d0) = frame_planes(0);
    let frame = view(&c0, &d0);
    let map = FrameMap::new(640, 480, &SegConfig::new(2));
    let (gw, gh) = map.grid_size();
    let mut labelled = vec![0u16; gw * gh];
    for y in 0..gh {
        for x in 0..gw {
            let (u, v) = (map.span_x(x).start + 4, map.span_y(y).start + 4);
            if (280..360).contains(&u) && (150..300).contains(&v) {
                labelled[y * gw + x] = 1;
            }
        }
    }
    let n = labelled.len();
    let mut logits = vec![0.0f32; 3 * n];
    for (i, &c) in labelled.iter().enumerate() {
        logits[c as usize * n + i] = 3.0;
    }
    let mut regions = DepthRegions::new(&[0.3, 0.3], DepthRegionParams::default());
    let mut cells = labelled.clone();
    let first = regions.apply(&frame, &map, &logits, &mut cells);
    assert!(first > 0, "the box's unlabelled half was not regrouped");
    let mut changed = 0;
    let allocations = allocations_in(|| {
        cells.copy_from_slice(&labelled);
        changed = regions.apply(&frame, &map, &logits, &mut cells);
    });
    assert_eq!(allocations, 0, "depth regrouping allocated {allocations} times after warm-up");
    assert_eq!(changed, first);
}

#[test]
fn a_background_offset_labels_more_cells_as_objects_and_zero_is_the_argmax() {
    let set = object_set(&[l_block(), step_block()]);
    let mut engine = engine(&set);
    engine.set_min_component_cells(0);
    engine.set_min_interior_cells(0);
    engine.set_max_elongation(0.0);
    let (c, d) = frame_planes(0);
    let objects = |l: &[u16]| l.iter().filter(|&&v| v != 0).count();
    // The cell argmax of the raw logits, before any offset.
    let mut plain = vec![0u16; 640 * 480];
    engine.set_background_offset(0.0);
    engine.segment(&view(&c, &d), &mut plain).unwrap();
    let logits = engine.logits().to_vec();
    let n = engine.cell_labels().len();
    let argmax: Vec<u16> = (0..n)
        .map(|i| (0..=set.len()).max_by(|&a, &b| logits[a * n + i].total_cmp(&logits[b * n + i])).unwrap_or(0) as u16)
        .collect();
    assert_eq!(engine.cell_labels(), &argmax[..], "offset 0 is the plain argmax");
    let mut lifted = vec![0u16; 640 * 480];
    engine.set_background_offset(1e6);
    engine.segment(&view(&c, &d), &mut lifted).unwrap();
    assert!(engine.cell_labels().iter().all(|&l| l != 0), "a huge offset leaves no background cell");
    assert!(objects(&lifted) > objects(&plain), "{} vs {}", objects(&lifted), objects(&plain));
    engine.set_background_offset(f32::NAN);
    engine.segment(&view(&c, &d), &mut lifted).unwrap();
    assert_eq!(lifted, plain, "a NaN offset is refused as 0");
}

/// A file with the offset branch computes its votes only when asked
/// (`compute_votes`, which the second look calls where it cuts) or when
/// voting is on; the votes are never last frame's, and computing them
/// allocates nothing.
#[test]
fn the_offset_branch_runs_on_demand_without_allocating() {
    let set = object_set(&[l_block(), step_block()]);
    let mut engine = engine_with(&SegConfig { offset_branch: true, ..SegConfig::new(set.len()) }, &set);
    let (c0, d0) = frame_planes(0);
    let (c1, d1) = frame_planes(40);
    let mut labels = vec![0u16; 640 * 480];
    engine.segment(&view(&c0, &d0), &mut labels).unwrap();
    assert!(engine.config().offsets);
    assert!(engine.offsets().is_empty() && engine.vote_at(300, 200).is_none(), "not computed unasked");
    assert_eq!(allocations_in(|| engine.compute_votes()), 0);
    let first = engine.offsets().to_vec();
    assert_eq!(first.len(), 2 * 60 * 80);
    assert!(first.iter().any(|&o| o != 0.0) && engine.vote_at(300, 200).is_some());
    engine.segment(&view(&c1, &d1), &mut labels).unwrap();
    assert!(engine.offsets().is_empty(), "a new frame's votes are not the last frame's");
    engine.compute_votes();
    assert_ne!(engine.offsets(), &first[..], "the new frame's votes");
    // With voting on, `segment` computes them itself (it needs them).
    engine.set_voting_mode(fusepose_estimator::seg::VotingMode::On(Default::default()));
    engine.segment(&view(&c0, &d0), &mut labels).unwrap();
    assert_eq!(engine.offsets(), &first[..]);
}

/// The contact branch runs only when asked, each frame's own, and computing
/// it allocates nothing.
#[test]
fn the_contact_branch_runs_on_demand_without_allocating() {
    let set = object_set(&[l_block(), step_block()]);
    let mut engine = engine_with(&SegConfig { offsets: false, contacts: true, ..SegConfig::new(set.len()) }, &set);
    let (c0, d0) = frame_planes(0);
    let (c1, d1) = frame_planes(40);
    let mut labels = vec![0u16; 640 * 480];
    engine.segment(&view(&c0, &d0), &mut labels).unwrap();
    assert!(engine.has_contacts());
    assert!(engine.contacts().is_empty() && engine.contact_at(300, 200).is_none(), "not computed unasked");
    assert_eq!(allocations_in(|| engine.compute_contacts()), 0);
    let first = engine.contacts().to_vec();
    assert_eq!(first.len(), 60 * 80);
    assert!(engine.contact_at(300, 200).is_some_and(|p| (0.0..=1.0).contains(&p)));
    engine.segment(&view(&c1, &d1), &mut labels).unwrap();
    assert!(engine.contacts().is_empty(), "a new frame's contacts are not the last frame's");
    engine.compute_contacts();
    assert_ne!(engine.contacts(), &first[..], "the new frame's contacts");
}

#[test]
fn flip_averaged_logits_are_the_mean_of_the_frame_and_its_mirror_and_do_not_allocate() {
    let set = object_set(&[l_block(), step_block()]);
    let mut engine = engine(&set);
    let cfg = engine.config().clone();
    let (in_w, out_w) = (cfg.input_width, cfg.output_size().1);
    let mirror = |plane: &[f32], w: usize| -> Vec<f32> {
        plane.chunks_exact(w).flat_map(|row| row.iter().rev().copied()).collect::<Vec<_>>()
    };
    // A lopsided input (a ramp and a block on the left), so that the mirror image differs.
    let input: Vec<f32> = (0..4 * cfg.input_height * in_w)
        .map(|i| {
            let (x, c) = (i % in_w, i / (cfg.input_height * in_w));
            if x < 40 { 1.5 - 0.3 * c as f32 } else { x as f32 / in_w as f32 - 0.5 }
        })
        .collect();
    let own = engine.forward(&input).unwrap().to_vec();
    let mirrored = mirror(engine.forward(&mirror(&input, in_w)).unwrap(), out_w);
    assert_ne!(own, mirrored, "a lopsided input has logits of its own");
    engine.set_flip_average(fusepose_estimator::seg::FlipAverage::All);
    let averaged = engine.forward(&input).unwrap().to_vec();
    let expected: Vec<f32> = own.iter().zip(&mirrored).map(|(a, b)| 0.5 * (a + b)).collect();
    assert_eq!(averaged, expected);

    // Without swaps: cells where the views pick two different objects keep
    // the frame's own logits. The shipped segmenter (eight objects) on noisy
    // inputs, until some cells disagree so.
    use rand::{Rng, SeedableRng};
    let weights = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/builtin.safetensors");
    let builtin = fusepose_scene::builtin::builtin_objects();
    let mut engine = SegEngine::load(&weights, &builtin).expect("the shipped model embeds a segmenter");
    let mut rng = rand_pcg::Pcg64::seed_from_u64(8);
    let cells = cfg.output_size().0 * out_w;
    let mut swaps = 0;
    for _ in 0..20 {
        let noisy: Vec<f32> = input.iter().map(|v| v + rng.random_range(-2.0f32..2.0)).collect();
        engine.set_flip_average(fusepose_estimator::seg::FlipAverage::Off);
        let own = engine.forward(&noisy).unwrap().to_vec();
        let mirrored = mirror(engine.forward(&mirror(&noisy, in_w)).unwrap(), out_w);
        engine.set_flip_average(fusepose_estimator::seg::FlipAverage::NoSwap);
        let no_swap = engine.forward(&noisy).unwrap().to_vec();
        let classes = own.len() / cells;
        let best = |l: &[f32], cell: usize| {
            (1..classes).fold(0, |b, c| if l[c * cells + cell] > l[b * cells + cell] { c } else { b })
        };
        for cell in 0..cells {
            let (o, m) = (best(&own, cell), best(&mirrored, cell));
            let swap = o != 0 && m != 0 && o != m;
            swaps += swap as usize;
            for c in 0..classes {
                let i = c * cells + cell;
                let mean = 0.5 * (own[i] + mirrored[i]);
                assert_eq!(no_swap[i], if swap { own[i] } else { mean }, "cell {cell} class {c}");
            }
        }
        if swaps > 0 {
            break;
        }
    }
    assert!(swaps > 0, "no input made the views pick two different objects");
    assert_eq!("no-swap".parse(), Ok(fusepose_estimator::seg::FlipAverage::NoSwap));
    engine.set_flip_average(fusepose_estimator::seg::FlipAverage::NoSwap);

    let (c0, d0) = frame_planes(0);
    let mut labels = vec![0u16; 640 * 480];
    engine.segment(&view(&c0, &d0), &mut labels).unwrap();
    let n = allocations_in(|| engine.segment(&view(&c0, &d0), &mut labels).unwrap());
    assert_eq!(n, 0, "flip-averaged (no-swap) segment allocated {n} times after warm-up");
}

/// A partner segmenter's logits are mixed in at its weight, after the
/// engine's own, without allocating; one of another shape or a weight
/// outside 0..=1 is refused by name.
#[test]
fn a_partner_segmenters_logits_are_mixed_in_at_its_weight() {
    let weights = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/builtin.safetensors");
    let builtin = fusepose_scene::builtin::builtin_objects();
    let mut engine = SegEngine::load(&weights, &builtin).expect("the shipped model embeds a segmenter");
    let cfg = engine.config().clone();
    let partner_file = || SegFile::from_bytes(&weight_bytes(&cfg, &builtin)).unwrap();
    let mut partner = SegEngine::new(&partner_file()).unwrap();
    let input: Vec<f32> =
        (0..4 * cfg.input_height * cfg.input_width).map(|i| ((i * 7919) % 1000) as f32 / 500.0 - 1.0).collect();
    let own = engine.forward(&input).unwrap().to_vec();
    let other = partner.forward(&input).unwrap().to_vec();
    assert_ne!(own, other, "two different segmenters give different logits");

    let small = object_set(&[l_block(), step_block()]);
    let mismatched =
        SegEngine::new(&SegFile::from_bytes(&weight_bytes(&SegConfig::new(small.len()), &small)).unwrap()).unwrap();
    let err = engine.set_partner(mismatched, 0.5).unwrap_err();
    assert!(
        matches!(err, fusepose_estimator::seg::SegError::PartnerMismatch { outputs: 9, partner_outputs: 3, .. }),
        "{err}"
    );
    let err = engine.set_partner(SegEngine::new(&partner_file()).unwrap(), 1.5).unwrap_err();
    assert!(err.to_string().contains("1.5"), "{err}");
    assert_eq!(engine.forward(&input).unwrap(), &own[..], "a refused partner leaves the logits alone");

    engine.set_partner(partner, 0.25).unwrap();
    let mixed = engine.forward(&input).unwrap().to_vec();
    for (i, ((m, a), b)) in mixed.iter().zip(&own).zip(&other).enumerate() {
        assert_eq!(*m, 0.75 * a + 0.25 * b, "logit {i}");
    }

    let (c0, d0) = frame_planes(0);
    let mut labels = vec![0u16; 640 * 480];
    engine.segment(&view(&c0, &d0), &mut labels).unwrap();
    let n = allocations_in(|| engine.segment(&view(&c0, &d0), &mut labels).unwrap());
    assert_eq!(n, 0, "segment with a partner allocated {n} times after warm-up");
}

/// `region_probability` is the peak softmax probability of the class over
/// the cells under the region's pixels inside the box: checked against that
/// definition, pixel by pixel, for blobs and boxes that cut through them.
#[test]
fn region_probability_is_the_peak_over_the_cells_under_the_region() {
    use rand::{Rng, SeedableRng};
    let set = object_set(&[l_block(), step_block()]);
    let mut engine = engine(&set);
    let (c0, d0) = frame_planes(0);
    let mut labels = vec![0u16; 640 * 480];
    engine.segment(&view(&c0, &d0), &mut labels).unwrap();
    let map = FrameMap::new(640, 480, engine.config());
    let (out_w, out_h) = map.grid_size();
    let cells = out_w * out_h;
    let logits = engine.logits().to_vec();
    let classes = set.len() + 1;
    let mut rng = rand_pcg::Pcg64::seed_from_u64(21);
    for round in 0..60 {
        // Two overlapping discs of ids 3 and 5 over noise of other ids.
        let mut ids: Vec<u32> = (0..640 * 480).map(|_| rng.random_range(6..9)).collect();
        for id in [3u32, 5] {
            let (cu, cv, r) =
                (rng.random_range(0..640) as i64, rng.random_range(0..480) as i64, rng.random_range(2..120));
            for (p, x) in ids.iter_mut().enumerate() {
                let (u, v) = ((p % 640) as i64, (p / 640) as i64);
                if (u - cu).pow(2) + (v - cv).pow(2) <= r * r {
                    *x = id;
                }
            }
        }
        let mut bbox = [rng.random_range(0..640u16), rng.random_range(0..480u16), 0, 0];
        bbox[2] = rng.random_range(bbox[0]..640);
        bbox[3] = rng.random_range(bbox[1]..480);
        let class = rng.random_range(1..classes) as u16;
        let mut under = std::collections::BTreeSet::new();
        for v in bbox[1] as usize..=bbox[3] as usize {
            for u in bbox[0] as usize..=bbox[2] as usize {
                if ids[v * 640 + u] == 3 {
                    let (cx, cy) = map.cell_of(u, v);
                    under.insert(cy * out_w + cx);
                }
            }
        }
        let peak = under
            .iter()
            .map(|&cell| {
                let logit = |c: usize| logits[c * cells + cell];
                let max = (0..classes).map(logit).fold(f32::NEG_INFINITY, f32::max);
                let sum: f32 = (0..classes).map(|c| (logit(c) - max).exp()).sum();
                logit(class as usize) - max - sum.ln()
            })
            .fold(f32::NEG_INFINITY, f32::max);
        let got = engine.region_probability(&ids, 3, class, bbox);
        if under.is_empty() {
            assert!(got.is_nan(), "round {round}: no pixels, {got}");
        } else {
            assert_eq!(got.to_bits(), peak.exp().to_bits(), "round {round}: {} cells", under.len());
        }
    }
}

#[test]
fn engine_refuses_an_object_set_that_differs() {
    let set = object_set(&[l_block(), step_block()]);
    let file = SegFile::from_bytes(&weight_bytes(&SegConfig::new(2), &set)).unwrap();
    assert!(file.check_objects(&object_set(&[step_block(), l_block()])).is_err());
    assert!(file.check_objects(&object_set(&[l_block()])).is_err());
    assert!(file.check_objects(&set).is_ok());
}

/// Median engine time per 640x480 frame over 50 frames (after 5 warm-up frames).
/// `cargo test --release -p fusepose-estimator --test seg_no_alloc -- --ignored --nocapture`
#[test]
#[ignore]
fn segment_time_per_frame() {
    let set = fusepose_scene::builtin::builtin_objects();
    let cfg = SegConfig::new(set.len());
    let mut engine = engine(&set);
    let (c0, d0) = frame_planes(0);
    let (c1, d1) = frame_planes(40);
    let mut labels = vec![0u16; 640 * 480];
    for _ in 0..5 {
        engine.segment(&view(&c0, &d0), &mut labels).unwrap();
    }
    let mut t = Vec::new();
    let mut t_net = Vec::new();
    let input = vec![0.1f32; 4 * cfg.input_width * cfg.input_height];
    for i in 0..50 {
        let (c, d) = if i % 2 == 0 { (&c0, &d0) } else { (&c1, &d1) };
        let s = std::time::Instant::now();
        engine.segment(&view(c, d), &mut labels).unwrap();
        t.push(s.elapsed().as_secs_f64() * 1e3);
        let s = std::time::Instant::now();
        engine.forward(&input).unwrap();
        t_net.push(s.elapsed().as_secs_f64() * 1e3);
    }
    t.sort_by(f64::total_cmp);
    t_net.sort_by(f64::total_cmp);
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    println!(
        "segment 640x480: median {:.2} ms (p10 {:.2}, p90 {:.2}); network only: median {:.2} ms; {:.1} MMAC = {:.0} MFLOP; {} params; loadavg {}",
        t[25],
        t[5],
        t[45],
        t_net[25],
        cfg.macs() as f64 / 1e6,
        2.0 * cfg.macs() as f64 / 1e6,
        cfg.parameter_count(),
        load.trim()
    );
}
