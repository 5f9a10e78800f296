//! Keeps `client/include/fusepose.h` in sync with the Rust wire types: a C
//! program compiled against the header prints every struct size, field
//! offset and field size and every constant; they must equal the Rust ones.
//! The Rust field lists are also read from the source, so a field added,
//! removed or renamed in Rust without the header fails here.
//!
//! Needs a C compiler (`$CC`, else `cc`); skipped with a message without one.

use std::fmt::Write as _;
use std::mem::{offset_of, size_of};
use std::path::{Path, PathBuf};
use std::process::Command;

use fusepose_client::*;

/// A struct's layout as Rust sees it, with the name of its C mirror.
struct Layout {
    rust: &'static str,
    source: &'static str,
    c: &'static str,
    size: usize,
    /// (field, offset, size) in declaration order.
    fields: Vec<(&'static str, usize, usize)>,
}

fn field_size<T, F>(_: fn(&T) -> &F) -> usize {
    size_of::<F>()
}

macro_rules! layout {
    ($t:ident in $source:literal as $c:literal: $($f:ident),* $(,)?) => {
        Layout {
            rust: stringify!($t),
            source: $source,
            c: $c,
            size: size_of::<$t>(),
            fields: vec![$((stringify!($f), offset_of!($t, $f), field_size(|s: &$t| &s.$f))),*],
        }
    };
}

fn layouts() -> Vec<Layout> {
    vec![
        layout!(PlaneRef in "frame_header.rs" as "fp_plane_ref": offset, len),
        layout!(FrameHeader in "frame_header.rs" as "fp_frame_header":
            magic, format_version, header_size, camera_id, width, height, depth_scale, color_format,
            depth_format, has_labels, label_format, instance_count, _reserved, sequence, capture_time_ns, fx, fy,
            cx, cy, color, depth, labels, instance_classes, _reserved_end),
        layout!(WireObjectPose in "pose_message.rs" as "fp_object_pose":
            class_id, instance_id, refine_iterations, flags, confidence, mask_pixels, bbox, quaternion,
            translation_m, fit_score, depth_residual_m),
        layout!(PoseMessage in "pose_message.rs" as "fp_pose_message":
            format_version, object_count, status, invalid_reason, camera_id, frame_sequence, capture_time_ns,
            received_time_ns, published_time_ns, stage_ns, objects),
        layout!(StatsRequest in "stats.rs" as "fp_stats_request": format_version, _reserved),
        layout!(LatencySummary in "stats.rs" as "fp_latency_summary": count, p50_ns, p90_ns, p99_ns, p999_ns, max_ns),
        layout!(StatsSnapshot in "stats.rs" as "fp_stats_snapshot":
            format_version, _reserved, camera_id, uptime_ns, window_ns, deadline_ns, frames_received,
            frames_processed, frames_skipped_stale, frames_missed_sequence, frames_invalid, invalid_by_reason,
            deadline_misses, estimator_failures, poses_non_finite, producer_restarts, since_start, last_window,
            poses_failed_verification, objects_shed, frames_degraded),
        layout!(CellView in "cell_message.rs" as "fp_cell_view":
            camera_id, instance_id, flags, confidence, offset_m, frame_sequence, capture_time_ns),
        layout!(CellObject in "cell_message.rs" as "fp_cell_object":
            class_id, view_count, flags, reserved, confidence, spread_m, quaternion, translation_m,
            newest_capture_time_ns, oldest_capture_time_ns, views),
        layout!(CellPoseMessage in "cell_message.rs" as "fp_cell_pose_message":
            format_version, object_count, camera_count, truncated, trigger_camera_id, reserved, sequence,
            published_time_ns, objects),
    ]
}

/// (C macro, Rust value) of every constant the header defines.
fn constants() -> Vec<(&'static str, u64)> {
    vec![
        ("FUSEPOSE_WIRE_VERSION", WIRE_VERSION as u64),
        ("FUSEPOSE_FRAME_MAGIC", FRAME_MAGIC as u64),
        ("FUSEPOSE_MAX_OBJECTS", MAX_OBJECTS as u64),
        ("FUSEPOSE_MAX_IMAGE_SIDE", MAX_IMAGE_SIDE as u64),
        ("FUSEPOSE_STAGE_COUNT", STAGE_COUNT as u64),
        ("FUSEPOSE_TIMELINE_COUNT", TIMELINE_COUNT as u64),
        ("FUSEPOSE_INVALID_REASON_COUNT", InvalidReason::COUNT as u64),
        ("FUSEPOSE_COLOR_RGB8", ColorFormat::Rgb8 as u64),
        ("FUSEPOSE_COLOR_BGR8", ColorFormat::Bgr8 as u64),
        ("FUSEPOSE_DEPTH_U16", DepthFormat::U16 as u64),
        ("FUSEPOSE_DEPTH_F32", DepthFormat::F32 as u64),
        ("FUSEPOSE_LABELS_U8", LabelFormat::U8.code() as u64),
        ("FUSEPOSE_LABELS_U16", LabelFormat::U16.code() as u64),
        ("FUSEPOSE_LABELS_INSTANCE_U16", LABELS_INSTANCE_U16 as u64),
        ("FUSEPOSE_STATUS_OK", PoseStatus::OK as u64),
        ("FUSEPOSE_STATUS_INVALID_FRAME", PoseStatus::INVALID_FRAME as u64),
        ("FUSEPOSE_STATUS_DEADLINE_MISSED", PoseStatus::DEADLINE_MISSED as u64),
        ("FUSEPOSE_STATUS_DEGRADED", PoseStatus::DEGRADED as u64),
        ("FUSEPOSE_STATUS_ESTIMATOR_FAILED", PoseStatus::ESTIMATOR_FAILED as u64),
        ("FUSEPOSE_POSE_VERIFIED", PoseFlags::VERIFIED as u64),
        ("FUSEPOSE_POSE_FROM_INSTANCE_LABELS", PoseFlags::FROM_INSTANCE_LABELS as u64),
        ("FUSEPOSE_POSE_CONFIRMED", PoseFlags::CONFIRMED as u64),
        ("FUSEPOSE_MAX_CELL_OBJECTS", MAX_CELL_OBJECTS as u64),
        ("FUSEPOSE_MAX_CELL_VIEWS", MAX_CELL_VIEWS as u64),
        ("FUSEPOSE_CELL_VERIFIED", CellFlags::VERIFIED as u64),
        ("FUSEPOSE_CELL_ROTATION_FROM_BEST_VIEW", CellFlags::ROTATION_FROM_BEST_VIEW as u64),
        ("FUSEPOSE_STAGE_INGEST", Stage::Ingest as u64),
        ("FUSEPOSE_STAGE_SEGMENTATION", Stage::Segmentation as u64),
        ("FUSEPOSE_STAGE_SAMPLING", Stage::Sampling as u64),
        ("FUSEPOSE_STAGE_NETWORK", Stage::Network as u64),
        ("FUSEPOSE_STAGE_REFINE", Stage::Refine as u64),
        ("FUSEPOSE_STAGE_PUBLISH", Stage::Publish as u64),
    ]
}

fn client_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The `pub` field names of `pub struct name { ... }` in a client source file.
fn source_fields(file: &str, name: &str) -> Vec<String> {
    let path = client_dir().join("src").join(file);
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let start = format!("pub struct {name} {{");
    let body = text.split_once(&start).unwrap_or_else(|| panic!("{start} not found in {}", path.display())).1;
    let body = body.split_once("\n}").expect("struct body ends with a closing brace at column 0").0;
    body.lines()
        .filter_map(|l| l.trim().strip_prefix("pub ")?.split_once(':').map(|(f, _)| f.trim().to_owned()))
        .collect()
}

/// The C compiler, or `None` (test skipped) when there is none.
fn c_compiler() -> Option<String> {
    let cc = std::env::var("CC").ok().filter(|c| !c.is_empty()).unwrap_or_else(|| "cc".to_owned());
    match Command::new(&cc).arg("--version").output() {
        Ok(o) if o.status.success() => Some(cc),
        _ => {
            eprintln!("SKIPPED: no C compiler ({cc:?}); install one (e.g. `apt-get install gcc`) to check fusepose.h");
            None
        }
    }
}

/// Compiles `source` (plus extra files) against the header; returns the executable.
fn compile(cc: &str, dir: &Path, name: &str, sources: &[PathBuf]) -> PathBuf {
    let exe = dir.join(name);
    let out = Command::new(cc)
        .args(["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-I"])
        .arg(client_dir().join("include"))
        .args(sources)
        .arg("-o")
        .arg(&exe)
        .output()
        .expect("running the C compiler");
    assert!(out.status.success(), "C compile failed (header out of date?):\n{}", String::from_utf8_lossy(&out.stderr));
    exe
}

fn run(exe: &Path, args: &[&Path]) -> String {
    let out = Command::new(exe).args(args).output().expect("running the C program");
    assert!(out.status.success(), "{} failed: {}", exe.display(), String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).expect("utf-8 output")
}

#[test]
fn rust_field_lists_match_the_source() {
    for l in layouts() {
        let listed: Vec<&str> = l.fields.iter().map(|f| f.0).collect();
        assert_eq!(
            source_fields(l.source, l.rust),
            listed,
            "{}: update this test and client/include/fusepose.h",
            l.rust
        );
        // No padding: every byte of a wire type is a field's.
        assert_eq!(l.fields.iter().map(|f| f.2).sum::<usize>(), l.size, "{} has padding", l.rust);
    }
}

#[test]
fn c_header_matches_rust_layouts_and_constants() {
    let Some(cc) = c_compiler() else { return };
    let dir = tempfile::tempdir().unwrap();
    let mut program = String::from(
        "#include <stddef.h>\n#include <stdio.h>\n#include \"fusepose.h\"\n\
         #define FIELD(T, f) printf(#T \".\" #f \" %zu %zu\\n\", offsetof(T, f), sizeof(((T *)0)->f))\n\
         int main(void) {\n",
    );
    let mut expected = String::new();
    for l in layouts() {
        writeln!(program, "    printf(\"{c} %zu\\n\", sizeof({c}));", c = l.c).unwrap();
        writeln!(expected, "{} {}", l.c, l.size).unwrap();
        for (f, offset, size) in &l.fields {
            writeln!(program, "    FIELD({}, {f});", l.c).unwrap();
            writeln!(expected, "{}.{f} {offset} {size}", l.c).unwrap();
        }
    }
    for (name, value) in constants() {
        writeln!(program, "    printf(\"{name} %llu\\n\", (unsigned long long)({name}));").unwrap();
        writeln!(expected, "{name} {value}").unwrap();
    }
    program.push_str("    return 0;\n}\n");
    let source = dir.path().join("layout.c");
    std::fs::write(&source, program).unwrap();
    let exe = compile(&cc, dir.path(), "layout", &[source]);
    let got = run(&exe, &[]);
    for (g, e) in got.lines().zip(expected.lines()) {
        assert_eq!(g, e, "C (left) and Rust (right) disagree: update client/include/fusepose.h");
    }
    assert_eq!(got.lines().count(), expected.lines().count());
}

#[test]
fn c_example_parses_a_pose_message_written_by_rust() {
    let Some(cc) = c_compiler() else { return };
    let dir = tempfile::tempdir().unwrap();
    let example = client_dir().join("examples/c/pose_consumer.c");
    let exe = compile(&cc, dir.path(), "pose_consumer", &[example]);

    let mut msg = PoseMessage {
        object_count: 2,
        status: PoseStatus::OK,
        camera_id: camera_id("cam0"),
        frame_sequence: 4242,
        capture_time_ns: 1_000_000,
        published_time_ns: 13_500_000,
        ..PoseMessage::default()
    };
    msg.objects[0] = WireObjectPose {
        class_id: 3,
        instance_id: 0,
        flags: PoseFlags::FROM_INSTANCE_LABELS,
        confidence: 0.75,
        quaternion: [0.0, 0.0, 0.6, 0.8],
        translation_m: [0.0125, -0.25, 0.875],
        fit_score: f32::NAN,
        depth_residual_m: f32::NAN,
        ..WireObjectPose::default()
    };
    msg.objects[1] = WireObjectPose {
        class_id: 7,
        instance_id: 1,
        flags: PoseFlags::VERIFIED,
        translation_m: [0.1, 0.2, 1.5],
        fit_score: 0.5,
        depth_residual_m: 0.0025,
        ..msg.objects[0]
    };
    // SAFETY: PoseMessage is #[repr(C)], Copy and has no padding (checked by
    // `rust_field_lists_match_the_source`), so all its bytes are initialised.
    let bytes =
        unsafe { std::slice::from_raw_parts((&msg as *const PoseMessage).cast::<u8>(), size_of::<PoseMessage>()) };
    let file = dir.path().join("poses.bin");
    let mut two = bytes.to_vec();
    two.extend_from_slice(bytes);
    std::fs::write(&file, &two).unwrap();

    let out = run(&exe, &[&file]);
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines[0], "frame 4242 status 0x1 objects 2 latency 12.500 ms", "{out}");
    assert_eq!(
        lines[1],
        "  class 3 instance 0 xyz_mm 12.5 -250.0 875.0 q_xyzw 0.0000 0.0000 0.6000 0.8000 conf 0.75 flags 0x2"
    );
    assert_eq!(
        lines[2],
        "  class 7 instance 1 xyz_mm 100.0 200.0 1500.0 q_xyzw 0.0000 0.0000 0.6000 0.8000 conf 0.75 flags 0x1 \
         fit 0.50 residual_mm 2.5"
    );
    assert_eq!(lines.last(), Some(&"2 messages"));

    // A message of another wire version is refused.
    msg.format_version = WIRE_VERSION + 1;
    // SAFETY: as above.
    let bytes =
        unsafe { std::slice::from_raw_parts((&msg as *const PoseMessage).cast::<u8>(), size_of::<PoseMessage>()) };
    std::fs::write(&file, bytes).unwrap();
    let out = Command::new(&exe).arg(&file).output().unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("not a fusepose"));
}
