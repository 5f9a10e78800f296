//! Randomised training frames: a benchmark and the documentation pictures.
//!
//! ```sh
//! # ms per 640x480 frame: SamplerConfig::training() with exactly 6 objects,
//! # every effect (shadows for 1-4 lights, specular, camera pipeline, JPEG in
//! # half the frames) and the structured-light depth model, on one core.
//! cargo run --release -p fusepose-scene --example randomized_render -- bench [FRAMES]
//! # docs/depth_sensors.png (one frame, each depth model) and
//! # docs/randomized_frames.png (8 randomised training frames).
//! cargo run --release -p fusepose-scene --example randomized_render -- pictures docs
//! ```

use fusepose_scene::builtin::builtin_objects;
use fusepose_scene::contact_sheet::ContactSheet;
use fusepose_scene::render::{
    Blur, CameraEffects, DepthSensor, NoiseConfig, Randomize, RenderTarget, apply_camera_effects,
};
use fusepose_scene::sampler::{SamplerConfig, Scene, ViewOptions, render_view, render_view_with, sample_scene};
use fusepose_scene::{Intrinsics, ObjectSet};
use std::path::Path;
use std::time::Instant;

fn loadavg() -> String {
    std::fs::read_to_string("/proc/loadavg").map(|s| s.trim().to_string()).unwrap_or_else(|_| "n/a".into())
}

/// This thread's on-CPU time in milliseconds (Linux), `None` elsewhere.
fn thread_cpu_ms() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    Some(s.split_whitespace().next()?.parse::<f64>().ok()? / 1e6)
}

/// (wall, cpu) milliseconds of `f`.
fn timed<T>(f: impl FnOnce() -> T) -> (T, f64, f64) {
    let (c0, t0) = (thread_cpu_ms(), Instant::now());
    let out = f();
    let wall = t0.elapsed().as_secs_f64() * 1e3;
    let cpu = match (c0, thread_cpu_ms()) {
        (Some(a), Some(b)) => b - a,
        _ => f64::NAN,
    };
    (out, wall, cpu)
}

fn percentile(mut v: Vec<f64>, q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// Scene of docs/depth_sensors.png: objects, a table edge and a wall behind.
const DEPTH_PICTURE_SEED: u64 = 3;

fn bench_config() -> SamplerConfig {
    SamplerConfig {
        min_objects: 6,
        max_objects: 6,
        instances_per_class: (1, 1),
        pair_probability: 0.0,
        heap_probability: 0.0,
        ..SamplerConfig::training()
    }
}

fn row(name: &str, wall: &[f64], cpu: &[f64]) {
    let n = cpu.len() as f64;
    let cpu_mean = cpu.iter().sum::<f64>() / n;
    println!(
        "{name:<40} {:>9.2} {:>9.2} {:>9.2} {:>9.1}",
        percentile(wall.to_vec(), 0.5),
        percentile(wall.to_vec(), 0.9),
        cpu_mean,
        1e3 / cpu_mean
    );
}

fn bench(frames: usize) {
    let set = builtin_objects();
    let k = Intrinsics::YCB_VIDEO;
    let cfg = bench_config();
    let scenes: Vec<Scene> =
        (0..frames as u64).map(|seed| sample_scene(&set, &cfg, 1000 + seed).expect("sample")).collect();
    let mut target = RenderTarget::for_intrinsics(&k);
    let distractors: usize = scenes.iter().map(|s| s.extras.distractors.len()).sum();
    let lights: usize = scenes.iter().map(|s| s.lighting.lights.len() + s.lighting.points.len()).sum();
    println!(
        "randomized_render bench: {frames} frames {}x{}, 6 built-in objects, {:.1} distractors and {:.1} lights per scene",
        k.width,
        k.height,
        distractors as f64 / frames as f64,
        lights as f64 / frames as f64
    );
    println!("load before: {}", loadavg());
    render_view(&scenes[0], &set, 0, &k, &NoiseConfig::default(), &mut target).expect("warm-up");
    println!("{:<40} {:>9} {:>9} {:>9} {:>9}", "ms per frame", "wall med", "wall p90", "cpu mean", "fps(cpu)");
    let modes: [(&str, Randomize, DepthSensor); 6] = [
        ("randomize off, basic (old renderer)", Randomize::Off, DepthSensor::Basic),
        ("randomize default, ideal depth", Randomize::Default, DepthSensor::Ideal),
        ("randomize default, basic", Randomize::Default, DepthSensor::Basic),
        ("randomize default, structured-light", Randomize::Default, DepthSensor::StructuredLight),
        ("randomize default, tof", Randomize::Default, DepthSensor::Tof),
        ("randomize strong, structured-light", Randomize::Strong, DepthSensor::StructuredLight),
    ];
    for (name, randomize, depth_sensor) in modes {
        let (mut wall, mut cpu) = (Vec::new(), Vec::new());
        for s in &scenes {
            let opts = ViewOptions { intrinsics: k, depth_sensor, randomize };
            let (_, w, c) = timed(|| render_view_with(s, &set, 0, &opts, &mut target).expect("render"));
            wall.push(w);
            cpu.push(c);
        }
        row(name, &wall, &cpu);
    }
    // Upper bound of an "every effect" frame: the structured-light frame plus
    // JPEG and defocus applied on top of whatever the view drew.
    let (mut wall, mut cpu) = (Vec::new(), Vec::new());
    let extra = CameraEffects { blur: Blur::Defocus { sigma_px: 1.0 }, jpeg_quality: Some(75), ..Default::default() };
    for s in &scenes {
        let opts =
            ViewOptions { intrinsics: k, depth_sensor: DepthSensor::StructuredLight, randomize: Randomize::Default };
        let (_, w, c) = timed(|| {
            render_view_with(s, &set, 0, &opts, &mut target).expect("render");
            apply_camera_effects(&mut target, &extra, 1);
        });
        wall.push(w);
        cpu.push(c);
    }
    row("  + JPEG and defocus forced on (bound)", &wall, &cpu);
    let (mut wall, mut cpu) = (Vec::new(), Vec::new());
    for seed in 0..frames as u64 {
        let (_, w, c) = timed(|| sample_scene(&set, &cfg, 5000 + seed).expect("sample"));
        wall.push(w);
        cpu.push(c);
    }
    row("sample_scene (training, 6 objects)", &wall, &cpu);
    let full = SamplerConfig::training();
    let (mut wall, mut cpu) = (Vec::new(), Vec::new());
    for seed in 0..frames as u64 {
        let (_, w, c) = timed(|| {
            if let Ok(s) = sample_scene(&set, &full, 9000 + seed) {
                render_view(&s, &set, 0, &k, &NoiseConfig::default(), &mut target).expect("render");
            }
        });
        wall.push(w);
        cpu.push(c);
    }
    row("training(): sample + render, as trained", &wall, &cpu);
    println!("load after: {}", loadavg());
}

fn pictures(dir: &Path, set: &ObjectSet, sensor_seed: u64) {
    let k = Intrinsics::YCB_VIDEO;
    let mut target = RenderTarget::for_intrinsics(&k);
    std::fs::create_dir_all(dir).expect("create the output folder");
    // One view, every depth model (rows: ideal, basic, structured light, ToF).
    // A mid-range view (0.6-0.9 m, 25-50° elevation) shows every effect.
    let cfg = SamplerConfig {
        min_objects: 5,
        max_objects: 5,
        camera_distance_m: (0.6, 0.9),
        camera_elevation_deg: (25.0, 50.0),
        ..SamplerConfig::training()
    };
    let scene = sample_scene(set, &cfg, sensor_seed).expect("sample");
    // One colour scale for all rows: the 2nd..98th percentile of the exact depth.
    let opts = ViewOptions { intrinsics: k, depth_sensor: DepthSensor::Ideal, randomize: Randomize::Default };
    render_view_with(&scene, set, 0, &opts, &mut target).expect("render");
    let mut z: Vec<f32> = target.depth_m().iter().copied().filter(|&z| z > 0.0).collect();
    z.sort_by(f32::total_cmp);
    let (lo, hi) = (z[z.len() / 50], z[z.len() * 49 / 50]);
    let mut sheet = ContactSheet::new(320).with_depth_range(lo, hi);
    for sensor in DepthSensor::ALL {
        let opts = ViewOptions { intrinsics: k, depth_sensor: sensor, randomize: Randomize::Default };
        render_view_with(&scene, set, 0, &opts, &mut target).expect("render");
        sheet.push((&target).into()).expect("sheet");
    }
    let path = dir.join("depth_sensors.png");
    sheet.save_png(&path).expect("write depth_sensors.png");
    println!("{} (rows: ideal, basic, structured-light, tof; scene seed {sensor_seed})", path.display());

    let cfg = SamplerConfig::training();
    let mut sheet = ContactSheet::new(320);
    let mut seed = 100;
    while sheet.len() < 8 {
        if let Ok(s) = sample_scene(set, &cfg, seed) {
            render_view(&s, set, 0, &k, &NoiseConfig::default(), &mut target).expect("render");
            sheet.push((&target).into()).expect("sheet");
        }
        seed += 1;
    }
    let path = dir.join("randomized_frames.png");
    sheet.save_png(&path).expect("write randomized_frames.png");
    println!("{} (SamplerConfig::training(), scene seeds 100..)", path.display());
}

fn main() {
    let mut args = std::env::args().skip(1);
    match args.next().as_deref() {
        Some("bench") => bench(args.next().and_then(|a| a.parse().ok()).unwrap_or(40).max(1)),
        Some("pictures") => {
            let dir = args.next().unwrap_or_else(|| "docs".into());
            let seed = args.next().and_then(|a| a.parse().ok()).unwrap_or(DEPTH_PICTURE_SEED);
            pictures(Path::new(&dir), &builtin_objects(), seed)
        }
        _ => eprintln!("usage: randomized_render bench [FRAMES] | pictures [DIR [SCENE_SEED]]"),
    }
}
