//! The segmenter's architecture: input resolution, channel widths, the layer
//! list with tensor names and shapes, and the cost (multiply–adds) of one frame.
//!
//! Layers (all 3x3 convolutions with padding 1 and ReLU, except the 1x1 head):
//! encoder `e1..e4` with stride 2 (`4 → enc[0] → … → enc[3]`); decoder `d3, d2, d1`
//! at the resolution of `e3, e2, e1`, each over `cat(nearest_up(previous), skip)`
//! (upsampled channels first); `head` 1x1 `dec[2] → num_classes + 1` logits at
//! half the input resolution. Output channel 0 is background, channel `c` class id `c`.
//! With [`SegConfig::offsets`], a second 1x1 head `offset` (`dec[2] → 2`) predicts
//! each cell's offset to the centre of its object instance (x then y, in units
//! of [`OFFSET_UNIT_CELLS`] output cells), which separates touching objects of
//! one class (centre-offset voting, as in Panoptic-DeepLab and PVN3D). With
//! [`SegConfig::offset_branch`] the offset head reads its own 3x3 layer `o1`
//! (same input and width as `d1`) instead of `d1`, so offsets can be trained
//! onto a finished segmenter without touching its class outputs.
//! With [`SegConfig::contacts`], a branch `b1` (3x3, as `o1`) and a 1x1 head
//! `contact` (`dec[2] → 1`) give each cell's logit of lying where two object
//! instances touch; the second look cuts a region along them
//! (`crate::recut::CutProposal::Contacts`).

use serde::{Deserialize, Serialize};

/// Input channels: normalised R, G, B and depth in metres (0 = missing).
pub const INPUT_CHANNELS: usize = 4;

/// Output cells per unit of the offset head: an output of 1.0 means 10 cells
/// (80 pixels of a 640x480 frame), which keeps the regression targets near ±1.
pub const OFFSET_UNIT_CELLS: f32 = 10.0;

/// Hyper-parameters fixing the tensor layout of a segmenter file.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct SegConfig {
    /// Objects (output channels are `num_classes + 1`, background first).
    pub num_classes: usize,
    /// Network input size in pixels (the frame is box-filtered down to it).
    pub input_width: usize,
    pub input_height: usize,
    /// Encoder widths `e1..e4`.
    pub enc: [usize; 4],
    /// Decoder widths `d3, d2, d1`.
    pub dec: [usize; 3],
    /// Whether the file has the instance centre-offset head (files written
    /// before it existed read as `false`).
    #[serde(default)]
    pub offsets: bool,
    /// Whether the offset head has its own layer `o1` (over `d1`'s input)
    /// rather than reading `d1` (files written before it existed read as `false`).
    #[serde(default)]
    pub offset_branch: bool,
    /// Whether the file has the contact branch `b1` and head `contact`
    /// (files written before it existed read as `false`).
    #[serde(default)]
    pub contacts: bool,
}

/// Size of a 3x3, padding-1 convolution's output along one axis.
#[inline]
pub fn conv_out(size: usize, stride: usize) -> usize {
    (size + 2 - 3) / stride + 1
}

impl SegConfig {
    /// The default architecture for `num_classes` objects: 160x120 input,
    /// encoder 16-32-64-64, decoder 32-16-16.
    pub fn new(num_classes: usize) -> Self {
        Self {
            num_classes,
            input_width: 160,
            input_height: 120,
            enc: [16, 32, 64, 64],
            dec: [32, 16, 16],
            offsets: true,
            offset_branch: false,
            contacts: false,
        }
    }

    /// Output channels (objects + background).
    pub fn outputs(&self) -> usize {
        self.num_classes + 1
    }

    /// `(height, width)` of the input and after each encoder block:
    /// index 0 = input, 1 = e1 (= logits), 2 = e2, 3 = e3, 4 = e4.
    pub fn sizes(&self) -> [(usize, usize); 5] {
        let mut s = [(self.input_height, self.input_width); 5];
        for i in 1..5 {
            s[i] = (conv_out(s[i - 1].0, 2), conv_out(s[i - 1].1, 2));
        }
        s
    }

    /// `(height, width)` of the logits (half the input resolution).
    pub fn output_size(&self) -> (usize, usize) {
        self.sizes()[1]
    }

    /// Checks widths and sizes; the message says what is wrong.
    pub fn validate(&self) -> Result<(), String> {
        if self.num_classes == 0 || self.num_classes > u16::MAX as usize - 1 {
            return Err(format!("num_classes {} must be in 1..65535", self.num_classes));
        }
        if !(16..=1024).contains(&self.input_width) || !(16..=1024).contains(&self.input_height) {
            return Err(format!(
                "input size {}x{} must be within 16..=1024 on each side",
                self.input_width, self.input_height
            ));
        }
        if self.enc.iter().chain(&self.dec).any(|&c| c == 0 || c > 1024) {
            return Err("channel widths must be in 1..=1024".into());
        }
        Ok(())
    }

    /// Every layer: `(name, input channels, output channels, kernel, stride)`.
    pub fn layers(&self) -> Vec<(&'static str, usize, usize, usize, usize)> {
        let [c1, c2, c3, c4] = self.enc;
        let [d3, d2, d1] = self.dec;
        let mut layers = vec![
            ("e1", INPUT_CHANNELS, c1, 3, 2),
            ("e2", c1, c2, 3, 2),
            ("e3", c2, c3, 3, 2),
            ("e4", c3, c4, 3, 2),
            ("d3", c4 + c3, d3, 3, 1),
            ("d2", d3 + c2, d2, 3, 1),
            ("d1", d2 + c1, d1, 3, 1),
            ("head", d1, self.outputs(), 1, 1),
        ];
        if self.offsets && self.offset_branch {
            layers.push(("o1", d2 + c1, d1, 3, 1));
        }
        if self.offsets {
            layers.push(("offset", d1, 2, 1, 1));
        }
        if self.contacts {
            layers.push(("b1", d2 + c1, d1, 3, 1));
            layers.push(("contact", d1, 1, 1, 1));
        }
        layers
    }

    /// Every tensor of a file with its shape (PyTorch layout `[O, I, kH, kW]`, bias `[O]`).
    pub fn tensor_shapes(&self) -> Vec<(String, Vec<usize>)> {
        self.layers()
            .into_iter()
            .flat_map(|(name, i, o, k, _)| {
                [(format!("{name}.weight"), vec![o, i, k, k]), (format!("{name}.bias"), vec![o])]
            })
            .collect()
    }

    /// Number of trainable parameters.
    pub fn parameter_count(&self) -> usize {
        self.tensor_shapes().iter().map(|(_, s)| s.iter().product::<usize>()).sum()
    }

    /// Multiply–adds of one forward pass (convolutions only; FLOPs ≈ 2 × this).
    pub fn macs(&self) -> usize {
        let s = self.sizes();
        let at = |level: usize| s[level].0 * s[level].1;
        // Output resolution of each layer in `layers()` order.
        let levels = [1, 2, 3, 4, 3, 2, 1, 1, 1, 1, 1, 1];
        self.layers().into_iter().zip(levels).map(|((_, i, o, k, _), l)| at(l) * o * i * k * k).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_sizes_and_cost() {
        let c = SegConfig { offsets: false, ..SegConfig::new(8) };
        assert_eq!(c.sizes(), [(120, 160), (60, 80), (30, 40), (15, 20), (8, 10)]);
        assert_eq!(c.output_size(), (60, 80));
        assert_eq!(c.tensor_shapes().len(), 16);
        assert_eq!(c.tensor_shapes()[0], ("e1.weight".to_string(), vec![16, 4, 3, 3]));
        // e1 4800*16*36 + e2 1200*32*144 + e3 300*64*288 + e4 80*64*576
        // + d3 300*32*1152 + d2 1200*16*576 + d1 4800*16*288 + head 4800*9*16
        let expect = 4800 * 16 * 36
            + 1200 * 32 * 144
            + 300 * 64 * 288
            + 80 * 64 * 576
            + 300 * 32 * 1152
            + 1200 * 16 * 576
            + 4800 * 16 * 288
            + 4800 * 9 * 16;
        assert_eq!(c.macs(), expect);
        assert!(c.validate().is_ok());
        let with = SegConfig::new(8);
        assert_eq!(with.tensor_shapes().len(), 18);
        assert_eq!(with.tensor_shapes()[16], ("offset.weight".to_string(), vec![2, 16, 1, 1]));
        assert_eq!(with.macs(), expect + 4800 * 2 * 16);
        // The branch: `o1` like d1 (4800*16*288) before the offset head.
        let branch = SegConfig { offset_branch: true, ..SegConfig::new(8) };
        assert_eq!(branch.tensor_shapes().len(), 20);
        assert_eq!(branch.tensor_shapes()[16], ("o1.weight".to_string(), vec![16, 32, 3, 3]));
        assert_eq!(branch.tensor_shapes()[18], ("offset.weight".to_string(), vec![2, 16, 1, 1]));
        assert_eq!(branch.macs(), expect + 4800 * 16 * 288 + 4800 * 2 * 16);
        // A branch without the head is no layer at all.
        let no_head = SegConfig { offsets: false, offset_branch: true, ..SegConfig::new(8) };
        assert_eq!(no_head.layers().len(), 8);
        // The contact branch: `b1` like d1, then a one-channel head, after the offset layers.
        let contacts = SegConfig { offsets: false, contacts: true, ..SegConfig::new(8) };
        assert_eq!(contacts.tensor_shapes().len(), 20);
        assert_eq!(contacts.tensor_shapes()[16], ("b1.weight".to_string(), vec![16, 32, 3, 3]));
        assert_eq!(contacts.tensor_shapes()[18], ("contact.weight".to_string(), vec![1, 16, 1, 1]));
        assert_eq!(contacts.macs(), expect + 4800 * 16 * 288 + 4800 * 16);
        let both = SegConfig { offset_branch: true, contacts: true, ..SegConfig::new(8) };
        assert_eq!(both.layers().iter().map(|l| l.0).collect::<Vec<_>>()[8..], ["o1", "offset", "b1", "contact"]);
    }

    #[test]
    fn files_without_the_offset_flag_read_as_without_offsets() {
        let json = r#"{"num_classes":8,"input_width":160,"input_height":120,"enc":[16,32,64,64],"dec":[32,16,16]}"#;
        let c: SegConfig = serde_json::from_str(json).unwrap();
        assert!(!c.offsets);
        assert_eq!(c.layers().len(), 8);
    }

    #[test]
    fn validate_refuses_bad_configs() {
        assert!(SegConfig::new(0).validate().is_err());
        let mut c = SegConfig::new(3);
        c.input_width = 4;
        assert!(c.validate().is_err());
        let mut c = SegConfig::new(3);
        c.dec[1] = 0;
        assert!(c.validate().is_err());
    }
}
