//! `--intrinsics`: the camera that training and test frames are rendered
//! for, by preset name or as `fx,fy,cx,cy,width,height` (pixels), so that a
//! model learns the views, resolution and field of view of the user's camera.

use fusepose_client::FOCAL_RANGE_PX;
use fusepose_scene::Intrinsics;

/// Named cameras (colour stream, pixels). For an exact match give your
/// camera's own K (ROS: `camera_info.k`; RealSense: `rs-enumerate-devices -c`).
pub const PRESETS: [(&str, Intrinsics); 2] = [
    ("ycb-video", Intrinsics::YCB_VIDEO),
    // Typical Intel RealSense D435/D435i colour stream at 640x480 (69° x 42° field of view).
    ("realsense-d435", Intrinsics { fx: 615.0, fy: 615.0, cx: 320.0, cy: 240.0, width: 640, height: 480 }),
];

/// Help text of every `--intrinsics` flag.
pub const HELP: &str =
    "Camera to render for: a preset (ycb-video, realsense-d435) or fx,fy,cx,cy,width,height in pixels";

/// Parses a preset name or `fx,fy,cx,cy,width,height`.
pub fn parse(text: &str) -> Result<Intrinsics, String> {
    if let Some((_, k)) = PRESETS.iter().find(|(name, _)| *name == text) {
        return Ok(*k);
    }
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    if parts.len() != 6 {
        let names: Vec<&str> = PRESETS.iter().map(|(n, _)| *n).collect();
        return Err(format!(
            "'{text}' is neither a camera preset ({}) nor fx,fy,cx,cy,width,height in pixels",
            names.join(", ")
        ));
    }
    let num = |i: usize, what: &str| -> Result<f64, String> {
        parts[i]
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("{what} '{}' is not a number", parts[i]))
    };
    let (fx, fy, cx, cy) = (num(0, "fx")?, num(1, "fy")?, num(2, "cx")?, num(3, "cy")?);
    let size = |i: usize, what: &str| -> Result<u32, String> {
        parts[i]
            .parse::<u32>()
            .ok()
            .filter(|v| (64..=4096).contains(v))
            .ok_or_else(|| format!("{what} '{}' must be a whole number of pixels in 64..=4096", parts[i]))
    };
    let (width, height) = (size(4, "width")?, size(5, "height")?);
    if !(FOCAL_RANGE_PX.contains(&fx) && FOCAL_RANGE_PX.contains(&fy)) {
        return Err(format!("focal lengths fx={fx}, fy={fy} must lie in {FOCAL_RANGE_PX:?} pixels"));
    }
    if !(0.0..=width as f64).contains(&cx) || !(0.0..=height as f64).contains(&cy) {
        return Err(format!(
            "principal point ({cx}, {cy}) lies outside the {width}x{height} image: is the order fx,fy,cx,cy,width,height?"
        ));
    }
    Ok(Intrinsics { fx, fy, cx, cy, width, height })
}

/// The flag value that [`parse`] reads back as `k`.
pub fn format(k: &Intrinsics) -> String {
    format!("{},{},{},{},{},{}", k.fx, k.fy, k.cx, k.cy, k.width, k.height)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_and_numbers_parse_and_mistakes_are_named() {
        assert_eq!(parse("ycb-video").unwrap(), Intrinsics::YCB_VIDEO);
        let k = parse("610.5, 611, 321.2, 239.8, 640, 480").unwrap();
        assert_eq!((k.fx, k.fy, k.cx, k.cy, k.width, k.height), (610.5, 611.0, 321.2, 239.8, 640, 480));
        assert_eq!(parse(&format(&k)).unwrap(), k);
        assert!(parse("d455").unwrap_err().contains("realsense-d435"));
        assert!(parse("610,611,640,480,320,240").unwrap_err().contains("principal point"));
        assert!(parse("610,611,320,240,640,x").unwrap_err().contains("height"));
        assert!(parse("0.6,0.6,320,240,640,480").unwrap_err().contains("focal"));
    }
}
