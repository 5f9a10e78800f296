//! The forward pass of the fusion network on preallocated buffers.
//!
//! [`Engine`] holds the weights (immutable, shareable across threads);
//! [`Scratch`] holds every activation of one instance, allocated once from the
//! [`NetConfig`] and the largest N and S. The operations mirror
//! `fusepose_train::model` exactly (the parity test holds them to 1e-4).

use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};
use ndarray::{Array1, Array2, ArrayView1, ArrayView2, ArrayViewMut2, Axis, s};

use super::config::NetConfig;
use super::gemm::{cols_len, conv3x3, dense, gemm_acc};
use super::weights::{NetLoadError, WeightFile};
use crate::resident;

/// A dense layer `[in, out]` + bias.
#[derive(Clone, Debug)]
struct Dense {
    w: Array2<f32>,
    b: Option<Array1<f32>>,
}

impl Dense {
    fn load(f: &WeightFile, name: &str, i: usize, o: usize, bias: bool) -> Result<Self, NetLoadError> {
        let w = Array2::from_shape_vec((i, o), f.tensor(&format!("{name}.weight"))?.to_vec())
            .map_err(|_| NetLoadError::MissingTensor(format!("{name}.weight")))?;
        let b = if bias { Some(Array1::from_vec(f.tensor(&format!("{name}.bias"))?.to_vec())) } else { None };
        Ok(Self { w, b })
    }

    fn run(&self, x: ArrayView2<f32>, relu: bool, out: ArrayViewMut2<f32>) {
        dense(x, self.w.view(), self.b.as_ref().map(|b| b.view()), relu, out);
    }

    /// Columns `[k*w, (k+1)*w)` only: the head row of class k.
    fn run_cols(&self, x: ArrayView2<f32>, k: usize, w: usize, out: ArrayViewMut2<f32>) {
        let wv = self.w.slice(s![.., k * w..(k + 1) * w]);
        let bv = self.b.as_ref().map(|b| b.slice(s![k * w..(k + 1) * w]));
        dense(x, wv, bv, false, out);
    }
}

/// A 3x3 convolution `[out, in*9]` + bias.
#[derive(Clone, Debug)]
struct Conv {
    w: Array2<f32>,
    b: Array1<f32>,
    c_in: usize,
    c_out: usize,
}

impl Conv {
    fn load(f: &WeightFile, name: &str, i: usize, o: usize) -> Result<Self, NetLoadError> {
        let w = Array2::from_shape_vec((o, i * 9), f.tensor(&format!("{name}.weight"))?.to_vec())
            .map_err(|_| NetLoadError::MissingTensor(format!("{name}.weight")))?;
        let b = Array1::from_vec(f.tensor(&format!("{name}.bias"))?.to_vec());
        Ok(Self { w, b, c_in: i, c_out: o })
    }

    fn run(&self, input: &[f32], h: usize, w: usize, stride: usize, cols: &mut [f32], out: &mut [f32]) {
        let ho = (h - 1) / stride + 1;
        let wo = (w - 1) / stride + 1;
        let out = ArrayViewMut2::from_shape((self.c_out, ho * wo), &mut out[..self.c_out * ho * wo]).expect("conv out");
        conv3x3(input, self.c_in, h, w, stride, self.w.view(), self.b.view(), cols, out);
    }
}

/// The network's weights in engine layout.
#[derive(Clone, Debug)]
pub struct Engine {
    pub config: NetConfig,
    e1: Conv,
    e2: Conv,
    e3: Conv,
    e4: Conv,
    d1: Conv,
    d2: Dense,
    p: [Dense; 12],
    r: [Dense; 9],
}

// Indices into `Engine::p` / `Engine::r`.
const G1: usize = 0;
const G2: usize = 1;
const C1: usize = 2;
const C2: usize = 3;
const L1: usize = 4;
const L2: usize = 5;
const H1L: usize = 6;
const H1G: usize = 7;
const H2: usize = 8;
const ROT: usize = 9;
const TRA: usize = 10;
const CONF: usize = 11;
const RM1: usize = 6;
const RROT: usize = 7;
const RTRA: usize = 8;

/// Activations of one instance. Sized once; reused for every instance and frame.
#[derive(Clone, Debug)]
pub struct Scratch {
    n: usize,
    /// Points the next passes use: the first `active` of the `n` sampled
    /// (a uniform random subset: sampling is a partial Fisher–Yates shuffle).
    active: usize,
    s: usize,
    crop: Vec<f32>,
    points: Array2<f32>,
    choose: Vec<u32>,
    cols: Vec<f32>,
    e1: Vec<f32>,
    e2: Vec<f32>,
    e3: Vec<f32>,
    e4: Vec<f32>,
    cat: Vec<f32>,
    d1: Vec<f32>,
    d2in: Array2<f32>,
    /// `[N, emb]` per-point colour embedding.
    pub emb: Array2<f32>,
    gx: Array2<f32>,
    local: Array2<f32>,
    l1: Array2<f32>,
    l2: Array2<f32>,
    glob: Array2<f32>,
    hg: Array2<f32>,
    h1: Array2<f32>,
    h2: Array2<f32>,
    /// `[N, 4]` raw per-point quaternions `[x, y, z, w]`.
    pub quat: Array2<f32>,
    /// `[N, 3]` per-point translations (point + offset), metres.
    pub trans: Array2<f32>,
    /// `[N, 1]` per-point confidences.
    pub conf: Array2<f32>,
    rlocal: Array2<f32>,
    rl1: Array2<f32>,
    rl2: Array2<f32>,
    rglob: Array2<f32>,
    rm: Array2<f32>,
    rrot: Array2<f32>,
    rtra: Array2<f32>,
}

impl Scratch {
    /// Buffers for up to `n` points and `s`×`s` crops.
    pub fn new(c: &NetConfig, n: usize, s: usize) -> Self {
        let [c1, c2, c3] = c.cnn;
        let (s2, s4) = ((s / 2) * (s / 2), (s / 4) * (s / 4));
        let cols = cols_len(3, s * s)
            .max(cols_len(c1, s2))
            .max(cols_len(c2, s4))
            .max(cols_len(c3, s4))
            .max(cols_len(c3 + c2, s2));
        let lw = c.local_width();
        // Every page resident now: later frames may use rows earlier ones did not
        // (`crate::resident`).
        let z = |r: usize, k: usize| resident::array((r, k), 0.0f32);
        let v = |len: usize| resident::vec(0.0f32, len);
        Self {
            n,
            active: n,
            s,
            crop: v(3 * s * s),
            points: z(n, 3),
            choose: resident::vec(0u32, n),
            cols: v(cols),
            e1: v(c1 * s * s),
            e2: v(c2 * s2),
            e3: v(c3 * s4),
            e4: v(c3 * s4),
            cat: v((c3 + c2) * s2),
            d1: v(c.emb * s2),
            d2in: z(n, c.emb + c1),
            emb: z(n, c.emb),
            gx: z(n, 3),
            local: z(n, lw),
            l1: z(n, c.lift[0]),
            l2: z(n, c.lift[1]),
            glob: z(1, c.lift[1]),
            hg: z(1, c.trunk[0]),
            h1: z(n, c.trunk[0]),
            h2: z(n, c.trunk[1]),
            quat: z(n, 4),
            trans: z(n, 3),
            conf: z(n, 1),
            rlocal: z(n, lw),
            rl1: z(n, c.ref_lift[0]),
            rl2: z(n, c.ref_lift[1]),
            rglob: z(1, c.ref_lift[1]),
            rm: z(1, c.ref_head),
            rrot: z(1, 4),
            rtra: z(1, 3),
        }
    }

    /// Uses only the first `m` points (clamped to 1..=N) from now on: the
    /// network is per point plus an average pool, so fewer points cost
    /// proportionally less (a degraded mode under overload).
    pub fn set_active_points(&mut self, m: usize) {
        self.active = m.clamp(1, self.n.max(1));
    }

    /// Points the passes use (see [`Scratch::set_active_points`]).
    pub fn active_points(&self) -> usize {
        self.active
    }

    /// Points the buffers hold (N).
    pub fn points(&self) -> usize {
        self.n
    }

    /// Whether these buffers fit `n` points and `s`×`s` crops exactly.
    pub fn fits(&self, n: usize, s: usize) -> bool {
        self.n == n && self.s == s
    }
}

/// Mean of the rows of `x` into `out[0, :]`.
fn mean_rows(x: ArrayView2<f32>, mut out: ArrayViewMut2<f32>) {
    out.fill(0.0);
    let mut o = out.row_mut(0);
    for r in x.rows() {
        o += &r;
    }
    o *= 1.0 / x.nrows() as f32;
}

/// Rotation matrix of a raw quaternion `[x, y, z, w]`, normalised as the trainer does.
pub fn quat_matrix(q: [f32; 4]) -> Matrix3<f32> {
    let n = (q.iter().map(|v| v * v).sum::<f32>() + 1e-12).sqrt();
    let [x, y, z, w] = q.map(|v| v / n);
    Matrix3::new(
        1.0 - 2.0 * (y * y + z * z),
        2.0 * (x * y - w * z),
        2.0 * (x * z + w * y),
        2.0 * (x * y + w * z),
        1.0 - 2.0 * (x * x + z * z),
        2.0 * (y * z - w * x),
        2.0 * (x * z - w * y),
        2.0 * (y * z + w * x),
        1.0 - 2.0 * (x * x + y * y),
    )
}

/// The unit quaternion of a raw `[x, y, z, w]` output (f64).
pub fn unit_quat(q: [f32; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(Quaternion::new(q[3] as f64, q[0] as f64, q[1] as f64, q[2] as f64))
}

impl Engine {
    /// Builds the engine from a checked weight file.
    pub fn new(f: &WeightFile) -> Result<Self, NetLoadError> {
        let c = f.config.clone();
        let [c1, c2, c3] = c.cnn;
        let k = c.num_classes;
        let lw = c.local_width();
        let d = |n: &str, i, o| Dense::load(f, n, i, o, true);
        Ok(Self {
            e1: Conv::load(f, "cnn.e1", 3, c1)?,
            e2: Conv::load(f, "cnn.e2", c1, c2)?,
            e3: Conv::load(f, "cnn.e3", c2, c3)?,
            e4: Conv::load(f, "cnn.e4", c3, c3)?,
            d1: Conv::load(f, "cnn.d1", c3 + c2, c.emb)?,
            d2: d("cnn.d2", c.emb + c1, c.emb)?,
            p: [
                d("pose.g1", 3, c.geo[0])?,
                d("pose.g2", c.geo[0], c.geo[1])?,
                d("pose.c1", c.emb, c.col[0])?,
                d("pose.c2", c.col[0], c.col[1])?,
                d("pose.l1", c.geo[1] + c.col[1], c.lift[0])?,
                d("pose.l2", c.lift[0], c.lift[1])?,
                d("pose.h1_local", lw, c.trunk[0])?,
                Dense::load(f, "pose.h1_global", c.lift[1], c.trunk[0], false)?,
                d("pose.h2", c.trunk[0], c.trunk[1])?,
                d("pose.rot", c.trunk[1], 4 * k)?,
                d("pose.tra", c.trunk[1], 3 * k)?,
                d("pose.conf", c.trunk[1], k)?,
            ],
            r: [
                d("refine.g1", 3, c.geo[0])?,
                d("refine.g2", c.geo[0], c.geo[1])?,
                d("refine.c1", c.emb, c.col[0])?,
                d("refine.c2", c.col[0], c.col[1])?,
                d("refine.l1", lw, c.ref_lift[0])?,
                d("refine.l2", c.ref_lift[0], c.ref_lift[1])?,
                d("refine.m1", c.ref_lift[1], c.ref_head)?,
                d("refine.rot", c.ref_head, 4 * k)?,
                d("refine.tra", c.ref_head, 3 * k)?,
            ],
            config: c,
        })
    }

    /// Copies one instance's inputs into the scratch: crop `[3,S,S]`, points `[N,3]`, choose `[N]`.
    pub fn set_inputs<'a>(
        &self,
        sc: &mut Scratch,
        crop: impl IntoIterator<Item = &'a f32>,
        points: ArrayView2<f32>,
        choose: ArrayView1<u32>,
    ) {
        for (d, &v) in sc.crop.iter_mut().zip(crop) {
            *d = v;
        }
        sc.points.assign(&points);
        for (d, &v) in sc.choose.iter_mut().zip(choose.iter()) {
            *d = v;
        }
    }

    /// Colour branch: crop → per-point embedding `sc.emb [N, emb]`.
    pub fn color(&self, sc: &mut Scratch) {
        let c = &self.config;
        let s = sc.s;
        let h = s / 2;
        let [c1, c2, c3] = c.cnn;
        self.e1.run(&sc.crop, s, s, 1, &mut sc.cols, &mut sc.e1);
        self.e2.run(&sc.e1, s, s, 2, &mut sc.cols, &mut sc.e2);
        self.e3.run(&sc.e2, h, h, 2, &mut sc.cols, &mut sc.e3);
        self.e4.run(&sc.e3, s / 4, s / 4, 1, &mut sc.cols, &mut sc.e4);
        // Nearest ×2 upsampling of e4, then e2: the decoder input [c3 + c2, S/2, S/2].
        let q = s / 4;
        for ch in 0..c3 {
            for y in 0..h {
                for x in 0..h {
                    sc.cat[ch * h * h + y * h + x] = sc.e4[ch * q * q + (y / 2) * q + x / 2];
                }
            }
        }
        sc.cat[c3 * h * h..(c3 + c2) * h * h].copy_from_slice(&sc.e2[..c2 * h * h]);
        self.d1.run(&sc.cat, h, h, 1, &mut sc.cols, &mut sc.d1);
        // Gather at the chosen pixels: d1 at (row/2, col/2) (nearest upsampling), e1 at (row, col).
        let emb = c.emb;
        let m = sc.active;
        for (i, &px) in sc.choose.iter().enumerate().take(m) {
            let px = (px as usize).min(s * s - 1);
            let (row, col) = (px / s, px % s);
            let half = (row / 2) * h + col / 2;
            let mut r = sc.d2in.row_mut(i);
            for ch in 0..emb {
                r[ch] = sc.d1[ch * h * h + half];
            }
            for ch in 0..c1 {
                r[emb + ch] = sc.e1[ch * s * s + px];
            }
        }
        self.d2.run(sc.d2in.slice(s![..m, ..]), true, sc.emb.slice_mut(s![..m, ..]));
    }

    /// Pose net on `sc.points` and `sc.emb` for class index `k` (0-based): fills
    /// `sc.quat`, `sc.trans`, `sc.conf`; returns the index of the most confident point.
    pub fn pose(&self, sc: &mut Scratch, k: usize) -> usize {
        self.pose_features(sc);
        self.pose_head(sc, k)
    }

    /// The class-independent part of [`Engine::pose`]: the fused per-point
    /// features `sc.h2` that every class's head reads.
    pub fn pose_features(&self, sc: &mut Scratch) {
        let c = &self.config;
        let n = sc.active;
        let [g0, g1w] = c.geo;
        let [c0, c1w] = c.col;
        // Centred, scaled geometry.
        let mut mean = [0.0f32; 3];
        for r in sc.points.slice(s![..n, ..]).rows() {
            for j in 0..3 {
                mean[j] += r[j];
            }
        }
        mean.iter_mut().for_each(|m| *m /= n as f32);
        for (mut g, p) in sc.gx.rows_mut().into_iter().zip(sc.points.slice(s![..n, ..]).rows()) {
            for j in 0..3 {
                g[j] = (p[j] - mean[j]) * c.geo_scale;
            }
        }
        let (a, b) = (g0, g0 + c0);
        debug_assert_eq!(b + g1w + c1w, c.local_width());
        {
            let (left, right) = sc.local.slice_mut(s![..n, ..]).split_at(Axis(1), b);
            let (mut l_g1, mut l_c1) = left.split_at(Axis(1), a);
            self.p[G1].run(sc.gx.slice(s![..n, ..]), true, l_g1.view_mut());
            self.p[C1].run(sc.emb.slice(s![..n, ..]), true, l_c1.view_mut());
            let (l_g2, l_c2) = right.split_at(Axis(1), g1w);
            self.p[G2].run(l_g1.view(), true, l_g2);
            self.p[C2].run(l_c1.view(), true, l_c2);
        }
        self.p[L1].run(sc.local.slice(s![..n, b..]), true, sc.l1.slice_mut(s![..n, ..]));
        self.p[L2].run(sc.l1.slice(s![..n, ..]), true, sc.l2.slice_mut(s![..n, ..]));
        mean_rows(sc.l2.slice(s![..n, ..]), sc.glob.view_mut());
        self.p[H1G].run(sc.glob.view(), false, sc.hg.view_mut());
        // h1 = relu(local · W + b + global · W_g): the global term is one row, added as a bias.
        let b1 = self.p[H1L].b.as_ref().expect("h1_local has a bias");
        for mut r in sc.h1.slice_mut(s![..n, ..]).rows_mut() {
            for ((d, &bv), &gv) in r.iter_mut().zip(b1.iter()).zip(sc.hg.row(0).iter()) {
                *d = bv + gv;
            }
        }
        gemm_acc(sc.local.slice(s![..n, ..]), self.p[H1L].w.view(), &mut sc.h1.slice_mut(s![..n, ..]));
        sc.h1.slice_mut(s![..n, ..]).mapv_inplace(|v| v.max(0.0));
        self.p[H2].run(sc.h1.slice(s![..n, ..]), true, sc.h2.slice_mut(s![..n, ..]));
    }

    /// Class `k`'s head on the features of the last [`Engine::pose_features`]:
    /// fills `sc.quat`, `sc.trans`, `sc.conf`; returns the most confident point.
    /// A second class costs only this (three narrow columns per point).
    pub fn pose_head(&self, sc: &mut Scratch, k: usize) -> usize {
        let c = &self.config;
        let n = sc.active;
        self.p[ROT].run_cols(sc.h2.slice(s![..n, ..]), k, 4, sc.quat.slice_mut(s![..n, ..]));
        self.p[TRA].run_cols(sc.h2.slice(s![..n, ..]), k, 3, sc.trans.slice_mut(s![..n, ..]));
        self.p[CONF].run_cols(sc.h2.slice(s![..n, ..]), k, 1, sc.conf.slice_mut(s![..n, ..]));
        let os = c.offset_scale;
        for (mut t, p) in sc.trans.rows_mut().into_iter().zip(sc.points.slice(s![..n, ..]).rows()) {
            for j in 0..3 {
                t[j] = p[j] + t[j] * os;
            }
        }
        let mut best = 0;
        let mut best_c = f32::NEG_INFINITY;
        for (i, v) in sc.conf.slice_mut(s![..n, ..]).iter_mut().enumerate() {
            *v = 1.0 / (1.0 + (-*v).exp());
            if *v > best_c {
                best_c = *v;
                best = i;
            }
        }
        best
    }

    /// The refiner's colour features (once per instance, after [`Engine::color`]).
    pub fn refine_color(&self, sc: &mut Scratch) {
        let c = &self.config;
        let (a, b) = (c.geo[0], c.geo[0] + c.col[0]);
        let m = sc.active;
        let (left, right) = sc.rlocal.slice_mut(s![..m, ..]).split_at(Axis(1), b);
        let (_, mut l_c1) = left.split_at(Axis(1), a);
        self.r[C1].run(sc.emb.slice(s![..m, ..]), true, l_c1.view_mut());
        let (_, l_c2) = right.split_at(Axis(1), c.geo[1]);
        self.r[C2].run(l_c1.view(), true, l_c2);
    }

    /// One refinement of `(rot, trans)` (object → camera) for class index `k`.
    pub fn refine(
        &self,
        sc: &mut Scratch,
        k: usize,
        rot: &Matrix3<f32>,
        trans: &Vector3<f32>,
    ) -> (Matrix3<f32>, Vector3<f32>) {
        let c = &self.config;
        let m = sc.active;
        for (mut g, p) in sc.gx.rows_mut().into_iter().zip(sc.points.slice(s![..m, ..]).rows()) {
            let d = Vector3::new(p[0] - trans.x, p[1] - trans.y, p[2] - trans.z);
            let o = rot.transpose() * d;
            for j in 0..3 {
                g[j] = o[j] * c.geo_scale;
            }
        }
        let (a, b) = (c.geo[0], c.geo[0] + c.col[0]);
        {
            let (left, right) = sc.rlocal.slice_mut(s![..m, ..]).split_at(Axis(1), b);
            let (mut l_g1, _) = left.split_at(Axis(1), a);
            self.r[G1].run(sc.gx.slice(s![..m, ..]), true, l_g1.view_mut());
            let (l_g2, _) = right.split_at(Axis(1), c.geo[1]);
            self.r[G2].run(l_g1.view(), true, l_g2);
        }
        self.r[L1].run(sc.rlocal.slice(s![..m, ..]), true, sc.rl1.slice_mut(s![..m, ..]));
        self.r[L2].run(sc.rl1.slice(s![..m, ..]), true, sc.rl2.slice_mut(s![..m, ..]));
        mean_rows(sc.rl2.slice(s![..m, ..]), sc.rglob.view_mut());
        self.r[RM1].run(sc.rglob.view(), true, sc.rm.view_mut());
        self.r[RROT].run_cols(sc.rm.view(), k, 4, sc.rrot.view_mut());
        self.r[RTRA].run_cols(sc.rm.view(), k, 3, sc.rtra.view_mut());
        let q = [sc.rrot[[0, 0]], sc.rrot[[0, 1]], sc.rrot[[0, 2]], sc.rrot[[0, 3]] + 1.0];
        let dr = quat_matrix(q);
        let dt = Vector3::new(sc.rtra[[0, 0]], sc.rtra[[0, 1]], sc.rtra[[0, 2]]) * c.offset_scale;
        (rot * dr, trans + rot * dt)
    }
}
