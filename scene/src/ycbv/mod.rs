//! The YCB-Video dataset reader (Xiang et al., PoseCNN, RSS 2018).
//!
//! Layout under the dataset root:
//! ```text
//! data/NNNN/NNNNNN-color.png   RGB8
//! data/NNNN/NNNNNN-depth.png   u16; metres = value / factor_depth (usually 10000)
//! data/NNNN/NNNNNN-label.png   class ids (0 = background)
//! data/NNNN/NNNNNN-meta.mat    MATLAB v5: poses 3x4xn, cls_indexes, intrinsic_matrix, factor_depth
//! image_sets/keyframe.txt      the test key frames, one `NNNN/NNNNNN` per line
//! image_sets/classes.txt       class names, line i ↔ class id i (1-based)
//! ```
//! Poses in `meta.mat` map object → camera in metres, our convention.

mod error;
mod meta;

#[cfg(test)]
mod mat_writer;
#[cfg(test)]
mod tests;

pub use error::YcbError;
pub use meta::{YcbMeta, read_meta};

use std::path::{Path, PathBuf};

use crate::bop::images::{read_depth_u16, read_labels_u16, read_rgb8};
use crate::{Intrinsics, Pose};

/// One ground-truth object of a frame.
#[derive(Clone, Debug, PartialEq)]
pub struct YcbGt {
    /// 1-based class id (`classes()[class_id - 1]`).
    pub class_id: u16,
    /// Object → camera, metres.
    pub pose: Pose,
}

/// One loaded frame.
#[derive(Clone, Debug, PartialEq)]
pub struct YcbFrame {
    /// The list entry, e.g. `0048/000001`.
    pub id: String,
    /// From `intrinsic_matrix`, image size from the colour image.
    pub intrinsics: Intrinsics,
    /// RGB8, `width * height * 3` bytes.
    pub rgb: Vec<u8>,
    /// Raw depth, `width * height`; metres = value * `depth_unit_m`; 0 = missing.
    pub depth: Vec<u16>,
    /// Metres per depth unit (`1 / factor_depth`).
    pub depth_unit_m: f64,
    /// Class-id plane from `-label.png` (0 = background).
    pub labels: Vec<u16>,
    pub gt: Vec<YcbGt>,
}

impl YcbFrame {
    /// The depth plane in metres (0 = missing).
    pub fn depth_metres(&self) -> Vec<f32> {
        self.depth.iter().map(|&d| (d as f64 * self.depth_unit_m) as f32).collect()
    }
}

/// A YCB-Video dataset root with a frame list.
#[derive(Clone, Debug)]
pub struct YcbVideo {
    root: PathBuf,
    classes: Vec<String>,
    frames: Vec<String>,
}

fn read_lines(path: &Path) -> Result<Vec<String>, YcbError> {
    let text = std::fs::read_to_string(path).map_err(|source| YcbError::Io { path: path.to_owned(), source })?;
    Ok(text.lines().map(str::trim).filter(|l| !l.is_empty()).map(str::to_string).collect())
}

impl YcbVideo {
    /// Opens `root` with the key-frame list `image_sets/keyframe.txt`.
    pub fn open(root: impl AsRef<Path>) -> Result<Self, YcbError> {
        let root = root.as_ref();
        Self::open_with_list(root, &root.join("image_sets").join("keyframe.txt"))
    }

    /// Opens `root` with a frame list file of `NNNN/NNNNNN` lines (entries
    /// starting with `data/` or `data_syn/` are taken relative to `root`,
    /// others relative to `root/data`). Class names come from
    /// `image_sets/classes.txt`, else `classes.txt` at the root.
    pub fn open_with_list(root: impl AsRef<Path>, list: &Path) -> Result<Self, YcbError> {
        let root = root.as_ref().to_path_buf();
        let candidates = [root.join("image_sets").join("classes.txt"), root.join("classes.txt")];
        let classes_path = candidates
            .iter()
            .find(|p| p.is_file())
            .ok_or_else(|| YcbError::NoClasses { tried: candidates.to_vec() })?;
        let classes = read_lines(classes_path)?;
        let frames = read_lines(list)?;
        for (line, entry) in frames.iter().enumerate() {
            let ok = !entry.starts_with('/')
                && !entry.contains('\\')
                && entry.split('/').all(|c| !c.is_empty() && c != "." && c != "..");
            if !ok {
                return Err(YcbError::BadListEntry { path: list.to_owned(), line: line + 1, entry: entry.clone() });
            }
        }
        Ok(YcbVideo { root, classes, frames })
    }

    /// Class names; class id `i + 1` is `classes()[i]`.
    pub fn classes(&self) -> &[String] {
        &self.classes
    }

    /// The frame list entries, in file order.
    pub fn frame_ids(&self) -> &[String] {
        &self.frames
    }

    pub fn len(&self) -> usize {
        self.frames.len()
    }

    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// The path prefix of a list entry (append `-color.png` etc.).
    fn prefix(&self, entry: &str) -> PathBuf {
        if entry.starts_with("data/") || entry.starts_with("data_syn/") {
            self.root.join(entry)
        } else {
            self.root.join("data").join(entry)
        }
    }

    fn file(&self, entry: &str, suffix: &str) -> PathBuf {
        let mut p = self.prefix(entry).into_os_string();
        p.push(suffix);
        PathBuf::from(p)
    }

    /// Reads only the `-meta.mat` of frame `index`.
    pub fn meta(&self, index: usize) -> Result<YcbMeta, YcbError> {
        let entry = self.entry(index)?;
        read_meta(&self.file(entry, "-meta.mat"))
    }

    fn entry(&self, index: usize) -> Result<&str, YcbError> {
        self.frames.get(index).map(String::as_str).ok_or(YcbError::FrameOutOfRange { index, len: self.frames.len() })
    }

    /// Loads frame `index`: colour, depth, labels and meta.
    pub fn load(&self, index: usize) -> Result<YcbFrame, YcbError> {
        let entry = self.entry(index)?;
        let image_err = |path: &Path| {
            let path = path.to_owned();
            move |source| YcbError::Image { path, source }
        };
        let meta_path = self.file(entry, "-meta.mat");
        let meta = read_meta(&meta_path)?;
        let color_path = self.file(entry, "-color.png");
        let rgb = read_rgb8(&color_path).map_err(image_err(&color_path))?;
        let (w, h) = (rgb.width, rgb.height);
        let depth_path = self.file(entry, "-depth.png");
        let depth = read_depth_u16(&depth_path).map_err(image_err(&depth_path))?;
        let label_path = self.file(entry, "-label.png");
        let labels = read_labels_u16(&label_path).map_err(image_err(&label_path))?;
        for (p, pw, ph) in [(&depth_path, depth.width, depth.height), (&label_path, labels.width, labels.height)] {
            if (pw, ph) != (w, h) {
                return Err(YcbError::Invalid {
                    path: p.clone(),
                    message: format!("{pw}x{ph} but the colour image is {w}x{h}"),
                });
            }
        }
        let gt = meta.class_ids.iter().zip(&meta.poses).map(|(&class_id, &pose)| YcbGt { class_id, pose }).collect();
        Ok(YcbFrame {
            id: entry.to_string(),
            intrinsics: meta.intrinsics(w, h),
            rgb: rgb.data,
            depth: depth.data,
            depth_unit_m: 1.0 / meta.factor_depth,
            labels: labels.data,
            gt,
        })
    }

    /// Loads every listed frame in order.
    pub fn iter(&self) -> impl Iterator<Item = Result<YcbFrame, YcbError>> + '_ {
        (0..self.len()).map(move |i| self.load(i))
    }
}
