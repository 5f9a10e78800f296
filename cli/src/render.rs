//! `fusepose render`: renders tabletop scenes of an object set into a BOP
//! dataset (see `fusepose_scene::bop`), with a progress bar and a summary.
//!
//! Seeds: scene `i` of split `s` rendered with `--seed S` uses the sampler
//! seed `scene_seed(S, s, i)`, a splitmix64 mix of all three. The split is
//! part of the mix, so `--split test --seed 0` and `--split train --seed 0`
//! draw different scenes (train and test never share a scene), while the same
//! (split, seed) always reproduces the same dataset.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use fusepose_scene::Intrinsics;
use fusepose_scene::bop::{BopWriter, FrameToWrite, InstanceToWrite, ObjectSource};
use fusepose_scene::contact_sheet::{ContactSheet, FrameView};
use fusepose_scene::mesh_io::load_object_set;
use fusepose_scene::render::{DEPTH_U16_PER_METRE, NoiseConfig, RenderTarget};
use fusepose_scene::sampler::{SamplerConfig, render_view, sample_scene};
use indicatif::{ProgressBar, ProgressStyle};

/// Which split to write; part of the seed derivation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Split {
    Train,
    Test,
}

impl Split {
    fn name(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Test => "test",
        }
    }

    /// A fixed tag per split mixed into every scene seed.
    fn tag(self) -> u64 {
        match self {
            Split::Train => 0x7472_6169_6e00_0001, // "train"
            Split::Test => 0x7465_7374_0000_0002,  // "test"
        }
    }
}

/// Sensor noise on or off.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Toggle {
    On,
    Off,
}

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Object set: `builtin` or a folder with one subfolder or .obj/.ply file per object.
    #[arg(long, default_value = "builtin")]
    pub objects: String,
    /// Metres per mesh-file unit for a mesh folder (0.001 for millimetre models).
    #[arg(long, default_value_t = 1.0)]
    pub mesh_scale: f64,
    /// Number of scenes.
    #[arg(long, default_value_t = 10)]
    pub scenes: u32,
    /// Camera views rendered per scene.
    #[arg(long, default_value_t = 5)]
    pub frames_per_scene: u32,
    /// Dataset root; frames go to OUT/<split>/NNNNNN/ (the split folder must be empty or absent).
    #[arg(long)]
    pub out: PathBuf,
    /// Base seed; combined with the split so train and test never share scenes.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Depth and colour sensor noise.
    #[arg(long, value_enum, default_value_t = Toggle::On)]
    pub noise: Toggle,
    /// Split to write.
    #[arg(long, value_enum, default_value_t = Split::Train)]
    pub split: Split,
    /// Also write OUT/<split>_contact_sheet.png showing the first N frames (0 = none).
    #[arg(long, default_value_t = 0)]
    pub contact_sheet: u32,
}

/// Thumbnail width (pixels) of each contact-sheet panel.
const CONTACT_SHEET_THUMB_WIDTH: u32 = 320;

fn splitmix64(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^ (x >> 31)
}

/// The sampler seed of scene `index` of `split` under base seed `seed`.
pub fn scene_seed(seed: u64, split: Split, index: u64) -> u64 {
    splitmix64(splitmix64(splitmix64(seed) ^ split.tag()) ^ index)
}

fn object_source(objects: &str) -> ObjectSource {
    match objects.parse::<ObjectSource>() {
        Ok(ObjectSource::Directory(p)) => ObjectSource::Directory(std::fs::canonicalize(&p).unwrap_or(p)),
        Ok(s) => s,
        Err(never) => match never {},
    }
}

#[derive(Default)]
struct Totals {
    frames: u64,
    instances: u64,
    occlusion_sum: f64,
    occlusion_count: u64,
    render: Duration,
    write: Duration,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if args.scenes == 0 || args.frames_per_scene == 0 {
        bail!("--scenes and --frames-per-scene must be at least 1");
    }
    let set = load_object_set(&args.objects, args.mesh_scale)
        .with_context(|| format!("loading object set '{}'", args.objects))?;
    let source = object_source(&args.objects);
    let split = args.split.name();
    let mut writer =
        BopWriter::create(&args.out, split, &set, &source).with_context(|| format!("preparing split '{split}'"))?;
    writer.set_split_params(split_params(&args))?;

    let k = Intrinsics::YCB_VIDEO;
    let cfg = SamplerConfig { views: args.frames_per_scene as usize, intrinsics: k, ..SamplerConfig::default() };
    let noise = match args.noise {
        Toggle::On => NoiseConfig::default(),
        Toggle::Off => NoiseConfig::off(),
    };
    let total = args.scenes as u64 * args.frames_per_scene as u64;
    let bar = ProgressBar::new(total);
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:40} {pos}/{len} frames ({per_sec}, eta {eta}) {msg}",
        )
        .expect("static progress template is valid"),
    );
    let mut target = RenderTarget::for_intrinsics(&k);
    let mut totals = Totals::default();
    let mut sheet = (args.contact_sheet > 0).then(|| ContactSheet::new(CONTACT_SHEET_THUMB_WIDTH));
    let started = Instant::now();
    for scene_id in 0..args.scenes {
        let seed = scene_seed(args.seed, args.split, scene_id as u64);
        let scene =
            sample_scene(&set, &cfg, seed).with_context(|| format!("sampling scene {scene_id} (seed {seed})"))?;
        for view in 0..scene.views.len() {
            let t0 = Instant::now();
            let truth = render_view(&scene, &set, view, &k, &noise, &mut target)
                .with_context(|| format!("rendering scene {scene_id} view {view}"))?;
            let t1 = Instant::now();
            let instances: Vec<InstanceToWrite> = truth
                .objects
                .iter()
                .map(|o| InstanceToWrite {
                    obj_id: o.class_id,
                    pose: o.pose,
                    instance_label: o.instance_label,
                    px_count_all: Some(o.alone_pixels),
                })
                .collect();
            writer.write_frame(&FrameToWrite {
                scene_id,
                im_id: view as u32,
                intrinsics: k,
                rgb: target.rgb(),
                depth: target.depth_u16(),
                depth_unit_m: 1.0 / DEPTH_U16_PER_METRE,
                instance_labels: target.labels(),
                instances: &instances,
            })?;
            totals.render += t1 - t0;
            totals.write += t1.elapsed();
            totals.frames += 1;
            totals.instances += truth.objects.len() as u64;
            for o in truth.objects.iter().filter(|o| o.alone_pixels > 0) {
                totals.occlusion_sum += 1.0 - o.visible_fraction;
                totals.occlusion_count += 1;
            }
            if let Some(sheet) = sheet.as_mut().filter(|s| (s.len() as u32) < args.contact_sheet) {
                sheet.push(FrameView::from(&target)).context("adding a frame to the contact sheet")?;
            }
            bar.inc(1);
        }
    }
    bar.finish_and_clear();
    let wall = started.elapsed();
    print_summary(&args, &set, writer.split_dir(), &totals, wall);
    if let Some(sheet) = sheet {
        let path = args.out.join(format!("{split}_contact_sheet.png"));
        sheet.save_png(&path).with_context(|| format!("writing {}", path.display()))?;
        println!("contact sheet of {} frames: {}", sheet.len(), path.display());
    }
    Ok(())
}

fn split_params(args: &Args) -> serde_json::Value {
    serde_json::json!({
        "seed": args.seed,
        "seed_rule": "scene i uses splitmix64(splitmix64(splitmix64(seed) ^ split_tag) ^ i)",
        "scenes": args.scenes,
        "frames_per_scene": args.frames_per_scene,
        "noise": args.noise == Toggle::On,
        "objects": args.objects,
        "mesh_scale": args.mesh_scale,
    })
}

fn print_summary(args: &Args, set: &fusepose_scene::ObjectSet, dir: &Path, t: &Totals, wall: Duration) {
    let frames = t.frames.max(1) as f64;
    let occlusion = if t.occlusion_count == 0 { 0.0 } else { 100.0 * t.occlusion_sum / t.occlusion_count as f64 };
    println!(
        "wrote {} frames ({} scenes x {} views, split {}, seed {}, noise {}) to {}",
        t.frames,
        args.scenes,
        args.frames_per_scene,
        args.split.name(),
        args.seed,
        if args.noise == Toggle::On { "on" } else { "off" },
        dir.display()
    );
    println!(
        "objects: {} classes from '{}', {} instances ({:.1} per frame), mean occlusion {:.1} %",
        set.len(),
        args.objects,
        t.instances,
        t.instances as f64 / frames,
        occlusion
    );
    println!(
        "time: {:.0} ms per frame (render {:.0} ms, write {:.0} ms), {:.1} s in all",
        1e3 * wall.as_secs_f64() / frames,
        1e3 * t.render.as_secs_f64() / frames,
        1e3 * t.write.as_secs_f64() / frames,
        wall.as_secs_f64()
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn train_and_test_never_share_seeds() {
        let train: std::collections::HashSet<u64> = (0..1000).map(|i| scene_seed(0, Split::Train, i)).collect();
        assert_eq!(train.len(), 1000);
        assert!((0..1000).all(|i| !train.contains(&scene_seed(0, Split::Test, i))));
        assert_eq!(scene_seed(7, Split::Test, 3), scene_seed(7, Split::Test, 3));
        assert_ne!(scene_seed(0, Split::Train, 0), scene_seed(1, Split::Train, 0));
    }
}
