//! Fuzz harnesses for fusepose, as plain functions.
//!
//! Targets: `frame` ([`frame_path`]), `model` ([`model_load`]), `seg`
//! ([`seg_load`]); see `docs/RELIABILITY.md`, section "Fuzzing".
//! Each `fuzz_targets/*.rs` calls one function of this file; the replay test
//! `tests/tests/fuzz_corpus_replay.rs` includes this same file (by `#[path]`)
//! and runs every input under `fuzz/corpus/<target>/` through it on every
//! `cargo test --workspace`, so the corpus is a regression suite on stable.
//!
//! A harness panics only when the code under test broke a rule: a panic
//! anywhere below it, or a violated invariant asserted here. Errors returned
//! for bad input are the expected outcome, never a failure.
//!
//! Uses only the fusepose crates (client, daemon, estimator, scene), nalgebra and std,
//! so both the fuzz crate and the workspace test crate can compile it.

#![allow(dead_code)] // The replay test uses a subset of the seed builders.

use fusepose_client::{FrameHeader, InvalidReason, PlaneRef, decode_frame};
use fusepose_daemon::frame_view::to_frame_view;
use fusepose_estimator::net::{NetEstimator, NetLoadError, NetOptions, WeightFile};
use fusepose_estimator::{
    ColorFormat, DepthPlane, Estimator, FrameError, FrameView, LabelPlane, PoseSet, Workspace, WorkspaceConfig,
};
use fusepose_scene::{Intrinsics, Mesh, ObjectModel, ObjectSet, Symmetry};

// ---------------------------------------------------------------------------
// Target `frame`: bytes → header + payload decode → FrameView → validate → prepare
// ---------------------------------------------------------------------------

/// Size of the wire header at the front of a `frame` input.
pub const HEADER_LEN: usize = 128;

/// The camera id the harness's "service" belongs to (frames must carry it, as in the daemon).
pub const FUZZ_CAMERA_ID: u32 = 0x00C0_FFEE;

/// Workspace sizes for the frame target: small so one run is fast.
pub fn frame_workspace_config() -> WorkspaceConfig {
    WorkspaceConfig {
        max_instances: 4,
        num_points: 16,
        crop_size: 8,
        min_pixels: 2,
        num_classes: 5,
        crop_margin: 0.15,
        min_valid_depth: 2,
        // As the daemon runs it: arbitrary depth goes through the plane fit too.
        support_floor_m: fusepose_estimator::workspace::DEFAULT_SUPPORT_FLOOR_M,
    }
}

/// What the frame path did with one input.
#[derive(Clone, Debug, PartialEq)]
pub enum FrameOutcome {
    /// Fewer than [`HEADER_LEN`] bytes: no header (the daemon always has a full one).
    TooShort,
    /// The client decoder refused the frame (what the daemon counts as invalid).
    Rejected(InvalidReason),
    /// Decoded, but the daemon's content check (`FrameView::check_content`) or
    /// `Workspace::prepare` refused it (e.g. no depth reading, no label plane).
    Refused(FrameError),
    /// Decoded and prepared: this many instances.
    Prepared(usize),
}

/// Reads the header the way the daemon sees it: the 128 bytes as a
/// `#[repr(C)]` little-endian [`FrameHeader`] (every bit pattern is a value).
pub fn parse_header(b: &[u8; HEADER_LEN]) -> FrameHeader {
    let mut at = 0usize;
    let mut take = |n: usize| {
        let s = &b[at..at + n];
        at += n;
        s
    };
    let magic = u32::from_le_bytes(take(4).try_into().unwrap());
    let format_version = u16::from_le_bytes(take(2).try_into().unwrap());
    let header_size = u16::from_le_bytes(take(2).try_into().unwrap());
    let camera_id = u32::from_le_bytes(take(4).try_into().unwrap());
    let width = u32::from_le_bytes(take(4).try_into().unwrap());
    let height = u32::from_le_bytes(take(4).try_into().unwrap());
    let depth_scale = f32::from_le_bytes(take(4).try_into().unwrap());
    let codes: [u8; 4] = take(4).try_into().unwrap();
    let instance_count = u16::from_le_bytes(take(2).try_into().unwrap());
    let _reserved = u16::from_le_bytes(take(2).try_into().unwrap());
    let mut u64s = [0u64; 6];
    for v in &mut u64s {
        *v = u64::from_le_bytes(take(8).try_into().unwrap());
    }
    let mut u32s = [0u32; 8];
    for v in &mut u32s {
        *v = u32::from_le_bytes(take(4).try_into().unwrap());
    }
    let _reserved_end: [u8; 16] = take(16).try_into().unwrap();
    let f = f64::from_bits;
    FrameHeader {
        magic,
        format_version,
        header_size,
        camera_id,
        width,
        height,
        depth_scale,
        color_format: codes[0],
        depth_format: codes[1],
        has_labels: codes[2],
        label_format: codes[3],
        instance_count,
        _reserved,
        sequence: u64s[0],
        capture_time_ns: u64s[1],
        fx: f(u64s[2]),
        fy: f(u64s[3]),
        cx: f(u64s[4]),
        cy: f(u64s[5]),
        color: PlaneRef { offset: u32s[0], len: u32s[1] },
        depth: PlaneRef { offset: u32s[2], len: u32s[3] },
        labels: PlaneRef { offset: u32s[4], len: u32s[5] },
        instance_classes: PlaneRef { offset: u32s[6], len: u32s[7] },
        _reserved_end,
    }
}

// The field order and offsets parse_header assumes, checked against the real layout.
const _: () = {
    use std::mem::offset_of;
    assert!(offset_of!(FrameHeader, depth_scale) == 20 && offset_of!(FrameHeader, color_format) == 24);
    assert!(offset_of!(FrameHeader, instance_count) == 28 && offset_of!(FrameHeader, _reserved) == 30);
    assert!(offset_of!(FrameHeader, sequence) == 32);
    assert!(offset_of!(FrameHeader, fx) == 48 && offset_of!(FrameHeader, cy) == 72);
    assert!(offset_of!(FrameHeader, color) == 80 && offset_of!(FrameHeader, labels) == 96);
    assert!(offset_of!(FrameHeader, instance_classes) == 104 && offset_of!(FrameHeader, _reserved_end) == 112);
    assert!(std::mem::size_of::<FrameHeader>() == HEADER_LEN);
};

/// The inverse of [`parse_header`] (for building seeds).
pub fn header_bytes(h: &FrameHeader) -> [u8; HEADER_LEN] {
    let mut out = Vec::with_capacity(HEADER_LEN);
    out.extend_from_slice(&h.magic.to_le_bytes());
    out.extend_from_slice(&h.format_version.to_le_bytes());
    out.extend_from_slice(&h.header_size.to_le_bytes());
    out.extend_from_slice(&h.camera_id.to_le_bytes());
    out.extend_from_slice(&h.width.to_le_bytes());
    out.extend_from_slice(&h.height.to_le_bytes());
    out.extend_from_slice(&h.depth_scale.to_le_bytes());
    out.extend_from_slice(&[h.color_format, h.depth_format, h.has_labels, h.label_format]);
    out.extend_from_slice(&h.instance_count.to_le_bytes());
    out.extend_from_slice(&h._reserved.to_le_bytes());
    for v in [h.sequence, h.capture_time_ns, h.fx.to_bits(), h.fy.to_bits(), h.cx.to_bits(), h.cy.to_bits()] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for p in [h.color, h.depth, h.labels, h.instance_classes] {
        out.extend_from_slice(&p.offset.to_le_bytes());
        out.extend_from_slice(&p.len.to_le_bytes());
    }
    out.extend_from_slice(&h._reserved_end);
    out.try_into().expect("header is 128 bytes")
}

/// The frame path of the daemon for one input: the first [`HEADER_LEN`] bytes
/// are the header, the rest the payload (copied into an 8-byte aligned buffer,
/// as iceoryx2 payloads are). Decode → `to_frame_view` → `validate` →
/// `Workspace::prepare`, twice with the same seed (results must agree).
pub fn frame_path(data: &[u8]) -> FrameOutcome {
    let Some((head, payload)) = data.split_first_chunk::<HEADER_LEN>() else {
        return FrameOutcome::TooShort;
    };
    let header = parse_header(head);
    let mut aligned = vec![0u64; payload.len().div_ceil(8)];
    let bytes: &mut [u8] = &mut bytemuck_u8(&mut aligned)[..payload.len()];
    bytes.copy_from_slice(payload);
    let bytes: &[u8] = bytes;

    let planes = match decode_frame(&header, bytes, Some(FUZZ_CAMERA_ID)) {
        Err(rejection) => return FrameOutcome::Rejected(rejection.reason()),
        Ok(planes) => planes,
    };
    // The decoder promises plane slices inside the payload with exact sizes.
    let base = bytes.as_ptr() as usize;
    let inside = |p: usize, n: usize| p >= base && p + n <= base + bytes.len();
    assert!(inside(planes.color.as_ptr() as usize, planes.color.len()));
    let view = to_frame_view(&planes);
    match view.depth {
        DepthPlane::U16 { data, .. } => assert!(inside(data.as_ptr() as usize, data.len() * 2)),
        DepthPlane::F32(data) => assert!(inside(data.as_ptr() as usize, data.len() * 4)),
    }
    // What the client decoder accepts, the estimator's validation accepts.
    if let Err(e) = view.validate() {
        panic!("decode_frame accepted a frame that FrameView::validate refuses: {e}");
    }

    let config = frame_workspace_config();
    // The daemon's content check (depth readings, label ids) runs before
    // prepare; here prepare runs either way, for coverage, and the two must agree.
    let content = view.check_content(config.num_classes);
    let mut ws = Workspace::new(config).expect("fixed config is valid");
    // Joining same-class pieces and cutting regions of several copies run
    // too (as in the daemon): 25 cm objects.
    ws.join_parts(&[0.25; 5]);
    ws.split_regions(&fusepose_estimator::split::CutLimits { extents: vec![0.25; 5], areas: vec![0.02; 5] });
    let result = ws.prepare(&view, header.sequence);
    check_workspace(&ws, &view, &result);
    if view.labels.is_some_and(|l| l.is_instances()) {
        assert_eq!(ws.stats().joined_parts, 0, "an instance plane's instances were joined");
        assert_eq!(ws.stats().split_regions, 0, "an instance plane's instances were cut");
    }
    match &content {
        Err(FrameError::DepthEmpty | FrameError::DepthNonFinite { .. }) => {
            assert!(ws.instances.is_empty(), "instances without a single depth reading")
        }
        Err(FrameError::LabelOutOfRange { .. }) => assert!(
            result.is_err() || ws.stats().labels.unknown_class_pixels > 0,
            "check_content saw an unknown label, prepare did not"
        ),
        // Pixels of an instance without a class (or past the table) are skipped by prepare.
        Err(FrameError::InstanceBeyondTable { .. } | FrameError::InstanceClassUnknown { .. }) => assert!(
            result.is_err() || ws.stats().labels.unknown_class_pixels > 0,
            "check_content saw an instance without a known class, prepare did not"
        ),
        Err(e) => panic!("check_content gave an unexpected error: {e}"),
        Ok(census) => assert!(census.valid > 0),
    }
    let first: Vec<_> = ws.instances.clone();
    let first_points = ws.points.clone();
    let again = ws.prepare(&view, header.sequence);
    assert_eq!(result, again, "prepare is not deterministic");
    assert_eq!(first, ws.instances, "prepare is not deterministic");
    assert!(
        first_points.iter().zip(ws.points.iter()).all(|(a, b)| a.to_bits() == b.to_bits()),
        "prepare is not deterministic"
    );
    match (content, result) {
        (Err(e), _) | (Ok(_), Err(e)) => FrameOutcome::Refused(e),
        (Ok(_), Ok(n)) => FrameOutcome::Prepared(n),
    }
}

/// Invariants of a prepared workspace.
fn check_workspace(ws: &Workspace, view: &FrameView<'_>, result: &Result<usize, FrameError>) {
    let c = ws.config;
    let (w, h) = (view.width(), view.height());
    match result {
        Err(_) => assert!(ws.instances.is_empty(), "instances left after an error"),
        Ok(n) => assert_eq!(*n, ws.instances.len()),
    }
    assert!(ws.instances.len() <= c.max_instances);
    for (i, inst) in ws.instances.iter().enumerate() {
        assert!(inst.class_id >= 1 && inst.class_id <= c.num_classes, "{inst:?}");
        assert!(inst.pixels as usize >= c.min_pixels, "{inst:?}");
        assert!(inst.valid_depth_pixels as usize >= c.min_valid_depth, "{inst:?}");
        assert!(inst.valid_depth_pixels <= inst.pixels, "{inst:?}");
        let [u0, v0, u1, v1] = inst.bbox.map(|x| x as usize);
        assert!(u0 <= u1 && u1 < w && v0 <= v1 && v1 < h, "bbox outside the image: {inst:?}");
        let [cu, cv, side] = inst.crop_window.map(|x| x as usize);
        assert!(side >= 1 && cu + side <= w && cv + side <= h, "crop window outside the image: {inst:?}");
        if i > 0 {
            assert!(ws.instances[i - 1].pixels >= inst.pixels, "instances not largest first");
        }
        for j in 0..c.num_points {
            assert!((ws.choose[[i, j]] as usize) < c.crop_size * c.crop_size, "choose out of the crop");
            // Every sampled point has the valid depth it was sampled for.
            let z = ws.points[[i, j, 2]];
            assert!(z.is_finite() && z > 0.0, "point {j} of instance {i} has depth {z}");
        }
    }
    // Rows past the instances are zero.
    let k = ws.instances.len();
    assert!(ws.points.iter().skip(k * c.num_points * 3).all(|&x| x == 0.0));
    assert!(ws.choose.iter().skip(k * c.num_points).all(|&x| x == 0));
    assert!(ws.crops.iter().skip(k * 3 * c.crop_size * c.crop_size).all(|&x| x == 0.0));
}

fn bytemuck_u8(words: &mut [u64]) -> &mut [u8] {
    let len = words.len() * 8;
    // SAFETY: u64 has no padding or invalid bit patterns, u8 has alignment 1,
    // and the byte slice covers exactly the same memory with the same lifetime.
    unsafe { std::slice::from_raw_parts_mut(words.as_mut_ptr().cast::<u8>(), len) }
}

/// Plane formats of a seed frame.
#[derive(Clone, Copy, Debug)]
pub struct SeedFormat {
    pub width: u32,
    pub height: u32,
    pub depth_f32: bool,
    /// None, Some(false) = u8 labels, Some(true) = u16 labels.
    pub labels: Option<bool>,
}

/// A well-formed frame input: header + payload, objects painted as rectangles
/// of classes 1..=3 with depth around 1 m, a depth hole in one of them.
pub fn seed_frame(f: SeedFormat) -> Vec<u8> {
    seed_frame_with(f, |_, metres| metres)
}

/// [`seed_frame`] with every depth value passed through `depth(pixel, metres)`.
pub fn seed_frame_with(f: SeedFormat, depth_of: impl Fn(usize, f32) -> f32) -> Vec<u8> {
    use fusepose_client::LabelFormat as L;
    let labels = f.labels.map(|wide| if wide { L::U16 } else { L::U8 });
    build_seed(f, labels, &[], depth_of)
}

/// A well-formed instance-label frame with the objects of [`seed_frame`]
/// (u16 depth): the class-1 rectangle as two touching instances 1 (left
/// column) and 2, the class-2 rectangle as instance 3, the class-3 one as
/// instance 4. `classes` is the instance class table sent (entry `id` =
/// class of instance `id`); `[0, 1, 1, 2, 3]` matches the class frame.
pub fn seed_instance_frame(width: u32, height: u32, classes: &[u16]) -> Vec<u8> {
    let max_instances = classes.len().saturating_sub(1) as u16;
    let f = SeedFormat { width, height, depth_f32: false, labels: Some(true) };
    build_seed(f, Some(fusepose_client::LabelFormat::InstanceU16 { max_instances }), classes, |_, m| m)
}

fn build_seed(
    f: SeedFormat,
    label_format: Option<fusepose_client::LabelFormat>,
    classes: &[u16],
    depth_of: impl Fn(usize, f32) -> f32,
) -> Vec<u8> {
    use fusepose_client::{ColorFormat as C, DepthFormat as D, FrameLayout, LabelFormat as L};
    let layout = FrameLayout {
        width: f.width,
        height: f.height,
        color_format: C::Rgb8,
        depth_format: if f.depth_f32 { D::F32 } else { D::U16 },
        depth_scale: 0.001,
        labels: label_format,
    };
    let (w, h) = (f.width as usize, f.height as usize);
    let header = FrameHeader {
        fx: 20.0,
        fy: 20.0,
        cx: w as f64 / 2.0,
        cy: h as f64 / 2.0,
        sequence: 42,
        ..layout.header(FUZZ_CAMERA_ID)
    };
    let [color, depth, labels] = layout.planes();
    let table = layout.instance_classes();
    let mut payload = vec![0u8; layout.payload_len()];
    let class_at = |u: usize, v: usize| -> u16 {
        if u >= 1 && u < w / 2 && v >= 1 && v < h / 2 {
            1
        } else if u > w / 2 && v >= h / 2 {
            2
        } else if u == w - 1 && v < 2 {
            3
        } else {
            0
        }
    };
    let instance_at = |u: usize, v: usize| -> u16 {
        match class_at(u, v) {
            1 if u < w / 4 => 1,
            1 => 2,
            2 => 3,
            3 => 4,
            _ => 0,
        }
    };
    for v in 0..h {
        for u in 0..w {
            let p = v * w + u;
            let c = color.offset as usize + p * 3;
            payload[c..c + 3].copy_from_slice(&[(u * 20) as u8, (v * 20) as u8, 99]);
            let hole = class_at(u, v) == 2 && u == w - 1;
            let metres = if hole { 0.0 } else { 0.9 + 0.01 * (u + v) as f32 };
            let metres = depth_of(p, metres);
            if f.depth_f32 {
                let d = depth.offset as usize + p * 4;
                payload[d..d + 4].copy_from_slice(&metres.to_le_bytes());
            } else {
                let d = depth.offset as usize + p * 2;
                payload[d..d + 2].copy_from_slice(&((metres * 1000.0) as u16).to_le_bytes());
            }
            let value = match label_format {
                None => continue,
                Some(L::U8) => {
                    payload[labels.offset as usize + p] = class_at(u, v) as u8;
                    continue;
                }
                Some(L::U16) => class_at(u, v),
                Some(L::InstanceU16 { .. }) => instance_at(u, v),
            };
            let l = labels.offset as usize + p * 2;
            payload[l..l + 2].copy_from_slice(&value.to_le_bytes());
        }
    }
    for (i, class) in classes.iter().enumerate().take(table.len as usize / 2) {
        let t = table.offset as usize + i * 2;
        payload[t..t + 2].copy_from_slice(&class.to_le_bytes());
    }
    let mut out = header_bytes(&header).to_vec();
    out.extend_from_slice(&payload);
    out
}

/// Rewrites the header of a frame input.
pub fn with_header(input: &[u8], edit: impl FnOnce(&mut FrameHeader)) -> Vec<u8> {
    let mut h = parse_header(input[..HEADER_LEN].try_into().unwrap());
    edit(&mut h);
    let mut out = header_bytes(&h).to_vec();
    out.extend_from_slice(&input[HEADER_LEN..]);
    out
}

// ---------------------------------------------------------------------------
// Target `model`: bytes → safetensors + metadata → WeightFile → NetEstimator → one frame
// ---------------------------------------------------------------------------

/// What the model loader did with one input.
#[derive(Debug)]
pub enum ModelOutcome {
    /// `WeightFile::from_bytes` or `NetEstimator::from_file` refused it.
    Refused(NetLoadError),
    /// Loaded; estimating the harness's tiny frame gave this many poses.
    Loaded { poses: usize },
}

/// The object set the harness checks files against: `num_classes` tiny objects
/// (`fuzz_0`, `fuzz_1`, …), so that seed files can match it exactly.
pub fn fuzz_objects(num_classes: usize) -> ObjectSet {
    let objects = (0..num_classes)
        .map(|i| ObjectModel {
            name: format!("fuzz_{i}"),
            mesh: Mesh::default(),
            symmetry: Symmetry::None,
            samples: vec![nalgebra_point(0.01 * (i + 1) as f64)],
            diameter: 0.05,
            bbox_min: nalgebra_point(0.0),
            bbox_max: nalgebra_point(0.0),
            shadow_mesh: None,
        })
        .collect();
    ObjectSet { objects }
}

fn nalgebra_point(x: f64) -> nalgebra::Point3<f64> {
    nalgebra::Point3::new(x, 0.0, 0.0)
}

/// Classes of the harness object set.
pub const MODEL_CLASSES: usize = 2;

/// Input modes of the `model` target (first byte, low bit):
/// - `0`: the rest is a safetensors file as stored on disk;
/// - `1`: the rest is `header JSON`, one 0x00 byte, then tensor data; the
///   harness writes the 8-byte header length itself, so size-changing
///   mutations of the JSON (metadata, shapes, offsets) still reach the parser.
pub fn model_file_bytes(data: &[u8]) -> Vec<u8> {
    let Some((&mode, rest)) = data.split_first() else {
        return Vec::new();
    };
    if mode & 1 == 0 {
        return rest.to_vec();
    }
    let split = rest.iter().position(|&b| b == 0).unwrap_or(rest.len());
    let (json, tensors) = (&rest[..split], rest.get(split + 1..).unwrap_or(&[]));
    let mut out = Vec::with_capacity(8 + rest.len());
    out.extend_from_slice(&(json.len() as u64).to_le_bytes());
    out.extend_from_slice(json);
    out.extend_from_slice(tensors);
    out
}

/// Loads one input as the daemon loads `--weights`: parse and check the file,
/// match it against the object set, build the engine, then estimate a tiny
/// frame with one instance of class 1.
pub fn model_load(data: &[u8]) -> ModelOutcome {
    let bytes = model_file_bytes(data);
    let file = match WeightFile::from_bytes(&bytes) {
        Ok(f) => f,
        Err(e) => return ModelOutcome::Refused(e),
    };
    // A parsed file has every tensor of its config with the declared shape.
    for (name, shape) in file.config.tensor_shapes() {
        let t = file.tensor(&name).expect("checked tensor present");
        assert_eq!(t.len(), shape.iter().product::<usize>(), "{name}");
    }
    let objects = fuzz_objects(MODEL_CLASSES);
    let options = NetOptions { refine_iterations: None, threads: 1, ..NetOptions::default() };
    let mut net = match NetEstimator::from_file(file, &objects, options) {
        Ok(n) => n,
        Err(e) => return ModelOutcome::Refused(e),
    };
    let mut ws = Workspace::new(net.workspace_config(1)).expect("a loaded net gives a valid workspace config");
    // 16x16 with an 8x8 object: above the default min_pixels (50) and min_valid_depth.
    let (w, h) = (16usize, 16usize);
    let color = vec![128u8; w * h * 3];
    let depth = vec![1000u16; w * h];
    let mut labels = vec![0u8; w * h];
    for v in 4..12 {
        for u in 4..12 {
            labels[v * w + u] = 1;
        }
    }
    let frame = FrameView {
        intrinsics: Intrinsics { fx: 20.0, fy: 20.0, cx: 8.0, cy: 8.0, width: w as u32, height: h as u32 },
        color_format: ColorFormat::Rgb8,
        color: &color,
        depth: DepthPlane::U16 { data: &depth, scale: 0.001 },
        labels: Some(LabelPlane::U8(&labels)),
    };
    let n = ws.prepare(&frame, 1).expect("the harness frame is valid");
    assert_eq!(n, 1);
    let mut out = PoseSet::with_capacity(4);
    net.cap_next_frame(1);
    if let Err(e) = net.estimate(&frame, &mut ws, &mut out) {
        panic!("estimate failed on a valid frame: {e}");
    }
    let poses = out.len();
    // An absurd focal length (points at infinity) is refused by validation
    // since the fx range check; the smallest accepted one must still estimate.
    let absurd = FrameView { intrinsics: Intrinsics { fx: 1e-300, fy: 1e-300, ..frame.intrinsics }, ..frame };
    assert!(matches!(ws.prepare(&absurd, 1), Err(FrameError::BadFocalLength { .. })));
    let extreme = FrameView {
        intrinsics: Intrinsics {
            fx: *fusepose_estimator::frame::FOCAL_RANGE_PX.start(),
            fy: *fusepose_estimator::frame::FOCAL_RANGE_PX.start(),
            ..frame.intrinsics
        },
        ..frame
    };
    assert_eq!(ws.prepare(&extreme, 1), Ok(1));
    net.cap_next_frame(1);
    if let Err(e) = net.estimate(&extreme, &mut ws, &mut out) {
        panic!("estimate failed on a valid frame: {e}");
    }
    ModelOutcome::Loaded { poses }
}

/// The smallest architecture (every width 1 or 2) for `classes` objects.
pub fn seed_config(classes: usize) -> fusepose_estimator::net::NetConfig {
    let mut c = fusepose_estimator::net::NetConfig::new(classes);
    c.crop_size = 4;
    c.num_points = 4;
    c.cnn = [1, 1, 1];
    c.emb = 1;
    c.geo = [1, 1];
    c.col = [1, 1];
    c.lift = [1, 2];
    c.trunk = [1, 1];
    c.ref_lift = [1, 1];
    c.ref_head = 1;
    c.refine_iters = 1;
    c
}

/// Metadata of a seed weight file for [`fuzz_objects`]`(classes)` with
/// [`seed_config`]: `(config JSON, objects JSON)`.
pub fn seed_model_metadata(classes: usize) -> (String, String) {
    let c = seed_config(classes);
    let pair = |p: [usize; 2]| format!("[{},{}]", p[0], p[1]);
    let config = format!(
        concat!(
            r#"{{"num_classes":{},"crop_size":{},"num_points":{},"cnn":[{},{},{}],"emb":{},"geo":{},"#,
            r#""col":{},"lift":{},"trunk":{},"ref_lift":{},"ref_head":{},"refine_iters":{},"#,
            r#""geo_scale":{:?},"offset_scale":{:?}}}"#
        ),
        c.num_classes,
        c.crop_size,
        c.num_points,
        c.cnn[0],
        c.cnn[1],
        c.cnn[2],
        c.emb,
        pair(c.geo),
        pair(c.col),
        pair(c.lift),
        pair(c.trunk),
        pair(c.ref_lift),
        c.ref_head,
        c.refine_iters,
        c.geo_scale,
        c.offset_scale
    );
    let entries: Vec<String> = fuzz_objects(classes)
        .objects
        .iter()
        .map(|m| {
            let e = fusepose_estimator::net::ObjectEntry::of(m);
            format!(
                r#"{{"name":"{}","symmetry":"{}","diameter":{:?},"hash":"{}"}}"#,
                e.name, e.symmetry, e.diameter, e.hash
            )
        })
        .collect();
    (config, format!("[{}]", entries.join(",")))
}

fn json_string(s: &str) -> String {
    let mut out = String::from("\"");
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// A safetensors file (no mode byte) with the given metadata and tensors
/// `(name, shape, values)`, written by hand to the format's specification.
pub fn safetensors_bytes(metadata: &[(&str, &str)], tensors: &[(String, Vec<usize>, Vec<f32>)]) -> Vec<u8> {
    let (header, data) = safetensors_parts(metadata, tensors);
    let mut out = (header.len() as u64).to_le_bytes().to_vec();
    out.extend_from_slice(header.as_bytes());
    out.extend_from_slice(&data);
    out
}

/// Header JSON (space-padded to a multiple of 8 bytes) and data of a safetensors file.
pub fn safetensors_parts(metadata: &[(&str, &str)], tensors: &[(String, Vec<usize>, Vec<f32>)]) -> (String, Vec<u8>) {
    let mut fields = Vec::new();
    let meta: Vec<String> = metadata.iter().map(|(k, v)| format!("{}:{}", json_string(k), json_string(v))).collect();
    fields.push(format!("\"__metadata__\":{{{}}}", meta.join(",")));
    let mut data = Vec::new();
    let mut sorted: Vec<&(String, Vec<usize>, Vec<f32>)> = tensors.iter().collect();
    sorted.sort_by(|a, b| a.0.cmp(&b.0));
    for (name, shape, values) in sorted {
        let start = data.len();
        for v in values {
            data.extend_from_slice(&v.to_le_bytes());
        }
        let shape: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
        fields.push(format!(
            r#"{}:{{"dtype":"F32","shape":[{}],"data_offsets":[{},{}]}}"#,
            json_string(name),
            shape.join(","),
            start,
            data.len()
        ));
    }
    let mut header = format!("{{{}}}", fields.join(","));
    while header.len() % 8 != 0 {
        header.push(' ');
    }
    (header, data)
}

/// Every tensor of a config with small deterministic values.
pub fn seed_tensors(config: &fusepose_estimator::net::NetConfig) -> Vec<(String, Vec<usize>, Vec<f32>)> {
    config
        .tensor_shapes()
        .into_iter()
        .enumerate()
        .map(|(t, (name, shape))| {
            let n: usize = shape.iter().product();
            let values = (0..n).map(|i| (((i * 7 + t * 13) % 17) as f32 - 8.0) * 0.05).collect();
            (name, shape, values)
        })
        .collect()
}

/// The seed weight file for the harness object set, as a `model` input in
/// `mode` 0 (raw file) or 1 (JSON + NUL + data, see [`model_file_bytes`]).
pub fn seed_model(
    mode: u8,
    edit: impl FnOnce(&mut String, &mut String, &mut Vec<(String, Vec<usize>, Vec<f32>)>),
) -> Vec<u8> {
    let (mut config, mut objects) = seed_model_metadata(MODEL_CLASSES);
    let mut tensors = seed_tensors(&seed_config(MODEL_CLASSES));
    edit(&mut config, &mut objects, &mut tensors);
    let metadata = [
        ("fusepose.format", "fusepose-net-v1"),
        ("fusepose.config", config.as_str()),
        ("fusepose.objects", objects.as_str()),
    ];
    let mut out = vec![mode];
    if mode & 1 == 0 {
        out.extend_from_slice(&safetensors_bytes(&metadata, &tensors));
    } else {
        let (header, data) = safetensors_parts(&metadata, &tensors);
        out.extend_from_slice(header.as_bytes());
        out.push(0);
        out.extend_from_slice(&data);
    }
    out
}

// ---------------------------------------------------------------------------
// Seeds
// ---------------------------------------------------------------------------

/// Hand-made seeds of the `frame` target, `(file name, input)`. Names state the
/// expected outcome, which the replay test checks: `valid_*` prepares (the
/// number after `_n` is the instance count), `refused_*` decodes but
/// `prepare` refuses it, `reject_*` the decoder refuses.
pub fn frame_seeds() -> Vec<(&'static str, Vec<u8>)> {
    let fmt = |width, height, depth_f32, labels| SeedFormat { width, height, depth_f32, labels };
    let base = seed_frame(fmt(8, 6, false, Some(false)));
    let nan = f64::NAN;
    let edit = |f: &dyn Fn(&mut FrameHeader)| with_header(&base, f);
    let mut unknown = seed_frame(fmt(8, 6, false, Some(true)));
    {
        // Relabel class 2 as 9 (unknown with num_classes = 5).
        let h = parse_header(unknown[..HEADER_LEN].try_into().unwrap());
        let at = HEADER_LEN + h.labels.offset as usize;
        for px in unknown[at..at + 2 * 48].chunks_exact_mut(2) {
            if px == [2, 0] {
                px.copy_from_slice(&[9, 0]);
            }
        }
    }
    let truncated = base[..base.len() - 1].to_vec();
    let instances = seed_instance_frame(8, 6, &[0, 1, 1, 2, 3]);
    let edit_instances = |f: &dyn Fn(&mut FrameHeader)| with_header(&instances, f);
    // The table moved one byte on, inside a payload 8 bytes longer.
    let mut misaligned_table = edit_instances(&|h| h.instance_classes.offset += 1);
    misaligned_table.extend_from_slice(&[0; 8]);
    vec![
        ("valid_n3_u16depth_u8labels", base.clone()),
        ("valid_n3_f32depth_u16labels_odd", seed_frame(fmt(7, 5, true, Some(true)))),
        ("refused_unknown_class", unknown),
        ("valid_n0_1x1", seed_frame(fmt(1, 1, false, Some(false)))),
        ("reject_tiny_fx", edit(&|h| (h.fx, h.cx) = (1e-300, -4.0))),
        ("valid_n3_smallest_fx", edit(&|h| (h.fx, h.fy) = (1.0, 1.0))),
        ("valid_n1_wide_512x2", seed_frame(fmt(512, 2, false, Some(true)))),
        ("refused_no_labels", seed_frame(fmt(8, 6, false, None))),
        ("reject_bad_magic", edit(&|h| h.magic = 0)),
        ("reject_version", edit(&|h| h.format_version = 99)),
        ("reject_wrong_camera", edit(&|h| h.camera_id ^= 1)),
        ("reject_bad_size", edit(&|h| h.width = 0)),
        ("reject_too_large", edit(&|h| (h.width, h.height) = (4097, 1))),
        ("reject_unknown_format", edit(&|h| h.depth_format = 3)),
        ("reject_label_flag", edit(&|h| h.has_labels = 2)),
        ("reject_bad_intrinsics", edit(&|h| h.fx = nan)),
        ("reject_principal_point", edit(&|h| h.cy = 1e9)),
        ("reject_depth_scale", edit(&|h| h.depth_scale = f32::INFINITY)),
        ("reject_plane_out_of_bounds", edit(&|h| h.labels.offset = u32::MAX - 3)),
        ("reject_plane_length", edit(&|h| h.color.len -= 3)),
        ("reject_plane_misaligned", edit(&|h| h.depth.offset += 1)),
        ("reject_plane_overlap", edit(&|h| h.labels.offset = h.depth.offset)),
        ("reject_truncated", truncated),
        ("reject_labels_missing", edit(&|h| h.labels.len = 0)),
        ("refused_all_zero_depth", seed_frame_with(fmt(8, 6, false, Some(false)), |_, _| 0.0)),
        ("refused_all_nan_depth", seed_frame_with(fmt(8, 6, true, Some(false)), |_, _| f32::NAN)),
        ("valid_n4_instances", instances.clone()),
        ("valid_n1_instances_wide_512x2", seed_instance_frame(512, 2, &[0, 1, 1, 2, 3])),
        ("refused_instance_class_unknown", seed_instance_frame(8, 6, &[0, 1, 1, 9, 3])),
        ("refused_instance_without_class", seed_instance_frame(8, 6, &[0, 1, 0, 2, 3])),
        ("refused_instance_beyond_table", seed_instance_frame(8, 6, &[0, 1, 1, 2])),
        ("reject_instance_table_missing", edit_instances(&|h| h.instance_classes = PlaneRef::default())),
        ("reject_instance_table_length", edit_instances(&|h| h.instance_classes.len -= 2)),
        ("reject_instance_table_misaligned", misaligned_table),
        ("reject_instance_without_has_labels", edit_instances(&|h| h.has_labels = 0)),
        ("reject_instance_count_on_class_labels", edit(&|h| h.instance_count = 2)),
    ]
}

/// Hand-made seeds of the `model` target. `valid_*` loads and estimates one
/// pose; `bad_*` is refused with an error.
pub fn model_seeds() -> Vec<(&'static str, Vec<u8>)> {
    let keep = |_: &mut String, _: &mut String, _: &mut Vec<(String, Vec<usize>, Vec<f32>)>| {};
    let raw = seed_model(0, keep);
    vec![
        ("valid_raw", raw.clone()),
        ("valid_json_mode", seed_model(1, keep)),
        ("bad_truncated", raw[..raw.len() - 5].to_vec()),
        ("bad_header_length", {
            let mut r = raw.clone();
            r[1] = r[1].wrapping_add(8);
            r
        }),
        ("bad_empty", vec![0]),
        ("bad_wrong_shape", seed_model(1, |_, _, t| t[0].1 = vec![t[0].2.len(), 1, 1, 1])),
        (
            "bad_missing_tensor",
            seed_model(1, |_, _, t| {
                t.pop();
            }),
        ),
        ("bad_config_json", seed_model(1, |c, _, _| *c = c.replace("\"emb\":1", "\"emb\":\"x\""))),
        ("bad_zero_width", seed_model(1, |c, _, _| *c = c.replace("\"emb\":1", "\"emb\":0"))),
        ("bad_crop_not_div4", seed_model(1, |c, _, _| *c = c.replace("\"crop_size\":4", "\"crop_size\":6"))),
        ("bad_object_count", seed_model(1, |_, o, _| *o = o[..o.find("},{").unwrap() + 1].to_string() + "]")),
        ("bad_object_name", seed_model(1, |_, o, _| *o = o.replace("fuzz_1", "fuzz_9"))),
        (
            "bad_huge_points",
            seed_model(1, |c, _, _| *c = c.replace("\"num_points\":4", "\"num_points\":1000000000000000")),
        ),
        ("bad_huge_crop", seed_model(1, |c, _, _| *c = c.replace("\"crop_size\":4", "\"crop_size\":4000000000000"))),
        (
            "valid_nan_weights",
            seed_model(1, |_, _, t| t.iter_mut().for_each(|x| x.2.iter_mut().for_each(|v| *v = f32::NAN))),
        ),
        (
            "bad_huge_refine_iters",
            seed_model(1, |c, _, _| *c = c.replace("\"refine_iters\":1", "\"refine_iters\":100000000000")),
        ),
        (
            "bad_huge_width",
            seed_model(1, |c, _, _| *c = c.replace("\"geo\":[1,1]", "\"geo\":[18446744073709551615,1]")),
        ),
        ("bad_object_hash", seed_model(1, |_, o, _| *o = o.replacen("\"hash\":\"", "\"hash\":\"0", 1))),
    ]
}

// ---------------------------------------------------------------------------
// Target `seg`: bytes → segmenter safetensors + metadata → SegFile → SegEngine → one frame
// ---------------------------------------------------------------------------

/// What the segmenter loader did with one input.
#[derive(Debug)]
pub enum SegOutcome {
    /// `SegFile::from_bytes`, `check_objects` or `SegEngine::new` refused it.
    Refused(NetLoadError),
    /// Loaded and segmented the harness's 32x24 frame; labels found (non-zero pixels).
    Segmented { labelled_pixels: usize },
}

/// Loads one input as a segmenter file (same input modes as [`model_file_bytes`]),
/// matches it against [`fuzz_objects`]`(MODEL_CLASSES)`, builds the engine and
/// segments a small valid frame. Every output label must be a class of the set.
pub fn seg_load(data: &[u8]) -> SegOutcome {
    use fusepose_estimator::seg::{SegEngine, SegFile};
    let bytes = model_file_bytes(data);
    let file = match SegFile::from_bytes(&bytes) {
        Ok(f) => f,
        Err(e) => return SegOutcome::Refused(e),
    };
    if let Err(e) = file.check_objects(&fuzz_objects(MODEL_CLASSES)) {
        return SegOutcome::Refused(e);
    }
    let mut engine = match SegEngine::new(&file) {
        Ok(e) => e,
        Err(e) => return SegOutcome::Refused(e),
    };
    let (w, h) = (32usize, 24usize);
    let color: Vec<u8> = (0..w * h * 3).map(|i| (i * 37 % 251) as u8).collect();
    let depth: Vec<u16> = (0..w * h).map(|i| if i % 7 == 0 { 0 } else { 800 + (i % 50) as u16 }).collect();
    let frame = FrameView {
        intrinsics: Intrinsics { fx: 30.0, fy: 30.0, cx: 16.0, cy: 12.0, width: w as u32, height: h as u32 },
        color_format: ColorFormat::Bgr8,
        color: &color,
        depth: DepthPlane::U16 { data: &depth, scale: 0.001 },
        labels: None,
    };
    let mut labels = vec![0u16; w * h];
    if let Err(e) = engine.segment(&frame, &mut labels) {
        panic!("segment failed on a valid frame: {e}");
    }
    assert!(labels.iter().all(|&c| c as usize <= MODEL_CLASSES), "label outside the object set");
    // A wrongly sized output buffer is an error, not a panic.
    assert!(engine.segment(&frame, &mut labels[1..]).is_err());
    SegOutcome::Segmented { labelled_pixels: labels.iter().filter(|&&c| c != 0).count() }
}

/// The smallest segmenter for `classes` objects (16x16 input, every width 1).
pub fn seed_seg_config(classes: usize) -> fusepose_estimator::seg::SegConfig {
    fusepose_estimator::seg::SegConfig {
        num_classes: classes,
        input_width: 16,
        input_height: 16,
        enc: [1, 1, 1, 1],
        dec: [1, 1, 1],
        offsets: false,
        offset_branch: false,
        contacts: false,
    }
}

/// A seed segmenter file as a `seg` input (`mode` as in [`model_file_bytes`]).
pub fn seed_seg(
    mode: u8,
    edit: impl FnOnce(&mut String, &mut String, &mut Vec<(String, Vec<usize>, Vec<f32>)>),
) -> Vec<u8> {
    let c = seed_seg_config(MODEL_CLASSES);
    let mut config = format!(
        r#"{{"num_classes":{},"input_width":{},"input_height":{},"enc":[{},{},{},{}],"dec":[{},{},{}]}}"#,
        c.num_classes,
        c.input_width,
        c.input_height,
        c.enc[0],
        c.enc[1],
        c.enc[2],
        c.enc[3],
        c.dec[0],
        c.dec[1],
        c.dec[2]
    );
    let (_, mut objects) = seed_model_metadata(MODEL_CLASSES);
    let mut tensors: Vec<(String, Vec<usize>, Vec<f32>)> = c
        .tensor_shapes()
        .into_iter()
        .enumerate()
        .map(|(t, (name, shape))| {
            let n: usize = shape.iter().product();
            let values = (0..n).map(|i| (((i * 5 + t * 11) % 13) as f32 - 6.0) * 0.1).collect();
            (name, shape, values)
        })
        .collect();
    edit(&mut config, &mut objects, &mut tensors);
    let metadata = [
        ("fusepose.format", "fusepose-seg-v1"),
        ("fusepose.seg.config", config.as_str()),
        ("fusepose.objects", objects.as_str()),
    ];
    let mut out = vec![mode];
    if mode & 1 == 0 {
        out.extend_from_slice(&safetensors_bytes(&metadata, &tensors));
    } else {
        let (header, data) = safetensors_parts(&metadata, &tensors);
        out.extend_from_slice(header.as_bytes());
        out.push(0);
        out.extend_from_slice(&data);
    }
    out
}

/// Hand-made seeds of the `seg` target: `valid_*` loads and segments, `bad_*` is refused.
pub fn seg_seeds() -> Vec<(&'static str, Vec<u8>)> {
    let keep = |_: &mut String, _: &mut String, _: &mut Vec<(String, Vec<usize>, Vec<f32>)>| {};
    let raw = seed_seg(0, keep);
    vec![
        ("valid_raw", raw.clone()),
        ("valid_json_mode", seed_seg(1, keep)),
        ("bad_truncated", raw[..raw.len() - 3].to_vec()),
        ("bad_net_file", model_seeds().remove(0).1),
        ("bad_wrong_shape", seed_seg(1, |_, _, t| t[0].1.reverse())),
        (
            "bad_missing_tensor",
            seed_seg(1, |_, _, t| {
                t.pop();
            }),
        ),
        ("bad_nan_weights", seed_seg(1, |_, _, t| t[1].2[0] = f32::NAN)),
        ("bad_huge_input", seed_seg(1, |c, _, _| *c = c.replace("\"input_width\":16", "\"input_width\":1000000000"))),
        ("bad_tiny_input", seed_seg(1, |c, _, _| *c = c.replace("\"input_width\":16", "\"input_width\":3"))),
        ("bad_zero_width", seed_seg(1, |c, _, _| *c = c.replace("\"enc\":[1,", "\"enc\":[0,"))),
        ("bad_object_count", seed_seg(1, |_, o, _| *o = o[..o.find("},{").unwrap() + 1].to_string() + "]")),
        ("bad_object_name", seed_seg(1, |_, o, _| *o = o.replace("fuzz_0", "fuzz_7"))),
    ]
}
