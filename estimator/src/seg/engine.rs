//! The segmenter's forward pass on buffers allocated once: im2col + the shared
//! GEMM ([`crate::net::gemm`]) per convolution, nearest upsampling into the
//! decoder's concatenation buffers (skip features are written there directly
//! by the encoder), a 1x1 head, per-cell argmax and nearest upsampling of the
//! cell labels to the frame. Mirrors `fusepose_train::seg::model` operation for
//! operation; after the first frame of a size, [`SegEngine::segment`] does not allocate.

use std::path::Path;

use fusepose_scene::ObjectSet;
use ndarray::{Array1, Array2, ArrayView2, ArrayViewMut2};

use super::config::{INPUT_CHANNELS, SegConfig};
use super::file::SegFile;
use super::input::FrameMap;
use crate::frame::{FrameError, FrameView};
use crate::net::NetLoadError;
use crate::net::gemm::{conv3x3, gemm_acc};
use crate::net::meta::ObjectEntry;

/// Why a frame could not be segmented.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SegError {
    #[error("invalid frame: {0}")]
    Frame(#[from] FrameError),
    #[error("label output has {got} values, the frame has {expected} pixels")]
    OutputLength { got: usize, expected: usize },
    #[error("network input has {got} values, expected {expected}")]
    InputLength { got: usize, expected: usize },
}

/// One layer's weights: `[O, I*k*k]` and bias `[O]`.
struct Layer {
    w: Array2<f32>,
    b: Array1<f32>,
}

/// Nearest source index of each output index, exactly as burn's `interpolate(Nearest)`:
/// `min(floor(o * (in / out)), in - 1)` in f64.
fn nearest_map(input: usize, output: usize) -> Vec<usize> {
    let ratio = input as f64 / output as f64;
    (0..output).map(|o| ((o as f64 * ratio).floor() as usize).min(input - 1)).collect()
}

/// Nearest upsampling of `[c, hi, wi]` into `[c, ys.len(), xs.len()]`.
fn upsample(src: &[f32], c: usize, wi: usize, ys: &[usize], xs: &[usize], dst: &mut [f32]) {
    let hi = src.len() / c.max(1) / wi.max(1);
    let plane = ys.len() * xs.len();
    for ch in 0..c {
        let s = &src[ch * hi * wi..(ch + 1) * hi * wi];
        let d = &mut dst[ch * plane..(ch + 1) * plane];
        for (row, &y) in d.chunks_exact_mut(xs.len()).zip(ys) {
            let srow = &s[y * wi..(y + 1) * wi];
            for (v, &x) in row.iter_mut().zip(xs) {
                *v = srow[x];
            }
        }
    }
}

/// The segmenter inference engine.
pub struct SegEngine {
    config: SegConfig,
    objects: Vec<ObjectEntry>,
    /// e1, e2, e3, e4, d3, d2, d1, head.
    layers: Vec<Layer>,
    /// `[4, H0*W0]`.
    input: Vec<f32>,
    /// `[d2 + e1, H1*W1]`: upsampled d2 then e1's output.
    cat1: Vec<f32>,
    /// `[d3 + e2, H2*W2]`.
    cat2: Vec<f32>,
    /// `[e4 + e3, H3*W3]`.
    cat3: Vec<f32>,
    e4: Vec<f32>,
    d3: Vec<f32>,
    d2: Vec<f32>,
    d1: Vec<f32>,
    /// `[K+1, H1*W1]`.
    logits: Vec<f32>,
    cols: Vec<f32>,
    cells: Vec<u16>,
    /// Nearest maps (rows, columns) for the upsampling into cat3, cat2, cat1.
    up: [(Vec<usize>, Vec<usize>); 3],
    map: Option<FrameMap>,
}

impl SegEngine {
    /// Reads `path`, checks it against `set` (same objects in the same order) and builds the engine.
    pub fn load(path: &Path, set: &ObjectSet) -> Result<Self, NetLoadError> {
        let file = SegFile::read(path)?;
        file.check_objects(set)?;
        Self::new(&file)
    }

    /// Builds the engine from a parsed file (no object-set check; see [`SegEngine::load`]).
    pub fn new(file: &SegFile) -> Result<Self, NetLoadError> {
        let c = file.config.clone();
        let mut layers = Vec::new();
        for (name, i, o, k, _) in c.layers() {
            let w = file.tensor(&format!("{name}.weight"))?;
            let b = file.tensor(&format!("{name}.bias"))?;
            let w = Array2::from_shape_vec((o, i * k * k), w.to_vec()).map_err(|e| NetLoadError::WrongShape {
                name: format!("{name}.weight ({e})"),
                expected: vec![o, i, k, k],
                got: vec![w.len()],
            })?;
            layers.push(Layer { w, b: Array1::from_vec(b.to_vec()) });
        }
        let s = c.sizes();
        let hw = |l: usize| s[l].0 * s[l].1;
        let [c1, c2, c3, c4] = c.enc;
        let [d3, d2, d1] = c.dec;
        let cols = c
            .layers()
            .into_iter()
            .zip([1, 2, 3, 4, 3, 2, 1, 1])
            .map(|((_, i, _, k, _), l)| i * k * k * hw(l))
            .max()
            .unwrap_or(0);
        let up = [(4, 3), (3, 2), (2, 1)]
            .map(|(from, to)| (nearest_map(s[from].0, s[to].0), nearest_map(s[from].1, s[to].1)));
        Ok(Self {
            input: vec![0.0; INPUT_CHANNELS * hw(0)],
            cat1: vec![0.0; (d2 + c1) * hw(1)],
            cat2: vec![0.0; (d3 + c2) * hw(2)],
            cat3: vec![0.0; (c4 + c3) * hw(3)],
            e4: vec![0.0; c4 * hw(4)],
            d3: vec![0.0; d3 * hw(3)],
            d2: vec![0.0; d2 * hw(2)],
            d1: vec![0.0; d1 * hw(1)],
            logits: vec![0.0; c.outputs() * hw(1)],
            cols: vec![0.0; cols],
            cells: vec![0; hw(1)],
            up,
            map: None,
            objects: file.objects.clone(),
            layers,
            config: c,
        })
    }

    pub fn config(&self) -> &SegConfig {
        &self.config
    }

    /// The objects the network was trained for, in class order.
    pub fn objects(&self) -> &[ObjectEntry] {
        &self.objects
    }

    /// Logits of the last forward pass, `[K+1, out_h * out_w]` (channel 0 = background).
    pub fn logits(&self) -> &[f32] {
        &self.logits
    }

    /// Class id per output cell of the last [`SegEngine::segment`], `[out_h * out_w]`.
    pub fn cell_labels(&self) -> &[u16] {
        &self.cells
    }

    /// Segments `frame` into `labels_out` (`width * height` class ids, 0 = background).
    pub fn segment(&mut self, frame: &FrameView<'_>, labels_out: &mut [u16]) -> Result<(), SegError> {
        frame.validate()?;
        let (w, h) = (frame.width(), frame.height());
        if labels_out.len() != w * h {
            return Err(SegError::OutputLength { got: labels_out.len(), expected: w * h });
        }
        if !self.map.as_ref().is_some_and(|m| m.fits(w, h, &self.config)) {
            self.map = Some(FrameMap::new(w, h, &self.config));
        }
        let Some(map) = self.map.take() else { return Ok(()) };
        map.fill_input(frame, &mut self.input);
        self.run();
        self.argmax();
        map.upsample(&self.cells, labels_out);
        self.map = Some(map);
        Ok(())
    }

    /// Runs the network on a prepared input `[4, H0, W0]` and returns the logits `[K+1, H1*W1]`.
    pub fn forward(&mut self, input: &[f32]) -> Result<&[f32], SegError> {
        if input.len() != self.input.len() {
            return Err(SegError::InputLength { got: input.len(), expected: self.input.len() });
        }
        self.input.copy_from_slice(input);
        self.run();
        Ok(&self.logits)
    }

    fn run(&mut self) {
        let s = self.config.sizes();
        let hw = |l: usize| s[l].0 * s[l].1;
        let [c1, c2, c3, c4] = self.config.enc;
        let [d3c, d2c, d1c] = self.config.dec;
        let l = &self.layers;
        let cols = &mut self.cols;
        let conv = |li: usize, input: &[f32], c_in: usize, lvl: usize, stride: usize, cols: &mut [f32], out: &mut [f32], out_lvl: usize| {
            let o = l[li].w.nrows();
            let view = ArrayViewMut2::from_shape((o, hw(out_lvl)), &mut out[..o * hw(out_lvl)]).expect("layer buffer");
            conv3x3(input, c_in, s[lvl].0, s[lvl].1, stride, l[li].w.view(), l[li].b.view(), cols, view);
        };
        // Encoder; skip outputs land in the tail of their decoder's concat buffer.
        {
            let (_, e1) = self.cat1.split_at_mut(d2c * hw(1));
            conv(0, &self.input, INPUT_CHANNELS, 0, 2, cols, e1, 1);
        }
        {
            let e1 = &self.cat1[d2c * hw(1)..];
            let (_, e2) = self.cat2.split_at_mut(d3c * hw(2));
            conv(1, e1, c1, 1, 2, cols, e2, 2);
        }
        {
            let e2 = &self.cat2[d3c * hw(2)..];
            let (_, e3) = self.cat3.split_at_mut(c4 * hw(3));
            conv(2, e2, c2, 2, 2, cols, e3, 3);
        }
        {
            let e3 = &self.cat3[c4 * hw(3)..];
            conv(3, e3, c3, 3, 2, cols, &mut self.e4, 4);
        }
        // Decoder.
        let (ys, xs) = &self.up[0];
        upsample(&self.e4, c4, s[4].1, ys, xs, &mut self.cat3[..c4 * hw(3)]);
        conv(4, &self.cat3, c4 + c3, 3, 1, cols, &mut self.d3, 3);
        let (ys, xs) = &self.up[1];
        upsample(&self.d3, d3c, s[3].1, ys, xs, &mut self.cat2[..d3c * hw(2)]);
        conv(5, &self.cat2, d3c + c2, 2, 1, cols, &mut self.d2, 2);
        let (ys, xs) = &self.up[2];
        upsample(&self.d2, d2c, s[2].1, ys, xs, &mut self.cat1[..d2c * hw(1)]);
        conv(6, &self.cat1, d2c + c1, 1, 1, cols, &mut self.d1, 1);
        // Head: 1x1, no ReLU.
        let head = &l[7];
        let k = head.w.nrows();
        for (row, &b) in self.logits.chunks_exact_mut(hw(1)).zip(head.b.iter()) {
            row.fill(b);
        }
        let x = ArrayView2::from_shape((d1c, hw(1)), &self.d1[..]).expect("d1 buffer");
        let mut out = ArrayViewMut2::from_shape((k, hw(1)), &mut self.logits[..]).expect("logits buffer");
        gemm_acc(head.w.view(), x, &mut out);
    }

    /// Per-cell argmax of the logits (first maximum wins; NaN never wins).
    fn argmax(&mut self) {
        let n = self.cells.len();
        self.cells.fill(0);
        for (i, cell) in self.cells.iter_mut().enumerate() {
            let mut m = self.logits[i];
            for c in 1..self.config.outputs() {
                let v = self.logits[c * n + i];
                if v > m || m.is_nan() && !v.is_nan() {
                    m = v;
                    *cell = c as u16;
                }
            }
        }
    }
}
