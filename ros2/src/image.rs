//! Checking ROS images and camera info against what a fusepose frame can
//! carry, and copying their pixels into a loaned frame.
//!
//! Colour: `rgb8` / `bgr8`. Depth: `16UC1` (or `mono16`) in millimetres, the
//! ROS convention (REP 118), or `32FC1` in metres; the same size as colour
//! (aligned to it). Rows may be padded (`step`); big-endian depth is swapped.

use fusepose_client::{ColorFormat, DepthFormat, DepthMut, FOCAL_RANGE_PX, FrameLayout};

use crate::msg::{CameraInfo, Image};

/// Pinhole intrinsics, pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pinhole {
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
}

/// Why a message was dropped; `key` groups log lines for rate limiting.
#[derive(Clone, Debug, PartialEq)]
pub struct Rejected {
    pub key: &'static str,
    pub message: String,
}

fn reject(key: &'static str, message: String) -> Rejected {
    Rejected { key, message }
}

/// The intrinsics of a `CameraInfo`, refusing any lens distortion.
pub fn pinhole(info: &CameraInfo) -> Result<Pinhole, Rejected> {
    let model = info.distortion_model.as_str();
    let zero = info.d.iter().all(|&d| d == 0.0);
    if !matches!(model, "plumb_bob" | "rational_polynomial" | "") || !zero {
        return Err(reject(
            "distortion",
            format!(
                "CameraInfo has distortion model '{model}' with coefficients {:?}: fusepose needs undistorted images \
                 (plumb_bob with zero coefficients, as realsense2_camera's colour and aligned depth topics are); \
                 rectify first (image_proc) or use the aligned topics",
                info.d
            ),
        ));
    }
    if info.binning_x > 1 || info.binning_y > 1 || info.roi.width != 0 || info.roi.height != 0 {
        return Err(reject(
            "binning",
            format!(
                "CameraInfo uses binning {}x{} or a region of interest {:?}: not supported; publish full-resolution images",
                info.binning_x, info.binning_y, info.roi
            ),
        ));
    }
    let k = info.k;
    let (fx, fy, cx, cy) = (k[0], k[4], k[2], k[5]);
    if !(FOCAL_RANGE_PX.contains(&fx) && FOCAL_RANGE_PX.contains(&fy) && cx.is_finite() && cy.is_finite()) {
        return Err(reject(
            "intrinsics",
            format!("CameraInfo has unusable intrinsics k = {k:?} (fx, fy must lie in {FOCAL_RANGE_PX:?} px)"),
        ));
    }
    Ok(Pinhole { width: info.width, height: info.height, fx, fy, cx, cy })
}

fn color_format(encoding: &str) -> Option<ColorFormat> {
    match encoding {
        "rgb8" => Some(ColorFormat::Rgb8),
        "bgr8" => Some(ColorFormat::Bgr8),
        _ => None,
    }
}

fn depth_format(encoding: &str) -> Option<DepthFormat> {
    match encoding {
        "16UC1" | "mono16" => Some(DepthFormat::U16),
        "32FC1" => Some(DepthFormat::F32),
        _ => None,
    }
}

/// Checks that `img` holds `height` rows of `width * bpp` bytes at its `step`.
fn check_size(img: &Image, what: &str, bpp: usize) -> Result<(), Rejected> {
    let row = img.width as usize * bpp;
    let needed = (img.step as usize).checked_mul(img.height.saturating_sub(1) as usize).map(|n| n + row);
    if img.width == 0 || img.height == 0 || (img.step as usize) < row || needed.is_none_or(|n| img.data.0.len() < n) {
        return Err(reject(
            "size",
            format!(
                "{what} image {}x{} step {} has {} data bytes, needs rows of {row} bytes: dropped",
                img.width,
                img.height,
                img.step,
                img.data.0.len()
            ),
        ));
    }
    Ok(())
}

/// The frame layout of a colour + depth pair (checked: encodings, sizes, alignment, intrinsics size).
pub fn layout_of(color: &Image, depth: &Image, k: &Pinhole) -> Result<FrameLayout, Rejected> {
    let cf = color_format(&color.encoding).ok_or_else(|| {
        reject("color_encoding", format!("colour encoding '{}' is not supported: publish rgb8 or bgr8", color.encoding))
    })?;
    let df = depth_format(&depth.encoding).ok_or_else(|| {
        reject(
            "depth_encoding",
            format!("depth encoding '{}' is not supported: publish 16UC1 (mm) or 32FC1 (m)", depth.encoding),
        )
    })?;
    check_size(color, "colour", 3)?;
    check_size(depth, "depth", df.bytes_per_pixel())?;
    if (color.width, color.height) != (depth.width, depth.height) {
        return Err(reject(
            "alignment",
            format!(
                "depth {}x{} differs from colour {}x{}: subscribe to depth aligned to colour (realsense: aligned_depth_to_color, align_depth.enable:=true)",
                depth.width, depth.height, color.width, color.height
            ),
        ));
    }
    if (k.width, k.height) != (color.width, color.height) {
        return Err(reject(
            "info_size",
            format!(
                "CameraInfo is for {}x{} images, colour is {}x{}: use the colour camera's camera_info",
                k.width, k.height, color.width, color.height
            ),
        ));
    }
    let layout = FrameLayout {
        width: color.width,
        height: color.height,
        color_format: cf,
        depth_format: df,
        depth_scale: if df == DepthFormat::U16 { 0.001 } else { 1.0 },
        labels: None,
    };
    layout.validate().map_err(|e| reject("layout", format!("images do not fit a fusepose frame: {e}")))?;
    Ok(layout)
}

/// Copies the pixels of a pair checked by [`layout_of`] into a frame's planes.
pub fn copy_planes(color: &Image, depth: &Image, out_color: &mut [u8], out_depth: DepthMut<'_>) {
    let (w, h) = (color.width as usize, color.height as usize);
    let row = w * 3;
    for (y, dst) in out_color.chunks_exact_mut(row).take(h).enumerate() {
        let start = y * color.step as usize;
        dst.copy_from_slice(&color.data.0[start..start + row]);
    }
    let swap = depth.is_bigendian != 0;
    match out_depth {
        DepthMut::U16(plane) => {
            for (y, dst) in plane.chunks_exact_mut(w).take(h).enumerate() {
                let src = &depth.data.0[y * depth.step as usize..][..w * 2];
                for (d, b) in dst.iter_mut().zip(src.chunks_exact(2)) {
                    let b = [b[0], b[1]];
                    *d = if swap { u16::from_be_bytes(b) } else { u16::from_le_bytes(b) };
                }
            }
        }
        DepthMut::F32(plane) => {
            for (y, dst) in plane.chunks_exact_mut(w).take(h).enumerate() {
                let src = &depth.data.0[y * depth.step as usize..][..w * 4];
                for (d, b) in dst.iter_mut().zip(src.chunks_exact(4)) {
                    let b = [b[0], b[1], b[2], b[3]];
                    *d = if swap { f32::from_be_bytes(b) } else { f32::from_le_bytes(b) };
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msg::ByteBuf;

    fn info() -> CameraInfo {
        CameraInfo {
            width: 4,
            height: 2,
            distortion_model: "plumb_bob".into(),
            d: vec![0.0; 5],
            k: [600.0, 0.0, 1.5, 0.0, 610.0, 0.5, 0.0, 0.0, 1.0],
            ..Default::default()
        }
    }

    fn image(encoding: &str, bpp: u32, pad: u32, big: bool) -> Image {
        let step = 4 * bpp + pad;
        let data = (0..step * 2).map(|i| i as u8).collect();
        Image {
            width: 4,
            height: 2,
            encoding: encoding.into(),
            step,
            is_bigendian: big as u8,
            data: ByteBuf(data),
            ..Default::default()
        }
    }

    #[test]
    fn intrinsics_come_from_k_and_distortion_is_refused() {
        let k = pinhole(&info()).unwrap();
        assert_eq!((k.fx, k.fy, k.cx, k.cy, k.width, k.height), (600.0, 610.0, 1.5, 0.5, 4, 2));
        let mut distorted = info();
        distorted.d[0] = 0.1;
        let e = pinhole(&distorted).unwrap_err();
        assert_eq!(e.key, "distortion");
        assert!(e.message.contains("undistorted"), "{}", e.message);
        let mut fisheye = info();
        fisheye.distortion_model = "equidistant".into();
        assert_eq!(pinhole(&fisheye).unwrap_err().key, "distortion");
        let mut zero_f = info();
        zero_f.k[0] = 0.0;
        assert_eq!(pinhole(&zero_f).unwrap_err().key, "intrinsics");
    }

    #[test]
    fn padded_rows_and_big_endian_depth_are_copied_into_tight_planes() {
        let k = pinhole(&info()).unwrap();
        let color = image("bgr8", 3, 4, false);
        let depth = image("16UC1", 2, 2, true);
        let layout = layout_of(&color, &depth, &k).unwrap();
        assert_eq!(
            (layout.color_format, layout.depth_format, layout.depth_scale),
            (ColorFormat::Bgr8, DepthFormat::U16, 0.001)
        );
        let mut rgb = vec![0u8; 24];
        let mut d = vec![0u16; 8];
        copy_planes(&color, &depth, &mut rgb, DepthMut::U16(&mut d));
        assert_eq!(&rgb[..12], &(0u8..12).collect::<Vec<_>>()[..]);
        assert_eq!(&rgb[12..], &(16u8..28).collect::<Vec<_>>()[..], "second row starts after the padding");
        assert_eq!(d[0], 0x0001, "big-endian bytes 0, 1");
        assert_eq!(d[4], u16::from_be_bytes([10, 11]), "second depth row at step 10");
    }

    #[test]
    fn wrong_encodings_sizes_and_misalignment_are_rejected_with_their_reason() {
        let k = pinhole(&info()).unwrap();
        let depth = image("32FC1", 4, 0, false);
        assert_eq!(layout_of(&image("rgba8", 4, 0, false), &depth, &k).unwrap_err().key, "color_encoding");
        assert_eq!(
            layout_of(&image("rgb8", 3, 0, false), &image("8UC1", 1, 0, false), &k).unwrap_err().key,
            "depth_encoding"
        );
        let mut short = image("rgb8", 3, 0, false);
        short.data.0.truncate(20);
        assert_eq!(layout_of(&short, &depth, &k).unwrap_err().key, "size");
        let mut small = image("32FC1", 4, 0, false);
        small.width = 2;
        small.step = 8;
        assert_eq!(layout_of(&image("rgb8", 3, 0, false), &small, &k).unwrap_err().key, "alignment");
        let ok = layout_of(&image("rgb8", 3, 0, false), &depth, &k).unwrap();
        assert_eq!((ok.depth_format, ok.depth_scale), (DepthFormat::F32, 1.0));
    }
}
