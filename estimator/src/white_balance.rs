//! A camera's white balance, done digitally before the networks, for a
//! frame whose light is strongly tinted.
//!
//! The segmenter learned object classes from colours as rendered, so a warm
//! cast (white-balance gains 1.0 / 0.82 / 0.6) costs it about 2 ADD(S) points
//! on the path-traced tuning splits where true masks lose 0.5
//! (docs/BENCHMARKS.md, session 46). Balancing every frame to gray (session
//! 20) moved the hues of well-lit frames and lost 8–16 points. Here the
//! light's colour is read from the frame's highlights (white patch: the
//! [`WhiteBalanceConfig::quantile`] of each channel in linear light, over
//! pixels none of whose channels is near saturation) as two log ratios,
//! `ln(R/G)` and `ln(B/G)`. Scenes of coloured objects under white light
//! spread those ratios by up to about ±0.6, so only the part of each ratio
//! beyond [`WhiteBalanceConfig::band`] is taken as the light's and undone, by
//! one gain per channel in linear light (green kept). A frame inside the band
//! is left as it is.
//!
//! Like [`crate::exposure`], a corrected frame's colour is mapped through
//! per-channel 256-entry tables into a buffer sized at the first frame of a
//! size; the producer's frame is untouched and nothing is allocated after
//! that first frame.

use fusepose_scene::render::srgb;

use crate::exposure::{METER_STRIDE, order_statistic};
use crate::frame::{ColorFormat, FrameView};

/// Settings of [`WhiteBalance`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WhiteBalanceConfig {
    /// Dead band of the log ratios `ln(R/G)`, `ln(B/G)` of the highlights:
    /// only the part beyond it is corrected.
    pub band: f64,
    /// Which share of the metered pixels lies below each channel's reading (0..1).
    pub quantile: f64,
}

impl Default for WhiteBalanceConfig {
    /// Chosen on the path-traced tuning splits (docs/BENCHMARKS.md, session
    /// 46): a band of 0.45 corrected nothing, 0.3 most of a warm cast.
    fn default() -> Self {
        Self { band: 0.3, quantile: 0.99 }
    }
}

impl WhiteBalanceConfig {
    /// Checks the settings; the message names the bad one.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.band >= 0.0 && self.band.is_finite()) {
            return Err(format!("band {} must be a log ratio of 0 or more", self.band));
        }
        if !(0.0..=1.0).contains(&self.quantile) {
            return Err(format!("quantile {} must be in 0..=1", self.quantile));
        }
        Ok(())
    }

    /// A setting as config files and command lines spell it: `off` (`None`),
    /// `on` (the defaults) or a comma list of `KEY=VALUE` over the defaults
    /// (`band`, `quantile`).
    pub fn parse_setting(s: &str) -> Result<Option<Self>, String> {
        crate::settings::parse_on_off(
            s,
            "white balance",
            |c: &mut Self, key, v| {
                match key {
                    "band" => c.band = v,
                    "quantile" => c.quantile = v,
                    other => return Err(format!("unknown key `{other}`; expected band or quantile")),
                }
                Ok(())
            },
            Self::validate,
        )
    }
}

/// Pixels with a channel at or above this sRGB code are clipped highlights:
/// their colour is the sensor's limit, not the light's.
const SATURATED: u8 = 250;

/// The white-balance stage of one camera (holds the corrected copy).
#[derive(Clone, Debug)]
pub struct WhiteBalance {
    config: WhiteBalanceConfig,
    /// sRGB code → linear light.
    decode: [f64; 256],
    /// Gain tables of the current frame, red, green, blue.
    luts: [[u8; 256]; 3],
    /// The corrected colour plane (sized at the first frame of a size).
    colour: Vec<u8>,
    /// Gains (red, green, blue) applied to the last frame (all 1 = untouched).
    last_gains: [f64; 3],
}

impl WhiteBalance {
    pub fn new(config: WhiteBalanceConfig) -> Self {
        Self {
            config,
            decode: std::array::from_fn(|v| srgb::decode(v as u8)),
            luts: [std::array::from_fn(|v| v as u8); 3],
            colour: Vec::new(),
            last_gains: [1.0; 3],
        }
    }

    pub fn config(&self) -> &WhiteBalanceConfig {
        &self.config
    }

    /// Gains (red, green, blue; linear light) applied to the last frame.
    pub fn last_gains(&self) -> [f64; 3] {
        self.last_gains
    }

    /// The highlights' log ratios `(ln(R/G), ln(B/G))` of an interleaved
    /// 8-bit plane whose channels are red, green, blue at `rgb_index`;
    /// `None` when no pixel is metered.
    pub fn highlight_ratios(&self, colour: &[u8], rgb_index: [usize; 3]) -> Option<(f64, f64)> {
        let mut histograms = [[0u32; 256]; 3];
        let mut n = 0usize;
        for px in colour.chunks_exact(3).step_by(METER_STRIDE) {
            if px[0].max(px[1]).max(px[2]) >= SATURATED {
                continue;
            }
            for (h, &i) in histograms.iter_mut().zip(&rgb_index) {
                h[px[i] as usize] += 1;
            }
            n += 1;
        }
        if n == 0 {
            return None;
        }
        // A black channel would make the ratio infinite.
        let reading = |h: &[u32; 256]| self.decode[order_statistic(h, n, self.config.quantile) as usize].max(1e-4);
        let [r, g, b] = histograms.each_ref().map(reading);
        Some(((r / g).ln(), (b / g).ln()))
    }

    /// Gains (red, green, blue) for a plane: each log ratio's part beyond the
    /// band undone, green kept.
    pub fn gains_for(&self, colour: &[u8], rgb_index: [usize; 3]) -> [f64; 3] {
        let Some((lr, lb)) = self.highlight_ratios(colour, rgb_index) else { return [1.0; 3] };
        let band = self.config.band;
        let excess = |l: f64| {
            if l > band {
                l - band
            } else if l < -band {
                l + band
            } else {
                0.0
            }
        };
        [(-excess(lr)).exp(), 1.0, (-excess(lb)).exp()]
    }

    fn fill_luts(&mut self, gains: [f64; 3]) {
        for (lut, gain) in self.luts.iter_mut().zip(gains) {
            for (v, out) in lut.iter_mut().enumerate() {
                *out = srgb::encode(self.decode[v] * gain);
            }
        }
    }

    /// The frame the networks should see: `None` when it is inside the band
    /// (use it as it is), else the frame with its colour corrected into this
    /// stage's buffer.
    pub fn apply<'a>(&'a mut self, frame: &FrameView<'a>) -> Option<FrameView<'a>> {
        // Sized on the first frame of a size: a camera whose light turns
        // warm minutes into a stream must not allocate then.
        if self.colour.len() != frame.color.len() {
            self.colour.resize(frame.color.len(), 0);
        }
        let rgb_index = rgb_index(frame.color_format);
        let gains = self.gains_for(frame.color, rgb_index);
        self.last_gains = gains;
        if gains == [1.0; 3] {
            return None;
        }
        self.fill_luts(gains);
        for (out, px) in self.colour.chunks_exact_mut(3).zip(frame.color.chunks_exact(3)) {
            for (channel, &i) in rgb_index.iter().enumerate() {
                out[i] = self.luts[channel][px[i] as usize];
            }
        }
        Some(FrameView { color: &self.colour, ..*frame })
    }

    /// The same correction in place on an RGB plane, for a caller that owns
    /// its frame (`fusepose eval`); returns the gains.
    pub fn apply_in_place(&mut self, rgb: &mut [u8]) -> [f64; 3] {
        let gains = self.gains_for(rgb, [0, 1, 2]);
        self.last_gains = gains;
        if gains != [1.0; 3] {
            self.fill_luts(gains);
            for px in rgb.chunks_exact_mut(3) {
                for (c, v) in px.iter_mut().enumerate() {
                    *v = self.luts[c][*v as usize];
                }
            }
        }
        gains
    }
}

/// Where red, green and blue sit in a pixel of `format`.
fn rgb_index(format: ColorFormat) -> [usize; 3] {
    match format {
        ColorFormat::Rgb8 => [0, 1, 2],
        ColorFormat::Bgr8 => [2, 1, 0],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::test_view as view;

    /// A scene of grey, red and blue patches under light of linear colour `light`.
    fn scene(width: usize, height: usize, light: [f64; 3]) -> Vec<u8> {
        let mut rgb = Vec::with_capacity(width * height * 3);
        for v in 0..height {
            for u in 0..width {
                let base = match (u / 16 + v / 16) % 4 {
                    0 => [0.5, 0.5, 0.5],
                    1 => [0.45, 0.12, 0.1],
                    2 => [0.1, 0.15, 0.4],
                    _ => [0.05, 0.05, 0.05],
                };
                let shade = 0.8 + 0.2 * ((u * 7 + v * 13) % 17) as f64 / 16.0;
                rgb.extend([0, 1, 2].map(|c| srgb::encode(base[c] * shade * light[c])));
            }
        }
        rgb
    }

    /// A strongly warm light: ln(R/G) = +0.36, ln(B/G) = −0.44 on neutral
    /// highlights, both beyond the band (the eval's warm cast, 1.0 / 0.82 /
    /// 0.6, gets there on scenes whose white-lit highlights lean warm).
    const WARM: [f64; 3] = [1.0, 0.7, 0.45];

    #[test]
    fn a_white_lit_frame_is_left_alone_and_a_warm_one_is_brought_back_to_the_band() {
        let (w, h) = (160, 120);
        let depth = vec![1.0f32; w * h];
        let mut wb = WhiteBalance::new(WhiteBalanceConfig::default());
        let white = scene(w, h, [1.0; 3]);
        let (lr, lb) = wb.highlight_ratios(&white, [0, 1, 2]).unwrap();
        assert!(lr.abs() < 0.3 && lb.abs() < 0.3, "white light reads ({lr}, {lb})");
        assert!(wb.apply(&view(&white, &depth, w, h, ColorFormat::Rgb8)).is_none());
        assert_eq!(wb.last_gains(), [1.0; 3]);
        // The warm light moves the ratios by ln(1 / 0.7) and ln(0.45 / 0.7).
        let warm = scene(w, h, WARM);
        let (wr, wl) = wb.highlight_ratios(&warm, [0, 1, 2]).unwrap();
        assert!((wr - lr - (1.0f64 / 0.7).ln()).abs() < 0.05, "{wr} vs {lr}");
        assert!((wl - lb - (0.45f64 / 0.7).ln()).abs() < 0.05, "{wl} vs {lb}");
        let corrected =
            wb.apply(&view(&warm, &depth, w, h, ColorFormat::Rgb8)).expect("a warm frame is corrected").color.to_vec();
        let gains = wb.last_gains();
        assert_eq!(gains[1], 1.0, "green is kept");
        assert!(gains[0] < 1.0 && gains[2] > 1.0, "{gains:?}");
        // Each byte is its channel's gain in linear light.
        for (i, (&out, &inp)) in corrected.iter().zip(&warm).enumerate().step_by(89) {
            assert_eq!(out, srgb::encode(srgb::decode(inp) * gains[i % 3]), "byte {i}");
        }
        // Afterwards both ratios sit on the band's edges.
        let (after_r, after_b) =
            WhiteBalance::new(WhiteBalanceConfig::default()).highlight_ratios(&corrected, [0, 1, 2]).unwrap();
        assert!((after_r - 0.3).abs() < 0.03 && (after_b + 0.3).abs() < 0.03, "({after_r}, {after_b})");
        // The producer's frame is untouched.
        assert_eq!(warm, scene(w, h, WARM));
    }

    #[test]
    fn bgr_frames_are_read_and_corrected_channel_for_channel() {
        let (w, h) = (96, 64);
        let depth = vec![1.0f32; w * h];
        let rgb = scene(w, h, WARM);
        let bgr: Vec<u8> = rgb.chunks_exact(3).flat_map(|p| [p[2], p[1], p[0]]).collect();
        let mut a = WhiteBalance::new(WhiteBalanceConfig::default());
        let mut b = WhiteBalance::new(WhiteBalanceConfig::default());
        let from_rgb = a.apply(&view(&rgb, &depth, w, h, ColorFormat::Rgb8)).unwrap().color.to_vec();
        let from_bgr = b.apply(&view(&bgr, &depth, w, h, ColorFormat::Bgr8)).unwrap().color.to_vec();
        assert_eq!(a.last_gains(), b.last_gains());
        let swapped: Vec<u8> = from_bgr.chunks_exact(3).flat_map(|p| [p[2], p[1], p[0]]).collect();
        assert_eq!(from_rgb, swapped);
        // In place on RGB does what the copy does.
        let mut in_place = rgb.clone();
        assert_eq!(WhiteBalance::new(WhiteBalanceConfig::default()).apply_in_place(&mut in_place), a.last_gains());
        assert_eq!(in_place, from_rgb);
    }

    #[test]
    fn settings_parse_and_bad_ones_name_the_key() {
        assert_eq!(WhiteBalanceConfig::parse_setting("off").unwrap(), None);
        assert_eq!(WhiteBalanceConfig::parse_setting("on").unwrap(), Some(WhiteBalanceConfig::default()));
        let c = WhiteBalanceConfig::parse_setting("band=0.2").unwrap().unwrap();
        assert_eq!((c.band, c.quantile), (0.2, 0.99));
        assert!(WhiteBalanceConfig::parse_setting("band=-1").unwrap_err().contains("band"));
        assert!(WhiteBalanceConfig::parse_setting("quantile=2").unwrap_err().contains("quantile"));
        assert!(WhiteBalanceConfig::parse_setting("gain=2").unwrap_err().contains("unknown key `gain`"));
    }
}
