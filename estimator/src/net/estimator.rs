//! [`NetEstimator`]: the fusion network as an [`Estimator`].
//!
//! Per instance: colour branch → pose net → the most confident point's pose →
//! up to `refine_iterations` refiner steps. With `threads = 2` a persistent
//! worker thread (started at load, never per frame) takes every second
//! instance of a frame, with its own scratch buffers. Buffers are sized at load
//! from the network config and re-sized only if a workspace with another N, S
//! or instance capacity shows up (the warm-up frame), so steady-state frames
//! do not allocate.
//!
//! Deadlines ([`Estimator::set_deadline`]): a frame plan from the learned
//! per-stage costs ([`super::budget`]) picks the refiner iterations (then the
//! points) that fit the remaining time, and each refiner iteration checks the
//! clock again. Tracking ([`crate::tracking`], optional): an object with a
//! good fit in the previous frame starts the refiner from that pose and skips
//! the pose net while the fit stays good.

use std::path::Path;
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use fusepose_scene::ObjectSet;
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use ndarray::s;

use super::budget::{self, CostModel, FramePlan, ObjectTimes};
use super::engine::{Engine, Scratch, quat_matrix, unit_quat};
use super::shed_order::ShedOrder;
use super::weights::{NetLoadError, WeightFile};
use crate::tracking::{FitCheck, Prior, TrackOutcome, TrackingConfig, Tracks};
use crate::{EstimateError, Estimator, FrameView, ObjectPose, PoseSet, Workspace, WorkspaceConfig};

/// Load-time options.
#[derive(Clone, Copy, Debug)]
pub struct NetOptions {
    /// Refiner iterations per object (`None`: the file's default).
    pub refine_iterations: Option<usize>,
    /// Threads per frame: 1 (caller only) or 2 (caller + one persistent worker).
    pub threads: usize,
    /// Tracking mode (None: every frame runs the full estimate).
    pub tracking: Option<TrackingConfig>,
    /// Pin the worker thread to this CPU (None: no pinning).
    pub pin_worker_cpu: Option<usize>,
}

impl Default for NetOptions {
    fn default() -> Self {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        Self { refine_iterations: None, threads: cores.clamp(1, 2), tracking: None, pin_worker_cpu: None }
    }
}

/// What one thread needs besides the engine, scratch and workspace.
#[derive(Clone, Copy)]
struct FrameJob<'a> {
    plan: FramePlan,
    deadline: Option<Instant>,
    /// Estimated cost of one refiner iteration at the plan's points, ns.
    iter_ns: f64,
    /// Estimated cost of one object's colour CNN and pose net at the plan's
    /// points, ns: an instance that would start later than this before the
    /// deadline is shed (see [`admitted`]).
    object_ns: f64,
    /// Estimated cost of the refiner's colour features at the plan's points, ns.
    setup_ns: f64,
    fit: Option<&'a FitCheck>,
    max_fit_m: f64,
    tracking_iterations: usize,
}

/// One instance's pose with how it was obtained.
#[derive(Clone, Copy, Debug)]
struct InstanceResult {
    pose: ObjectPose,
    /// The same region as its alternate class, when one was estimated.
    alternate: Option<ObjectPose>,
    prior: Prior,
    outcome: TrackOutcome,
    times: ObjectTimes,
}

fn since(t: &mut Instant) -> Duration {
    let now = Instant::now();
    let d = now - *t;
    *t = now;
    d
}

/// Refiner iterations from `(rot, t)` while the deadline allows; returns how many ran.
fn refine_loop(
    engine: &Engine,
    sc: &mut Scratch,
    k: usize,
    rot: &mut Matrix3<f32>,
    t: &mut Vector3<f32>,
    iterations: usize,
    job: &FrameJob<'_>,
) -> usize {
    let mut done = 0;
    while done < iterations && budget::step_fits(job.deadline, job.iter_ns) {
        (*rot, *t) = engine.refine(sc, k, rot, t);
        done += 1;
    }
    done
}

/// Runs instance `i` of `ws` through the network (from `prior` when tracking).
/// Whether the instance in place `slot` of the frame's order may still
/// start: the first always does; any other only while its colour CNN and pose
/// net end before the deadline. The plan is made from average costs; this
/// check at each start keeps a frame whose objects run slower than average
/// from overrunning.
fn admitted(slot: usize, job: &FrameJob<'_>) -> bool {
    slot == 0 || budget::step_fits(job.deadline, job.object_ns)
}

impl FrameJob<'_> {
    /// This job with its step costs scaled to the speed one object of this
    /// frame actually ran at, when slower than the cost model: a frame can run
    /// at half the average speed (a shared machine), and its later admission
    /// and iteration checks must know.
    fn at_speed_of(&self, t: &ObjectTimes) -> Self {
        if t.pose.is_zero() || self.object_ns <= 0.0 {
            return *self;
        }
        let s = ((t.color + t.pose).as_nanos() as f64 / self.object_ns).max(1.0);
        FrameJob { object_ns: self.object_ns * s, setup_ns: self.setup_ns * s, iter_ns: self.iter_ns * s, ..*self }
    }
}

/// Runs the instances in places `first, first + 2, …` below `count` of
/// `order` on one thread into `out`, each admitted (or shed) at the speed the
/// thread's previous object ran at.
#[allow(clippy::too_many_arguments)]
fn run_share(
    engine: &Engine,
    sc: &mut Scratch,
    ws: &Workspace,
    priors: &[Option<Prior>],
    order: &[u16],
    first: usize,
    count: usize,
    job: &FrameJob<'_>,
    out: &mut Vec<Option<InstanceResult>>,
) {
    let mut local = *job;
    for slot in (first..count).step_by(2) {
        let i = usize::from(order[slot]);
        let r = estimate_admitted(engine, sc, ws, slot, i, priors[i], &local);
        if let Some(r) = &r {
            local = job.at_speed_of(&r.times);
        }
        out.push(r);
    }
}

/// [`estimate_instance`] of instance `i`, in place `slot` of the frame's
/// order, when it is [`admitted`], else `None` (shed).
fn estimate_admitted(
    engine: &Engine,
    sc: &mut Scratch,
    ws: &Workspace,
    slot: usize,
    i: usize,
    prior: Option<Prior>,
    job: &FrameJob<'_>,
) -> Option<InstanceResult> {
    admitted(slot, job).then(|| estimate_instance(engine, sc, ws, i, prior, job))
}

fn estimate_instance(
    engine: &Engine,
    sc: &mut Scratch,
    ws: &Workspace,
    i: usize,
    prior: Option<Prior>,
    job: &FrameJob<'_>,
) -> InstanceResult {
    let inst = ws.instances[i];
    let k = inst.class_id as usize - 1;
    let mut times = ObjectTimes { points: job.plan.points, full_points: sc.points(), ..ObjectTimes::default() };
    let mut clock = Instant::now();
    engine.set_inputs(
        sc,
        ws.crops.slice(s![i, .., .., ..]),
        ws.points.slice(s![i, .., ..]),
        ws.choose.slice(s![i, ..]),
    );
    sc.set_active_points(job.plan.points);
    engine.color(sc);
    times.color = since(&mut clock);
    let observed = ws.points.slice(s![i, ..job.plan.points.min(ws.points.dim().1), ..]);
    let fit_of = |rot: &Matrix3<f32>, t: &Vector3<f32>| job.fit.map_or(f64::NAN, |f| f.fit_m(k, observed, rot, t));

    let mut refine_ready = false;
    if let Some(prior) = prior {
        // Tracking: the refiner from last frame's pose; kept if the fit stays good.
        engine.refine_color(sc);
        times.refine_setup = since(&mut clock);
        refine_ready = true;
        let (mut rot, mut t) = (prior.rotation, prior.translation);
        let iterations = job.tracking_iterations.min(job.plan.refine_iterations.max(1));
        let done = refine_loop(engine, sc, k, &mut rot, &mut t, iterations, job);
        times.refine = since(&mut clock);
        times.refine_iterations = done;
        let fit_m = fit_of(&rot, &t);
        if fit_m <= job.max_fit_m {
            let pose = finish_pose(inst, i, &rot, &t, prior.confidence, done);
            let prior = Prior { rotation: rot, translation: t, confidence: prior.confidence };
            // No pose net ran: keep its cost model out of this object's times.
            times.pose = Duration::ZERO;
            return InstanceResult {
                pose,
                alternate: None,
                prior,
                outcome: TrackOutcome { tracked: true, fit_m },
                times,
            };
        }
    }
    let best = engine.pose(sc, k);
    times.pose = since(&mut clock);
    let head = HeadPose { inst, i, k, best };
    let (pose, rot, t) = refined_head_pose(engine, sc, head, &mut refine_ready, job, &mut times, &mut clock);
    let alternate = alternate_pose(engine, sc, inst, i, &mut refine_ready, job, &mut times, &mut clock);
    let fit_m = if job.fit.is_some() { fit_of(&rot, &t) } else { f64::NAN };
    InstanceResult {
        pose,
        alternate,
        prior: Prior { rotation: rot, translation: t, confidence: pose.confidence },
        outcome: TrackOutcome { tracked: false, fit_m },
        times,
    }
}

/// Which head's output to turn into a pose: instance `i` as class index `k`,
/// from its most confident point `best`.
#[derive(Clone, Copy)]
struct HeadPose {
    inst: crate::Instance,
    i: usize,
    k: usize,
    best: usize,
}

/// Class `head.k`'s pose from the head output in `sc`, refined as far as the
/// plan and the deadline allow; also the refined rotation and translation.
fn refined_head_pose(
    engine: &Engine,
    sc: &mut Scratch,
    head: HeadPose,
    refine_ready: &mut bool,
    job: &FrameJob<'_>,
    times: &mut ObjectTimes,
    clock: &mut Instant,
) -> (ObjectPose, Matrix3<f32>, Vector3<f32>) {
    let best = head.best;
    let q = [sc.quat[[best, 0]], sc.quat[[best, 1]], sc.quat[[best, 2]], sc.quat[[best, 3]]];
    let confidence = sc.conf[[best, 0]];
    let mut rot = quat_matrix(q);
    let mut t = Vector3::new(sc.trans[[best, 0]], sc.trans[[best, 1]], sc.trans[[best, 2]]);
    let mut done = 0;
    let setup_ns = if *refine_ready { 0.0 } else { job.setup_ns };
    if job.plan.refine_iterations > 0 && budget::step_fits(job.deadline, setup_ns + job.iter_ns) {
        if !*refine_ready {
            engine.refine_color(sc);
            times.refine_setup = since(clock);
            *refine_ready = true;
        }
        done = refine_loop(engine, sc, head.k, &mut rot, &mut t, job.plan.refine_iterations, job);
        times.refine += since(clock);
    }
    times.refine_iterations += done;
    let mut pose = finish_pose(head.inst, head.i, &rot, &t, confidence, done);
    pose.class_id = head.k as u16 + 1;
    if done == 0 {
        // The pose net's own quaternion (no matrix round trip).
        pose.rotation = unit_quat(q);
    }
    (pose, rot, t)
}

/// The instance's pose as its alternate class ([`crate::Instance::alt_class_id`]),
/// from the same fused features: only that class's head and refiner run, and
/// only while the deadline leaves room for all of the refiner's iterations
/// (an alternate is the first thing a late frame sheds).
#[allow(clippy::too_many_arguments)]
fn alternate_pose(
    engine: &Engine,
    sc: &mut Scratch,
    inst: crate::Instance,
    i: usize,
    refine_ready: &mut bool,
    job: &FrameJob<'_>,
    times: &mut ObjectTimes,
    clock: &mut Instant,
) -> Option<ObjectPose> {
    let k = (inst.alt_class_id as usize).checked_sub(1)?;
    if k + 1 == inst.class_id as usize
        || !budget::step_fits(job.deadline, job.setup_ns + job.iter_ns * job.plan.refine_iterations as f64)
    {
        return None;
    }
    let best = engine.pose_head(sc, k);
    let head = HeadPose { inst, i, k, best };
    Some(refined_head_pose(engine, sc, head, refine_ready, job, times, clock).0)
}

fn finish_pose(
    inst: crate::Instance,
    i: usize,
    rot: &Matrix3<f32>,
    t: &Vector3<f32>,
    confidence: f32,
    iterations: usize,
) -> ObjectPose {
    // Bounded: `from_matrix` iterates until convergence, which never comes
    // for a non-finite matrix (e.g. from NaN weights), and hung `estimate`
    // forever (found with the `model` fuzz harness, docs/RELIABILITY.md).
    let rotation = UnitQuaternion::from_matrix_eps(&rot.cast::<f64>(), f64::EPSILON, 1000, UnitQuaternion::identity());
    ObjectPose {
        class_id: inst.class_id,
        instance_id: i as u16,
        rotation,
        translation: t.cast::<f64>(),
        confidence,
        mask_pixels: inst.pixels,
        bbox: inst.bbox,
        iterations: iterations as u16,
    }
}

/// A frame's share of work for the worker: the instances in places
/// `1, 3, 5, …` of `*order`.
struct Task {
    ws: *const Workspace,
    /// Tracking priors per instance (same length as the instances).
    priors: *const [Option<Prior>],
    /// The order the frame's instances are tried in ([`ShedOrder`]).
    order: *const [u16],
    /// Instances estimated this frame: the first `count` of the order.
    count: usize,
    plan: FramePlan,
    deadline: Option<Instant>,
    iter_ns: f64,
    object_ns: f64,
    setup_ns: f64,
    max_fit_m: f64,
    tracking_iterations: usize,
    check_fit: bool,
}

// SAFETY: the caller blocks until the worker reports the task done (also when
// unwinding, see `WaitGuard`), so `*ws`, `*priors` and `*order` outlive every
// access; all are plain data read concurrently by both threads and written by neither.
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
        Self { value: Mutex::new(None), cv: Condvar::new() }
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
    results: Mutex<Vec<Option<InstanceResult>>>,
}

/// The persistent second thread. Sibling estimators (one per camera, see
/// [`NetEstimator::sibling`]) share it; `frame` serialises their frames.
struct Worker {
    shared: Arc<Shared>,
    handle: Option<JoinHandle<()>>,
    frame: Mutex<()>,
}

impl Worker {
    fn spawn(
        engine: Arc<Engine>,
        fit: Option<Arc<FitCheck>>,
        pin: Option<usize>,
        n: usize,
        s: usize,
        cap: usize,
    ) -> Option<Self> {
        let shared =
            Arc::new(Shared { msg: Slot::new(), done: Slot::new(), results: Mutex::new(Vec::with_capacity(cap)) });
        let sh = shared.clone();
        let handle = std::thread::Builder::new()
            .name("fusepose-net".into())
            .spawn(move || {
                if let Some(cpu) = pin
                    && let Err(e) = crate::cpu_pin::pin_current_thread(cpu)
                {
                    tracing::warn!(cpu, error = %e, "cannot pin the network worker thread");
                }
                let mut sc = Scratch::new(&engine.config, n, s);
                loop {
                    match sh.msg.take() {
                        Msg::Run(task) => {
                            let ok = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                                // SAFETY: see `Task`.
                                let (ws, priors, order) = unsafe { (&*task.ws, &*task.priors, &*task.order) };
                                let job = FrameJob {
                                    plan: task.plan,
                                    deadline: task.deadline,
                                    iter_ns: task.iter_ns,
                                    object_ns: task.object_ns,
                                    setup_ns: task.setup_ns,
                                    fit: fit.as_deref().filter(|_| task.check_fit),
                                    max_fit_m: task.max_fit_m,
                                    tracking_iterations: task.tracking_iterations,
                                };
                                let mut out = sh.results.lock().unwrap_or_else(|e| e.into_inner());
                                out.clear();
                                let count = task.count.min(ws.instances.len()).min(order.len());
                                run_share(&engine, &mut sc, ws, priors, order, 1, count, &job, &mut out);
                            }))
                            .is_ok();
                            sh.done.put(ok);
                        }
                        Msg::Resize(n, s, cap) => {
                            sc = Scratch::new(&engine.config, n, s);
                            sh.results.lock().unwrap_or_else(|e| e.into_inner()).reserve(cap);
                            sh.done.put(true);
                        }
                        Msg::Stop => break,
                    }
                }
            })
            .ok()?;
        Some(Self { shared, handle: Some(handle), frame: Mutex::new(()) })
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

/// Counters of what the estimator did, since load.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct NetCounters {
    /// Objects estimated.
    pub objects: u64,
    /// Objects whose tracked pose was kept (no pose net).
    pub tracked: u64,
    /// Frames whose plan gave up refiner iterations or points.
    pub degraded_frames: u64,
    /// Objects run on fewer than N points.
    pub reduced_point_objects: u64,
    /// Instances left without a pose because the deadline did not pay for
    /// them (see [`budget::affordable`]; which ones: [`ShedOrder`]).
    pub shed_objects: u64,
}

/// The fusion-network estimator.
pub struct NetEstimator {
    engine: Arc<Engine>,
    file: Arc<WeightFile>,
    scratch: Scratch,
    worker: Option<Arc<Worker>>,
    /// Sizes the buffers were made for: (N, S, max instances).
    sizes: (usize, usize, usize),
    mine: Vec<Option<InstanceResult>>,
    refine_iterations: usize,
    frame_cap: Option<usize>,
    deadline: Option<Instant>,
    costs: CostModel,
    last_plan: FramePlan,
    last_degraded: bool,
    last_shed: usize,
    /// Per class id (0 unused): whether the last frame shed an instance of it.
    shed_classes: Vec<bool>,
    tracks: Option<Tracks>,
    fit: Option<Arc<FitCheck>>,
    priors: Vec<Option<Prior>>,
    /// The order this frame's instances are tried in, and its state across frames.
    order: Vec<u16>,
    shed_order: ShedOrder,
    counters: NetCounters,
}

impl NetEstimator {
    /// Loads a weight file and checks it against `objects` (names, symmetries,
    /// diameters, mesh hashes, in class order).
    pub fn load(path: &Path, objects: &ObjectSet, options: NetOptions) -> Result<Self, NetLoadError> {
        let file = WeightFile::read(path)?;
        Self::from_file(file, objects, options)
    }

    /// As [`NetEstimator::load`], from an already parsed file.
    pub fn from_file(file: WeightFile, objects: &ObjectSet, options: NetOptions) -> Result<Self, NetLoadError> {
        file.check_objects(objects)?;
        let engine = Arc::new(Engine::new(&file)?);
        let c = &engine.config;
        let (n, s, cap) = (c.num_points, c.crop_size, 8);
        let shed_order = ShedOrder::new(c.num_classes, cap);
        let shed_classes = vec![false; c.num_classes + 1];
        let scratch = Scratch::new(c, n, s);
        let refine_iterations = options.refine_iterations.unwrap_or(c.refine_iters);
        let fit = options.tracking.map(|_| Arc::new(FitCheck::new(objects)));
        let tracks = options.tracking.map(|t| Tracks::new(t, c.num_classes));
        let worker = if options.threads >= 2 {
            Worker::spawn(engine.clone(), fit.clone(), options.pin_worker_cpu, n, s, cap).map(Arc::new)
        } else {
            None
        };
        Ok(Self {
            engine,
            file: Arc::new(file),
            scratch,
            worker,
            sizes: (n, s, cap),
            mine: Vec::with_capacity(cap),
            refine_iterations,
            frame_cap: None,
            deadline: None,
            costs: CostModel::default(),
            last_plan: FramePlan::full(refine_iterations, n),
            last_degraded: false,
            last_shed: 0,
            shed_classes,
            tracks,
            fit,
            priors: Vec::with_capacity(cap),
            order: Vec::with_capacity(cap),
            shed_order,
            counters: NetCounters::default(),
        })
    }

    /// A second estimator for another camera on the same weights: it shares
    /// this one's network engine (one copy of the weights in memory), weight
    /// file and worker thread, and has its own buffers, cost model, tracks and
    /// counters. Frames of siblings never run at the same time (they take
    /// turns on the worker).
    pub fn sibling(&self) -> Self {
        let c = &self.engine.config;
        let (n, s, cap) = (c.num_points, c.crop_size, 8);
        Self {
            engine: self.engine.clone(),
            file: self.file.clone(),
            scratch: Scratch::new(c, n, s),
            worker: self.worker.clone(),
            sizes: (n, s, cap),
            mine: Vec::with_capacity(cap),
            refine_iterations: self.refine_iterations,
            frame_cap: None,
            deadline: None,
            costs: self.costs,
            last_plan: FramePlan::full(self.refine_iterations, n),
            last_degraded: false,
            last_shed: 0,
            shed_classes: vec![false; c.num_classes + 1],
            tracks: self.tracks.as_ref().map(|t| Tracks::new(*t.config(), c.num_classes)),
            fit: self.fit.clone(),
            priors: Vec::with_capacity(cap),
            order: Vec::with_capacity(cap),
            shed_order: ShedOrder::new(c.num_classes, cap),
            counters: NetCounters::default(),
        }
    }

    /// A [`sibling`](Self::sibling) that never tracks: for instances that
    /// are not the camera's objects from frame to frame (the pieces of
    /// [`crate::recut`]), whose tracks would replace the camera's.
    pub fn untracked_sibling(&self) -> Self {
        Self { tracks: None, fit: None, ..self.sibling() }
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

    /// The plan the last frame ran with (refiner iterations, points).
    pub fn last_plan(&self) -> FramePlan {
        self.last_plan
    }

    /// Instances the last frame left without a pose for lack of time.
    pub fn last_shed(&self) -> usize {
        self.last_shed
    }

    /// Whether the last frame left an instance of class `class_id` without
    /// a pose for lack of time.
    pub fn last_shed_class(&self, class_id: u16) -> bool {
        self.shed_classes.get(usize::from(class_id)).copied().unwrap_or(false)
    }

    /// The learned per-object stage costs.
    pub fn costs(&self) -> &CostModel {
        &self.costs
    }

    pub fn counters(&self) -> NetCounters {
        self.counters
    }

    /// Forgets every track (tracking mode), e.g. when the camera jumped.
    pub fn reset_tracks(&mut self) {
        if let Some(t) = self.tracks.as_mut() {
            t.clear();
        }
    }

    fn fit(&mut self, ws: &Workspace) {
        let want = (ws.config.num_points, ws.config.crop_size, ws.config.max_instances);
        if want == self.sizes {
            return;
        }
        let (n, s, cap) = want;
        if (n, s) != (self.sizes.0, self.sizes.1) {
            self.scratch = Scratch::new(&self.engine.config, n, s);
        }
        self.mine.reserve(cap);
        self.priors.reserve(cap);
        self.order.reserve(cap);
        self.shed_order.reserve(cap);
        if let Some(w) = &self.worker {
            let _turn = w.frame.lock().unwrap_or_else(|e| e.into_inner());
            w.shared.msg.put(Msg::Resize(n, s, cap));
            w.shared.done.take();
        }
        self.sizes = want;
    }

    /// Priors of this frame's instances (tracking): a class seen twice is not tracked.
    fn gather_priors(&mut self, ws: &Workspace) {
        self.priors.clear();
        let Some(tracks) = self.tracks.as_mut() else {
            self.priors.resize(ws.instances.len(), None);
            return;
        };
        tracks.begin_frame();
        for (i, inst) in ws.instances.iter().enumerate() {
            let duplicate = ws.instances.iter().enumerate().any(|(j, o)| j != i && o.class_id == inst.class_id);
            self.priors.push(if duplicate { None } else { tracks.prior(inst.class_id) });
        }
    }

    /// The frame gave up accuracy when its plan did or an instance was shed.
    /// Its poses go back into the instances' order (each instance's own class
    /// first, then its alternate), and the shed order learns who was posed.
    fn finish_frame(&mut self, ws: &Workspace, out: &mut PoseSet, plan_degraded: bool) {
        self.last_degraded = plan_degraded || self.last_shed > 0;
        self.counters.degraded_frames += self.last_degraded as u64;
        let class_of = |i: usize| usize::from(ws.instances[i].class_id) - 1;
        let found = ws.instances.len();
        if self.order.iter().enumerate().any(|(slot, &i)| usize::from(i) != slot) {
            out.sort_unstable_by_key(|p| {
                let own = ws.instances.get(usize::from(p.instance_id)).map(|inst| inst.class_id);
                (p.instance_id, own != Some(p.class_id))
            });
        }
        let poses = out.as_slice();
        let posed = |i: usize| poses.iter().any(|p| usize::from(p.instance_id) == i);
        for i in (0..found).filter(|&i| !posed(i)) {
            if let Some(shed) = self.shed_classes.get_mut(usize::from(ws.instances[i].class_id)) {
                *shed = true;
            }
        }
        self.shed_order.finish(class_of, found, posed);
    }

    /// Folds one frame's results into the costs, counters and tracks; writes
    /// the poses. `None`: the instance was shed at its start.
    fn absorb(&mut self, result: Option<&InstanceResult>, out: &mut PoseSet) {
        let Some(result) = result else {
            self.last_shed += 1;
            self.counters.shed_objects += 1;
            return;
        };
        self.costs.observe(&result.times);
        self.counters.objects += 1;
        self.counters.tracked += result.outcome.tracked as u64;
        self.counters.reduced_point_objects += (result.times.points < result.times.full_points) as u64;
        if let Some(tracks) = self.tracks.as_mut() {
            tracks.update(result.pose.class_id, result.prior, result.outcome);
        }
        out.push(result.pose);
        if let Some(alternate) = result.alternate {
            out.push(alternate);
        }
    }
}

impl Estimator for NetEstimator {
    fn name(&self) -> &str {
        "net"
    }

    fn cap_next_frame(&mut self, max_iterations: usize) {
        NetEstimator::cap_next_frame(self, max_iterations);
    }

    fn set_deadline(&mut self, deadline: Option<Instant>) {
        self.deadline = deadline;
    }

    fn degraded(&self) -> bool {
        self.last_degraded
    }

    fn shed(&self) -> usize {
        self.last_shed
    }

    fn shed_class(&self, class_id: u16) -> bool {
        self.last_shed_class(class_id)
    }

    fn estimate(&mut self, _frame: &FrameView<'_>, ws: &mut Workspace, out: &mut PoseSet) -> Result<(), EstimateError> {
        out.clear();
        self.shed_classes.fill(false);
        let max_iterations = self.frame_cap.take().map_or(self.refine_iterations, |c| c.min(self.refine_iterations));
        let deadline = self.deadline;
        let k_max = self.engine.config.num_classes;
        if let Some(bad) = ws.instances.iter().find(|i| i.class_id == 0 || i.class_id as usize > k_max) {
            return Err(EstimateError::UnknownClass(bad.class_id));
        }
        if let Some(bad) = ws.instances.iter().find(|i| i.alt_class_id as usize > k_max) {
            return Err(EstimateError::UnknownClass(bad.alt_class_id));
        }
        self.fit(ws);
        let found = ws.instances.len();
        let ws: &Workspace = ws;
        self.gather_priors(ws);
        let class_of = |i: usize| usize::from(ws.instances[i].class_id) - 1;
        self.shed_order.order(class_of, found, &mut self.order);
        let remaining = deadline.map(|d| d.saturating_duration_since(Instant::now()));
        let count = budget::affordable(&self.costs, remaining, found, if found >= 2 { self.threads() } else { 1 });
        self.last_shed = found - count;
        self.counters.shed_objects += self.last_shed as u64;
        let threads = if count >= 2 { self.threads() } else { 1 };
        let full_points = self.scratch.points();
        let plan = budget::plan(&self.costs, remaining, count.div_ceil(threads), max_iterations, full_points);
        self.last_plan = plan;
        let plan_degraded = plan.is_degraded(max_iterations, full_points);
        let tracking = self.tracks.as_ref().map(|t| *t.config());
        let (max_fit_m, tracking_iterations) =
            tracking.map_or((f64::NAN, 0), |t| (t.max_fit_m, t.refine_iterations.max(1)));
        let iter_ns = self.costs.refine_iter_ns(plan.points, full_points);
        let fit = self.fit.clone();
        let object_ns = self.costs.object_ns(plan.points, full_points);
        let setup_ns = self.costs.refine_setup_ns(plan.points, full_points);
        let job = FrameJob {
            plan,
            deadline,
            iter_ns,
            object_ns,
            setup_ns,
            fit: fit.as_deref(),
            max_fit_m,
            tracking_iterations,
        };
        self.mine.clear();
        let mut mine = std::mem::take(&mut self.mine);
        if threads == 2
            && let Some(w) = self.worker.clone()
        {
            let turn = w.frame.lock().unwrap_or_else(|e| e.into_inner());
            w.shared.msg.put(Msg::Run(Task {
                ws,
                priors: self.priors.as_slice(),
                order: self.order.as_slice(),
                count,
                plan,
                deadline,
                iter_ns,
                object_ns,
                setup_ns,
                max_fit_m,
                tracking_iterations,
                check_fit: job.fit.is_some(),
            }));
            let guard = WaitGuard { shared: &w.shared, ok: None };
            run_share(&self.engine, &mut self.scratch, ws, &self.priors, &self.order, 0, count, &job, &mut mine);
            let ok = guard.wait();
            let theirs = w.shared.results.lock().unwrap_or_else(|e| e.into_inner());
            if ok && theirs.len() == count / 2 {
                for i in 0..count {
                    let r = if i % 2 == 0 { mine[i / 2] } else { theirs[i / 2] };
                    self.absorb(r.as_ref(), out);
                }
                drop(theirs);
                drop(turn);
                self.mine = mine;
                self.finish_frame(ws, out, plan_degraded);
                return Ok(());
            }
            // The worker panicked: this frame and later ones run on the caller's thread.
            drop(theirs);
            drop(turn);
            self.worker = None;
            out.clear();
            mine.clear();
        }
        let mut local = job;
        for slot in 0..count {
            let i = usize::from(self.order[slot]);
            let r = estimate_admitted(&self.engine, &mut self.scratch, ws, slot, i, self.priors[i], &local);
            if let Some(r) = &r {
                local = job.at_speed_of(&r.times);
            }
            self.absorb(r.as_ref(), out);
        }
        self.mine = mine;
        self.finish_frame(ws, out, plan_degraded);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn job(deadline: Option<Instant>, object_ns: f64) -> FrameJob<'static> {
        FrameJob {
            plan: FramePlan::full(2, 256),
            deadline,
            iter_ns: 0.0,
            object_ns,
            setup_ns: 0.0,
            fit: None,
            max_fit_m: f64::NAN,
            tracking_iterations: 0,
        }
    }

    #[test]
    fn instances_start_only_while_their_cost_fits_the_deadline() {
        let now = Instant::now();
        let soon = job(Some(now + Duration::from_millis(5)), 8e6);
        assert!(admitted(0, &soon), "the largest instance always runs");
        assert!(!admitted(1, &soon) && !admitted(5, &soon), "8 ms of work does not fit 5 ms");
        assert!(
            !admitted(1, &job(Some(now + Duration::from_millis(5)), 4.5e6)),
            "4.5 ms with its margin does not fit 5 ms"
        );
        let later = job(Some(now + Duration::from_millis(50)), 8e6);
        assert!(admitted(1, &later) && admitted(5, &later));
        assert!(admitted(3, &job(None, 8e6)), "no deadline: every instance");
        assert!(admitted(3, &job(Some(now + Duration::from_millis(1)), 0.0)), "no costs yet: every instance");
    }

    #[test]
    fn a_slow_object_slows_the_rest_of_its_frame() {
        let planned = FrameJob { iter_ns: 0.5e6, setup_ns: 0.1e6, ..job(None, 4e6) };
        let ran = |ms: u64| ObjectTimes {
            color: Duration::from_millis(ms / 2),
            pose: Duration::from_millis(ms / 2),
            ..ObjectTimes::default()
        };
        let slow = planned.at_speed_of(&ran(8));
        assert_eq!((slow.object_ns, slow.iter_ns, slow.setup_ns), (8e6, 1e6, 0.2e6));
        let fast = planned.at_speed_of(&ran(2));
        assert_eq!(fast.object_ns, 4e6, "never faster than the model");
        let tracked = ObjectTimes { pose: Duration::ZERO, ..ran(8) };
        assert_eq!(planned.at_speed_of(&tracked).object_ns, 4e6, "no pose net ran: no measurement");
        // At twice the speed model, 8 ms of work no longer fits 9 ms.
        let soon = FrameJob { deadline: Some(Instant::now() + Duration::from_millis(9)), ..planned };
        assert!(admitted(1, &soon) && !admitted(1, &soon.at_speed_of(&ran(8))));
    }
}
