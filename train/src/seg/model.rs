//! The segmenter in burn. Field names are the weight file's tensor names
//! (`e1.weight`, `head.bias`, …) and the architecture is fixed by
//! [`SegConfig`]; the inference engine (`fusepose_estimator::seg::engine`)
//! mirrors [`SegNet::forward`] operation for operation.

use burn::module::{Module, Param};
use burn::nn::PaddingConfig2d;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::prelude::{Device, Tensor, TensorData};
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

    /// The same function at larger widths `to` (Net2Net-style): each layer's
    /// trained weights fill the leading block of its wider copy; the new
    /// output channels keep their fresh initialisation, and every weight that
    /// reads a new channel starts at zero, so the wider network computes
    /// exactly what this one did and the new channels learn from there.
    /// `to` must differ from `from` only in `enc` / `dec`, none narrower.
    pub fn widened(&self, from: &SegConfig, to: &SegConfig, device: &Device) -> anyhow::Result<Self> {
        let same = SegConfig { enc: from.enc, dec: from.dec, ..to.clone() };
        if &same != from {
            anyhow::bail!("widening changes only the channel widths: {from:?} -> {to:?}");
        }
        if to.enc.iter().zip(&from.enc).chain(to.dec.iter().zip(&from.dec)).any(|(t, f)| t < f) {
            anyhow::bail!(
                "widths {:?} / {:?} are narrower than the file's {:?} / {:?}",
                to.enc,
                to.dec,
                from.enc,
                from.dec
            );
        }
        let mut wide = SegNet::new(to, device);
        let ([c1, c2, c3, c4], [d3, d2, d1]) = (from.enc, from.dec);
        let ([_, _, _, w4], [v3, v2, _]) = (to.enc, to.dec);
        // Input channel runs `(old start, new start, length)`; a decoder layer
        // reads `cat(up(previous), skip)`, so its skip channels move.
        let single = |n: usize| vec![(0, 0, n)];
        let cat = |up_old: usize, up_new: usize, skip: usize| vec![(0, 0, up_old), (up_old, up_new, skip)];
        let pairs: [(&Conv2d, &mut Conv2d, Runs); 8] = [
            (&self.e1, &mut wide.e1, single(fusepose_estimator::seg::config::INPUT_CHANNELS)),
            (&self.e2, &mut wide.e2, single(c1)),
            (&self.e3, &mut wide.e3, single(c2)),
            (&self.e4, &mut wide.e4, single(c3)),
            (&self.d3, &mut wide.d3, cat(c4, w4, c3)),
            (&self.d2, &mut wide.d2, cat(d3, v3, c2)),
            (&self.d1, &mut wide.d1, cat(d2, v2, c1)),
            (&self.head, &mut wide.head, single(d1)),
        ];
        for (old, new, runs) in pairs {
            copy_into(old, new, &runs, device);
        }
        for (old, new, runs) in [
            (&self.o1, &mut wide.o1, cat(d2, v2, c1)),
            (&self.offset, &mut wide.offset, single(d1)),
            (&self.b1, &mut wide.b1, cat(d2, v2, c1)),
            (&self.contact, &mut wide.contact, single(d1)),
        ] {
            if let (Some(old), Some(new)) = (old, new.as_mut()) {
                copy_into(old, new, &runs, device);
            }
        }
        Ok(wide)
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

/// Input channel runs `(old start, new start, length)` of [`copy_into`].
type Runs = Vec<(usize, usize, usize)>;

/// Writes `old`'s weights into the leading output rows of `new`, input
/// channels placed by `runs` (`(old start, new start, length)`); the inputs
/// no run covers get weight 0 in those rows, the other rows stay as they were.
fn copy_into(old: &Conv2d, new: &mut Conv2d, runs: &Runs, device: &Device) {
    let [o_old, i_old, kh, kw] = old.weight.dims();
    let [o_new, i_new, _, _] = new.weight.dims();
    let k = kh * kw;
    let src = old.weight.val().into_data().try_to_vec::<f32>().expect("f32 weights");
    let mut dst = new.weight.val().into_data().try_to_vec::<f32>().expect("f32 weights");
    for o in 0..o_old {
        dst[o * i_new * k..(o + 1) * i_new * k].fill(0.0);
        for &(from, to, n) in runs {
            for i in 0..n {
                let s = (o * i_old + from + i) * k;
                let d = (o * i_new + to + i) * k;
                dst[d..d + k].copy_from_slice(&src[s..s + k]);
            }
        }
    }
    new.weight = Param::from_tensor(Tensor::from_data(TensorData::new(dst, [o_new, i_new, kh, kw]), device));
    if let (Some(ob), Some(nb)) = (&old.bias, &new.bias) {
        let src = ob.val().into_data().try_to_vec::<f32>().expect("f32 bias");
        let mut dst = nb.val().into_data().try_to_vec::<f32>().expect("f32 bias");
        dst[..src.len()].copy_from_slice(&src);
        new.bias = Some(Param::from_tensor(Tensor::from_data(TensorData::new(dst, [o_new]), device)));
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

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::Distribution;

    fn values(t: Tensor<4>) -> Vec<f32> {
        t.into_data().try_to_vec::<f32>().expect("f32")
    }

    #[test]
    fn a_widened_network_computes_what_it_was_widened_from() {
        let device = Device::default();
        let narrow = SegConfig { offset_branch: true, contacts: true, ..SegConfig::new(3) };
        let wide = SegConfig { enc: [20, 40, 72, 80], dec: [40, 24, 20], ..narrow.clone() };
        let net = SegNet::new(&narrow, &device);
        let widened = net.widened(&narrow, &wide, &device).unwrap();
        assert_eq!(widened.e1.weight.dims(), [20, 4, 3, 3]);
        assert_eq!(widened.d3.weight.dims(), [40, 80 + 72, 3, 3]);
        assert_eq!(widened.b1.as_ref().unwrap().weight.dims(), [20, 24 + 20, 3, 3]);
        let x = Tensor::<4>::random([2, 4, 24, 32], Distribution::Uniform(-1.0, 1.0), &device);
        let (a, b) = (net.forward_outputs(x.clone()), widened.forward_outputs(x));
        for (u, v) in
            [(a.logits, b.logits), (a.offsets.unwrap(), b.offsets.unwrap()), (a.contacts.unwrap(), b.contacts.unwrap())]
        {
            let (u, v) = (values(u), values(v));
            assert_eq!(u.len(), v.len());
            let worst = u.iter().zip(&v).map(|(p, q)| (p - q).abs()).fold(0.0f32, f32::max);
            assert!(worst < 1e-4, "outputs differ by {worst}");
        }
        // The new channels are there: they compute something (fresh incoming
        // weights), only their outgoing weights start at zero.
        let e1 = values(widened.e1.weight.val());
        assert!(e1[16 * 36..].iter().any(|&w| w != 0.0));
        let e2 = values(widened.e2.weight.val());
        assert!((0..32).all(|o| e2[o * 20 * 9 + 16 * 9..(o + 1) * 20 * 9].iter().all(|&w| w == 0.0)));
    }

    #[test]
    fn widening_refuses_narrower_widths_and_other_changes() {
        let device = Device::default();
        let c = SegConfig::new(3);
        let net = SegNet::new(&c, &device);
        let narrower = SegConfig { enc: [8, 32, 64, 64], ..c.clone() };
        assert!(net.widened(&c, &narrower, &device).unwrap_err().to_string().contains("narrower"));
        let other = SegConfig { num_classes: 4, enc: [32, 32, 64, 64], ..c.clone() };
        assert!(net.widened(&c, &other, &device).unwrap_err().to_string().contains("only the channel widths"));
    }
}
