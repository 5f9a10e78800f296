//! Writes the hand-made seeds into `fuzz/corpus/<target>/` (run from `fuzz/`):
//! `cargo run --bin gen_corpus`. Files found by fuzzing are kept alongside.
fn main() -> std::io::Result<()> {
    for (target, seeds) in [
        ("frame", fusepose_fuzz::frame_seeds()),
        ("model", fusepose_fuzz::model_seeds()),
        ("seg", fusepose_fuzz::seg_seeds()),
    ] {
        let dir = std::path::Path::new("corpus").join(target);
        std::fs::create_dir_all(&dir)?;
        for (name, bytes) in seeds {
            std::fs::write(dir.join(name), bytes)?;
        }
    }
    Ok(())
}
