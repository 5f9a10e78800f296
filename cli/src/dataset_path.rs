//! One rule for every command that opens a BOP dataset (`eval`, `camera`,
//! `train`): `--dataset` names either the dataset root, whose `--split`
//! subfolder is then used, or a split folder itself (the folder holding the
//! `NNNNNN/` scene folders).

use std::path::{Path, PathBuf};

use anyhow::bail;

/// Whether `dir` holds at least one BOP scene folder (`NNNNNN/scene_gt.json`).
pub fn is_split_dir(dir: &Path) -> bool {
    let Ok(entries) = std::fs::read_dir(dir) else { return false };
    entries.flatten().any(|e| {
        let name = e.file_name();
        let name = name.to_string_lossy();
        name.len() == 6 && name.bytes().all(|b| b.is_ascii_digit()) && e.path().join("scene_gt.json").is_file()
    })
}

/// The split folder `path` stands for: `path` itself when it is a split
/// folder, else `path/split`. The error says what was found instead.
pub fn resolve_bop_split(path: &Path, split: &str) -> anyhow::Result<PathBuf> {
    if !path.is_dir() {
        bail!("--dataset {}: no such directory", path.display());
    }
    if is_split_dir(path) {
        return Ok(path.to_path_buf());
    }
    let candidate = path.join(split);
    if is_split_dir(&candidate) {
        return Ok(candidate);
    }
    let mut splits: Vec<String> = std::fs::read_dir(path)?
        .flatten()
        .filter(|e| is_split_dir(&e.path()))
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    splits.sort();
    let found = if splits.is_empty() { "none".to_owned() } else { splits.join(", ") };
    bail!(
        "--dataset {}: neither a BOP split folder (NNNNNN/scene_gt.json inside) nor a dataset root with a `{split}` \
         split (splits found there: {found}); pass the split folder, or the root with --split NAME",
        path.display()
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(dir: &Path) {
        std::fs::create_dir_all(dir.join("000000")).unwrap();
        std::fs::write(dir.join("000000/scene_gt.json"), "{}").unwrap();
    }

    #[test]
    fn root_and_split_folder_resolve_to_the_same_split() {
        let root = tempfile::tempdir().unwrap();
        scene(&root.path().join("test"));
        scene(&root.path().join("train"));
        let test = root.path().join("test");
        assert_eq!(resolve_bop_split(root.path(), "test").unwrap(), test);
        assert_eq!(resolve_bop_split(&test, "test").unwrap(), test);
        // A split folder stands for itself whatever --split says.
        assert_eq!(resolve_bop_split(&test, "train").unwrap(), test);
        assert_eq!(resolve_bop_split(root.path(), "train").unwrap(), root.path().join("train"));
        let err = resolve_bop_split(root.path(), "val").unwrap_err().to_string();
        assert!(err.contains("`val`") && err.contains("test, train"), "{err}");
        let err = resolve_bop_split(&root.path().join("nope"), "test").unwrap_err().to_string();
        assert!(err.contains("no such directory"), "{err}");
    }
}
