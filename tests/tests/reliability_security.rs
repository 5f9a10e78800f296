//! Security checks of issue 8, against the real `fuseposed` binary: iceoryx2
//! files and shared memory closed to other users, a tamperable root path
//! refused, configuration and weight-file errors at startup naming the key or
//! file.

use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use fusepose_tests::*;

/// Every file and directory under `dir`, with its mode.
fn walk(dir: &Path, out: &mut Vec<(PathBuf, u32)>) -> anyhow::Result<()> {
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        let meta = std::fs::symlink_metadata(entry.path())?;
        out.push((entry.path(), meta.permissions().mode() & 0o7777));
        if meta.is_dir() {
            walk(&entry.path(), out)?;
        }
    }
    Ok(())
}

#[test]
fn shared_memory_and_root_directory_are_closed_to_other_users() -> anyhow::Result<()> {
    let mut env = TestEnv::new("perm")?;
    // A root iceoryx2 creates itself (the harness's own is made by the test with the umask).
    env.iox_root = env.dir.path().join("fresh-root");
    let config = env.write_daemon_config("kind = \"none\"")?;
    let _daemon = start_daemon(&env, &config)?;
    let _producer = start_producer(&env, 0, 30.0, 0, &[])?;
    let consumer = start_consumer(&env, Duration::from_secs(30))?;
    let mut lines = Vec::new();
    assert!(consumer.collect_until(&mut lines, Duration::from_secs(20), |l| !pose_lines(l).is_empty()));

    let root_mode = std::fs::metadata(&env.iox_root)?.permissions().mode() & 0o7777;
    assert_eq!(root_mode & 0o007, 0, "root {} has mode {root_mode:04o}", env.iox_root.display());
    let mut files = Vec::new();
    walk(&env.iox_root, &mut files)?;
    assert!(!files.is_empty(), "iceoryx2 wrote nothing under its root?");
    let shm: Vec<PathBuf> = std::fs::read_dir("/dev/shm")?
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with(&env.prefix))
        .map(|e| e.path())
        .collect();
    assert!(shm.len() >= 4, "expected the frame/pose segments in /dev/shm, found {shm:?}");
    for path in &shm {
        let mode = std::fs::metadata(path)?.permissions().mode() & 0o7777;
        files.push((path.clone(), mode));
    }
    // iceoryx2 0.10 creates its node-id counter segment
    // (`<prefix>…_node.<version>.global_mgmt`) with global access on purpose;
    // `fusepose_client::Ipc::new` narrows it to 0600, so no exception remains.
    assert!(
        files.iter().any(|(p, _)| p.to_string_lossy().ends_with(".global_mgmt")),
        "the node counter segment was not found in /dev/shm: {files:?}"
    );
    for (path, mode) in &files {
        assert_eq!(mode & 0o007, 0, "{} is open to other users: mode {mode:04o}", path.display());
    }

    println!("RESULT checked {} iceoryx2 files and segments; root mode {root_mode:04o}", files.len());
    Ok(())
}

fn run_daemon(env: &TestEnv, config: &Path, check_only: bool) -> anyhow::Result<(Option<i32>, String)> {
    let mut cmd = Command::new(daemon_binary()?);
    cmd.arg("--config").arg(config).current_dir(env.dir.path());
    if check_only {
        cmd.arg("--check");
    }
    let out = cmd.output()?;
    Ok((out.status.code(), String::from_utf8_lossy(&out.stderr).into_owned() + &String::from_utf8_lossy(&out.stdout)))
}

#[test]
fn world_writable_root_without_sticky_bit_is_refused() -> anyhow::Result<()> {
    let env = TestEnv::new("wwroot")?;
    let config = env.write_daemon_config("kind = \"none\"")?;
    std::fs::set_permissions(&env.iox_root, std::fs::Permissions::from_mode(0o777))?;
    let mut daemon = spawn_daemon(&env, &config, Some(&env.dir.path().join("refused.log")))?;
    let status = daemon.wait_timeout(Duration::from_secs(20))?;
    assert!(!status.success(), "fuseposed started on a world-writable root");
    let log = std::fs::read_to_string(env.dir.path().join("refused.log"))?;
    assert!(log.contains("ipc.root_path") && log.contains("sticky"), "{log}");
    // Nothing was created there.
    assert_eq!(std::fs::read_dir(&env.iox_root)?.count(), 0);

    // The same directory with the sticky bit (like /tmp) is accepted.
    std::fs::set_permissions(&env.iox_root, std::fs::Permissions::from_mode(0o1777))?;
    let _daemon = start_daemon(&env, &config)?;
    Ok(())
}

#[test]
fn configuration_errors_stop_startup_and_name_the_key() -> anyhow::Result<()> {
    let env = TestEnv::new("config")?;
    let path = env.dir.path().join("bad.toml");
    for (text, key) in [
        ("deadline = 3\n", "deadline"),
        ("[estimator]\nnum_pionts = 3\n", "num_pionts"),
        ("[stats]\nwindow = 1.0\n", "window"),
        ("[ipc]\nroot = \"/tmp\"\n", "root"),
        ("[estimator]\nnum_points = 0\n", "estimator.num_points"),
        ("[estimator]\nmax_instances = 99\n", "estimator.max_instances"),
        ("deadline_ms = -1.0\n", "deadline_ms"),
        ("[ipc]\ntick_ms = 0\n", "ipc.tick_ms"),
        ("[stats]\nwindow_s = 0.0\n", "stats.window_s"),
        ("cameras = []\n", "cameras"),
        ("[estimator]\nkind = \"magic\"\n", "kind"),
    ] {
        std::fs::write(&path, text)?;
        let (code, output) = run_daemon(&env, &path, true)?;
        assert_eq!(code, Some(2), "{text:?}: {output}");
        assert!(output.contains("configuration error") && output.contains(key), "{text:?} should name {key}: {output}");
    }
    Ok(())
}

/// `models/builtin.safetensors` (in the repository).
fn builtin_weights() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/builtin.safetensors")
}

#[test]
fn unreadable_or_corrupt_weight_files_stop_startup_and_name_the_file() -> anyhow::Result<()> {
    let env = TestEnv::new("weights")?;
    let good = std::fs::read(builtin_weights())?;
    let truncated = good[..good.len() / 2].to_vec();
    // The format tag in the metadata, changed at the same length (the file stays parseable).
    let mut wrong_format = good.clone();
    let at = good.windows(15).position(|w| w == b"fusepose-net-v1").expect("format tag in the builtin file");
    wrong_format[at + 14] = b'9';
    let mut bad_length = good.clone();
    bad_length[..8].copy_from_slice(&u64::MAX.to_le_bytes());
    let dir = env.dir.path().join("a-directory.safetensors");
    std::fs::create_dir(&dir)?;
    let cases: Vec<(&str, Option<Vec<u8>>)> = vec![
        ("truncated.safetensors", Some(truncated)),
        ("wrong-format.safetensors", Some(wrong_format)),
        ("bad-header-length.safetensors", Some(bad_length)),
        ("garbage.safetensors", Some(b"not a weight file".to_vec())),
        ("a-directory.safetensors", None),
    ];
    let config = env.dir.path().join("net.toml");
    for (name, bytes) in cases {
        let file = env.dir.path().join(name);
        if let Some(bytes) = bytes {
            std::fs::write(&file, bytes)?;
        }
        std::fs::write(&config, format!("[estimator]\nkind = \"net\"\nweights = {:?}\n", file))?;
        let (code, output) = run_daemon(&env, &config, true)?;
        assert_eq!(code, Some(2), "{name}: {output}");
        assert!(
            output.contains("estimator.weights") && output.contains(name),
            "{name}: should name key and file: {output}"
        );
    }
    Ok(())
}
