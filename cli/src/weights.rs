//! The network weights a command runs: `--weights FILE`, else the shipped
//! `models/builtin.safetensors` of the working directory (the path the
//! daemon's configuration defaults to), else the copy of it compiled into
//! this binary, so every command that runs the network works from any
//! directory without flags.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};

/// The shipped weights as built into this binary.
pub static BUILTIN_WEIGHTS: &[u8] = include_bytes!("../../models/builtin.safetensors");

/// Where the shipped weights lie in a checkout (relative to its root).
pub const SHIPPED_WEIGHTS: &str = "models/builtin.safetensors";

/// The help text of every `--weights` flag.
pub const WEIGHTS_HELP: &str =
    "Network weights (safetensors) [default: models/builtin.safetensors, else the copy built into this binary]";

/// `given`, which must exist, or the shipped weights (see the module doc).
pub fn resolve_weights(given: Option<&Path>) -> anyhow::Result<PathBuf> {
    match given {
        Some(path) if path.is_file() => Ok(path.to_path_buf()),
        Some(path) => bail!("--weights {}: no such file", path.display()),
        None if Path::new(SHIPPED_WEIGHTS).is_file() => Ok(PathBuf::from(SHIPPED_WEIGHTS)),
        None => builtin_copy(&std::env::temp_dir()),
    }
}

/// The built-in weights as a file in `dir`, named by their hash (written
/// once, through a temporary name, so concurrent commands never read half a file).
fn builtin_copy(dir: &Path) -> anyhow::Result<PathBuf> {
    let hash =
        BUILTIN_WEIGHTS.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| (h ^ b as u64).wrapping_mul(0x100_0000_01b3));
    let path = dir.join(format!("fusepose-builtin-{hash:016x}.safetensors"));
    if std::fs::metadata(&path).is_ok_and(|m| m.len() == BUILTIN_WEIGHTS.len() as u64) {
        return Ok(path);
    }
    let partial = dir.join(format!("fusepose-builtin-{hash:016x}.{}.part", std::process::id()));
    std::fs::write(&partial, BUILTIN_WEIGHTS).with_context(|| format!("writing {}", partial.display()))?;
    std::fs::rename(&partial, &path).with_context(|| format!("writing {}", path.display()))?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn given_weights_must_exist_and_the_builtin_copy_is_complete() {
        let err = resolve_weights(Some(Path::new("/nonexistent/w.safetensors"))).unwrap_err().to_string();
        assert!(err.contains("no such file"), "{err}");
        let dir = tempfile::tempdir().unwrap();
        let a = builtin_copy(dir.path()).unwrap();
        let b = builtin_copy(dir.path()).unwrap();
        assert_eq!(a, b);
        assert_eq!(std::fs::read(&a).unwrap(), BUILTIN_WEIGHTS);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1, "no partial file left");
    }
}
