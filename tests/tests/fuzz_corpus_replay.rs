//! Replays the fuzz corpora (`fuzz/corpus/<target>/`) through the fuzz
//! harness functions on stable, on every `cargo test --workspace`.
//!
//! The harnesses (`fuzz/src/lib.rs`, included here by path) panic when the
//! code under test panics or breaks an asserted invariant; this test runs every
//! corpus file through them and, for the hand-made seeds, also checks the
//! outcome their name promises (`valid_n<k>_*`, `refused_*`, `reject_*`,
//! `bad_*`). Seeds are regenerated with `cargo run --bin gen_corpus` in `fuzz/`
//! (or `FUSEPOSE_WRITE_SEEDS=1` on this test); the test below also checks that
//! the files on disk match the generator.

#[path = "../../fuzz/src/lib.rs"]
mod harness;

use std::path::{Path, PathBuf};

use harness::{FrameOutcome, ModelOutcome, SegOutcome};

fn corpus(target: &str) -> Vec<(String, Vec<u8>)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/corpus").join(target);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    assert!(!files.is_empty(), "{} is empty", dir.display());
    files
        .into_iter()
        .map(|p| (p.file_name().unwrap().to_string_lossy().into_owned(), std::fs::read(&p).unwrap()))
        .collect()
}

#[test]
fn frame_corpus_replays_without_panics_and_seeds_keep_their_outcome() {
    let files = corpus("frame");
    let (mut prepared, mut rejected) = (0, 0);
    for (name, bytes) in &files {
        let outcome = harness::frame_path(bytes);
        match &outcome {
            FrameOutcome::Prepared(_) => prepared += 1,
            FrameOutcome::Rejected(_) => rejected += 1,
            _ => {}
        }
        if let Some(rest) = name.strip_prefix("valid_n") {
            let k: usize = rest.split('_').next().unwrap().parse().unwrap();
            assert_eq!(outcome, FrameOutcome::Prepared(k), "{name}");
        } else if name.starts_with("refused_") {
            assert!(matches!(outcome, FrameOutcome::Refused(_)), "{name}: {outcome:?}");
        } else if name.starts_with("reject_") {
            assert!(matches!(outcome, FrameOutcome::Rejected(_)), "{name}: {outcome:?}");
        }
    }
    assert!(prepared >= 5 && rejected >= 10, "{prepared} prepared, {rejected} rejected");
}

#[test]
fn frame_seed_rejections_name_their_reason() {
    use fusepose_client::InvalidReason as R;
    let expect = [
        ("reject_bad_magic", R::BadMagic),
        ("reject_version", R::VersionMismatch),
        ("reject_wrong_camera", R::WrongCamera),
        ("reject_bad_size", R::BadSize),
        ("reject_too_large", R::BadSize),
        ("reject_unknown_format", R::UnknownFormat),
        ("reject_label_flag", R::UnknownFormat),
        ("reject_bad_intrinsics", R::BadFocalLength),
        ("reject_tiny_fx", R::BadFocalLength),
        ("reject_principal_point", R::BadPrincipalPoint),
        ("reject_labels_missing", R::LabelsMissing),
        ("reject_depth_scale", R::BadDepthScale),
        ("reject_plane_out_of_bounds", R::PlaneOutOfBounds),
        ("reject_plane_length", R::PlaneLength),
        ("reject_plane_misaligned", R::PlaneMisaligned),
        ("reject_plane_overlap", R::PlaneOverlap),
        ("reject_truncated", R::PayloadTruncated),
        ("reject_instance_table_missing", R::InstanceTableMissing),
        ("reject_instance_table_length", R::InstanceTableLength),
        ("reject_instance_table_misaligned", R::InstanceTableMisaligned),
        ("reject_instance_without_has_labels", R::InstanceLabelsInconsistent),
        ("reject_instance_count_on_class_labels", R::InstanceLabelsInconsistent),
    ];
    let seeds = harness::frame_seeds();
    for (name, reason) in expect {
        let (_, bytes) = seeds.iter().find(|(n, _)| *n == name).unwrap();
        assert_eq!(harness::frame_path(bytes), FrameOutcome::Rejected(reason), "{name}");
    }
    // Decoded, then refused by the daemon's content check with its own reason.
    use fusepose_estimator::FrameError as F;
    for (name, check) in [
        ("refused_all_zero_depth", (|e: &F| *e == F::DepthEmpty) as fn(&F) -> bool),
        ("refused_all_nan_depth", |e| matches!(e, F::DepthNonFinite { values: 48 })),
        ("refused_unknown_class", |e| *e == F::LabelOutOfRange { max: 9, num_classes: 5 }),
        ("refused_instance_class_unknown", |e| {
            *e == F::InstanceClassUnknown { id: 3, class: 9, num_classes: 5, u: 5, v: 3 }
        }),
        ("refused_instance_without_class", |e| {
            *e == F::InstanceClassUnknown { id: 2, class: 0, num_classes: 5, u: 2, v: 1 }
        }),
        ("refused_instance_beyond_table", |e| *e == F::InstanceBeyondTable { id: 4, entries: 4, u: 7, v: 0 }),
    ] {
        let (_, bytes) = seeds.iter().find(|(n, _)| *n == name).unwrap();
        match harness::frame_path(bytes) {
            FrameOutcome::Refused(e) => assert!(check(&e), "{name}: {e:?}"),
            other => panic!("{name}: {other:?}"),
        }
    }
    // Anything shorter than a header is not a frame at all.
    assert_eq!(harness::frame_path(&[0; 127]), FrameOutcome::TooShort);
}

#[test]
fn model_corpus_replays_without_panics_and_seeds_keep_their_outcome() {
    let files = corpus("model");
    let mut loaded = 0;
    for (name, bytes) in &files {
        let outcome = harness::model_load(bytes);
        if let ModelOutcome::Loaded { .. } = outcome {
            loaded += 1;
        }
        if name.starts_with("valid_") {
            assert!(matches!(outcome, ModelOutcome::Loaded { poses: 1 }), "{name}: {outcome:?}");
        } else if name.starts_with("bad_") {
            assert!(matches!(outcome, ModelOutcome::Refused(_)), "{name}: {outcome:?}");
        }
    }
    assert!(loaded >= 2, "{loaded} loaded");
}

#[test]
fn model_seed_errors_are_the_specific_ones() {
    use fusepose_estimator::net::NetLoadError as E;
    let seeds = harness::model_seeds();
    let outcome = |name: &str| {
        let (_, bytes) = seeds.iter().find(|(n, _)| *n == name).unwrap();
        match harness::model_load(bytes) {
            ModelOutcome::Refused(e) => e,
            other => panic!("{name}: {other:?}"),
        }
    };
    assert!(matches!(outcome("bad_truncated"), E::Format(_)));
    assert!(matches!(outcome("bad_header_length"), E::Format(_)));
    assert!(matches!(outcome("bad_empty"), E::Format(_)));
    assert!(matches!(outcome("bad_wrong_shape"), E::WrongShape { .. }));
    assert!(matches!(outcome("bad_missing_tensor"), E::MissingTensor(_)));
    assert!(matches!(outcome("bad_config_json"), E::BadMetadata { .. }));
    assert!(matches!(outcome("bad_zero_width"), E::BadMetadata { .. }));
    assert!(matches!(outcome("bad_crop_not_div4"), E::BadMetadata { .. }));
    assert!(matches!(outcome("bad_object_count"), E::BadMetadata { .. }));
    assert!(matches!(outcome("bad_object_name"), E::ObjectMismatch { what: "name", .. }));
    assert!(matches!(outcome("bad_object_hash"), E::ObjectMismatch { .. }));
}

#[test]
fn seg_corpus_replays_without_panics_and_seeds_keep_their_outcome() {
    let mut segmented = 0;
    for (name, bytes) in &corpus("seg") {
        let outcome = harness::seg_load(bytes);
        if let SegOutcome::Segmented { .. } = outcome {
            segmented += 1;
        }
        if name.starts_with("valid_") {
            assert!(matches!(outcome, SegOutcome::Segmented { .. }), "{name}: {outcome:?}");
        } else if name.starts_with("bad_") {
            assert!(matches!(outcome, SegOutcome::Refused(_)), "{name}: {outcome:?}");
        }
    }
    assert!(segmented >= 2, "{segmented} segmented");
}

/// With `FUSEPOSE_WRITE_SEEDS=1` the seeds are written instead (what
/// `cargo run --bin gen_corpus` in `fuzz/` does, without building the fuzz crate).
#[test]
fn seed_files_match_the_generator() {
    for (target, seeds) in
        [("frame", harness::frame_seeds()), ("model", harness::model_seeds()), ("seg", harness::seg_seeds())]
    {
        if std::env::var_os("FUSEPOSE_WRITE_SEEDS").is_some_and(|v| v == "1") {
            let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/corpus").join(target);
            for (name, bytes) in &seeds {
                std::fs::write(dir.join(name), bytes).unwrap();
            }
        }
        let on_disk = corpus(target);
        for (name, bytes) in seeds {
            let file = on_disk.iter().find(|(n, _)| n == name);
            let file = file.unwrap_or_else(|| panic!("fuzz/corpus/{target}/{name} is missing; run gen_corpus"));
            assert!(file.1 == bytes, "fuzz/corpus/{target}/{name} differs from the generator; run gen_corpus");
        }
    }
}

#[test]
fn corpora_stay_small() {
    for target in ["frame", "model", "seg"] {
        let files = corpus(target);
        let total: usize = files.iter().map(|(_, b)| b.len()).sum();
        assert!(files.len() <= 60 && total <= 256 * 1024, "{target}: {} files, {total} bytes", files.len());
    }
}
