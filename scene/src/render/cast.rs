//! Colour-cast variants of stored images, so that an accuracy table can
//! carry a robustness column (issue 19; `fusepose eval --cast`,
//! `fusepose-bench e2e --cast`). Each cast acts on a frame's RGB in linear
//! light: sRGB-decoded values are scaled per channel (white balance warm /
//! cool, or −1.2 EV) and re-encoded to sRGB; `dim` then adds Gaussian sensor
//! noise of σ = 3 8-bit levels, seeded per frame so that runs repeat. Depth,
//! masks and ground truth are untouched.

use super::srgb;

/// A colour cast applied to each frame before estimation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cast {
    /// The images as stored.
    None,
    /// Warm white balance: linear gains (1.0, 0.82, 0.6).
    Warm,
    /// Cool white balance: linear gains (0.75, 0.88, 1.0).
    Cool,
    /// −1.2 EV (× 2^−1.2 in linear light) plus Gaussian noise, σ = 3 levels.
    Dim,
}

/// Standard deviation of `dim`'s sensor noise, in 8-bit sRGB levels.
const DIM_NOISE_LEVELS: f64 = 3.0;

impl std::str::FromStr for Cast {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|c| c.name() == s)
            .ok_or_else(|| format!("unknown colour cast {s:?}: expected one of none, warm, cool, dim"))
    }
}

impl Cast {
    /// Every cast, in the order tables list them.
    pub const ALL: [Cast; 4] = [Cast::None, Cast::Warm, Cast::Cool, Cast::Dim];

    pub fn name(self) -> &'static str {
        match self {
            Cast::None => "none",
            Cast::Warm => "warm",
            Cast::Cool => "cool",
            Cast::Dim => "dim",
        }
    }

    /// Per-channel gains in linear light (R, G, B).
    pub fn gains(self) -> [f64; 3] {
        match self {
            Cast::None => [1.0; 3],
            Cast::Warm => [1.0, 0.82, 0.6],
            Cast::Cool => [0.75, 0.88, 1.0],
            Cast::Dim => [(-1.2f64).exp2(); 3],
        }
    }

    /// Noise added after re-encoding, in 8-bit levels (0 = none).
    pub fn noise_levels(self) -> f64 {
        if self == Cast::Dim { DIM_NOISE_LEVELS } else { 0.0 }
    }

    /// Applies the cast to interleaved RGB8 pixels; `seed` fixes the noise.
    pub fn apply(self, rgb: &mut [u8], seed: u64) {
        if self == Cast::None {
            return;
        }
        // One 256-entry table per channel: decode, scale, encode.
        let luts: [[u8; 256]; 3] =
            self.gains().map(|g| std::array::from_fn(|v| srgb::encode(srgb::decode(v as u8) * g)));
        let sigma = self.noise_levels();
        let mut rng = SplitMix64(seed ^ 0x6361_7374_u64.wrapping_mul(0x9E37_79B9_7F4A_7C15));
        let mut spare: Option<f64> = None;
        for (i, v) in rgb.iter_mut().enumerate() {
            let cast = luts[i % 3][*v as usize];
            *v = if sigma > 0.0 {
                let n = spare.take().unwrap_or_else(|| {
                    let (a, b) = rng.gaussian_pair();
                    spare = Some(b);
                    a
                });
                (cast as f64 + sigma * n).round().clamp(0.0, 255.0) as u8
            } else {
                cast
            };
        }
    }
}

/// A small seeded generator (splitmix64) with Box–Muller normals: the noise
/// needs repeatability, not cryptographic quality.
struct SplitMix64(u64);

impl SplitMix64 {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in (0, 1].
    fn unit(&mut self) -> f64 {
        ((self.next_u64() >> 11) + 1) as f64 / (1u64 << 53) as f64
    }

    fn gaussian_pair(&mut self) -> (f64, f64) {
        let (u, v) = (self.unit(), self.unit());
        let r = (-2.0 * u.ln()).sqrt();
        let a = std::f64::consts::TAU * v;
        (r * a.cos(), r * a.sin())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(len: usize) -> Vec<u8> {
        (0..len).map(|i| (i * 37 % 256) as u8).collect()
    }

    #[test]
    fn names_parse_back_and_others_are_refused() {
        for c in Cast::ALL {
            assert_eq!(c.name().parse::<Cast>(), Ok(c));
        }
        assert!("sepia".parse::<Cast>().unwrap_err().contains("none, warm, cool, dim"));
    }

    #[test]
    fn none_leaves_the_image_as_it_is() {
        let mut rgb = image(3 * 1000);
        Cast::None.apply(&mut rgb, 7);
        assert_eq!(rgb, image(3 * 1000));
    }

    #[test]
    fn gains_act_on_linear_light_not_on_code_values() {
        // Mid grey 128 is 0.2158 in linear light: × 0.82 → 0.1770 → sRGB 117,
        // where scaling the code value would give 105; × 0.6 → 0.1295 → 101.
        let mut rgb = vec![128u8, 128, 128];
        Cast::Warm.apply(&mut rgb, 0);
        assert_eq!(rgb, [128, 117, 101]);
        let mut rgb = vec![128u8, 128, 128];
        Cast::Cool.apply(&mut rgb, 0);
        assert_eq!(rgb, [112, 121, 128]);
        // A gain of 1 round-trips every code value exactly.
        let mut all: Vec<u8> = (0..=255u8).flat_map(|v| [v, 0, 0]).collect();
        Cast::Warm.apply(&mut all, 0);
        assert!(all.chunks(3).enumerate().all(|(v, p)| p[0] == v as u8), "red changed under gain 1");
        // White stays the brightest value each gain allows.
        let mut white = vec![255u8; 3];
        Cast::Warm.apply(&mut white, 0);
        assert_eq!(white, [255, 234, 203]);
    }

    #[test]
    fn dim_is_minus_1_2_ev_with_3_level_noise() {
        let n = 3 * 20_000;
        let mut rgb = vec![200u8; n];
        Cast::Dim.apply(&mut rgb, 42);
        let expected = srgb::encode(srgb::decode(200) * 2f64.powf(-1.2)) as f64;
        assert_eq!(expected, 137.0, "200 at −1.2 EV");
        let mean = rgb.iter().map(|&v| v as f64).sum::<f64>() / n as f64;
        let var = rgb.iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / n as f64;
        assert!((mean - expected).abs() < 0.1, "mean {mean}, expected {expected}");
        assert!((var.sqrt() - 3.0).abs() < 0.1, "noise σ {}", var.sqrt());
    }

    #[test]
    fn noise_repeats_for_a_seed_and_differs_between_seeds() {
        let run = |seed| {
            let mut rgb = image(3 * 500);
            Cast::Dim.apply(&mut rgb, seed);
            rgb
        };
        assert_eq!(run(5), run(5));
        assert_ne!(run(5), run(6));
        // The gain-only casts draw no noise: the seed does not matter.
        let warm = |seed| {
            let mut rgb = image(300);
            Cast::Warm.apply(&mut rgb, seed);
            rgb
        };
        assert_eq!(warm(1), warm(2));
    }
}
