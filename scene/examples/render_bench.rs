//! Renderer benchmark: time to render one 640x480 YCB-Video-like frame (6
//! built-in objects on a textured table in a room) on one core, with sensor
//! noise off and on, and with nearest vs bilinear texture sampling.
//!
//! ```sh
//! cargo run --release -p fusepose-scene --example render_bench [-- FRAMES [SHEET.png]]
//! ```
//! FRAMES defaults to 50; SHEET.png, if given, receives a contact sheet of the
//! first four frames (noise on).

use fusepose_scene::builtin::builtin_objects;
use fusepose_scene::contact_sheet::ContactSheet;
use fusepose_scene::render::{self, NoiseConfig, RenderSettings, RenderTarget, TextureFilter};
use fusepose_scene::sampler::{SamplerConfig, Scene, render_view, sample_scene};
use fusepose_scene::{Intrinsics, ObjectSet};
use std::time::Instant;

fn loadavg() -> String {
    std::fs::read_to_string("/proc/loadavg").map(|s| s.trim().to_string()).unwrap_or_else(|_| "n/a".into())
}

/// This thread's on-CPU time in milliseconds (Linux `/proc/thread-self/schedstat`),
/// so timings stay meaningful on a loaded machine; `None` elsewhere.
fn thread_cpu_ms() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    Some(s.split_whitespace().next()?.parse::<f64>().ok()? / 1e6)
}

/// Wall-clock and on-CPU milliseconds of `f`.
fn timed(f: impl FnOnce()) -> (f64, f64) {
    let (c0, t0) = (thread_cpu_ms(), Instant::now());
    f();
    let wall = t0.elapsed().as_secs_f64() * 1e3;
    let cpu = match (c0, thread_cpu_ms()) {
        (Some(a), Some(b)) => b - a,
        _ => f64::NAN,
    };
    (wall, cpu)
}

/// Median and 90th percentile (milliseconds) of the samples.
fn stats(mut ms: Vec<f64>) -> (f64, f64) {
    ms.sort_by(f64::total_cmp);
    let at = |q: f64| ms[((ms.len() - 1) as f64 * q).round() as usize];
    (at(0.5), at(0.9))
}

/// Renders every scene's first view; per-frame (wall, CPU) milliseconds.
fn time_frames(
    scenes: &[Scene],
    set: &ObjectSet,
    k: &Intrinsics,
    noise: &NoiseConfig,
    filter: TextureFilter,
    target: &mut RenderTarget,
) -> Vec<(f64, f64)> {
    scenes
        .iter()
        .map(|s| {
            timed(|| {
                if filter == TextureFilter::Bilinear {
                    render_view(s, set, 0, k, noise, target).expect("render");
                } else {
                    // Same as render_view, with another texture filter.
                    let items = s.render_items(set, 0).expect("items");
                    let cam = s.views[0].camera_from_table;
                    let settings = RenderSettings {
                        lighting: s.lighting.rotated(&cam.rotation.to_rotation_matrix()),
                        texture_filter: filter,
                        ..RenderSettings::default()
                    };
                    render::render_scene(&items, k, &settings, target).expect("render");
                    render::apply_noise(target, noise, s.seed);
                }
            })
        })
        .collect()
}

/// Prints one table row: wall-clock median and p90 per frame, and the mean
/// on-CPU time per frame (the scheduler accounts CPU time in ticks, so only
/// its sum over many frames is precise).
fn row(name: &str, samples: Vec<(f64, f64)>) {
    let n = samples.len() as f64;
    let cpu_mean = samples.iter().map(|s| s.1).sum::<f64>() / n;
    let (wm, wp) = stats(samples.iter().map(|s| s.0).collect());
    println!("{name:<26} {wm:>9.2} {wp:>9.2} {cpu_mean:>9.2} {:>9.1}", 1e3 / cpu_mean);
}

fn main() {
    let mut args = std::env::args().skip(1);
    let frames: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(50).max(1);
    let sheet_path = args.next();

    let set = builtin_objects();
    let k = Intrinsics::YCB_VIDEO;
    let cfg = SamplerConfig { min_objects: 6, max_objects: 6, ..SamplerConfig::default() };
    let scenes: Vec<Scene> = (0..frames as u64).map(|seed| sample_scene(&set, &cfg, seed).expect("sample")).collect();
    let tris: Vec<usize> =
        scenes.iter().map(|s| s.render_items(&set, 0).unwrap().iter().map(|i| i.mesh.triangles.len()).sum()).collect();
    let mut target = RenderTarget::for_intrinsics(&k);

    println!("render_bench: {frames} frames, {}x{}, 6 built-in objects + table + room", k.width, k.height);
    println!(
        "triangles per frame: min {} max {} (objects: {})",
        tris.iter().min().unwrap(),
        tris.iter().max().unwrap(),
        set.objects.iter().map(|o| format!("{} {}", o.name, o.mesh.triangles.len())).collect::<Vec<_>>().join(", ")
    );
    println!("load before: {}", loadavg());
    // Warm-up (page in buffers, lazy tables).
    time_frames(&scenes[..1], &set, &k, &NoiseConfig::default(), TextureFilter::Bilinear, &mut target);

    println!("{:<26} {:>9} {:>9} {:>9} {:>9}", "mode (ms per frame)", "wall med", "wall p90", "cpu mean", "fps(cpu)");
    let modes = [
        ("noise off, bilinear", NoiseConfig::off(), TextureFilter::Bilinear),
        ("noise on,  bilinear", NoiseConfig::default(), TextureFilter::Bilinear),
        ("noise off, nearest", NoiseConfig::off(), TextureFilter::Nearest),
        ("noise on,  nearest", NoiseConfig::default(), TextureFilter::Nearest),
    ];
    for (name, noise, filter) in modes {
        row(name, time_frames(&scenes, &set, &k, &noise, filter, &mut target));
    }
    // Noise alone, on an already rendered frame.
    let noise_ms: Vec<(f64, f64)> = scenes
        .iter()
        .map(|s| {
            render_view(s, &set, 0, &k, &NoiseConfig::off(), &mut target).expect("render");
            timed(|| render::apply_noise(&mut target, &NoiseConfig::default(), 1))
        })
        .collect();
    row("apply_noise only", noise_ms);
    // Scene sampling (no occlusion target) for reference.
    let sample_ms: Vec<(f64, f64)> = (0..frames as u64)
        .map(|seed| timed(|| drop(sample_scene(&set, &cfg, 10_000 + seed).expect("sample"))))
        .collect();
    row("sample_scene", sample_ms);
    let occl = SamplerConfig { target_occlusion: Some((0.3, 0.7)), ..cfg.clone() };
    let occl_ms: Vec<(f64, f64)> = (0..frames as u64)
        .map(|seed| timed(|| drop(sample_scene(&set, &occl, 20_000 + seed).expect("sample"))))
        .collect();
    row("sample_scene, occl 30-70%", occl_ms);
    println!("load after: {}", loadavg());

    if let Some(path) = sheet_path {
        let mut sheet = ContactSheet::new(320);
        for s in scenes.iter().take(4) {
            render_view(s, &set, 0, &k, &NoiseConfig::default(), &mut target).expect("render");
            sheet.push((&target).into()).expect("sheet");
        }
        sheet.save_png(&path).expect("write sheet");
        println!("contact sheet: {path}");
    }
}
