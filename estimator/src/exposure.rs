//! A camera's auto exposure, done digitally before the networks: a frame
//! whose highlights are dim is brightened by one gain in linear light.
//!
//! The segmenter learned object classes from colours as rendered, so an
//! underexposed camera (−1.2 EV on the path-traced tuning splits) costs it
//! 2–9 ADD(S) points where true masks lose 0–3 (docs/BENCHMARKS.md, sessions
//! 38 and 42). Balancing every frame to gray (session 20) moved object hues
//! and lost 8–16 points; one gain for all three channels keeps hues, and
//! applying it only to frames darker than the training renders leaves those
//! alone. The meter is the [`ExposureConfig::quantile`] of each pixel's
//! brightest channel: a lit object's highlights, which a dark table does not
//! pull down (a frame's mean brightness does, and brightening well-exposed
//! frames over dark tables cost 0.4–1.1 points on the path-traced tuning split).
//!
//! The gain is `clamp(target / meter, 1, max_gain)`; at 1 nothing is copied.
//! Otherwise the colour plane is mapped through one 256-entry table into a
//! buffer sized at the first frame of a size (dim or not), so the estimator
//! sees a brightened copy and the producer's frame is untouched. No
//! allocation after that first frame.

use fusepose_scene::render::srgb;

use crate::frame::FrameView;

/// Settings of [`AutoExposure`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExposureConfig {
    /// Brightness (linear, 0..1) the meter is brought up to.
    pub target: f64,
    /// Which share of the metered pixels lies below the meter reading (0..1).
    pub quantile: f64,
    /// Largest gain applied.
    pub max_gain: f64,
}

impl Default for ExposureConfig {
    /// Chosen on the tuning splits (docs/BENCHMARKS.md, sessions 42 and 46):
    /// the 90th percentile of the brightest channel brought up to 0.2, gain
    /// at most 4. At 0.28 (session 42) some uncast path-traced frames were
    /// brightened too and lost up to 0.35 ADD(S); at 0.2 only the dim casts
    /// change (+0.2 to +2.3 on four path-traced tuning splits), and the
    /// stage is on by default (`estimator.auto_exposure`).
    fn default() -> Self {
        Self { target: 0.2, quantile: 0.9, max_gain: 4.0 }
    }
}

impl ExposureConfig {
    /// Checks the settings; the message names the bad one.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.target > 0.0 && self.target <= 1.0) {
            return Err(format!("target {} must be in (0, 1] (linear brightness)", self.target));
        }
        if !(0.0..=1.0).contains(&self.quantile) {
            return Err(format!("quantile {} must be in 0..=1", self.quantile));
        }
        if !(self.max_gain >= 1.0 && self.max_gain.is_finite()) {
            return Err(format!("max_gain {} must be at least 1", self.max_gain));
        }
        Ok(())
    }
}

impl ExposureConfig {
    /// A setting as config files and command lines spell it: `off` (`None`),
    /// `on` (the defaults) or a comma list of `KEY=VALUE` over the defaults
    /// (`target`, `quantile`, `max-gain`).
    pub fn parse_setting(s: &str) -> Result<Option<Self>, String> {
        crate::settings::parse_on_off(
            s,
            "auto exposure",
            |c: &mut Self, key, v| {
                match key {
                    "target" => c.target = v,
                    "quantile" => c.quantile = v,
                    "max-gain" => c.max_gain = v,
                    other => return Err(format!("unknown key `{other}`; expected target, quantile or max-gain")),
                }
                Ok(())
            },
            Self::validate,
        )
    }
}

/// Every `METER_STRIDE`-th pixel is metered.
pub(crate) const METER_STRIDE: usize = 7;

/// The 8-bit code at index `⌊(n − 1) · quantile⌋` of the sorted readings
/// that `histogram` counts (`n` of them, at least one).
pub(crate) fn order_statistic(histogram: &[u32; 256], n: usize, quantile: f64) -> u8 {
    let index = ((n.max(1) - 1) as f64 * quantile) as usize;
    let mut below = 0usize;
    for (code, &count) in histogram.iter().enumerate() {
        below += count as usize;
        if below > index {
            return code as u8;
        }
    }
    255
}

/// The auto-exposure stage of one camera (holds the brightened copy).
#[derive(Clone, Debug)]
pub struct AutoExposure {
    config: ExposureConfig,
    /// sRGB code → linear light.
    decode: [f64; 256],
    /// Gain table of the current frame.
    lut: [u8; 256],
    /// The brightened colour plane (sized at the first frame that needs it).
    colour: Vec<u8>,
    /// Gain of the last frame looked at (1 = untouched).
    last_gain: f64,
}

impl AutoExposure {
    pub fn new(config: ExposureConfig) -> Self {
        Self {
            config,
            decode: std::array::from_fn(|v| srgb::decode(v as u8)),
            lut: std::array::from_fn(|v| v as u8),
            colour: Vec::new(),
            last_gain: 1.0,
        }
    }

    pub fn config(&self) -> &ExposureConfig {
        &self.config
    }

    /// Gain applied to the last frame (1 when it was left as it was).
    pub fn last_gain(&self) -> f64 {
        self.last_gain
    }

    /// The meter: the configured quantile of the metered pixels' brightest
    /// channel, in linear light (the order statistic at index
    /// `⌊(n − 1) · quantile⌋` of the sorted readings). 0 for an empty plane.
    pub fn meter(&self, colour: &[u8]) -> f64 {
        let mut histogram = [0u32; 256];
        let mut n = 0usize;
        for px in colour.chunks_exact(3).step_by(METER_STRIDE) {
            histogram[px[0].max(px[1]).max(px[2]) as usize] += 1;
            n += 1;
        }
        if n == 0 {
            return 0.0;
        }
        self.decode[order_statistic(&histogram, n, self.config.quantile) as usize]
    }

    /// The gain for a colour plane: `clamp(target / meter, 1, max_gain)`.
    pub fn gain_for(&self, colour: &[u8]) -> f64 {
        let meter = self.meter(colour);
        if meter <= 0.0 {
            return self.config.max_gain;
        }
        (self.config.target / meter).clamp(1.0, self.config.max_gain)
    }

    fn fill_lut(&mut self, gain: f64) {
        for (v, out) in self.lut.iter_mut().enumerate() {
            *out = srgb::encode(self.decode[v] * gain);
        }
    }

    /// The frame the networks should see: `None` when its gain is 1 (use it
    /// as it is), else the frame with its colour plane brightened into this
    /// stage's buffer.
    pub fn apply<'a>(&'a mut self, frame: &FrameView<'a>) -> Option<FrameView<'a>> {
        // Sized on the first frame of a size, dim or not: a camera that turns
        // dim minutes into a stream must not allocate then.
        if self.colour.len() != frame.color.len() {
            self.colour.resize(frame.color.len(), 0);
        }
        let gain = self.gain_for(frame.color);
        self.last_gain = gain;
        if gain <= 1.0 {
            return None;
        }
        self.fill_lut(gain);
        for (out, &v) in self.colour.iter_mut().zip(frame.color) {
            *out = self.lut[v as usize];
        }
        Some(FrameView { color: &self.colour, ..*frame })
    }

    /// The same brightening in place, for a caller that owns its frame
    /// (`fusepose eval`); returns the gain.
    pub fn apply_in_place(&mut self, colour: &mut [u8]) -> f64 {
        let gain = self.gain_for(colour);
        self.last_gain = gain;
        if gain > 1.0 {
            self.fill_lut(gain);
            for v in colour.iter_mut() {
                *v = self.lut[*v as usize];
            }
        }
        gain
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{ColorFormat, test_view};

    /// A frame-sized colour plane: a dark table with a few lit patches.
    fn scene(width: usize, height: usize, exposure: f64) -> Vec<u8> {
        let mut rgb = Vec::with_capacity(width * height * 3);
        for v in 0..height {
            for u in 0..width {
                let lit = (u / 16 + v / 16) % 5 == 0;
                let base = if lit { [0.4, 0.26, 0.15] } else { [0.03, 0.04, 0.05] };
                let shade = 0.8 + 0.2 * ((u * 7 + v * 13) % 17) as f64 / 16.0;
                rgb.extend(base.map(|c| srgb::encode(c * shade * exposure)));
            }
        }
        rgb
    }

    fn view<'a>(rgb: &'a [u8], depth: &'a [f32], w: usize, h: usize) -> FrameView<'a> {
        test_view(rgb, depth, w, h, ColorFormat::Rgb8)
    }

    #[test]
    fn the_meter_is_the_order_statistic_of_the_brightest_channel() {
        let ae = AutoExposure::new(ExposureConfig::default());
        let mut state = 0x2545_f491_4f6c_dd1du64;
        for len in [1usize, 2, 7, 8, 50, 1000, 4321] {
            let rgb: Vec<u8> = (0..len * 3)
                .map(|_| {
                    state ^= state << 13;
                    state ^= state >> 7;
                    state ^= state << 17;
                    (state >> 56) as u8
                })
                .collect();
            let mut sorted: Vec<f64> = rgb
                .chunks_exact(3)
                .step_by(METER_STRIDE)
                .map(|px| px.iter().map(|&v| srgb::decode(v)).fold(0.0, f64::max))
                .collect();
            sorted.sort_by(f64::total_cmp);
            let expected = sorted[((sorted.len() - 1) as f64 * 0.9) as usize];
            assert_eq!(ae.meter(&rgb), expected, "{len} pixels");
        }
        assert_eq!(ae.meter(&[]), 0.0);
    }

    #[test]
    fn an_underexposed_frame_is_brought_back_and_a_well_exposed_one_is_left_alone() {
        let (w, h) = (160, 120);
        let depth = vec![1.0f32; w * h];
        let bright = scene(w, h, 1.0);
        let dim = scene(w, h, (-1.2f64).exp2());
        let target = ExposureConfig::default().target;
        let mut ae = AutoExposure::new(ExposureConfig::default());
        // The lit patches meter above the target: nothing is copied.
        assert!(ae.meter(&bright) > target);
        assert!(ae.apply(&view(&bright, &depth, w, h)).is_none());
        assert_eq!(ae.last_gain(), 1.0);
        // At −1.2 EV the meter falls below it; the gain brings it to the target.
        let meter = ae.meter(&dim);
        assert!(meter < target, "{meter}");
        let gained = ae.apply(&view(&dim, &depth, w, h)).expect("a dim frame is brightened");
        let gain = target / meter;
        for (i, (&out, &inp)) in gained.color.iter().zip(&dim).enumerate().step_by(97) {
            assert_eq!(out, srgb::encode(srgb::decode(inp) * gain), "pixel byte {i}");
        }
        assert!((AutoExposure::new(ExposureConfig::default()).meter(gained.color) - target).abs() < 0.01);
        // One gain for all channels: hue (channel ratios in linear light) kept on a lit pixel.
        let lit = (0..w * h).find(|&p| dim[3 * p] > 60).unwrap();
        let ratio = |px: &[u8]| srgb::decode(px[0]) / srgb::decode(px[2]);
        assert!((ratio(&gained.color[3 * lit..]) / ratio(&dim[3 * lit..]) - 1.0).abs() < 0.05);
        // The producer's frame is untouched; the other planes pass through.
        assert_eq!(dim, scene(w, h, (-1.2f64).exp2()));
        assert_eq!(gained.depth.len(), w * h);
    }

    #[test]
    fn the_gain_is_capped_and_in_place_matches_the_copy() {
        let (w, h) = (64, 48);
        let depth = vec![1.0f32; w * h];
        let dark = scene(w, h, 0.02);
        let mut ae = AutoExposure::new(ExposureConfig { max_gain: 2.5, ..ExposureConfig::default() });
        let copy = ae.apply(&view(&dark, &depth, w, h)).unwrap().color.to_vec();
        assert_eq!(ae.last_gain(), 2.5);
        let mut in_place = dark.clone();
        assert_eq!(ae.apply_in_place(&mut in_place), 2.5);
        assert_eq!(in_place, copy);
        // A black frame gets the largest gain and stays black.
        let mut black = vec![0u8; 30];
        assert_eq!(ae.apply_in_place(&mut black), 2.5);
        assert!(black.iter().all(|&v| v == 0));
    }

    #[test]
    fn settings_parse_as_config_files_spell_them() {
        assert_eq!(ExposureConfig::parse_setting("off"), Ok(None));
        assert_eq!(ExposureConfig::parse_setting("on"), Ok(Some(ExposureConfig::default())));
        let c = ExposureConfig::parse_setting("target=0.3,max-gain=2").unwrap().unwrap();
        assert_eq!((c.target, c.quantile, c.max_gain), (0.3, 0.9, 2.0));
        for (bad, says) in [
            ("bright", "KEY=VALUE"),
            ("gain=2", "unknown key `gain`"),
            ("target=x", "needs a number"),
            ("quantile=2", "quantile 2"),
        ] {
            let e = ExposureConfig::parse_setting(bad).unwrap_err();
            assert!(e.starts_with("auto exposure") && e.contains(says), "{bad}: {e}");
        }
    }

    #[test]
    fn settings_outside_their_ranges_are_named() {
        let bad = |c: ExposureConfig| c.validate().unwrap_err();
        let d = ExposureConfig::default();
        assert!(d.validate().is_ok());
        assert!(bad(ExposureConfig { target: 0.0, ..d }).starts_with("target"));
        assert!(bad(ExposureConfig { target: 1.5, ..d }).starts_with("target"));
        assert!(bad(ExposureConfig { quantile: -0.1, ..d }).starts_with("quantile"));
        assert!(bad(ExposureConfig { max_gain: 0.5, ..d }).starts_with("max_gain"));
        assert!(bad(ExposureConfig { max_gain: f64::NAN, ..d }).starts_with("max_gain"));
    }
}
