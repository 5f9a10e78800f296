//! The iceoryx2 root directory must not be open to tampering by other users.
//!
//! iceoryx2 keeps its node and service files under the root path (default
//! `/tmp/iceoryx2/`). In a directory every user may write to without the
//! sticky bit, anyone can delete or replace those files (and so redirect or
//! break the daemon's services), so the daemon refuses to start there. The
//! same holds for every existing ancestor: a world-writable parent lets anyone
//! rename the root itself. `/tmp` (mode 1777) is fine.

use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};

/// Why the root path is refused.
#[derive(Debug, thiserror::Error)]
pub enum RootPathError {
    #[error(
        "ipc.root_path = {root:?}: {dir:?} is world-writable without the sticky bit (mode {mode:04o}); \
         any local user could replace iceoryx2's files there: `chmod o-w` or `chmod +t` it, or choose another root_path"
    )]
    WorldWritable { root: PathBuf, dir: PathBuf, mode: u32 },
    #[error("ipc.root_path: {0}")]
    Options(#[from] fusepose_client::ClientError),
}

/// The root path iceoryx2 will use for `options` (its default when unset).
pub fn effective_root(options: &fusepose_client::IpcOptions) -> Result<PathBuf, RootPathError> {
    let config = options.config()?;
    Ok(PathBuf::from(config.global.root_path().to_string()))
}

/// The resource prefix iceoryx2 will use for `options` (its default when unset).
pub fn effective_prefix(options: &fusepose_client::IpcOptions) -> Result<String, RootPathError> {
    Ok(options.config()?.global.prefix.to_string())
}

/// Checks the root path and each existing ancestor (see the module doc).
pub fn check_root_path(root: &Path) -> Result<(), RootPathError> {
    for dir in root.ancestors() {
        // Missing parts are created by iceoryx2 later; only existing ones matter now.
        let Ok(meta) = std::fs::metadata(dir) else { continue };
        let mode = meta.permissions().mode() & 0o7777;
        if meta.is_dir() && mode & 0o002 != 0 && mode & 0o1000 == 0 {
            return Err(RootPathError::WorldWritable { root: root.to_owned(), dir: dir.to_owned(), mode });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chmod(p: &Path, mode: u32) {
        std::fs::set_permissions(p, std::fs::Permissions::from_mode(mode)).unwrap();
    }

    #[test]
    fn world_writable_without_sticky_bit_is_refused_anywhere_on_the_path() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().join("iox2");
        std::fs::create_dir(&root).unwrap();
        chmod(&root, 0o750);
        check_root_path(&root).unwrap();
        // Not created yet: the existing ancestors are checked.
        check_root_path(&root.join("not/yet")).unwrap();

        chmod(&root, 0o777);
        let err = check_root_path(&root).unwrap_err();
        assert!(matches!(&err, RootPathError::WorldWritable { dir, mode: 0o777, .. } if dir == &root), "{err}");
        assert!(err.to_string().starts_with("ipc.root_path"), "{err}");
        chmod(&root, 0o1777);
        check_root_path(&root).unwrap();

        // A world-writable parent without sticky bit is as bad.
        chmod(&root, 0o750);
        chmod(dir.path(), 0o777);
        let err = check_root_path(&root.join("sub")).unwrap_err();
        assert!(matches!(&err, RootPathError::WorldWritable { dir: d, .. } if d == dir.path()), "{err}");
        chmod(dir.path(), 0o700);
    }

    #[test]
    fn default_root_is_iceoryx2s() {
        let root = effective_root(&fusepose_client::IpcOptions::default()).unwrap();
        assert!(root.is_absolute(), "{}", root.display());
        let custom = fusepose_client::IpcOptions { root_path: Some("/run/fp".into()), ..Default::default() };
        assert_eq!(effective_root(&custom).unwrap(), PathBuf::from("/run/fp/"));
        assert_eq!(effective_prefix(&fusepose_client::IpcOptions::default()).unwrap(), "iox2_");
        let custom = fusepose_client::IpcOptions { prefix: Some("fp_".into()), ..Default::default() };
        assert_eq!(effective_prefix(&custom).unwrap(), "fp_");
    }
}
