//! `fusepose record`: keeps every n-th frame a camera publishes (subscribing
//! to its frame service beside the daemon) as a BOP split without ground
//! truth, to adapt the segmenter to that camera with (`fusepose adapt`, or
//! by hand `fusepose eval --pseudo-labels` and `fusepose train --stage seg
//! --adapt-labels`). Colour is written as RGB; u16 depth keeps its units,
//! metres (f32) become BOP's 0.1 mm units; labels the producer sent are not
//! written.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::Context;
use fusepose_client::{ColorFormat, DepthData, FrameHeader, Ipc, IpcOptions, decode_frame};
use fusepose_scene::Intrinsics;
use fusepose_scene::bop::{BopWriter, FrameToWrite};
use fusepose_scene::render::DEPTH_U16_PER_METRE;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Camera name (the producer's and the daemon's).
    #[arg(long, default_value = "cam0")]
    pub name: String,
    /// Dataset root to write (BOP layout; the split folder must be new).
    #[arg(long)]
    pub out: PathBuf,
    /// Split folder under `--out`.
    #[arg(long, default_value = "test")]
    pub split: String,
    /// Frames to keep.
    #[arg(long, default_value_t = 200)]
    pub frames: u32,
    /// Keep one frame in this many (24 at 24 FPS: one a second, so the views differ).
    #[arg(long, default_value_t = 24)]
    pub every: u32,
    /// Object set the daemon serves (`builtin` or a mesh folder), recorded in the dataset.
    #[arg(long, default_value = "builtin")]
    pub objects: String,
    /// Metres per mesh-file unit for a mesh folder (0.001 for millimetre meshes).
    #[arg(long, default_value_t = 1.0)]
    pub scale: f64,
    /// Give up after this long without a frame (seconds).
    #[arg(long, default_value_t = 10.0)]
    pub idle_timeout_s: f64,
}

/// One decoded frame as BOP stores it.
#[derive(Debug, PartialEq)]
pub struct RecordedFrame {
    pub intrinsics: Intrinsics,
    pub rgb: Vec<u8>,
    pub depth: Vec<u16>,
    pub depth_unit_m: f64,
}

/// A wire frame in BOP's terms: RGB colour, u16 depth (units kept, or metres
/// as 0.1 mm units: readings past 6.55 m or invalid become 0, no reading).
pub fn bop_frame(header: &FrameHeader, payload: &[u8], camera_id: u32) -> anyhow::Result<RecordedFrame> {
    let planes = decode_frame(header, payload, Some(camera_id)).map_err(|e| anyhow::anyhow!("a refused frame: {e}"))?;
    let h = &planes.header;
    let intrinsics = Intrinsics { fx: h.fx, fy: h.fy, cx: h.cx, cy: h.cy, width: h.width, height: h.height };
    let rgb = match planes.color_format {
        ColorFormat::Rgb8 => planes.color.to_vec(),
        ColorFormat::Bgr8 => planes.color.chunks_exact(3).flat_map(|p| [p[2], p[1], p[0]]).collect(),
    };
    let (depth, depth_unit_m) = match planes.depth {
        DepthData::U16 { data, scale } => (data.to_vec(), f64::from(scale)),
        DepthData::F32(data) => (
            data.iter()
                .map(|&z| {
                    let units = f64::from(z) * DEPTH_U16_PER_METRE;
                    if units.is_finite() && units >= 0.5 && units < f64::from(u16::MAX) {
                        units.round() as u16
                    } else {
                        0
                    }
                })
                .collect(),
            1.0 / DEPTH_U16_PER_METRE,
        ),
    };
    Ok(RecordedFrame { intrinsics, rgb, depth, depth_unit_m })
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if args.every == 0 || args.frames == 0 {
        anyhow::bail!("--every and --frames must be at least 1");
    }
    let objects = fusepose_scene::mesh_io::load_object_set(&args.objects, args.scale)
        .with_context(|| format!("loading object set `{}`", args.objects))?;
    let source = crate::render::object_source(&args.objects);
    let mut writer = BopWriter::create(&args.out, &args.split, &objects, &source)
        .with_context(|| format!("--out {}", args.out.display()))?;
    let ipc = Ipc::new(&IpcOptions::from_env().with_node_name("fusepose-record"))?;
    let services = fusepose_client::CameraServices::open(&ipc, &args.name)?;
    let frames = services.frame_subscriber()?;
    let idle = Duration::from_secs_f64(args.idle_timeout_s.max(0.1));
    let (mut seen, mut kept, mut last) = (0u64, 0u32, Instant::now());
    while kept < args.frames {
        let Some(sample) = frames.receive().map_err(|e| anyhow::anyhow!("receiving a frame: {e:?}"))? else {
            if last.elapsed() >= idle {
                anyhow::bail!("no frame on camera {} for {idle:?} ({kept} kept)", args.name);
            }
            std::thread::sleep(Duration::from_millis(5));
            continue;
        };
        last = Instant::now();
        seen += 1;
        if (seen - 1) % u64::from(args.every) != 0 {
            continue;
        }
        let header = *sample.user_header();
        let f = match bop_frame(&header, sample.payload(), header.camera_id) {
            Ok(f) => f,
            Err(e) => {
                eprintln!("frame {}: {e:#}; skipped", header.sequence);
                continue;
            }
        };
        let no_labels = vec![0u16; f.depth.len()];
        writer.write_frame(&FrameToWrite {
            scene_id: 0,
            im_id: kept,
            intrinsics: f.intrinsics,
            rgb: &f.rgb,
            depth: &f.depth,
            depth_unit_m: f.depth_unit_m,
            instance_labels: &no_labels,
            instances: &[],
        })?;
        kept += 1;
    }
    println!("recorded {kept} frames of camera {} into {}", args.name, args.out.join(&args.split).display());
    let split = if args.split == "test" { String::new() } else { format!(" --split {}", args.split) };
    println!(
        "adapt the segmenter to them: fusepose adapt --frames {}{split} --out models/{}.safetensors",
        args.out.display(),
        args.name
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use fusepose_client::{DepthFormat, FrameLayout};

    fn frame(color: ColorFormat, depth: DepthFormat) -> (FrameHeader, Vec<u8>) {
        let layout = FrameLayout {
            width: 4,
            height: 2,
            color_format: color,
            depth_format: depth,
            depth_scale: 0.001,
            labels: None,
        };
        let mut header = layout.header(0);
        (header.fx, header.fy, header.cx, header.cy) = (500.0, 500.0, 1.5, 0.5);
        let mut payload = vec![0u8; layout.payload_len()];
        let [c, d, _] = layout.planes();
        for (i, px) in payload[c.offset as usize..(c.offset + c.len) as usize].chunks_exact_mut(3).enumerate() {
            px.copy_from_slice(&[i as u8, 100, 200]);
        }
        let plane = &mut payload[d.offset as usize..(d.offset + d.len) as usize];
        if depth == DepthFormat::U16 {
            for (i, v) in plane.chunks_exact_mut(2).enumerate() {
                v.copy_from_slice(&(500 + i as u16).to_ne_bytes());
            }
        } else {
            for (v, z) in plane.chunks_exact_mut(4).zip([0.5f32, 1.25, 0.0, f32::NAN, 7.0, 0.33333, 2.0, 0.00001]) {
                v.copy_from_slice(&z.to_ne_bytes());
            }
        }
        (header, payload)
    }

    #[test]
    fn frames_become_rgb_and_bop_depth_units() {
        let (h, p) = frame(ColorFormat::Bgr8, DepthFormat::U16);
        let f = bop_frame(&h, &p, h.camera_id).unwrap();
        assert_eq!((f.intrinsics.width, f.intrinsics.height, f.intrinsics.fx), (4, 2, 500.0));
        assert_eq!(&f.rgb[..6], &[200, 100, 0, 200, 100, 1], "BGR turned to RGB");
        assert_eq!(f.depth[..3], [500, 501, 502], "u16 units kept");
        assert!((f.depth_unit_m - 0.001).abs() < 1e-9);

        let (h, p) = frame(ColorFormat::Rgb8, DepthFormat::F32);
        let f = bop_frame(&h, &p, h.camera_id).unwrap();
        assert_eq!(&f.rgb[..3], &[0, 100, 200]);
        assert_eq!(f.depth, vec![5000, 12500, 0, 0, 0, 3333, 20000, 0], "metres as 0.1 mm; none, NaN, past 6.55 m: 0");
        assert!((f.depth_unit_m - 1e-4).abs() < 1e-12);
    }
}
