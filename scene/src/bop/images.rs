//! PNG/JPEG plane I/O shared by the dataset readers and writers: RGB8 colour,
//! 16-bit depth, 8/16-bit label and mask planes. Errors carry no path; callers
//! attach it.

use std::path::Path;

use image::{DynamicImage, ImageBuffer, ImageReader, Luma, Rgb};

/// Why an image file could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum ImageFileError {
    #[error("{0}")]
    Io(#[from] std::io::Error),
    #[error("cannot decode or encode image: {0}")]
    Codec(#[from] image::ImageError),
    #[error("{0}")]
    Format(String),
}

/// A decoded plane: `width * height * channels` values, row-major, top row first.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Plane<T> {
    pub width: u32,
    pub height: u32,
    pub data: Vec<T>,
}

fn decode(path: &Path) -> Result<DynamicImage, ImageFileError> {
    Ok(ImageReader::open(path)?.with_guessed_format()?.decode()?)
}

/// Reads a colour image as RGB8 (grey or RGBA are converted; 16-bit is scaled to 8).
pub(crate) fn read_rgb8(path: &Path) -> Result<Plane<u8>, ImageFileError> {
    let img = decode(path)?.into_rgb8();
    Ok(Plane { width: img.width(), height: img.height(), data: img.into_raw() })
}

/// Reads a single-channel 16-bit depth image (values unscaled).
pub(crate) fn read_depth_u16(path: &Path) -> Result<Plane<u16>, ImageFileError> {
    match decode(path)? {
        DynamicImage::ImageLuma16(img) => Ok(Plane { width: img.width(), height: img.height(), data: img.into_raw() }),
        other => Err(ImageFileError::Format(format!(
            "depth must be a single-channel 16-bit image, found {:?}",
            other.color()
        ))),
    }
}

/// Reads a single-channel 8- or 16-bit label image as u16 values (unscaled).
pub(crate) fn read_labels_u16(path: &Path) -> Result<Plane<u16>, ImageFileError> {
    match decode(path)? {
        DynamicImage::ImageLuma8(img) => Ok(Plane {
            width: img.width(),
            height: img.height(),
            data: img.into_raw().into_iter().map(u16::from).collect(),
        }),
        DynamicImage::ImageLuma16(img) => Ok(Plane { width: img.width(), height: img.height(), data: img.into_raw() }),
        other => Err(ImageFileError::Format(format!(
            "labels must be a single-channel 8- or 16-bit image, found {:?}",
            other.color()
        ))),
    }
}

/// Reads a mask: `true` where any channel is non-zero.
pub(crate) fn read_mask(path: &Path) -> Result<Plane<bool>, ImageFileError> {
    let img = decode(path)?;
    let (width, height) = (img.width(), img.height());
    let data = match img {
        DynamicImage::ImageLuma8(i) => i.into_raw().into_iter().map(|v| v != 0).collect(),
        DynamicImage::ImageLuma16(i) => i.into_raw().into_iter().map(|v| v != 0).collect(),
        other => other.into_rgb8().pixels().map(|p| p.0 != [0, 0, 0]).collect(),
    };
    Ok(Plane { width, height, data })
}

fn check_len(len: usize, width: u32, height: u32, channels: usize) -> Result<(), ImageFileError> {
    let expected = width as usize * height as usize * channels;
    if len != expected || width == 0 || height == 0 {
        return Err(ImageFileError::Format(format!(
            "{len} values for a {width}x{height} image with {channels} channel(s), expected {expected} (> 0)"
        )));
    }
    Ok(())
}

/// Writes an RGB8 PNG.
pub(crate) fn write_rgb8_png(path: &Path, width: u32, height: u32, rgb: &[u8]) -> Result<(), ImageFileError> {
    check_len(rgb.len(), width, height, 3)?;
    let img: ImageBuffer<Rgb<u8>, &[u8]> =
        ImageBuffer::from_raw(width, height, rgb).ok_or_else(|| ImageFileError::Format("bad RGB buffer".into()))?;
    img.save_with_format(path, image::ImageFormat::Png)?;
    Ok(())
}

/// Writes a single-channel 16-bit PNG.
pub(crate) fn write_u16_png(path: &Path, width: u32, height: u32, values: &[u16]) -> Result<(), ImageFileError> {
    check_len(values.len(), width, height, 1)?;
    let img: ImageBuffer<Luma<u16>, &[u16]> = ImageBuffer::from_raw(width, height, values)
        .ok_or_else(|| ImageFileError::Format("bad 16-bit buffer".into()))?;
    img.save_with_format(path, image::ImageFormat::Png)?;
    Ok(())
}

/// Writes a single-channel 8-bit PNG.
pub(crate) fn write_u8_png(path: &Path, width: u32, height: u32, values: &[u8]) -> Result<(), ImageFileError> {
    check_len(values.len(), width, height, 1)?;
    let img: ImageBuffer<Luma<u8>, &[u8]> = ImageBuffer::from_raw(width, height, values)
        .ok_or_else(|| ImageFileError::Format("bad 8-bit buffer".into()))?;
    img.save_with_format(path, image::ImageFormat::Png)?;
    Ok(())
}
