//! [`NetEstimator`]: the fusion network as an [`Estimator`].
//!
//! Per instance: colour branch → pose net → the most confident point's pose →
//! up to `refine_iterations` refiner steps. With `threads = 2` a persistent
//! worker thread (started at load, never per frame) takes every second
//! instance of a frame, with its own scratch buffers. Buffers are sized at load
//! from the network config and re-sized only if a workspace with another N, S
//! or instance capacity shows up (the warm-up frame), so steady-state frames
//! do not allocate.

use std::path::Path;
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;

use fusepose_scene::ObjectSet;
use nalgebra::{UnitQuaternion, Vector3};
use ndarray::s;

use super::engine::{Engine, Scratch, quat_matrix, unit_quat};
use super::weights::{NetLoadError, WeightFile};
use crate::{EstimateError, Estimator, FrameView, ObjectPose, PoseSet, Workspace, WorkspaceConfig};

/// Load-time options.
#[derive(Clone, Copy, Debug)]
pub struct NetOptions {
    /// Refiner iterations per object (`None`: the file's default).
    pub refine_iterations: Option<usize>,
    /// Threads per frame: 1 (caller only) or 2 (caller + one persistent worker).
    pub threads: usize,
}

impl Default for NetOptions {
    fn default() -> Self {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        Self {
            refine_iterations: None,
            threads: cores.clamp(1, 2),
        }
    }
}

/// Runs instance `i` of `ws` through the network.
fn estimate_instance(
    engine: &Engine,
    sc: &mut Scratch,
    ws: &Workspace,
    i: usize,
    iters: usize,
) -> ObjectPose {
    let inst = ws.instances[i];
    let k = inst.class_id as usize - 1;
    engine.set_inputs(
        sc,
        ws.crops.slice(s![i, .., .., ..]),
        ws.points.slice(s![i, .., ..]),
        ws.choose.slice(s![i, ..]),
    );
    engine.color(sc);
    let best = engine.pose(sc, k);
    let q = [
        sc.quat[[best, 0]],
        sc.quat[[best, 1]],
        sc.quat[[best, 2]],
        sc.quat[[best, 3]],
    ];
    let confidence = sc.conf[[best, 0]];
    let mut rot = quat_matrix(q);
    let mut t = Vector3::new(
        sc.trans[[best, 0]],
        sc.trans[[best, 1]],
        sc.trans[[best, 2]],
    );
    let mut rotation = unit_quat(q);
    if iters > 0 {
        engine.refine_color(sc);
        for _ in 0..iters {
            (rot, t) = engine.refine(sc, k, &rot, &t);
        }
        // Bounded: `from_matrix` iterates until convergence, which never comes
        // for a non-finite matrix (e.g. from NaN weights), and hung `estimate`
        // forever (found with the `model` fuzz harness, docs/RELIABILITY.md).
        rotation = UnitQuaternion::from_matrix_eps(
            &rot.cast::<f64>(),
            f64::EPSILON,
            1000,
            UnitQuaternion::identity(),
        );
    }
    ObjectPose {
        class_id: inst.class_id,
        instance_id: i as u16,
        rotation,
        translation: t.cast::<f64>(),
        confidence,
        mask_pixels: inst.pixels,
        bbox: inst.bbox,
        iterations: iters as u16,
    }
}

/// A frame's share of work for the worker: instances `1, 3, 5, …` of `*ws`.
struct Task {
    ws: *const Workspace,
    iters: usize,
}

// SAFETY: the caller blocks until the worker reports the task done (also when
// unwinding, see `WaitGuard`), so `*ws` outlives every access; `Workspace` is
// plain data read concurrently by both threads and written by neither.
unsafe impl Send for Task {}

enum Msg {
    Run(Task),
    /// New buffer sizes (N, S, instance capacity).
    Resize(usize, usize, usize),
    Stop,
}

/// A one-element hand-over slot on a std `Mutex` + `Condvar` (futex based:
/// blocking and waking never allocate, unlike a channel's waker lists).
struct Slot<T> {
    value: Mutex<Option<T>>,
    cv: Condvar,
}

impl<T> Slot<T> {
    fn new() -> Self {
        Self {
            value: Mutex::new(None),
            cv: Condvar::new(),
        }
    }

    fn put(&self, t: T) {
        let mut g = self.value.lock().unwrap_or_else(|e| e.into_inner());
        while g.is_some() {
            g = self.cv.wait(g).unwrap_or_else(|e| e.into_inner());
        }
        *g = Some(t);
        self.cv.notify_all();
    }

    fn take(&self) -> T {
        let mut g = self.value.lock().unwrap_or_else(|e| e.into_inner());
        loop {
            if let Some(t) = g.take() {
                self.cv.notify_all();
                return t;
            }
            g = self.cv.wait(g).unwrap_or_else(|e| e.into_inner());
        }
    }
}

/// The caller ↔ worker hand-over: a message slot, a "done" slot (true = ok,
/// false = the worker panicked) and the worker's poses.
struct Shared {
    msg: Slot<Msg>,
    done: Slot<bool>,
    results: Mutex<Vec<ObjectPose>>,
}

struct Worker {
    shared: Arc<Shared>,
    handle: Option<JoinHandle<()>>,
}

impl Worker {
    fn spawn(engine: Arc<Engine>, n: usize, s: usize, cap: usize) -> Option<Self> {
        let shared = Arc::new(Shared {
            msg: Slot::new(),
            done: Slot::new(),
            results: Mutex::new(Vec::with_capacity(cap)),
        });
        let sh = shared.clone();
        let handle = std::thread::Builder::new()
            .name("fusepose-net".into())
            .spawn(move || {
                let mut sc = Scratch::new(&engine.config, n, s);
                loop {
                    match sh.msg.take() {
                        Msg::Run(task) => {
                            let ok = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                                // SAFETY: see `Task`.
                                let ws = unsafe { &*task.ws };
                                let mut out = sh.results.lock().unwrap_or_else(|e| e.into_inner());
                                out.clear();
                                for i in (1..ws.instances.len()).step_by(2) {
                                    out.push(estimate_instance(
                                        &engine, &mut sc, ws, i, task.iters,
                                    ));
                                }
                            }))
                            .is_ok();
                            sh.done.put(ok);
                        }
                        Msg::Resize(n, s, cap) => {
                            sc = Scratch::new(&engine.config, n, s);
                            sh.results
                                .lock()
                                .unwrap_or_else(|e| e.into_inner())
                                .reserve(cap);
                            sh.done.put(true);
                        }
                        Msg::Stop => break,
                    }
                }
            })
            .ok()?;
        Some(Self {
            shared,
            handle: Some(handle),
        })
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        self.shared.msg.put(Msg::Stop);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

/// Waits for the worker's "done" even if the caller unwinds mid-frame; holds its verdict.
struct WaitGuard<'a> {
    shared: &'a Shared,
    ok: Option<bool>,
}

impl WaitGuard<'_> {
    fn wait(mut self) -> bool {
        let ok = self.shared.done.take();
        self.ok = Some(ok);
        ok
    }
}

impl Drop for WaitGuard<'_> {
    fn drop(&mut self) {
        if self.ok.is_none() {
            let _ = self.shared.done.take();
        }
    }
}

/// The fusion-network estimator.
pub struct NetEstimator {
    engine: Arc<Engine>,
    file: WeightFile,
    scratch: Scratch,
    worker: Option<Worker>,
    /// Sizes the buffers were made for: (N, S, max instances).
    sizes: (usize, usize, usize),
    mine: Vec<ObjectPose>,
    refine_iterations: usize,
    frame_cap: Option<usize>,
}

impl NetEstimator {
    /// Loads a weight file and checks it against `objects` (names, symmetries,
    /// diameters, mesh hashes, in class order).
    pub fn load(
        path: &Path,
        objects: &ObjectSet,
        options: NetOptions,
    ) -> Result<Self, NetLoadError> {
        let file = WeightFile::read(path)?;
        Self::from_file(file, objects, options)
    }

    /// As [`NetEstimator::load`], from an already parsed file.
    pub fn from_file(
        file: WeightFile,
        objects: &ObjectSet,
        options: NetOptions,
    ) -> Result<Self, NetLoadError> {
        file.check_objects(objects)?;
        let engine = Arc::new(Engine::new(&file)?);
        let c = &engine.config;
        let (n, s, cap) = (c.num_points, c.crop_size, 8);
        let scratch = Scratch::new(c, n, s);
        let refine_iterations = options.refine_iterations.unwrap_or(c.refine_iters);
        let worker = if options.threads >= 2 {
            Worker::spawn(engine.clone(), n, s, cap)
        } else {
            None
        };
        Ok(Self {
            engine,
            file,
            scratch,
            worker,
            sizes: (n, s, cap),
            mine: Vec::with_capacity(cap),
            refine_iterations,
            frame_cap: None,
        })
    }

    /// The weight file (config, objects, training record).
    pub fn weights(&self) -> &WeightFile {
        &self.file
    }

    pub fn engine(&self) -> &Engine {
        &self.engine
    }

    /// Threads used per frame (1 or 2).
    pub fn threads(&self) -> usize {
        if self.worker.is_some() { 2 } else { 1 }
    }

    /// The workspace sizes the network was trained with (N points, S crop).
    pub fn workspace_config(&self, max_instances: usize) -> WorkspaceConfig {
        let c = &self.engine.config;
        WorkspaceConfig {
            max_instances,
            num_points: c.num_points,
            crop_size: c.crop_size,
            num_classes: c.num_classes as u16,
            ..WorkspaceConfig::default()
        }
    }

    /// Refiner iterations per object from now on.
    pub fn set_refine_iterations(&mut self, n: usize) {
        self.refine_iterations = n;
    }

    pub fn refine_iterations(&self) -> usize {
        self.refine_iterations
    }

    /// Caps refiner iterations for the next frame only (e.g. when the daemon is
    /// behind its deadline); cleared after that frame.
    pub fn cap_next_frame(&mut self, max_refine_iterations: usize) {
        self.frame_cap = Some(max_refine_iterations);
    }

    fn fit(&mut self, ws: &Workspace) {
        let want = (
            ws.config.num_points,
            ws.config.crop_size,
            ws.config.max_instances,
        );
        if want == self.sizes {
            return;
        }
        let (n, s, cap) = want;
        if (n, s) != (self.sizes.0, self.sizes.1) {
            self.scratch = Scratch::new(&self.engine.config, n, s);
        }
        self.mine.reserve(cap);
        if let Some(w) = &self.worker {
            w.shared.msg.put(Msg::Resize(n, s, cap));
            w.shared.done.take();
        }
        self.sizes = want;
    }
}

impl Estimator for NetEstimator {
    fn name(&self) -> &str {
        "net"
    }

    fn cap_next_frame(&mut self, max_iterations: usize) {
        NetEstimator::cap_next_frame(self, max_iterations);
    }

    fn estimate(
        &mut self,
        _frame: &FrameView<'_>,
        ws: &mut Workspace,
        out: &mut PoseSet,
    ) -> Result<(), EstimateError> {
        out.clear();
        let iters = self
            .frame_cap
            .take()
            .map_or(self.refine_iterations, |c| c.min(self.refine_iterations));
        let k_max = self.engine.config.num_classes;
        if let Some(bad) = ws
            .instances
            .iter()
            .find(|i| i.class_id == 0 || i.class_id as usize > k_max)
        {
            return Err(EstimateError::UnknownClass(bad.class_id));
        }
        self.fit(ws);
        let count = ws.instances.len();
        let ws: &Workspace = ws;
        self.mine.clear();
        if count >= 2
            && let Some(w) = self.worker.as_ref()
        {
            w.shared.msg.put(Msg::Run(Task { ws, iters }));
            let guard = WaitGuard {
                shared: &w.shared,
                ok: None,
            };
            for i in (0..count).step_by(2) {
                self.mine.push(estimate_instance(
                    &self.engine,
                    &mut self.scratch,
                    ws,
                    i,
                    iters,
                ));
            }
            let ok = guard.wait();
            let theirs = w.shared.results.lock().unwrap_or_else(|e| e.into_inner());
            if ok && theirs.len() == count / 2 {
                for i in 0..count {
                    out.push(if i % 2 == 0 {
                        self.mine[i / 2]
                    } else {
                        theirs[i / 2]
                    });
                }
                return Ok(());
            }
            // The worker panicked: this frame and later ones run on the caller's thread.
            drop(theirs);
            self.worker = None;
            out.clear();
        }
        for i in 0..count {
            out.push(estimate_instance(
                &self.engine,
                &mut self.scratch,
                ws,
                i,
                iters,
            ));
        }
        Ok(())
    }
}
