//! Colour constancy before the networks: a camera's white balance or
//! exposure that differs from the training renders (a warm or cool cast, a
//! dim cell) costs the segmenter 2-5 ADD(S) points on path-traced images
//! (docs/BENCHMARKS.md, issue 19). Gray-world balancing in linear light
//! moves a frame's channel means together before the segmenter and the pose
//! network see it; optionally one exposure gain brings its mean brightness to
//! that of the training renders.
//!
//! The gains come from a subsample of the frame; the pixels are then mapped
//! through one 256-entry table per channel, in place. No allocation.

/// What [`WhiteBalance::balance`] does.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Mode {
    /// Pixels untouched.
    #[default]
    Off,
    /// Gray world: per-channel gains that make the three linear channel means
    /// equal to their average (mean brightness kept).
    GrayWorld,
    /// Gray world, then one gain that brings the mean linear brightness to
    /// the target.
    GrayWorldExposure,
}

impl std::str::FromStr for Mode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "off" => Ok(Mode::Off),
            "gray" => Ok(Mode::GrayWorld),
            "gray-ev" => Ok(Mode::GrayWorldExposure),
            other => Err(format!("`{other}`: expected \"off\", \"gray\" or \"gray-ev\"")),
        }
    }
}

/// Largest per-channel correction (and its inverse as the smallest): a scene
/// that is mostly one colour is not balanced to gray.
pub const MAX_CHANNEL_GAIN: f32 = 2.0;
/// Largest exposure gain (its inverse is the smallest).
pub const MAX_EXPOSURE_GAIN: f32 = 4.0;
/// Every `SUBSAMPLE`-th pixel is measured.
const SUBSAMPLE: usize = 7;

/// Gray-world balancing of interleaved RGB8 frames.
#[derive(Clone, Debug)]
pub struct WhiteBalance {
    mode: Mode,
    /// Mean linear brightness (0..1) of the training renders, for `GrayWorldExposure`.
    target: f32,
    decode: [f32; 256],
    /// Linear light → sRGB code, at 4096 steps.
    encode: Vec<u8>,
    luts: [[u8; 256]; 3],
}

impl WhiteBalance {
    /// `target`: the mean linear brightness `GrayWorldExposure` aims at.
    pub fn new(mode: Mode, target: f32) -> Self {
        let decode = std::array::from_fn(|v| srgb_decode(v as u8) as f32);
        let encode = (0..4096).map(|i| srgb_encode(i as f64 / 4095.0)).collect();
        Self { mode, target, decode, encode, luts: [[0; 256]; 3] }
    }

    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// Balances `rgb` (interleaved RGB8) in place; returns the linear gains
    /// applied (R, G, B), all 1 when off or for a black frame.
    pub fn balance(&mut self, rgb: &mut [u8]) -> [f32; 3] {
        if self.mode == Mode::Off || rgb.len() < 3 {
            return [1.0; 3];
        }
        let (mut sum, mut n) = ([0.0f64; 3], 0usize);
        for px in rgb.chunks_exact(3).step_by(SUBSAMPLE) {
            for c in 0..3 {
                sum[c] += self.decode[px[c] as usize] as f64;
            }
            n += 1;
        }
        let mean = sum.map(|s| (s / n as f64) as f32);
        let gray = (mean[0] + mean[1] + mean[2]) / 3.0;
        if gray.is_nan() || gray <= 0.0 {
            return [1.0; 3];
        }
        let lo = 1.0 / MAX_CHANNEL_GAIN;
        let mut gains = mean.map(|m| if m > 0.0 { (gray / m).clamp(lo, MAX_CHANNEL_GAIN) } else { 1.0 });
        if self.mode == Mode::GrayWorldExposure {
            let ev = (self.target / gray).clamp(1.0 / MAX_EXPOSURE_GAIN, MAX_EXPOSURE_GAIN);
            gains = gains.map(|g| g * ev);
        }
        for (lut, g) in self.luts.iter_mut().zip(gains) {
            for (v, out) in lut.iter_mut().enumerate() {
                let l = (self.decode[v] * g).clamp(0.0, 1.0);
                *out = self.encode[(l * 4095.0).round() as usize];
            }
        }
        for px in rgb.chunks_exact_mut(3) {
            for (v, lut) in px.iter_mut().zip(&self.luts) {
                *v = lut[*v as usize];
            }
        }
        gains
    }

    /// Mean linear brightness of `rgb`, for choosing a target.
    pub fn brightness(&self, rgb: &[u8]) -> f32 {
        let (mut sum, mut n) = (0.0f64, 0usize);
        for px in rgb.chunks_exact(3).step_by(SUBSAMPLE) {
            sum += px.iter().map(|&v| self.decode[v as usize] as f64).sum::<f64>() / 3.0;
            n += 1;
        }
        if n == 0 { 0.0 } else { (sum / n as f64) as f32 }
    }
}

/// sRGB code value → linear light in 0..=1 (IEC 61966-2-1).
pub fn srgb_decode(v: u8) -> f64 {
    let c = v as f64 / 255.0;
    if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }
}

/// Linear light → sRGB code value (clipped, rounded).
pub fn srgb_encode(l: f64) -> u8 {
    let l = l.clamp(0.0, 1.0);
    let c = if l <= 0.003_130_8 { 12.92 * l } else { 1.055 * l.powf(1.0 / 2.4) - 0.055 };
    (c * 255.0).round() as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame of two surfaces, linear colours `a` and `b`, encoded to sRGB.
    fn frame(a: [f32; 3], b: [f32; 3], gains: [f32; 3]) -> Vec<u8> {
        (0..640 * 48)
            .flat_map(|i| if i % 5 < 3 { a } else { b })
            .enumerate()
            .map(|(i, v)| srgb_encode((v * gains[i % 3]) as f64))
            .collect()
    }

    #[test]
    fn a_cast_is_undone_up_to_rounding_and_off_touches_nothing() {
        let (a, b) = ([0.30, 0.25, 0.20], [0.10, 0.14, 0.16]);
        let plain = frame(a, b, [1.0; 3]);
        let mut reference = plain.clone();
        // With exposure, a cast frame and the plain one end at one brightness.
        let mut wb = WhiteBalance::new(Mode::GrayWorldExposure, 0.2);
        let plain_gains = wb.balance(&mut reference);
        for cast in [[1.0, 0.82, 0.6], [0.75, 0.88, 1.0]] {
            let mut f = frame(a, b, cast);
            let gains = wb.balance(&mut f);
            // Cast then balanced = plain then balanced: gain × cast = the plain frame's gain.
            for c in 0..3 {
                assert!((gains[c] * cast[c] / plain_gains[c] - 1.0).abs() < 0.02, "{gains:?} vs {plain_gains:?}");
            }
            let worst = f.iter().zip(&reference).map(|(x, y)| (*x as i32 - *y as i32).abs()).max().unwrap();
            assert!(worst <= 3, "cast {cast:?} left a difference of {worst} levels");
        }
        let mut untouched = plain.clone();
        assert_eq!(WhiteBalance::new(Mode::Off, 0.2).balance(&mut untouched), [1.0; 3]);
        assert_eq!(untouched, plain);
    }

    #[test]
    fn exposure_brings_a_dim_frame_to_the_target() {
        let mut f = frame([0.08, 0.08, 0.08], [0.04, 0.04, 0.04], [1.0; 3]);
        let mut wb = WhiteBalance::new(Mode::GrayWorldExposure, 0.2);
        wb.balance(&mut f);
        assert!((wb.brightness(&f) - 0.2).abs() < 0.01, "{}", wb.brightness(&f));
        let mut black = vec![0u8; 300];
        assert_eq!(wb.balance(&mut black), [1.0; 3]);
    }
}
