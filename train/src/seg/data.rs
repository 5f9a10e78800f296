//! Segmentation samples rendered on the fly: a tabletop scene from
//! `scene::sampler`, rendered with sensor noise and an instance label map, turned
//! into the network input by the engine's own [`FrameMap`] (so training and
//! inference see identical inputs), with the class at each output cell's
//! centre as the target and, for the centre-offset head, the offset from each
//! object cell to the centroid of its instance's visible pixels (cell units /
//! [`OFFSET_UNIT_CELLS`]), and for the contact head each object cell with
//! a cell of another instance among its eight neighbours ([`contact_targets`]).
//! Training augmentation: per-channel colour gain and
//! bias plus a global brightness shift on the normalised colour, and a
//! horizontal flip of the full-resolution frame (input and target stay
//! aligned). Background threads render the frames ([`SegStream`]).

use std::sync::Arc;

use anyhow::Context;
use fusepose_estimator::seg::config::OFFSET_UNIT_CELLS;
use fusepose_estimator::seg::{FrameMap, SegConfig};
use fusepose_estimator::{ColorFormat, DepthPlane, FrameView};
use fusepose_scene::render::{GAUSS_BITS, NoiseConfig, RenderTarget, gauss_table, srgb};
use fusepose_scene::sampler::{LabelKind, SamplerConfig, SamplerError, render_view_labelled, sample_scene};
use fusepose_scene::{Intrinsics, ObjectSet};
use rand::{Rng, RngCore, SeedableRng};
use rand_pcg::Pcg64;

use crate::seeded_workers::{RecvError, SeededWorkers};

/// One rendered frame as the segmenter sees it.
#[derive(Clone, Debug)]
pub struct SegSample {
    /// `[4, H0, W0]` network input.
    pub input: Vec<f32>,
    /// `[H1 * W1]` class id per output cell (0 = background).
    pub target: Vec<u16>,
    /// `[2, H1 * W1]` offset (x, y) of each object cell to its instance's
    /// centre, in units of [`OFFSET_UNIT_CELLS`] cells; 0 on background.
    pub offsets: Vec<f32>,
    /// `[H1 * W1]` 1 where `offsets` is a target (object cells), else 0.
    pub offset_mask: Vec<f32>,
    /// `[H1 * W1]` 1 on object cells next to another instance's cell, else 0.
    pub contacts: Vec<f32>,
}

/// Renders scene `seed` (class labels, sensor noise) into `target`; `None` when
/// the sampler could not place the objects (the seed is skipped).
pub fn render_frame(set: &ObjectSet, seed: u64, target: &mut RenderTarget) -> anyhow::Result<Option<Intrinsics>> {
    Ok(render_with(set, &SamplerConfig::default(), seed, LabelKind::Class, target)?.map(|(k, _)| k))
}

/// The camera training frames are rendered with: the target camera
/// (YCB-Video) at half resolution when the scenes are randomised. The network
/// sees a 160x120 box filter of the frame either way, and a randomised frame
/// costs four times less to render at 320x240 (rendering, not the network,
/// bounds the segmenter's training speed on two cores). Plain scenes keep the
/// full resolution of the runs before randomisation.
pub fn render_camera(sampler: &SamplerConfig) -> Intrinsics {
    let k = sampler.intrinsics;
    if !sampler.randomize.is_on() {
        return k;
    }
    Intrinsics {
        fx: k.fx * 0.5,
        fy: k.fy * 0.5,
        cx: (k.cx + 0.5) * 0.5 - 0.5,
        cy: (k.cy + 0.5) * 0.5 - 0.5,
        width: k.width / 2,
        height: k.height / 2,
    }
}

/// Renders scene `seed` drawn with `sampler` into `target` with labels of
/// `kind`; also returns the instance → class table (index 0 = background).
pub fn render_with(
    set: &ObjectSet,
    sampler: &SamplerConfig,
    seed: u64,
    kind: LabelKind,
    target: &mut RenderTarget,
) -> anyhow::Result<Option<(Intrinsics, Vec<u16>)>> {
    let k = render_camera(sampler);
    let scene = match sample_scene(set, sampler, seed) {
        Ok(s) => s,
        Err(SamplerError::Placement { .. }) => return Ok(None),
        Err(e) => return Err(e).context("sampling a scene"),
    };
    let truth =
        render_view_labelled(&scene, set, 0, &k, &NoiseConfig::default(), kind, target).context("rendering a scene")?;
    Ok(Some((truth.intrinsics, truth.class_lut())))
}

/// Class target and centre-offset target of every output cell from a frame's
/// instance labels (`instance_at(pixel index)`) and its instance → class table.
fn cell_targets(map: &FrameMap, labels: &[u16], lut: &[u16], cells: &mut [u16]) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    let (w, h) = map.frame_size();
    let (gw, gh) = map.grid_size();
    // Visible-pixel centroid of every instance, in cell coordinates (cell centres at integers).
    let mut sum = vec![[0.0f64; 3]; lut.len()];
    for (p, &l) in labels.iter().enumerate().take(w * h) {
        if l == 0 || l as usize >= lut.len() {
            continue;
        }
        let (u, v) = ((p % w) as f64, (p / w) as f64);
        let s = &mut sum[l as usize];
        s[0] += (u + 0.5) * gw as f64 / w as f64 - 0.5;
        s[1] += (v + 0.5) * gh as f64 / h as f64 - 0.5;
        s[2] += 1.0;
    }
    let mut ids = vec![0u16; cells.len()];
    map.target(|i| labels.get(i).copied().unwrap_or(0), &mut ids);
    let n = cells.len();
    let (mut off, mut mask) = (vec![0.0f32; 2 * n], vec![0.0f32; n]);
    for (i, (&id, cell)) in ids.iter().zip(cells.iter_mut()).enumerate() {
        let class = lut.get(id as usize).copied().unwrap_or(0);
        *cell = class;
        if class == 0 || sum[id as usize][2] == 0.0 {
            continue;
        }
        let s = sum[id as usize];
        let (cx, cy) = (s[0] / s[2], s[1] / s[2]);
        off[i] = ((cx - (i % gw) as f64) / OFFSET_UNIT_CELLS as f64) as f32;
        off[n + i] = ((cy - (i / gw) as f64) / OFFSET_UNIT_CELLS as f64) as f32;
        mask[i] = 1.0;
    }
    let contacts = contact_targets(&ids, gw, gh);
    (off, mask, contacts)
}

/// 1 on every cell of an instance (`ids`, 0 = background, on a `w`×`h` grid)
/// that has a cell of another instance among its eight neighbours, else 0:
/// a band two cells wide where two objects touch or overlap in the image,
/// whatever their classes (the second look cuts along it within one class).
pub fn contact_targets(ids: &[u16], w: usize, h: usize) -> Vec<f32> {
    let mut out = vec![0.0f32; ids.len()];
    for y in 0..h {
        for x in 0..w {
            let id = ids[y * w + x];
            if id == 0 {
                continue;
            }
            let touches = (y.saturating_sub(1)..=(y + 1).min(h - 1)).any(|ny| {
                (x.saturating_sub(1)..=(x + 1).min(w - 1)).any(|nx| {
                    let other = ids[ny * w + nx];
                    other != 0 && other != id
                })
            });
            out[y * w + x] = f32::from(u8::from(touches));
        }
    }
    out
}

/// A rendered frame (in `target`) as a borrowed view without labels.
pub fn frame_view(k: Intrinsics, target: &RenderTarget) -> FrameView<'_> {
    FrameView {
        intrinsics: k,
        color_format: ColorFormat::Rgb8,
        color: target.rgb(),
        depth: DepthPlane::F32(target.depth_m()),
        labels: None,
    }
}

/// Renders scene `seed` and returns its sample (augmented when `augment`).
///
/// `cast`: share of augmented frames given a camera cast first ([`camera_cast`]).
pub fn frame_sample(
    set: &ObjectSet,
    cfg: &SegConfig,
    sampler: &SamplerConfig,
    seed: u64,
    augment: bool,
    cast: f64,
    target: &mut RenderTarget,
) -> anyhow::Result<Option<SegSample>> {
    let Some((k, lut)) = render_with(set, sampler, seed, LabelKind::Instance, target)? else {
        return Ok(None);
    };
    // Its own generator: runs without casts draw the same flips and jitter as before.
    let mut cast_rng = Pcg64::seed_from_u64(seed ^ 0xca57_ca57);
    if augment && cast > 0.0 && cast_rng.random_bool(cast.min(1.0)) {
        camera_cast(target.rgb_mut(), &mut cast_rng);
    }
    let mut rng = Pcg64::seed_from_u64(seed ^ 0xa46_5e9);
    let (w, h) = (k.width as usize, k.height as usize);
    let map = FrameMap::new(w, h, cfg);
    let mut input = vec![0.0; map.input_len()];
    let mut cells = vec![0u16; map.cells()];
    let (offsets, offset_mask, contacts) = if augment && rng.random_bool(0.5) {
        let mut color = target.rgb().to_vec();
        let mut depth = target.depth_m().to_vec();
        let mut labels = target.labels().to_vec();
        flip_rows(&mut color, &mut depth, &mut labels, w);
        let frame = FrameView { color: &color, depth: DepthPlane::F32(&depth), ..frame_view(k, target) };
        map.fill_input(&frame, &mut input);
        cell_targets(&map, &labels, &lut, &mut cells)
    } else {
        map.fill_input(&frame_view(k, target), &mut input);
        cell_targets(&map, target.labels(), &lut, &mut cells)
    };
    let mut s = SegSample { input, target: cells, offsets, offset_mask, contacts };
    if augment {
        jitter_colour(&mut s, cfg, &mut rng);
    }
    Ok(Some(s))
}

/// Mirrors a full-resolution frame `w` pixels wide left to right (RGB8
/// colour, depth, labels), so that input and target stay aligned exactly.
pub fn flip_rows(color: &mut [u8], depth: &mut [f32], labels: &mut [u16], w: usize) {
    for row in color.chunks_exact_mut(3 * w) {
        row.reverse();
        for px in row.chunks_exact_mut(3) {
            px.reverse();
        }
    }
    depth.chunks_exact_mut(w).for_each(<[f32]>::reverse);
    labels.chunks_exact_mut(w).for_each(<[u16]>::reverse);
}

/// A camera's colour rendition unlike the renderer's, in linear light on the
/// rendered RGB: white balance along the warm–cool axis (red and blue gains
/// exp(±u), u in ±0.45: a 0.6 blue gain is u ≈ 0.26), a green tint (±0.1),
/// exposure from −1.5 to +0.5 EV, then sensor noise of up to 4 levels. The
/// colour-cast variants of the path-traced split (warm, cool, −1.2 EV) cost
/// the segmenter 2–5 ADD(S) when training saw only the jitter below.
pub fn camera_cast(rgb: &mut [u8], rng: &mut Pcg64) {
    let u: f64 = rng.random_range(-0.45..0.45);
    let v: f64 = rng.random_range(-0.1..0.1);
    let ev: f64 = rng.random_range(-1.5..0.5);
    let sigma: f64 = rng.random_range(0.0..4.0);
    let exposure = ev.exp2();
    apply_cast(rgb, [u.exp() * exposure, v.exp() * exposure, (-u).exp() * exposure], sigma, rng);
}

/// Linear-light gains per channel (R, G, B), then Gaussian noise of `sigma`
/// 8-bit levels, on interleaved sRGB bytes.
fn apply_cast(rgb: &mut [u8], gains: [f64; 3], sigma: f64, rng: &mut Pcg64) {
    let luts: [[u8; 256]; 3] = gains.map(|g| std::array::from_fn(|c| srgb::encode(srgb::decode(c as u8) * g)));
    // The LUT's levels are whole, so a level plus σ·n rounds to the level
    // plus round(σ·n): the noise is whole steps, drawn from the scene's
    // equiprobable normal table (12 random bits per value, five values per
    // draw) instead of a Box–Muller per value, which took a quarter of a
    // cast-augmented segmenter run's CPU time.
    let g = gauss_table();
    let steps: [i16; 1 << GAUSS_BITS] = std::array::from_fn(|i| (sigma * f64::from(g[i])).round() as i16);
    let mask = (1u64 << GAUSS_BITS) - 1;
    for (i, chunk) in rgb.chunks_mut(5).enumerate() {
        let mut bits = rng.next_u64();
        for (j, px) in chunk.iter_mut().enumerate() {
            let step = steps[(bits & mask) as usize];
            bits >>= GAUSS_BITS;
            let level = i16::from(luts[(i * 5 + j) % 3][*px as usize]);
            *px = (level + step).clamp(0, 255) as u8;
        }
    }
}

/// Colour jitter on the normalised colour channels: per-channel gain and bias
/// plus a global brightness shift.
pub fn jitter_colour(s: &mut SegSample, cfg: &SegConfig, rng: &mut Pcg64) {
    let plane = cfg.input_height * cfg.input_width;
    let brightness: f32 = rng.random_range(-0.3..0.3);
    for c in 0..3 {
        let gain: f32 = rng.random_range(0.8..1.2);
        let bias: f32 = rng.random_range(-0.15..0.15) + brightness;
        for v in &mut s.input[c * plane..(c + 1) * plane] {
            *v = *v * gain + bias;
        }
    }
}

/// Training frames rendered on `threads` background threads, delivered in
/// seed order ([`SeededWorkers`]: the same frames for any thread count).
pub struct SegStream(SeededWorkers<SegSample>);

impl SegStream {
    /// Renders scenes `first_seed, first_seed + 1, …` (augmented) until dropped.
    ///
    /// With `adapt` = (frames, share), that share of the seeds draws a
    /// pseudo-labelled frame instead ([`super::adapt`]).
    #[allow(clippy::too_many_arguments)]
    pub fn spawn(
        set: Arc<ObjectSet>,
        cfg: SegConfig,
        sampler: SamplerConfig,
        cast: f64,
        first_seed: u64,
        capacity: usize,
        threads: usize,
        adapt: Option<(Arc<super::adapt::AdaptFrames>, f64)>,
    ) -> anyhow::Result<Self> {
        let camera = render_camera(&sampler);
        let workers = SeededWorkers::spawn(
            "fusepose-seg-data",
            threads,
            first_seed,
            capacity,
            move || Ok(RenderTarget::for_intrinsics(&camera)),
            move |target, seed| {
                if let Some((frames, share)) = &adapt {
                    let mut rng = Pcg64::seed_from_u64(seed ^ 0xada9_7ed0);
                    if rng.random_bool(share.clamp(0.0, 1.0)) {
                        return Ok(Some(frames.sample(&cfg, cast, &mut rng)));
                    }
                }
                frame_sample(&set, &cfg, &sampler, seed, true, cast, target)
            },
        )?;
        Ok(Self(workers))
    }

    /// The next frame, waiting at most `timeout`.
    pub fn recv_timeout(&mut self, timeout: std::time::Duration) -> Result<SegSample, RecvError> {
        self.0.recv_timeout(timeout)
    }
}

#[cfg(test)]
mod cast_tests {
    use super::*;

    #[test]
    fn contacts_are_the_cells_where_two_instances_meet() {
        // 6x3 grid: instances 1 and 2 side by side, 3 apart from both by background.
        #[rustfmt::skip]
        let ids: Vec<u16> = vec![
            1, 1, 2, 2, 0, 3,
            1, 1, 2, 2, 0, 3,
            1, 1, 1, 2, 0, 3,
        ];
        let c = contact_targets(&ids, 6, 3);
        #[rustfmt::skip]
        let want: Vec<f32> = vec![
            0., 1., 1., 0., 0., 0.,
            0., 1., 1., 1., 0., 0.,
            0., 1., 1., 1., 0., 0.,
        ];
        assert_eq!(c, want);
        // One instance alone has no contact anywhere.
        assert!(contact_targets(&[0, 4, 4, 4, 4, 0], 3, 2).iter().all(|&v| v == 0.0));
    }

    #[test]
    fn camera_casts_span_warm_to_cool_and_dim_to_bright() {
        let (mut warm, mut cool, mut dim, mut bright) = (false, false, false, false);
        for seed in 0..200 {
            let mut rgb = vec![128u8; 3 * 400];
            camera_cast(&mut rgb, &mut Pcg64::seed_from_u64(seed));
            let mean = |c: usize| rgb.iter().skip(c).step_by(3).map(|&v| v as f64).sum::<f64>() / 400.0;
            let (r, g, b) = (mean(0), mean(1), mean(2));
            warm |= r / b > 1.3;
            cool |= b / r > 1.3;
            dim |= g < 80.0;
            bright |= g > 150.0;
        }
        assert!(warm && cool && dim && bright, "warm {warm} cool {cool} dim {dim} bright {bright}");
        // Seeded: the same draw twice.
        let (mut a, mut b) = (vec![90u8; 300], vec![90u8; 300]);
        camera_cast(&mut a, &mut Pcg64::seed_from_u64(7));
        camera_cast(&mut b, &mut Pcg64::seed_from_u64(7));
        assert_eq!(a, b);
    }

    /// `cargo test --release -p fusepose-train camera_cast_speed -- --ignored --nocapture`
    #[test]
    #[ignore = "timing: prints ms per 640x480 frame"]
    fn camera_cast_speed() {
        let mut rgb: Vec<u8> = (0..640 * 480 * 3).map(|i| (i * 7 % 251) as u8).collect();
        let mut rng = Pcg64::seed_from_u64(5);
        let reps = 200;
        let start = std::time::Instant::now();
        for _ in 0..reps {
            camera_cast(&mut rgb, &mut rng);
        }
        let ms = start.elapsed().as_secs_f64() * 1e3 / reps as f64;
        println!(
            "camera_cast: {ms:.3} ms per 640x480 frame ({reps} frames, checksum {})",
            rgb.iter().map(|&v| v as u64).sum::<u64>()
        );
    }

    #[test]
    fn cast_noise_has_its_sigma_and_is_independent_per_value() {
        for sigma in [0.0, 1.0, 3.0] {
            let mut rgb = vec![128u8; 3 * 40_000];
            apply_cast(&mut rgb, [1.0; 3], sigma, &mut Pcg64::seed_from_u64(3));
            let x: Vec<f64> = rgb.iter().map(|&v| f64::from(v) - 128.0).collect();
            let n = x.len() as f64;
            let mean = x.iter().sum::<f64>() / n;
            let var = x.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / n;
            // Whole steps of a normal: variance σ² + 1/12 (rounding) for σ ≥ 1.
            let want = if sigma > 0.0 { sigma * sigma + 1.0 / 12.0 } else { 0.0 };
            assert!(
                mean.abs() < 0.03 && (var - want).abs() < 0.05 * want.max(0.1),
                "σ {sigma}: mean {mean}, var {var}"
            );
            // Neighbours (the same draw's bits, and the next draw's) are uncorrelated.
            for lag in [1, 4, 5] {
                let c = x.windows(lag + 1).map(|w| (w[0] - mean) * (w[lag] - mean)).sum::<f64>() / n;
                assert!(c.abs() < 0.02 * want.max(0.1), "σ {sigma} lag {lag}: covariance {c}");
            }
        }
        // Gain 1 keeps a level; channels take their own gains.
        let mut rgb = vec![100u8; 30];
        apply_cast(&mut rgb, [1.0, 0.5, 2.0], 0.0, &mut Pcg64::seed_from_u64(1));
        assert!(rgb.chunks(3).all(|p| p[0] == 100 && p[1] < 100 && p[2] > 100), "{rgb:?}");
    }
}
