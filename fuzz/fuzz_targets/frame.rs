//! Frame path: header + payload decode → FrameView → validate → Workspace::prepare.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = fusepose_fuzz::frame_path(data);
});
