//! Configuration reload on SIGHUP: cameras are added, removed or changed
//! while the others keep running with their counters and histograms. The
//! whole change is prepared first (config parsed and checked, new cameras
//! locked and opened, new engines built); if any step fails nothing changes
//! and the running configuration stays. Keys outside the camera list
//! (`[estimator]`, `[ipc]`, `[stats]`, `log_level`) take effect at the next
//! start; a changed one is named in the log.

use std::path::Path;

use fusepose_client::{Ipc, monotonic_ns};

use crate::camera_set::{Camera, EngineCatalog, PreparedUpdate, lock_camera};
use crate::config::DaemonConfig;

/// What opening a camera needs from the running daemon.
pub struct ReloadContext<'a> {
    pub ipc: &'a Ipc,
    pub root: &'a Path,
    pub prefix: &'a str,
    pub node: &'a str,
}

/// Names of the top-level parts that differ but are applied only at start.
fn restart_only_changes(old: &DaemonConfig, new: &DaemonConfig) -> Vec<&'static str> {
    let mut changed = Vec::new();
    if old.estimator != new.estimator {
        changed.push("[estimator]");
    }
    if old.ipc != new.ipc {
        changed.push("[ipc]");
    }
    if old.stats != new.stats {
        changed.push("[stats]");
    }
    if old.log_level != new.log_level {
        changed.push("log_level");
    }
    changed
}

/// Re-reads `path` and applies its camera list to `cameras`; returns the
/// new configuration when applied, `None` when refused (logged).
pub fn reload(
    path: &Path,
    running: &DaemonConfig,
    cameras: &mut Vec<Camera>,
    catalog: &mut EngineCatalog<'_>,
    ctx: &ReloadContext<'_>,
) -> Option<DaemonConfig> {
    tracing::info!(config = %path.display(), "SIGHUP: reloading the configuration");
    let new = match DaemonConfig::load(path) {
        Ok(c) => c,
        Err(e) => {
            tracing::error!("reload refused, the running configuration stays: {e}");
            return None;
        }
    };
    // Estimator overrides of cameras resolve against the running [estimator]
    // (a changed [estimator] needs a restart).
    let mut effective = new.clone();
    effective.estimator = running.estimator.clone();
    let wanted = effective.camera_settings();
    match prepare(&wanted, cameras, catalog, ctx) {
        Ok(plan) => {
            apply(plan, cameras);
            catalog.retain_used(cameras);
        }
        Err(e) => {
            tracing::error!("reload refused, the running configuration stays: {e:#}");
            return None;
        }
    }
    let later = restart_only_changes(running, &new);
    if !later.is_empty() {
        tracing::warn!("reload: {later:?} changed: those keys take effect when fuseposed restarts");
    }
    if running.cell != new.cell {
        tracing::info!("reload: [cell] settings applied");
    }
    tracing::info!(cameras = ?cameras.iter().map(|c| c.state.name.as_str()).collect::<Vec<_>>(), "reload done");
    Some(effective)
}

/// Everything a reload changes, ready to apply.
struct Plan {
    removed: Vec<String>,
    updates: Vec<(usize, PreparedUpdate)>,
    added: Vec<Camera>,
}

fn prepare(
    wanted: &[crate::config::CameraSettings],
    cameras: &[Camera],
    catalog: &mut EngineCatalog<'_>,
    ctx: &ReloadContext<'_>,
) -> anyhow::Result<Plan> {
    let removed = cameras
        .iter()
        .filter(|c| !wanted.iter().any(|w| w.name == c.settings.name))
        .map(|c| c.settings.name.clone())
        .collect();
    let mut updates = Vec::new();
    let mut added = Vec::new();
    for w in wanted {
        match cameras.iter().position(|c| c.settings.name == w.name) {
            Some(i) if cameras[i].settings == *w => {}
            Some(i) => updates.push((i, cameras[i].prepare_update(w, catalog)?)),
            None => {
                let lock = lock_camera(ctx.root, ctx.prefix, ctx.node, &w.name)?;
                added.push(Camera::open(ctx.ipc, lock, w, catalog, monotonic_ns())?);
            }
        }
    }
    Ok(Plan { removed, updates, added })
}

fn apply(plan: Plan, cameras: &mut Vec<Camera>) {
    for (i, update) in plan.updates {
        let name = cameras[i].state.name.clone();
        let changed = cameras[i].apply(update);
        tracing::info!(camera = %name, "reload: camera {name} changed ({changed}); its counters and histograms carry over");
    }
    for name in &plan.removed {
        if let Some(i) = cameras.iter().position(|c| c.settings.name == *name) {
            let cam = cameras.remove(i);
            tracing::info!(camera = %name, "reload: camera {name} removed (final: {})", cam.state.summary_line(false));
        }
    }
    for cam in plan.added {
        tracing::info!(camera = %cam.state.name, "reload: camera {} added", cam.state.name);
        cameras.push(cam);
    }
}
