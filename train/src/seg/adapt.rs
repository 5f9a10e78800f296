//! Frames from the camera the segmenter will serve, labelled by the
//! estimator's own published poses (`fusepose eval --pseudo-labels DIR`),
//! mixed into its training: the segmenter learns that camera's colours and
//! light without anyone drawing a mask. Pixels the labels leave unknown are
//! [`IGNORE`] cells, which take no loss.
//!
//! The frames are held in memory at full resolution, so each draw gets the
//! same augmentation as a rendered frame (camera cast, horizontal flip,
//! colour jitter; [`super::data`]).

use std::path::{Path, PathBuf};

use anyhow::Context;
use fusepose_estimator::seg::{FrameMap, SegConfig};
use fusepose_estimator::{ColorFormat, DepthPlane, FrameView};
use fusepose_scene::Intrinsics;
use fusepose_scene::bop::{BopDataset, UNKNOWN_LABEL, read_pseudo_labels, read_pseudo_manifest};
use rand::Rng;
use rand_pcg::Pcg64;

use super::data::{SegSample, camera_cast, flip_rows, jitter_colour};

/// Cell target of a cell whose class is unknown: no loss there.
pub const IGNORE: u16 = u16::MAX;

/// One pseudo-labelled frame.
#[derive(Clone, Debug)]
struct AdaptFrame {
    intrinsics: Intrinsics,
    rgb: Vec<u8>,
    depth_m: Vec<f32>,
    /// Class per pixel, [`IGNORE`] where unknown.
    labels: Vec<u16>,
}

/// The pseudo-labelled frames of one or more folders.
#[derive(Clone, Debug, Default)]
pub struct AdaptFrames {
    frames: Vec<AdaptFrame>,
}

impl AdaptFrames {
    /// Loads every frame of the pseudo-label folders `dirs` (their manifests
    /// name the BOP splits the colour and depth come from); labels must be of
    /// `num_classes` classes.
    pub fn load(dirs: &[PathBuf], num_classes: usize) -> anyhow::Result<Self> {
        let mut frames = Vec::new();
        for dir in dirs {
            load_folder(dir, num_classes, &mut frames).with_context(|| format!("--adapt-labels {}", dir.display()))?;
        }
        if frames.is_empty() {
            anyhow::bail!(
                "--adapt-labels: the folders hold no frames; write them with `fusepose eval --pseudo-labels DIR`"
            );
        }
        Ok(Self { frames })
    }

    pub fn len(&self) -> usize {
        self.frames.len()
    }

    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// A training sample of a random frame, augmented like a rendered one
    /// (`cast`: the share given a camera cast).
    pub fn sample(&self, cfg: &SegConfig, cast: f64, rng: &mut Pcg64) -> SegSample {
        let f = &self.frames[rng.random_range(0..self.frames.len())];
        let (w, h) = (f.intrinsics.width as usize, f.intrinsics.height as usize);
        let mut rgb = f.rgb.clone();
        let mut depth = f.depth_m.clone();
        let mut labels = f.labels.clone();
        if cast > 0.0 && rng.random_bool(cast.min(1.0)) {
            camera_cast(&mut rgb, rng);
        }
        if rng.random_bool(0.5) {
            flip_rows(&mut rgb, &mut depth, &mut labels, w);
        }
        let map = FrameMap::new(w, h, cfg);
        let mut input = vec![0.0; map.input_len()];
        let view = FrameView {
            intrinsics: f.intrinsics,
            color_format: ColorFormat::Rgb8,
            color: &rgb,
            depth: DepthPlane::F32(&depth),
            labels: None,
        };
        map.fill_input(&view, &mut input);
        let mut target = vec![0u16; map.cells()];
        map.target(|i| labels.get(i).copied().unwrap_or(IGNORE), &mut target);
        let n = target.len();
        let mut s =
            SegSample { input, target, offsets: vec![0.0; 2 * n], offset_mask: vec![0.0; n], contacts: vec![0.0; n] };
        jitter_colour(&mut s, cfg, rng);
        s
    }
}

fn load_folder(dir: &Path, num_classes: usize, out: &mut Vec<AdaptFrame>) -> anyhow::Result<()> {
    let manifest = read_pseudo_manifest(dir)
        .context("not a pseudo-label folder: write one with `fusepose eval --masks net --pseudo-labels DIR`")?;
    if manifest.num_classes as usize != num_classes {
        anyhow::bail!("labels are of {} classes, the object set has {num_classes}", manifest.num_classes);
    }
    let split = BopDataset::open(&manifest.source_split)
        .with_context(|| format!("opening its source split {}", manifest.source_split.display()))?;
    for entry in &manifest.frames {
        let Some(index) =
            split.frame_ids().iter().position(|id| (id.scene_id, id.im_id) == (entry.scene_id, entry.im_id))
        else {
            anyhow::bail!("frame {}/{} is not in {}", entry.scene_id, entry.im_id, manifest.source_split.display());
        };
        let frame = split.load(index)?;
        let (w, h) = (frame.width(), frame.height());
        let labels = read_pseudo_labels(dir, entry, w, h)?
            .into_iter()
            .map(|l| if l == UNKNOWN_LABEL { IGNORE } else { u16::from(l) })
            .collect();
        out.push(AdaptFrame { intrinsics: frame.intrinsics, depth_m: frame.depth_metres(), rgb: frame.rgb, labels });
    }
    Ok(())
}
