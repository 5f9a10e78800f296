//! Hyper-parameters of the fusion network (pose net + integrated refiner).
//!
//! Every size lives here and is stored with the weights (as JSON in the
//! safetensors metadata under [`crate::net::meta::KEY_CONFIG`]), so the trainer
//! and the inference engine build exactly the same architecture.
//!
//! Conventions: points in the camera optical frame (x right, y down, z forward),
//! metres; quaternions `[x, y, z, w]`; a pose maps object to camera coordinates.

use serde::{Deserialize, Serialize};

/// Architecture of the fusion network. Layer names (tensor names in the weight
/// file) follow the trainer's module paths, e.g. `pose.l1.weight`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NetConfig {
    /// Object classes K (class id `k` selects head row `k - 1`).
    pub num_classes: usize,
    /// Side S of the square colour crop the network was trained on (pixels; divisible by 4).
    pub crop_size: usize,
    /// Points N per instance the network was trained on (the architecture itself
    /// accepts any N: everything per point plus an average pool).
    pub num_points: usize,
    /// Colour encoder channels: `e1` (3x3, stride 1), `e2` (3x3, stride 2), `e3`/`e4` (3x3, stride 2 / 1).
    pub cnn: [usize; 3],
    /// Per-pixel colour embedding channels (decoder output).
    pub emb: usize,
    /// Geometry PointNet widths (1x1 convs `3 -> geo[0] -> geo[1]`).
    pub geo: [usize; 2],
    /// Colour per-point widths (`emb -> col[0] -> col[1]`).
    pub col: [usize; 2],
    /// Fusion lift (`geo[1] + col[1] -> lift[0] -> lift[1]`); `lift[1]` is the global feature.
    pub lift: [usize; 2],
    /// Per-point head trunk (`local + global -> trunk[0] -> trunk[1]`).
    pub trunk: [usize; 2],
    /// Refiner lift (`local features -> ref_lift[0] -> ref_lift[1]` = refiner global feature).
    pub ref_lift: [usize; 2],
    /// Refiner head hidden width (global -> ref_head -> K x (4 + 3)).
    pub ref_head: usize,
    /// Default refiner iterations at inference.
    pub refine_iters: usize,
    /// Geometry inputs are multiplied by this (metres -> network units; 10 = decimetres).
    pub geo_scale: f32,
    /// Translation outputs are multiplied by this to give metres (0.1 = decimetres).
    pub offset_scale: f32,
}

impl NetConfig {
    /// The default ("lean") architecture for `num_classes` objects.
    pub fn new(num_classes: usize) -> Self {
        Self {
            num_classes,
            crop_size: 64,
            num_points: 256,
            cnn: [16, 32, 64],
            emb: 32,
            geo: [64, 128],
            col: [64, 128],
            lift: [256, 512],
            trunk: [256, 128],
            ref_lift: [128, 256],
            ref_head: 128,
            refine_iters: 2,
            geo_scale: 10.0,
            offset_scale: 0.1,
        }
    }

    /// Largest accepted `num_classes` (class ids are u16).
    pub const MAX_CLASSES: usize = u16::MAX as usize;
    /// Largest accepted `crop_size` (as `WorkspaceConfig`).
    pub const MAX_CROP_SIZE: usize = 1024;
    /// Largest accepted `num_points` (as `WorkspaceConfig`).
    pub const MAX_POINTS: usize = 1 << 20;
    /// Largest accepted layer width (`cnn`, `emb`, `geo`, `col`, `lift`, `trunk`, `ref_lift`, `ref_head`).
    pub const MAX_WIDTH: usize = 1 << 16;
    /// Largest accepted default refiner iteration count.
    pub const MAX_REFINE_ITERS: usize = 100;

    /// Largest accepted activation size of one instance, f32 values (1 GiB).
    pub const MAX_ACTIVATION_FLOATS: usize = 1 << 28;

    /// Upper bound of the f32 activations one instance needs at `num_points`
    /// and `crop_size` (what [`crate::net::Scratch::new`] allocates). Only
    /// called by `validate` after the width bounds, so nothing overflows.
    fn activation_floats(&self) -> usize {
        let [c1, c2, c3] = self.cnn;
        let lw = self.local_width();
        let per_point = [
            8, // points, choose, gx
            self.emb + c1,
            self.emb,
            2 * lw,
            self.lift[0],
            self.lift[1],
            self.trunk[0],
            self.trunk[1],
            8, // quat, trans, conf
            self.ref_lift[0],
            self.ref_lift[1],
        ];
        let per_pixel = [30, 10 * c1, 10 * c2, 10 * c3, 10 * c3, 10 * (c2 + c3), self.emb];
        let sum = |v: &[usize]| v.iter().fold(0usize, |a, &b| a.saturating_add(b));
        sum(&per_point)
            .saturating_mul(self.num_points)
            .saturating_add(sum(&per_pixel).saturating_mul(self.crop_size.saturating_mul(self.crop_size)))
    }

    /// Width of the per-point local feature `[g1 | c1 | g2 | c2]`.
    pub fn local_width(&self) -> usize {
        self.geo[0] + self.col[0] + self.geo[1] + self.col[1]
    }

    /// Checks internal consistency (non-zero sizes, S divisible by 4) and
    /// bounds every size read from a file (see [`NetConfig::MAX_WIDTH`] and
    /// friends), so a corrupt or hostile config is refused here instead of
    /// overflowing, exhausting memory or spinning when the engine is built.
    pub fn validate(&self) -> Result<(), String> {
        let sizes = [
            self.num_classes,
            self.crop_size,
            self.num_points,
            self.cnn[0],
            self.cnn[1],
            self.cnn[2],
            self.emb,
            self.geo[0],
            self.geo[1],
            self.col[0],
            self.col[1],
            self.lift[0],
            self.lift[1],
            self.trunk[0],
            self.trunk[1],
            self.ref_lift[0],
            self.ref_lift[1],
            self.ref_head,
        ];
        if sizes.contains(&0) {
            return Err("a layer size is zero".into());
        }
        if self.num_classes > Self::MAX_CLASSES {
            return Err(format!("{} classes, at most {} (u16 class ids)", self.num_classes, Self::MAX_CLASSES));
        }
        if self.crop_size > Self::MAX_CROP_SIZE || self.num_points > Self::MAX_POINTS {
            return Err(format!(
                "crop size {} / {} points exceed {} / {}",
                self.crop_size,
                self.num_points,
                Self::MAX_CROP_SIZE,
                Self::MAX_POINTS
            ));
        }
        if let Some(w) = sizes[3..].iter().find(|&&w| w > Self::MAX_WIDTH) {
            return Err(format!("layer width {w} exceeds {}", Self::MAX_WIDTH));
        }
        if self.refine_iters > Self::MAX_REFINE_ITERS {
            return Err(format!("{} refiner iterations, at most {}", self.refine_iters, Self::MAX_REFINE_ITERS));
        }
        let floats = self.activation_floats();
        if floats > Self::MAX_ACTIVATION_FLOATS {
            return Err(format!(
                "activations of {} points and a {}-pixel crop need {floats} floats, at most {}",
                self.num_points,
                self.crop_size,
                Self::MAX_ACTIVATION_FLOATS
            ));
        }
        if !self.crop_size.is_multiple_of(4) {
            return Err(format!("crop size {} is not divisible by 4", self.crop_size));
        }
        if !(self.geo_scale.is_finite()
            && self.geo_scale > 0.0
            && self.offset_scale.is_finite()
            && self.offset_scale > 0.0)
        {
            return Err("geo_scale and offset_scale must be positive".into());
        }
        Ok(())
    }

    /// Every weight tensor of the network with its shape, in a fixed order.
    /// Linear layers are `[in, out]` (x · W + b); convolutions `[out, in, 3, 3]`.
    pub fn tensor_shapes(&self) -> Vec<(String, Vec<usize>)> {
        let k = self.num_classes;
        let [c1, c2, c3] = self.cnn;
        let mut v: Vec<(String, Vec<usize>)> = Vec::new();
        let mut conv = |name: &str, i: usize, o: usize| {
            v.push((format!("{name}.weight"), vec![o, i, 3, 3]));
            v.push((format!("{name}.bias"), vec![o]));
        };
        conv("cnn.e1", 3, c1);
        conv("cnn.e2", c1, c2);
        conv("cnn.e3", c2, c3);
        conv("cnn.e4", c3, c3);
        conv("cnn.d1", c3 + c2, self.emb);
        let mut lin = |name: &str, i: usize, o: usize, bias: bool| {
            v.push((format!("{name}.weight"), vec![i, o]));
            if bias {
                v.push((format!("{name}.bias"), vec![o]));
            }
        };
        lin("cnn.d2", self.emb + c1, self.emb, true);
        lin("pose.g1", 3, self.geo[0], true);
        lin("pose.g2", self.geo[0], self.geo[1], true);
        lin("pose.c1", self.emb, self.col[0], true);
        lin("pose.c2", self.col[0], self.col[1], true);
        lin("pose.l1", self.geo[1] + self.col[1], self.lift[0], true);
        lin("pose.l2", self.lift[0], self.lift[1], true);
        lin("pose.h1_local", self.local_width(), self.trunk[0], true);
        lin("pose.h1_global", self.lift[1], self.trunk[0], false);
        lin("pose.h2", self.trunk[0], self.trunk[1], true);
        lin("pose.rot", self.trunk[1], 4 * k, true);
        lin("pose.tra", self.trunk[1], 3 * k, true);
        lin("pose.conf", self.trunk[1], k, true);
        lin("refine.g1", 3, self.geo[0], true);
        lin("refine.g2", self.geo[0], self.geo[1], true);
        lin("refine.c1", self.emb, self.col[0], true);
        lin("refine.c2", self.col[0], self.col[1], true);
        lin("refine.l1", self.local_width(), self.ref_lift[0], true);
        lin("refine.l2", self.ref_lift[0], self.ref_lift[1], true);
        lin("refine.m1", self.ref_lift[1], self.ref_head, true);
        lin("refine.rot", self.ref_head, 4 * k, true);
        lin("refine.tra", self.ref_head, 3 * k, true);
        v
    }

    /// Floating-point operations (2 per multiply-add) of one object at inference:
    /// colour branch, pose net (only the instance's head rows) and `iters` refiner iterations,
    /// for `n` points and an `s`×`s` crop.
    pub fn flops_per_object(&self, n: usize, s: usize, iters: usize) -> f64 {
        let [c1, c2, c3] = self.cnn;
        let (s1, s2, s4) = ((s * s) as f64, ((s / 2) * (s / 2)) as f64, ((s / 4) * (s / 4)) as f64);
        let n = n as f64;
        let f = |v: usize| v as f64;
        let cnn = s1 * f(c1 * 27)
            + s2 * f(c2 * c1 * 9)
            + s4 * f(c3 * c2 * 9 + c3 * c3 * 9)
            + s2 * f(self.emb * (c3 + c2) * 9)
            + n * f((self.emb + c1) * self.emb);
        let [g0, g1] = self.geo;
        let [k0, k1] = self.col;
        let lw = self.local_width();
        let pose =
            n * f(3 * g0 + g0 * g1 + self.emb * k0 + k0 * k1 + (g1 + k1) * self.lift[0] + self.lift[0] * self.lift[1])
                + n * f(lw * self.trunk[0] + self.trunk[0] * self.trunk[1] + self.trunk[1] * 8)
                + f(self.lift[1] * self.trunk[0]);
        let ref_color = n * f(self.emb * k0 + k0 * k1);
        let ref_iter = n * f(3 * g0 + g0 * g1 + lw * self.ref_lift[0] + self.ref_lift[0] * self.ref_lift[1])
            + f(self.ref_lift[1] * self.ref_head + self.ref_head * 7);
        2.0 * (cnn + pose + if iters > 0 { ref_color } else { 0.0 } + iters as f64 * ref_iter)
    }

    /// Number of parameters.
    pub fn parameter_count(&self) -> usize {
        self.tensor_shapes().iter().map(|(_, s)| s.iter().product::<usize>()).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_config_is_valid_and_small() {
        let c = NetConfig::new(5);
        c.validate().unwrap();
        assert_eq!(c.local_width(), 384);
        let p = c.parameter_count();
        assert!(p > 300_000 && p < 2_500_000, "{p} parameters");
    }

    #[test]
    fn sizes_a_file_could_abuse_are_bounded() {
        // Found by the `model` fuzz target: these passed `validate` and then
        // overflowed or aborted on allocation in `Scratch::new`, or spun.
        let huge = |edit: fn(&mut NetConfig)| {
            let mut c = NetConfig::new(3);
            edit(&mut c);
            c.validate().unwrap_err()
        };
        huge(|c| c.crop_size = 4_000_000_000_000);
        huge(|c| c.num_points = 1_000_000_000_000_000);
        huge(|c| c.geo[1] = usize::MAX);
        huge(|c| c.num_classes = 70_000);
        huge(|c| c.refine_iters = 1 << 40);
        // Within each bound but too much memory together.
        huge(|c| (c.num_points, c.lift) = (NetConfig::MAX_POINTS, [4096, 4096]));
        let mut big = NetConfig::new(21);
        (big.num_points, big.crop_size) = (4096, 256);
        big.validate().unwrap();
    }

    #[test]
    fn bad_crop_size_is_refused() {
        let mut c = NetConfig::new(1);
        c.crop_size = 62;
        assert!(c.validate().is_err());
    }
}
