//! A segmenter's recorded certainty of real objects (`seg::file::Certainty`):
//! percentiles from peaks, the record in the shipped file, storing a record
//! without touching the tensors, and a bad record refused by name.

use fusepose_estimator::net::NetLoadError;
use fusepose_estimator::seg::SegFile;
use fusepose_estimator::seg::file::{Certainty, KEY_CERTAINTY, store_certainty, with_metadata};

fn shipped() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/builtin.safetensors")
}

#[test]
fn percentiles_come_from_the_peaks_and_quantiles_outside_1_to_50_percent_are_refused() {
    let mut peaks: Vec<f32> = (0..200).rev().map(|i| i as f32 / 200.0).collect();
    let c = Certainty::from_peaks(&mut peaks, 7, "test");
    assert_eq!((c.regions, c.frames, c.percentiles.len()), (200, 7, 50));
    assert_eq!(c.quantile(0.05), Some(10.0 / 200.0));
    assert_eq!(c.quantile(0.5), Some(100.0 / 200.0));
    assert_eq!(c.quantile(0.01), Some(2.0 / 200.0));
    assert_eq!((c.quantile(0.0), c.quantile(0.6)), (None, None));
}

#[test]
fn the_shipped_file_records_its_segmenters_certainty() {
    let c = SegFile::read(&shipped()).unwrap().certainty.expect("the shipped file records the certainty");
    assert!(c.regions >= 1000 && c.frames >= 100, "{c:?}");
    assert!(c.percentiles.is_sorted());
    let floor = c.quantile(fusepose_estimator::seg::file::DEFAULT_CERTAINTY_QUANTILE).unwrap();
    assert!((0.5..0.95).contains(&floor), "default floor {floor}");
}

#[test]
fn a_stored_record_round_trips_and_leaves_the_tensors_alone() {
    let original = SegFile::read(&shipped()).unwrap();
    let path = std::env::temp_dir().join(format!("fusepose-certainty-{}.safetensors", std::process::id()));
    std::fs::copy(shipped(), &path).unwrap();
    let mut peaks = vec![0.25, 0.5, 0.75, 1.0];
    let c = Certainty::from_peaks(&mut peaks, 1, "round trip");
    store_certainty(&path, &c).unwrap();
    let back = SegFile::read(&path).unwrap();
    std::fs::remove_file(&path).ok();
    assert_eq!(back.certainty.as_ref(), Some(&c));
    for (name, _) in original.config.tensor_shapes() {
        assert_eq!(back.tensor(&name).unwrap(), original.tensor(&name).unwrap(), "{name}");
    }
    assert_eq!(back.config, original.config);
}

#[test]
fn a_bad_record_is_refused_naming_its_key() {
    let bytes = std::fs::read(shipped()).unwrap();
    for bad in [
        r#"{"percentiles":[0.5],"regions":1,"frames":1,"data":""}"#.to_owned(),
        format!(r#"{{"percentiles":{:?},"regions":1,"frames":1,"data":""}}"#, vec![1.5f32; 50]),
        "not json".to_owned(),
    ] {
        let err = SegFile::from_bytes(&with_metadata(&bytes, KEY_CERTAINTY, bad.clone()).unwrap()).unwrap_err();
        assert!(matches!(err, NetLoadError::BadMetadata { key: KEY_CERTAINTY, .. }), "{bad}: {err}");
    }
}
