//! Child processes of the benchmark binary: the same executable started with
//! a hidden subcommand, which prints `ready` once its ports are open. Killed
//! (by process id) when dropped, so a failed run leaves nothing behind.

use std::io::{BufRead, BufReader};
use std::process::{Child, ChildStdout, Command, Stdio};
use std::sync::mpsc::{Receiver, channel};
use std::time::Duration;

/// A running child and the lines of its stdout.
pub struct ChildProcess {
    pub name: &'static str,
    child: Child,
    lines: Receiver<String>,
}

impl ChildProcess {
    /// Starts this executable with `args` (and extra environment) and waits up
    /// to `ready_timeout` for it to print `ready`.
    pub fn spawn(
        name: &'static str,
        args: &[String],
        env: &[(&str, String)],
        ready_timeout: Duration,
    ) -> anyhow::Result<Self> {
        let mut cmd = Command::new(std::env::current_exe()?);
        cmd.args(args).stdout(Stdio::piped()).stderr(Stdio::inherit());
        for (k, v) in env {
            cmd.env(k, v);
        }
        let mut child = cmd.spawn().map_err(|e| anyhow::anyhow!("cannot start {name}: {e}"))?;
        let stdout: ChildStdout = child.stdout.take().ok_or_else(|| anyhow::anyhow!("{name}: no stdout"))?;
        let (tx, lines) = channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        let mut me = Self { name, child, lines };
        me.expect_line("ready", ready_timeout)?;
        Ok(me)
    }

    /// Waits for a line starting with `prefix`; returns the rest of it.
    pub fn expect_line(&mut self, prefix: &str, timeout: Duration) -> anyhow::Result<String> {
        let deadline = std::time::Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(line) if line.starts_with(prefix) => {
                    return Ok(line[prefix.len()..].trim().to_owned());
                }
                Ok(_) => continue,
                Err(_) => anyhow::bail!("{}: no `{prefix}` line within {timeout:?}", self.name),
            }
        }
    }

    /// Waits up to `timeout` for the child to exit by itself; kills it otherwise.
    pub fn finish(mut self, timeout: Duration) -> anyhow::Result<std::process::ExitStatus> {
        let deadline = std::time::Instant::now() + timeout;
        loop {
            if let Some(status) = self.child.try_wait()? {
                return Ok(status);
            }
            if std::time::Instant::now() >= deadline {
                anyhow::bail!("{} did not exit within {timeout:?}", self.name);
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// The child's process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Asks the child to stop with SIGINT (the daemon then writes its summary).
    pub fn interrupt(&self) {
        // SAFETY: plain kill(2) on our own child's pid.
        unsafe {
            libc::kill(self.child.id() as libc::pid_t, libc::SIGINT);
        }
    }
}

impl Drop for ChildProcess {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// A private iceoryx2 namespace (root directory and prefix) for one run;
/// removes its shared-memory objects when dropped.
pub struct IpcNamespace {
    pub dir: std::path::PathBuf,
    pub root: std::path::PathBuf,
    pub prefix: String,
}

impl IpcNamespace {
    pub fn new(tag: &str) -> anyhow::Result<Self> {
        let dir = std::env::temp_dir().join(format!("fusepose-bench-{tag}-{}", std::process::id()));
        let root = dir.join("iox2");
        std::fs::create_dir_all(&root)?;
        Ok(Self { dir, root, prefix: format!("fpb{}{tag}_", std::process::id()) })
    }

    pub fn options(&self) -> fusepose_client::IpcOptions {
        fusepose_client::IpcOptions {
            root_path: Some(self.root.clone()),
            prefix: Some(self.prefix.clone()),
            ..Default::default()
        }
    }

    /// The environment that puts a child process in this namespace.
    pub fn env(&self) -> Vec<(&'static str, String)> {
        vec![("FUSEPOSE_IOX2_ROOT", self.root.display().to_string()), ("FUSEPOSE_IOX2_PREFIX", self.prefix.clone())]
    }
}

impl Drop for IpcNamespace {
    fn drop(&mut self) {
        if let Ok(entries) = std::fs::read_dir("/dev/shm") {
            for entry in entries.flatten() {
                if entry.file_name().to_string_lossy().starts_with(&self.prefix) {
                    let _ = std::fs::remove_file(entry.path());
                }
            }
        }
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}
