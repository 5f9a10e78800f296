//! Model loader: safetensors + metadata → WeightFile → NetEstimator → one tiny frame.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = fusepose_fuzz::model_load(data);
});
