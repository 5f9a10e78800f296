//! The segmenter in burn. Field names are the weight file's tensor names
//! (`e1.weight`, `head.bias`, …) and the architecture is fixed by
//! [`SegConfig`]; the inference engine (`fusepose_estimator::seg::engine`)
//! mirrors [`SegNet::forward`] operation for operation.

use burn::module::{Module, Param};
use burn::nn::PaddingConfig2d;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::prelude::{Device, Tensor};
use burn::tensor::activation::relu;
use burn::tensor::module::interpolate;
use burn::tensor::ops::{InterpolateMode, InterpolateOptions};
use fusepose_estimator::seg::SegConfig;

fn conv(i: usize, o: usize, k: usize, stride: usize, device: &Device) -> Conv2d {
    let pad = k / 2;
    Conv2dConfig::new([i, o], [k, k])
        .with_stride([stride, stride])
        .with_padding(PaddingConfig2d::Explicit(pad, pad, pad, pad))
        .init(device)
}

/// Encoder `e1..e4` (stride 2), decoder `d3, d2, d1` over `cat(up(prev), skip)`, 1x1 `head`,
/// the optional 1x1 centre-offset head `offset` ([`SegConfig::offsets`]) and
/// the optional branch `o1` it then reads instead of `d1` ([`SegConfig::offset_branch`]),
/// and the optional contact branch `b1` with its 1x1 head `contact` ([`SegConfig::contacts`]).
#[derive(Module, Debug)]
pub struct SegNet {
    pub e1: Conv2d,
    pub e2: Conv2d,
    pub e3: Conv2d,
    pub e4: Conv2d,
    pub d3: Conv2d,
    pub d2: Conv2d,
    pub d1: Conv2d,
    pub head: Conv2d,
    pub o1: Option<Conv2d>,
    pub offset: Option<Conv2d>,
    pub b1: Option<Conv2d>,
    pub contact: Option<Conv2d>,
}

/// What one forward pass gives: class logits `[B, K+1, H1, W1]`, and where
/// the network has them centre offsets `[B, 2, H1, W1]` and contact logits `[B, 1, H1, W1]`.
pub struct SegOutputs {
    pub logits: Tensor<4>,
    pub offsets: Option<Tensor<4>>,
    pub contacts: Option<Tensor<4>>,
}

fn up(x: Tensor<4>, like: &Tensor<4>) -> Tensor<4> {
    let [_, _, h, w] = like.dims();
    interpolate(x, InterpolateOptions::new(InterpolateMode::Nearest).with_output_size([h, w]))
}

impl SegNet {
    pub fn new(c: &SegConfig, device: &Device) -> Self {
        let mut layers = c.layers().into_iter().take(9).map(|(_, i, o, k, s)| conv(i, o, k, s, device));
        let mut next = || layers.next().expect("SegConfig::layers has at least eight layers");
        Self {
            e1: next(),
            e2: next(),
            e3: next(),
            e4: next(),
            d3: next(),
            d2: next(),
            d1: next(),
            head: next(),
            o1: (c.offsets && c.offset_branch).then(&mut next),
            offset: c.offsets.then(|| offset_head(c, device)),
            b1: c.contacts.then(|| conv(c.dec[1] + c.enc[0], c.dec[2], 3, 1, device)),
            contact: c.contacts.then(|| contact_head(c, device)),
        }
    }

    /// Adds the contact branch `b1`, a copy of `d1` as [`SegNet::with_offset_branch`]'s
    /// `o1`, and a fresh contact head over it (sure of no contact at the start).
    pub fn with_contact_branch(mut self, c: &SegConfig, device: &Device) -> Self {
        if self.b1.is_none() {
            self.b1 = Some(self.copy_of_d1(c, device));
            self.contact = Some(contact_head(c, device));
        }
        self
    }

    /// Adds the offset branch `o1`, a copy of `d1` (so the branch starts with
    /// the class features the head could already read), and a fresh offset
    /// head over it, replacing a head that read `d1`. With
    /// [`SegNet::frozen_trunk`] and the offset loss alone, only these two layers learn.
    pub fn with_offset_branch(mut self, c: &SegConfig, device: &Device) -> Self {
        if self.o1.is_none() {
            self.o1 = Some(self.copy_of_d1(c, device));
            self.offset = Some(offset_head(c, device));
        }
        self
    }

    /// A new layer over `d1`'s input holding `d1`'s weights: a branch that
    /// starts with the class features a head could already read.
    fn copy_of_d1(&self, c: &SegConfig, device: &Device) -> Conv2d {
        let mut layer = conv(c.dec[1] + c.enc[0], c.dec[2], 3, 1, device);
        layer.weight = Param::from_tensor(self.d1.weight.val());
        layer.bias = self.d1.bias.as_ref().map(|b| Param::from_tensor(b.val()));
        layer
    }

    /// Adds a freshly initialised offset head to a network loaded without one
    /// (resuming a file written before the head existed).
    pub fn with_offset_head(mut self, c: &SegConfig, device: &Device) -> Self {
        if self.offset.is_none() {
            self.offset = Some(offset_head(c, device));
        }
        self
    }

    /// Stops gradient tracking for every layer but the offset branch and head,
    /// so a step on the offset loss alone neither changes nor records the
    /// trunk (an autodiff graph of layers no loss reaches is never freed).
    /// With `contacts_only`, the offset branch and head are frozen too and
    /// only the contact branch learns.
    pub fn frozen_trunk(mut self, contacts_only: bool) -> Self {
        if contacts_only {
            self.o1 = self.o1.map(|l| l.no_grad());
            self.offset = self.offset.map(|l| l.no_grad());
        }
        for layer in [
            &mut self.e1,
            &mut self.e2,
            &mut self.e3,
            &mut self.e4,
            &mut self.d3,
            &mut self.d2,
            &mut self.d1,
            &mut self.head,
        ] {
            *layer = layer.clone().no_grad();
        }
        self
    }

    /// `x [B, 4, H0, W0]` → logits `[B, K+1, H1, W1]` (half resolution).
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        self.forward_all(x).0
    }

    /// Logits and, with the offset head, centre offsets `[B, 2, H1, W1]`.
    pub fn forward_all(&self, x: Tensor<4>) -> (Tensor<4>, Option<Tensor<4>>) {
        let out = self.forward_outputs(x);
        (out.logits, out.offsets)
    }

    /// Every output the network has.
    pub fn forward_outputs(&self, x: Tensor<4>) -> SegOutputs {
        let e1 = relu(self.e1.forward(x));
        let e2 = relu(self.e2.forward(e1.clone()));
        let e3 = relu(self.e3.forward(e2.clone()));
        let e4 = relu(self.e4.forward(e3.clone()));
        let d3 = relu(self.d3.forward(Tensor::cat(vec![up(e4, &e3), e3], 1)));
        let d2 = relu(self.d2.forward(Tensor::cat(vec![up(d3, &e2), e2], 1)));
        let cat1 = Tensor::cat(vec![up(d2, &e1), e1], 1);
        let d1 = relu(self.d1.forward(cat1.clone()));
        let offsets = self.offset.as_ref().map(|o| {
            o.forward(match &self.o1 {
                Some(o1) => relu(o1.forward(cat1.clone())),
                None => d1.clone(),
            })
        });
        let contacts =
            self.b1.as_ref().zip(self.contact.as_ref()).map(|(b1, head)| head.forward(relu(b1.forward(cat1))));
        SegOutputs { logits: self.head.forward(d1), offsets, contacts }
    }
}

/// The offset head starts at zero (every cell votes for itself), so a head
/// added to a trained segmenter does not disturb its features with large
/// random gradients at the start.
fn offset_head(c: &SegConfig, device: &Device) -> Conv2d {
    Conv2dConfig::new([c.dec[2], 2], [1, 1]).with_initializer(burn::nn::Initializer::Zeros).init(device)
}

/// The contact head starts sure of no contact anywhere (weights 0, bias
/// −3: a probability of 5 %), as contacts are a few cells in a hundred.
fn contact_head(c: &SegConfig, device: &Device) -> Conv2d {
    let mut head = Conv2dConfig::new([c.dec[2], 1], [1, 1]).with_initializer(burn::nn::Initializer::Zeros).init(device);
    head.bias = Some(Param::from_tensor(Tensor::<1>::full([1], -3.0, device)));
    head
}
