//! The fusion network in burn: colour encoder–decoder, pose net (per-point
//! quaternion, translation offset and confidence) and the integrated refiner.
//!
//! The architecture is fixed by [`NetConfig`]; field names are the tensor names
//! of the weight file (`cnn.e1.weight`, `pose.l1.bias`, …), and the inference
//! engine (`fusepose_estimator::net`) mirrors this file operation for operation.
//!
//! Conventions: points in the camera optical frame, metres; quaternions
//! `[x, y, z, w]`; rotation matrices act on column vectors (`p_cam = R p_obj + t`).
//! Choices recorded: geometry inputs are centred on the points' mean and scaled
//! by `geo_scale` (10 → decimetres); translation outputs are offsets in units of
//! `offset_scale` metres added to each point's own position; the refiner's
//! residual quaternion is `raw + [0, 0, 0, 1]` so a fresh refiner starts near identity.

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{Linear, LinearConfig, PaddingConfig2d};
use burn::prelude::{Device, Int, Tensor, TensorData};
use burn::tensor::activation::{relu, sigmoid};
use burn::tensor::module::interpolate;
use burn::tensor::ops::{InterpolateMode, InterpolateOptions};
use fusepose_estimator::net::NetConfig;

use crate::geometry::quat_to_rot;

fn conv3(i: usize, o: usize, stride: usize, device: &Device) -> Conv2d {
    Conv2dConfig::new([i, o], [3, 3])
        .with_stride([stride, stride])
        .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
        .init(device)
}

fn lin(i: usize, o: usize, device: &Device) -> Linear {
    LinearConfig::new(i, o).init(device)
}

/// Colour encoder–decoder: crop `[B,3,S,S]` → per-point embedding `[B,N,emb]`.
#[derive(Module, Debug)]
pub struct ColorCnn {
    pub e1: Conv2d,
    pub e2: Conv2d,
    pub e3: Conv2d,
    pub e4: Conv2d,
    pub d1: Conv2d,
    /// The full-resolution 1x1 decoder layer, evaluated only at the chosen pixels.
    pub d2: Linear,
}

impl ColorCnn {
    pub fn new(c: &NetConfig, device: &Device) -> Self {
        let [c1, c2, c3] = c.cnn;
        Self {
            e1: conv3(3, c1, 1, device),
            e2: conv3(c1, c2, 2, device),
            e3: conv3(c2, c3, 2, device),
            e4: conv3(c3, c3, 1, device),
            d1: conv3(c3 + c2, c.emb, 1, device),
            d2: lin(c.emb + c1, c.emb, device),
        }
    }

    /// `choose`: pixel index `row * S + col` of each point in the crop; `choose_half`:
    /// `(row / 2) * (S / 2) + col / 2` (nearest upsampling of the half-resolution decoder).
    pub fn forward(&self, crops: Tensor<4>, choose: Tensor<2, Int>, choose_half: Tensor<2, Int>) -> Tensor<3> {
        let [b, _, s, _] = crops.dims();
        let n = choose.dims()[1];
        let e1 = relu(self.e1.forward(crops));
        let e2 = relu(self.e2.forward(e1.clone()));
        let e3 = relu(self.e3.forward(e2.clone()));
        let e4 = relu(self.e4.forward(e3));
        let up = interpolate(e4, InterpolateOptions::new(InterpolateMode::Nearest).with_output_size([s / 2, s / 2]));
        let d1 = relu(self.d1.forward(Tensor::cat(vec![up, e2], 1)));
        let [_, emb, h2, w2] = d1.dims();
        let c1 = e1.dims()[1];
        let idx_half = choose_half.unsqueeze_dim::<3>(1).repeat_dim(1, emb);
        let g_d1 = d1.reshape([b, emb, h2 * w2]).gather(2, idx_half);
        let idx = choose.unsqueeze_dim::<3>(1).repeat_dim(1, c1);
        let g_e1 = e1.reshape([b, c1, s * s]).gather(2, idx);
        let x = Tensor::cat(vec![g_d1, g_e1], 1).swap_dims(1, 2);
        debug_assert_eq!(x.dims()[1], n);
        relu(self.d2.forward(x))
    }
}

/// Per-point outputs of the pose net.
#[derive(Clone, Debug)]
pub struct PoseOut {
    /// `[B,N,4]` raw quaternions `[x, y, z, w]` (not normalised).
    pub quat: Tensor<3>,
    /// `[B,N,3]` translations (point + offset), metres.
    pub trans: Tensor<3>,
    /// `[B,N]` confidences in (0, 1).
    pub conf: Tensor<2>,
}

/// Selects row `class` of a `[B,N,K*w]` head output → `[B,N,w]`.
fn select_class3(x: Tensor<3>, classes: &[usize], w: usize) -> Tensor<3> {
    let [b, n, kw] = x.dims();
    let k = kw / w;
    let device = x.device();
    let idx: Vec<i64> = classes.iter().flat_map(|&c| std::iter::repeat_n(c as i64, n * w)).collect();
    let idx = Tensor::<4, Int>::from_data(TensorData::new(idx, [b, n, 1, w]), &device);
    x.reshape([b, n, k, w]).gather(2, idx).reshape([b, n, w])
}

/// The pose net (PointNet geometry + colour fusion + per-point heads).
#[derive(Module, Debug)]
pub struct PoseNet {
    pub g1: Linear,
    pub g2: Linear,
    pub c1: Linear,
    pub c2: Linear,
    pub l1: Linear,
    pub l2: Linear,
    pub h1_local: Linear,
    pub h1_global: Linear,
    pub h2: Linear,
    pub rot: Linear,
    pub tra: Linear,
    pub conf: Linear,
}

impl PoseNet {
    pub fn new(c: &NetConfig, device: &Device) -> Self {
        let k = c.num_classes;
        Self {
            g1: lin(3, c.geo[0], device),
            g2: lin(c.geo[0], c.geo[1], device),
            c1: lin(c.emb, c.col[0], device),
            c2: lin(c.col[0], c.col[1], device),
            l1: lin(c.geo[1] + c.col[1], c.lift[0], device),
            l2: lin(c.lift[0], c.lift[1], device),
            h1_local: lin(c.local_width(), c.trunk[0], device),
            h1_global: LinearConfig::new(c.lift[1], c.trunk[0]).with_bias(false).init(device),
            h2: lin(c.trunk[0], c.trunk[1], device),
            rot: lin(c.trunk[1], 4 * k, device),
            tra: lin(c.trunk[1], 3 * k, device),
            conf: lin(c.trunk[1], k, device),
        }
    }

    /// `points [B,N,3]` camera frame metres, `emb [B,N,emb]`, `classes` 0-based per instance.
    pub fn forward(&self, c: &NetConfig, points: Tensor<3>, emb: Tensor<3>, classes: &[usize]) -> PoseOut {
        let [b, n, _] = points.dims();
        let mean = points.clone().mean_dim(1);
        let x = (points.clone() - mean).mul_scalar(c.geo_scale);
        let g1 = relu(self.g1.forward(x));
        let g2 = relu(self.g2.forward(g1.clone()));
        let c1 = relu(self.c1.forward(emb));
        let c2 = relu(self.c2.forward(c1.clone()));
        let l1 = relu(self.l1.forward(Tensor::cat(vec![g2.clone(), c2.clone()], 2)));
        let l2 = relu(self.l2.forward(l1));
        let global = l2.mean_dim(1); // [B,1,G]
        let local = Tensor::cat(vec![g1, c1, g2, c2], 2);
        let hg = self.h1_global.forward(global);
        let h1 = relu(self.h1_local.forward(local) + hg);
        let h2 = relu(self.h2.forward(h1));
        let quat = select_class3(self.rot.forward(h2.clone()), classes, 4);
        let off = select_class3(self.tra.forward(h2.clone()), classes, 3).mul_scalar(c.offset_scale);
        let conf = sigmoid(select_class3(self.conf.forward(h2), classes, 1)).reshape([b, n]);
        PoseOut { quat, trans: points + off, conf }
    }
}

/// The refiner: residual pose from points seen in the current estimate's object frame.
#[derive(Module, Debug)]
pub struct Refiner {
    pub g1: Linear,
    pub g2: Linear,
    pub c1: Linear,
    pub c2: Linear,
    pub l1: Linear,
    pub l2: Linear,
    pub m1: Linear,
    pub rot: Linear,
    pub tra: Linear,
}

/// The refiner's colour features, computed once per instance and reused every iteration.
#[derive(Clone, Debug)]
pub struct RefineColor {
    pub c1: Tensor<3>,
    pub c2: Tensor<3>,
}

impl Refiner {
    pub fn new(c: &NetConfig, device: &Device) -> Self {
        let k = c.num_classes;
        Self {
            g1: lin(3, c.geo[0], device),
            g2: lin(c.geo[0], c.geo[1], device),
            c1: lin(c.emb, c.col[0], device),
            c2: lin(c.col[0], c.col[1], device),
            l1: lin(c.local_width(), c.ref_lift[0], device),
            l2: lin(c.ref_lift[0], c.ref_lift[1], device),
            m1: lin(c.ref_lift[1], c.ref_head, device),
            rot: lin(c.ref_head, 4 * k, device),
            tra: lin(c.ref_head, 3 * k, device),
        }
    }

    pub fn color(&self, emb: Tensor<3>) -> RefineColor {
        let c1 = relu(self.c1.forward(emb));
        let c2 = relu(self.c2.forward(c1.clone()));
        RefineColor { c1, c2 }
    }

    /// One refinement: `rot [B,3,3]`, `trans [B,3]` (current estimate) → refined `(rot, trans)`.
    pub fn step(
        &self,
        c: &NetConfig,
        points: Tensor<3>,
        color: &RefineColor,
        rot: Tensor<3>,
        trans: Tensor<2>,
        classes: &[usize],
    ) -> (Tensor<3>, Tensor<2>) {
        let [b, _, _] = points.dims();
        // Row vectors: (p - t)^T R = (R^T (p - t))^T, the points in the estimate's object frame.
        let local_pts = (points - trans.clone().unsqueeze_dim::<3>(1)).matmul(rot.clone());
        let x = local_pts.mul_scalar(c.geo_scale);
        let g1 = relu(self.g1.forward(x));
        let g2 = relu(self.g2.forward(g1.clone()));
        let local = Tensor::cat(vec![g1, color.c1.clone(), g2, color.c2.clone()], 2);
        let l1 = relu(self.l1.forward(local));
        let l2 = relu(self.l2.forward(l1));
        let global = l2.mean_dim(1); // [B,1,R2]
        let m1 = relu(self.m1.forward(global));
        let dq = select_class3(self.rot.forward(m1.clone()), classes, 4).reshape([b, 4]);
        let identity = Tensor::<2>::from_data(TensorData::new(vec![0.0f32, 0.0, 0.0, 1.0], [1, 4]), &dq.device());
        let dq = dq + identity;
        let dt = select_class3(self.tra.forward(m1), classes, 3).reshape([b, 3]).mul_scalar(c.offset_scale);
        let dr = quat_to_rot(dq); // [B,3,3]
        let new_rot = rot.clone().matmul(dr);
        let new_t = trans + rot.matmul(dt.reshape([b, 3, 1])).reshape([b, 3]);
        (new_rot, new_t)
    }
}

/// The whole network.
#[derive(Module, Debug)]
pub struct FusionNet {
    pub cnn: ColorCnn,
    pub pose: PoseNet,
    pub refine: Refiner,
}

impl FusionNet {
    pub fn new(c: &NetConfig, device: &Device) -> Self {
        Self { cnn: ColorCnn::new(c, device), pose: PoseNet::new(c, device), refine: Refiner::new(c, device) }
    }

    /// The trunk — colour CNN and every layer of the pose net and refiner
    /// that does not depend on the class count, the tensors a warm start
    /// copies — set to learn or not. The per-class output layers
    /// (`pose.rot|tra|conf`, `refine.rot|tra`) always learn. A frozen trunk
    /// records no autodiff graph, so a step costs its forward pass and the
    /// heads' backward pass only.
    pub fn with_trunk_learning(mut self, learn: bool) -> Self {
        self.cnn = self.cnn.set_require_grad(learn);
        let p = &mut self.pose;
        for layer in [
            &mut p.g1,
            &mut p.g2,
            &mut p.c1,
            &mut p.c2,
            &mut p.l1,
            &mut p.l2,
            &mut p.h1_local,
            &mut p.h1_global,
            &mut p.h2,
        ] {
            *layer = layer.clone().set_require_grad(learn);
        }
        let r = &mut self.refine;
        for layer in [&mut r.g1, &mut r.g2, &mut r.c1, &mut r.c2, &mut r.l1, &mut r.l2, &mut r.m1] {
            *layer = layer.clone().set_require_grad(learn);
        }
        self
    }
}
