//! One daemon per camera: before serving a camera, `fuseposed` takes an
//! exclusive advisory lock (`flock(2)`) on a file beside iceoryx2's own in
//! the root directory, `<root>/<prefix>fuseposed.<camera>.lock`. A second
//! daemon for the same camera in the same namespace (root path and prefix)
//! refuses to start and names the holder (pid and iceoryx2 node, which the
//! holder writes into the file). The kernel releases the lock when the holder
//! exits in any way — SIGKILL included — so a crashed daemon never blocks its
//! restart; a stale file without a lock on it is simply taken over.

use std::fs::{File, OpenOptions, TryLockError};
use std::io::{Read, Seek, SeekFrom, Write};
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};

/// The lock file of `camera` in the namespace `root` + `prefix`.
pub fn lock_path(root: &Path, prefix: &str, camera: &str) -> PathBuf {
    root.join(format!("{prefix}fuseposed.{camera}.lock"))
}

/// Who holds a camera, as its lock file says.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Holder {
    pub pid: Option<u32>,
    /// iceoryx2 node name and id of the holding daemon.
    pub node: Option<String>,
}

impl std::fmt::Display for Holder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.pid {
            Some(pid) => write!(f, "pid {pid}")?,
            None => write!(f, "a process still starting (pid not written yet)")?,
        }
        if let Some(node) = &self.node {
            write!(f, ", iceoryx2 node {node}")?;
        }
        Ok(())
    }
}

impl Holder {
    fn parse(text: &str) -> Self {
        let field = |key: &str| text.lines().find_map(|l| l.strip_prefix(key)).map(str::trim);
        Self { pid: field("pid=").and_then(|p| p.parse().ok()), node: field("node=").map(str::to_owned) }
    }
}

/// Why a camera could not be locked.
#[derive(Debug, thiserror::Error)]
pub enum CameraLockError {
    #[error(
        "camera {camera} is already served by another fuseposed ({holder}; lock {}): one daemon per camera — \
         stop that daemon first, or give this one other `cameras` or another [ipc] root_path / prefix",
        path.display()
    )]
    Held { camera: String, holder: Holder, path: PathBuf },
    #[error("cannot lock camera {camera} ({}): {source}", path.display())]
    Io { camera: String, path: PathBuf, source: std::io::Error },
}

/// The held lock of one camera; released when dropped (or when the process dies).
#[derive(Debug)]
pub struct CameraLock {
    camera: String,
    path: PathBuf,
    file: File,
}

impl CameraLock {
    /// Takes the lock of `camera` in `root` (which must exist) + `prefix`,
    /// recording this process's pid in it.
    pub fn acquire(root: &Path, prefix: &str, camera: &str) -> Result<Self, CameraLockError> {
        let path = lock_path(root, prefix, camera);
        let io = |source| CameraLockError::Io { camera: camera.to_owned(), path: path.clone(), source };
        // Not truncated on open: the holder's pid must stay readable for the refusal.
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .mode(0o600)
            .open(&path)
            .map_err(io)?;
        match file.try_lock() {
            Ok(()) => {}
            Err(TryLockError::WouldBlock) => {
                let mut text = String::new();
                let _ = file.read_to_string(&mut text);
                return Err(CameraLockError::Held {
                    camera: camera.to_owned(),
                    holder: Holder::parse(&text),
                    path: path.clone(),
                });
            }
            Err(TryLockError::Error(e)) => return Err(io(e)),
        }
        let mut lock = Self { camera: camera.to_owned(), path: path.clone(), file };
        lock.write(&format!("pid={}\ncamera={camera}\n", std::process::id())).map_err(io)?;
        Ok(lock)
    }

    /// Adds the iceoryx2 node (name and id) to the recorded holder.
    pub fn record_node(&mut self, node: &str) -> std::io::Result<()> {
        let text = format!("pid={}\ncamera={}\nnode={node}\n", std::process::id(), self.camera);
        self.write(&text)
    }

    fn write(&mut self, text: &str) -> std::io::Result<()> {
        self.file.set_len(0)?;
        self.file.seek(SeekFrom::Start(0))?;
        self.file.write_all(text.as_bytes())?;
        self.file.flush()
    }

    pub fn path(&self) -> &Path {
        &self.path
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_lock_names_the_holder_and_a_dropped_lock_is_free_again() {
        let dir = tempfile::tempdir().unwrap();
        let mut first = CameraLock::acquire(dir.path(), "iox2_", "cam0").unwrap();
        first.record_node("fuseposed (0x1234)").unwrap();
        // flock locks belong to the open file description: a second open in
        // this process conflicts exactly like another process would.
        let err = CameraLock::acquire(dir.path(), "iox2_", "cam0").unwrap_err();
        match &err {
            CameraLockError::Held { camera, holder, .. } => {
                assert_eq!(camera, "cam0");
                assert_eq!(holder.pid, Some(std::process::id()));
                assert_eq!(holder.node.as_deref(), Some("fuseposed (0x1234)"));
            }
            other => panic!("{other}"),
        }
        let text = err.to_string();
        assert!(text.contains("camera cam0") && text.contains(&format!("pid {}", std::process::id())), "{text}");
        // Other cameras and other prefixes are independent.
        let _cam1 = CameraLock::acquire(dir.path(), "iox2_", "cam1").unwrap();
        let _other = CameraLock::acquire(dir.path(), "mine_", "cam0").unwrap();
        drop(first);
        let again = CameraLock::acquire(dir.path(), "iox2_", "cam0").unwrap();
        assert_eq!(
            std::fs::read_to_string(again.path()).unwrap(),
            format!("pid={}\ncamera=cam0\n", std::process::id())
        );
        let mode = std::os::unix::fs::PermissionsExt::mode(&std::fs::metadata(again.path()).unwrap().permissions());
        assert_eq!(mode & 0o077, 0, "lock file mode {mode:o}");
    }

    #[test]
    fn holder_text_is_parsed_leniently() {
        assert_eq!(Holder::parse(""), Holder::default());
        assert_eq!(Holder::parse("pid=42\nnode=x y\n"), Holder { pid: Some(42), node: Some("x y".into()) });
        assert_eq!(Holder::parse("pid=garbage"), Holder::default());
        assert!(Holder::default().to_string().contains("pid not written yet"));
    }
}
