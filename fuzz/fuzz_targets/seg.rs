//! Segmenter loader: safetensors + metadata → SegFile → SegEngine → one frame.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = fusepose_fuzz::seg_load(data);
});
