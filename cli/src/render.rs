//! `fusepose render`: renders tabletop scenes of an object set into a BOP
//! dataset (see `fusepose_scene::bop`), with a progress bar and a summary.
//!
//! Seeds: scene `i` of split `s` rendered with `--seed S` uses the sampler
//! seed `scene_seed(S, s, i)`, a splitmix64 mix of all three. The split is
//! part of the mix, so `--split test --seed 0` and `--split train --seed 0`
//! draw different scenes (train and test never share a scene), while the same
//! (split, seed) always reproduces the same dataset.
//!
//! Domain randomisation (`--randomize`, default `default`) and the depth-sensor
//! model (`--depth-sensor`, default `structured-light`) follow
//! `SamplerConfig::training()`; `--randomize off --depth-sensor basic` gives
//! the frames of datasets rendered before randomisation existed, bit for bit.
//! What was used is recorded per split in `fusepose_dataset.json`.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use fusepose_scene::Intrinsics;
use fusepose_scene::bop::{BopWriter, FrameToWrite, InstanceToWrite, ObjectSource};
use fusepose_scene::contact_sheet::{ContactSheet, FrameView};
use fusepose_scene::mesh_io::load_object_set;
use fusepose_scene::render::{DepthSensor, NoiseConfig, Randomize, RenderTarget};
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

/// Domain randomisation level (`fusepose_scene::render::Randomize`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum RandomizeArg {
    /// None: the scenes and images of datasets rendered before randomisation.
    Off,
    /// The training ranges: lights, textures, walls, distractors, occluders, shadows, highlights, camera pipeline.
    Default,
    /// Every range widened.
    Strong,
}

impl From<RandomizeArg> for Randomize {
    fn from(r: RandomizeArg) -> Self {
        match r {
            RandomizeArg::Off => Randomize::Off,
            RandomizeArg::Default => Randomize::Default,
            RandomizeArg::Strong => Randomize::Strong,
        }
    }
}

/// Depth-sensor model (`fusepose_scene::render::DepthSensor`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum DepthSensorArg {
    /// Exact rendered depth.
    Ideal,
    /// The original generic noise model.
    Basic,
    /// Active stereo / structured light (RealSense D4xx, Kinect v1): projector shadows, quantised disparity.
    StructuredLight,
    /// Time of flight (Kinect v2, Azure Kinect): multipath in corners, mixed pixels at edges.
    Tof,
}

impl From<DepthSensorArg> for DepthSensor {
    fn from(d: DepthSensorArg) -> Self {
        match d {
            DepthSensorArg::Ideal => DepthSensor::Ideal,
            DepthSensorArg::Basic => DepthSensor::Basic,
            DepthSensorArg::StructuredLight => DepthSensor::StructuredLight,
            DepthSensorArg::Tof => DepthSensor::Tof,
        }
    }
}

/// An inclusive count range written `N` or `MIN..MAX`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CountRange(pub usize, pub usize);

impl std::str::FromStr for CountRange {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let parse =
            |t: &str| t.trim().parse::<usize>().map_err(|_| format!("'{s}' is not N or MIN..MAX (whole numbers)"));
        let (lo, hi) = match s.split_once("..") {
            Some((a, b)) => (parse(a)?, parse(b.trim_start_matches('='))?),
            None => {
                let n = parse(s)?;
                (n, n)
            }
        };
        if lo == 0 || hi < lo {
            return Err(format!("'{s}': need 1 <= MIN <= MAX"));
        }
        Ok(CountRange(lo, hi))
    }
}

/// A probability in 0..=1.
pub(crate) fn probability(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(p) if (0.0..=1.0).contains(&p) => Ok(p),
        _ => Err(format!("'{s}' is not a probability between 0 and 1")),
    }
}

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Object set: `builtin` or a folder with one subfolder or .obj/.ply file per object.
    #[arg(long, default_value = "builtin")]
    pub objects: String,
    #[arg(long, default_value = "ycb-video", value_parser = crate::camera_model::parse, help = crate::camera_model::HELP)]
    pub intrinsics: Intrinsics,
    /// Metres per mesh-file unit for a mesh folder (0.001 for millimetre models).
    #[arg(long = "scale", alias = "mesh-scale", default_value_t = 1.0)]
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
    /// Sensor noise: `off` gives exact depth and no colour noise (the
    /// randomised camera pipeline still applies unless --randomize off).
    #[arg(long, value_enum, default_value_t = Toggle::On)]
    pub noise: Toggle,
    /// Domain randomisation. `off` with `--depth-sensor basic` reproduces
    /// datasets rendered before randomisation (the original sampler ranges).
    #[arg(long, value_enum, default_value_t = RandomizeArg::Default)]
    pub randomize: RandomizeArg,
    /// Depth-sensor model applied to the rendered depth.
    #[arg(long, value_enum, default_value_t = DepthSensorArg::StructuredLight)]
    pub depth_sensor: DepthSensorArg,
    /// Copies of each drawn class: N or MIN..MAX, each its own instance
    /// (default: 1..2 with randomisation, 1 with --randomize off).
    #[arg(long, value_name = "N|MIN..MAX")]
    pub instances_per_class: Option<CountRange>,
    /// Probability that a scene holds a heap of 4-8 touching copies of one
    /// object; `--heap` alone means every scene (default: 0.15 with
    /// randomisation, 0 with --randomize off).
    #[arg(long, value_name = "P", num_args = 0..=1, default_missing_value = "1", value_parser = probability)]
    pub heap: Option<f64>,
    /// Probability that a scene holds a pair of identical objects side by side
    /// (0-3 mm apart); `--pairs` alone means every scene (default: 0.35 with
    /// randomisation, 0 with --randomize off).
    #[arg(long, value_name = "P", num_args = 0..=1, default_missing_value = "1", value_parser = probability)]
    pub pairs: Option<f64>,
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

/// The object set `objects` names, a mesh folder made absolute (datasets record it).
pub(crate) fn object_source(objects: &str) -> ObjectSource {
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

    let k = args.intrinsics;
    let cfg = sampler_config(&args, k);
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
            let instances = InstanceToWrite::of_truth(&truth);
            // The camera actually used (jittered per view with randomisation).
            writer.write_frame(&FrameToWrite::rendered(scene_id, view as u32, &truth, &target, &instances))?;
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

/// The sampler configuration the flags ask for: `SamplerConfig::training()`
/// with randomisation, `SamplerConfig::default()` (the original ranges)
/// without, then the explicit flags.
pub fn sampler_config(args: &Args, k: Intrinsics) -> SamplerConfig {
    let randomize = Randomize::from(args.randomize);
    let base = if randomize == Randomize::Off { SamplerConfig::default() } else { SamplerConfig::training() };
    let mut cfg = SamplerConfig {
        views: args.frames_per_scene as usize,
        intrinsics: k,
        randomize,
        depth_sensor: args.depth_sensor.into(),
        ..base
    };
    if let Some(CountRange(lo, hi)) = args.instances_per_class {
        cfg.instances_per_class = (lo, hi);
    }
    if let Some(p) = args.heap {
        cfg.heap_probability = p;
    }
    if let Some(p) = args.pairs {
        cfg.pair_probability = p;
    }
    cfg
}

fn split_params(args: &Args) -> serde_json::Value {
    let cfg = sampler_config(args, args.intrinsics);
    serde_json::json!({
        "seed": args.seed,
        "seed_rule": "scene i uses splitmix64(splitmix64(splitmix64(seed) ^ split_tag) ^ i)",
        "scenes": args.scenes,
        "frames_per_scene": args.frames_per_scene,
        "noise": args.noise == Toggle::On,
        "objects": args.objects,
        "mesh_scale": args.mesh_scale,
        "randomize": Randomize::from(args.randomize).to_string(),
        "depth_sensor": DepthSensor::from(args.depth_sensor).to_string(),
        "intrinsics_jitter": if cfg.randomize.is_on() { "per view; scene_camera.json holds the camera used" } else { "none" },
        "sampler": {
            "objects_per_scene": [cfg.min_objects, cfg.max_objects],
            "instances_per_class": [cfg.instances_per_class.0, cfg.instances_per_class.1],
            "pair_probability": cfg.pair_probability,
            "pair_gap_m": [cfg.pair_gap_m.0, cfg.pair_gap_m.1],
            "heap_probability": cfg.heap_probability,
            "heap_size": [cfg.heap_size.0, cfg.heap_size.1],
            "camera_distance_m": [cfg.camera_distance_m.0, cfg.camera_distance_m.1],
            "camera_elevation_deg": [cfg.camera_elevation_deg.0, cfg.camera_elevation_deg.1],
            "camera_max_roll_deg": cfg.camera_max_roll_deg,
            "look_at_jitter_m": cfg.look_at_jitter_m,
        },
    })
}

fn print_summary(args: &Args, set: &fusepose_scene::ObjectSet, dir: &Path, t: &Totals, wall: Duration) {
    let frames = t.frames.max(1) as f64;
    let occlusion = if t.occlusion_count == 0 { 0.0 } else { 100.0 * t.occlusion_sum / t.occlusion_count as f64 };
    println!(
        "wrote {} frames ({} scenes x {} views, split {}, seed {}, noise {}, randomize {}, depth sensor {}) to {}",
        t.frames,
        args.scenes,
        args.frames_per_scene,
        args.split.name(),
        args.seed,
        if args.noise == Toggle::On { "on" } else { "off" },
        Randomize::from(args.randomize),
        DepthSensor::from(args.depth_sensor),
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

    fn args(extra: &[&str]) -> Args {
        use clap::Parser;
        #[derive(clap::Parser)]
        struct Cli {
            #[command(flatten)]
            args: Args,
        }
        let argv = ["render", "--out", "/tmp/x"].iter().chain(extra).copied();
        Cli::try_parse_from(argv).unwrap().args
    }

    #[test]
    fn flags_pick_the_sampler_config() {
        let k = Intrinsics::YCB_VIDEO;
        // Defaults: the training configuration with the structured-light sensor.
        let cfg = sampler_config(&args(&[]), k);
        let training = SamplerConfig { views: 5, intrinsics: k, ..SamplerConfig::training() };
        assert_eq!(cfg, training);
        assert_eq!((cfg.randomize, cfg.depth_sensor), (Randomize::Default, DepthSensor::StructuredLight));
        // Off + basic: exactly the original sampler (old splits reproduce).
        let cfg = sampler_config(&args(&["--randomize", "off", "--depth-sensor", "basic"]), k);
        assert_eq!(cfg, SamplerConfig { views: 5, intrinsics: k, ..SamplerConfig::default() });
        let cfg = sampler_config(
            &args(&["--randomize", "strong", "--depth-sensor", "tof", "--instances-per-class", "2..4", "--heap"]),
            k,
        );
        assert_eq!((cfg.randomize, cfg.depth_sensor), (Randomize::Strong, DepthSensor::Tof));
        assert_eq!(cfg.instances_per_class, (2, 4));
        assert_eq!(cfg.heap_probability, 1.0);
        let cfg = sampler_config(&args(&["--instances-per-class", "3", "--heap", "0.25", "--pairs", "0"]), k);
        assert_eq!((cfg.instances_per_class, cfg.heap_probability, cfg.pair_probability), ((3, 3), 0.25, 0.0));
        assert!("0..2".parse::<CountRange>().is_err() && "3..2".parse::<CountRange>().is_err());
        assert_eq!("1..=3".parse::<CountRange>().unwrap(), CountRange(1, 3));
        assert!(probability("1.5").is_err());
    }

    #[test]
    fn train_and_test_never_share_seeds() {
        let train: std::collections::HashSet<u64> = (0..1000).map(|i| scene_seed(0, Split::Train, i)).collect();
        assert_eq!(train.len(), 1000);
        assert!((0..1000).all(|i| !train.contains(&scene_seed(0, Split::Test, i))));
        assert_eq!(scene_seed(7, Split::Test, 3), scene_seed(7, Split::Test, 3));
        assert_ne!(scene_seed(0, Split::Train, 0), scene_seed(1, Split::Train, 0));
    }
}
