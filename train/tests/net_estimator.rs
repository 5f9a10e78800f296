//! The shipped engine end to end: a weight file written by the trainer's store
//! is loaded by `NetEstimator` against the object set, estimates a rendered
//! frame (one pose per instance, refiner iterations reported, per-frame cap),
//! allocates nothing after warm-up, and every malformed or mismatched file is
//! refused with its own typed error.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::collections::HashMap;
use std::path::PathBuf;

use burn::prelude::Device;
use fusepose_estimator::net::meta::{self, TrainRecord, object_entries};
use fusepose_estimator::net::{NetConfig, NetEstimator, NetLoadError, NetOptions, WeightFile};
use fusepose_estimator::{
    ColorFormat, DepthPlane, Estimator, FrameView, LabelPlane, PoseSet, Workspace, WorkspaceConfig,
};
use fusepose_scene::builtin::builtin_objects;
use fusepose_scene::render::{NoiseConfig, RenderTarget};
use fusepose_scene::sampler::{LabelKind, SamplerConfig, render_view_labelled, sample_scene};
use fusepose_scene::{Intrinsics, ObjectSet};
use fusepose_train::model::FusionNet;
use safetensors::SafeTensors;
use safetensors::tensor::TensorView;

struct CountingAllocator;

thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if COUNTING.try_with(Cell::get).unwrap_or(false) {
            let _ = ALLOCATIONS.try_with(|a| a.set(a.get() + 1));
        }
        unsafe { System.alloc(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if COUNTING.try_with(Cell::get).unwrap_or(false) {
            let _ = ALLOCATIONS.try_with(|a| a.set(a.get() + 1));
        }
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

fn allocations_in(f: impl FnOnce()) -> usize {
    ALLOCATIONS.with(|a| a.set(0));
    COUNTING.with(|c| c.set(true));
    f();
    COUNTING.with(|c| c.set(false));
    ALLOCATIONS.with(Cell::get)
}

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("fusepose-net-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join("net.safetensors")
}

fn write_random(set: &ObjectSet, name: &str) -> PathBuf {
    let cfg = NetConfig::new(set.len());
    let net = FusionNet::new(&cfg, &Device::flex());
    let path = temp(name);
    fusepose_train::store::save(&net, &cfg, &object_entries(set), &TrainRecord::default(), &path).unwrap();
    path
}

#[test]
fn estimates_a_rendered_frame_without_allocating_after_warm_up() {
    let set = builtin_objects();
    let path = write_random(&set, "e2e");
    let mut est = NetEstimator::load(&path, &set, NetOptions::default()).unwrap();
    assert_eq!(est.refine_iterations(), 2);
    let wcfg = WorkspaceConfig { num_classes: set.len() as u16, ..est.workspace_config(8) };
    let mut ws = Workspace::new(wcfg).unwrap();
    let k = Intrinsics::YCB_VIDEO;
    let mut target = RenderTarget::for_intrinsics(&k);
    let scene = sample_scene(&set, &SamplerConfig::default(), 11).unwrap();
    render_view_labelled(&scene, &set, 0, &k, &NoiseConfig::default(), LabelKind::Class, &mut target).unwrap();
    let frame = FrameView {
        intrinsics: k,
        color_format: ColorFormat::Rgb8,
        color: target.rgb(),
        depth: DepthPlane::F32(target.depth_m()),
        labels: Some(LabelPlane::U16(target.labels())),
    };
    let count = ws.prepare(&frame, 1).unwrap();
    assert!(count >= 2, "the parallel path needs two instances, got {count}");
    let mut out = PoseSet::with_capacity(8);
    est.estimate(&frame, &mut ws, &mut out).unwrap();
    assert_eq!(out.len(), count);
    for (i, p) in out.as_slice().iter().enumerate() {
        assert_eq!(p.class_id, ws.instances[i].class_id);
        assert_eq!(p.iterations, 2);
        assert!(p.translation.iter().all(|v| v.is_finite()));
        assert!(p.confidence > 0.0 && p.confidence < 1.0);
    }
    for _ in 0..5 {
        let allocs = allocations_in(|| est.estimate(&frame, &mut ws, &mut out).unwrap());
        assert_eq!(allocs, 0, "allocations in a warm estimate");
    }
    // The two-thread split returns exactly the single-thread poses, in instance order.
    let single = NetOptions { threads: 1, ..NetOptions::default() };
    let mut one = NetEstimator::load(&path, &set, single).unwrap();
    assert_eq!(one.threads(), 1);
    let mut out1 = PoseSet::with_capacity(8);
    one.estimate(&frame, &mut ws, &mut out1).unwrap();
    assert_eq!(out1.as_slice(), out.as_slice());
    est.cap_next_frame(0);
    est.estimate(&frame, &mut ws, &mut out).unwrap();
    assert!(out.as_slice().iter().all(|p| p.iterations == 0));
    est.estimate(&frame, &mut ws, &mut out).unwrap();
    assert!(out.as_slice().iter().all(|p| p.iterations == 2));

    // A class alternate for every instance: two poses each (the segmenter's
    // class first), still no allocation, and the two-thread split still
    // equals one thread.
    for inst in ws.instances.iter_mut() {
        inst.alt_class_id = inst.class_id % set.len() as u16 + 1;
    }
    let mut alt = PoseSet::with_capacity(16);
    est.estimate(&frame, &mut ws, &mut alt).unwrap();
    assert_eq!(alt.len(), 2 * count);
    for (i, pair) in alt.as_slice().chunks(2).enumerate() {
        assert_eq!((pair[0].instance_id, pair[1].instance_id), (i as u16, i as u16));
        assert_eq!((pair[0].class_id, pair[1].class_id), (ws.instances[i].class_id, ws.instances[i].alt_class_id));
        assert_eq!(pair[0], out.as_slice()[i], "the segmenter's class is estimated as without an alternate");
    }
    let allocs = allocations_in(|| est.estimate(&frame, &mut ws, &mut alt).unwrap());
    assert_eq!(allocs, 0, "allocations in a warm estimate with alternates");
    let mut alt1 = PoseSet::with_capacity(16);
    one.estimate(&frame, &mut ws, &mut alt1).unwrap();
    assert_eq!(alt1.as_slice(), alt.as_slice());
}

/// Rewrites a valid file with `edit` applied to its tensors and metadata.
fn rewrite(
    bytes: &[u8],
    edit: impl FnOnce(&mut Vec<(String, Vec<usize>, Vec<u8>)>, &mut HashMap<String, String>),
) -> Vec<u8> {
    let (_, header) = SafeTensors::read_metadata(bytes).unwrap();
    let mut md = header.metadata().clone().unwrap_or_default();
    let st = SafeTensors::deserialize(bytes).unwrap();
    let mut tensors: Vec<(String, Vec<usize>, Vec<u8>)> =
        st.tensors().into_iter().map(|(n, v)| (n, v.shape().to_vec(), v.data().to_vec())).collect();
    edit(&mut tensors, &mut md);
    let views: Vec<(String, TensorView<'_>)> = tensors
        .iter()
        .map(|(n, s, d)| (n.clone(), TensorView::new(safetensors::Dtype::F32, s.clone(), d).unwrap()))
        .collect();
    safetensors::serialize(views, Some(md)).unwrap()
}

#[test]
fn malformed_or_mismatched_files_are_refused_with_typed_errors() {
    let set = builtin_objects();
    let path = write_random(&set, "errors");
    let bytes = std::fs::read(&path).unwrap();
    assert!(WeightFile::from_bytes(&bytes).is_ok());

    let e = WeightFile::read(&path.with_extension("nope")).unwrap_err();
    assert!(matches!(e, NetLoadError::Io { .. }), "{e}");
    let e = WeightFile::from_bytes(&bytes[..bytes.len() - 100]).unwrap_err();
    assert!(matches!(e, NetLoadError::Format(_)), "{e}");
    let e = WeightFile::from_bytes(&bytes[..5]).unwrap_err();
    assert!(matches!(e, NetLoadError::Format(_)), "{e}");

    let b = rewrite(&bytes, |t, _| t.retain(|(n, _, _)| n != "pose.l2.weight"));
    let e = WeightFile::from_bytes(&b).unwrap_err();
    assert!(matches!(&e, NetLoadError::MissingTensor(n) if n == "pose.l2.weight"), "{e}");

    let b = rewrite(&bytes, |t, _| {
        let x = t.iter_mut().find(|(n, _, _)| n == "refine.m1.bias").unwrap();
        x.1 = vec![x.1[0] / 2, 2];
    });
    let e = WeightFile::from_bytes(&b).unwrap_err();
    assert!(matches!(e, NetLoadError::WrongShape { .. }), "{e}");

    let b = rewrite(&bytes, |_, md| {
        md.remove(meta::KEY_CONFIG);
    });
    let e = WeightFile::from_bytes(&b).unwrap_err();
    assert!(matches!(e, NetLoadError::MissingMetadata(meta::KEY_CONFIG)), "{e}");

    let b = rewrite(&bytes, |_, md| {
        md.insert(meta::KEY_CONFIG.into(), "{\"num_classes\": 3}".into());
    });
    let e = WeightFile::from_bytes(&b).unwrap_err();
    assert!(matches!(e, NetLoadError::BadMetadata { .. }), "{e}");

    let b = rewrite(&bytes, |_, md| {
        md.insert(meta::KEY_FORMAT.into(), "something-else".into());
    });
    let e = WeightFile::from_bytes(&b).unwrap_err();
    assert!(matches!(e, NetLoadError::UnsupportedFormat { .. }), "{e}");

    let mut fewer = set.clone();
    fewer.objects.pop();
    let e = NetEstimator::load(&path, &fewer, NetOptions::default()).err().unwrap();
    assert!(matches!(e, NetLoadError::ObjectCount { .. }), "{e}");
    let mut renamed = set.clone();
    renamed.objects[1].name.push_str("_v2");
    let e = NetEstimator::load(&path, &renamed, NetOptions::default()).err().unwrap();
    assert!(matches!(e, NetLoadError::ObjectMismatch { class: 2, what: "name", .. }), "{e}");
    let mut moved = set.clone();
    moved.objects[0].samples[0].x += 0.001;
    let e = NetEstimator::load(&path, &moved, NetOptions::default()).err().unwrap();
    assert!(matches!(e, NetLoadError::ObjectMismatch { class: 1, .. }), "{e}");
}
