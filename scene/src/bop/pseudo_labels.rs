//! Pseudo-label folders: class labels for the frames of a BOP split that no
//! person labelled, drawn from the poses the estimator itself published and
//! the depth image confirmed (`fusepose eval --pseudo-labels DIR`), so that
//! the segmenter can learn a camera's colours from its own unlabelled frames
//! (`fusepose train --stage seg --adapt-labels DIR`).
//!
//! Not a BOP file kind; its own folder:
//! ```text
//! DIR/pseudo_labels.json            the source split, the class count, one entry per frame
//! DIR/labels/SSSSSS_IIIIII.png      8-bit: 0 background, a class id, 255 unknown (no loss)
//! ```

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::BopError;
use super::images::{read_labels_u16, write_u8_png};

/// The manifest's file name inside a pseudo-label folder.
pub const PSEUDO_MANIFEST_FILE: &str = "pseudo_labels.json";
/// Label value of pixels whose class is unknown: the trainer takes no loss there.
pub const UNKNOWN_LABEL: u8 = 255;

/// What a pseudo-label folder holds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PseudoLabelManifest {
    /// The BOP split folder the frames come from (as given when written).
    pub source_split: PathBuf,
    /// Classes of the object set the labels use (ids 1..=num_classes).
    pub num_classes: u16,
    pub frames: Vec<PseudoLabelFrame>,
}

/// One labelled frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PseudoLabelFrame {
    pub scene_id: u32,
    pub im_id: u32,
    /// Published poses whose silhouettes gave the class pixels.
    pub poses: u32,
    /// Pixels labelled with a class, labelled background, and left unknown.
    pub object_px: u64,
    pub background_px: u64,
    pub unknown_px: u64,
}

impl PseudoLabelFrame {
    /// The label file of this frame, relative to the folder.
    pub fn label_path(&self) -> PathBuf {
        PathBuf::from("labels").join(format!("{:06}_{:06}.png", self.scene_id, self.im_id))
    }
}

/// Writes a pseudo-label folder frame by frame; [`PseudoLabelWriter::finish`] writes the manifest.
#[derive(Debug)]
pub struct PseudoLabelWriter {
    dir: PathBuf,
    manifest: PseudoLabelManifest,
}

impl PseudoLabelWriter {
    /// Creates `dir/labels` (refusing a folder that already holds a manifest).
    pub fn create(dir: &Path, source_split: &Path, num_classes: u16) -> Result<Self, BopError> {
        let manifest_path = dir.join(PSEUDO_MANIFEST_FILE);
        if manifest_path.exists() {
            return Err(BopError::Invalid {
                path: manifest_path,
                message: "already holds pseudo-labels; choose another folder or remove it".into(),
            });
        }
        let labels = dir.join("labels");
        std::fs::create_dir_all(&labels).map_err(|source| BopError::Io { path: labels, source })?;
        Ok(Self {
            dir: dir.to_path_buf(),
            manifest: PseudoLabelManifest { source_split: source_split.to_path_buf(), num_classes, frames: Vec::new() },
        })
    }

    /// Writes one frame's labels (`width * height`, row-major).
    pub fn write_frame(
        &mut self,
        scene_id: u32,
        im_id: u32,
        width: u32,
        height: u32,
        labels: &[u8],
        poses: u32,
    ) -> Result<(), BopError> {
        let count = |f: &dyn Fn(u8) -> bool| labels.iter().filter(|&&l| f(l)).count() as u64;
        let frame = PseudoLabelFrame {
            scene_id,
            im_id,
            poses,
            object_px: count(&|l| l != 0 && l != UNKNOWN_LABEL),
            background_px: count(&|l| l == 0),
            unknown_px: count(&|l| l == UNKNOWN_LABEL),
        };
        if let Some(&bad) = labels.iter().find(|&&l| l != UNKNOWN_LABEL && u16::from(l) > self.manifest.num_classes) {
            return Err(BopError::BadFrame {
                scene_id,
                im_id,
                message: format!("label {bad} is no class of {} and not unknown", self.manifest.num_classes),
            });
        }
        let path = self.dir.join(frame.label_path());
        write_u8_png(&path, width, height, labels).map_err(|source| BopError::Image { path, source })?;
        self.manifest.frames.push(frame);
        Ok(())
    }

    /// Frames written so far.
    pub fn frames(&self) -> &[PseudoLabelFrame] {
        &self.manifest.frames
    }

    /// Writes the manifest; returns the folder's path.
    pub fn finish(self) -> Result<PathBuf, BopError> {
        let path = self.dir.join(PSEUDO_MANIFEST_FILE);
        let text = serde_json::to_string_pretty(&self.manifest)
            .map_err(|source| BopError::Json { path: path.clone(), source })?;
        std::fs::write(&path, text).map_err(|source| BopError::Io { path: path.clone(), source })?;
        Ok(self.dir)
    }
}

/// Reads a pseudo-label folder's manifest.
pub fn read_pseudo_manifest(dir: &Path) -> Result<PseudoLabelManifest, BopError> {
    let path = dir.join(PSEUDO_MANIFEST_FILE);
    let text = std::fs::read_to_string(&path).map_err(|source| BopError::Io { path: path.clone(), source })?;
    serde_json::from_str(&text).map_err(|source| BopError::Json { path, source })
}

/// Reads one frame's labels; they must be `width` x `height`.
pub fn read_pseudo_labels(dir: &Path, frame: &PseudoLabelFrame, width: u32, height: u32) -> Result<Vec<u8>, BopError> {
    let path = dir.join(frame.label_path());
    let plane = read_labels_u16(&path).map_err(|source| BopError::Image { path: path.clone(), source })?;
    if (plane.width, plane.height) != (width, height) {
        return Err(BopError::Invalid {
            path,
            message: format!("labels are {}x{}, the frame {width}x{height}", plane.width, plane.height),
        });
    }
    plane
        .data
        .into_iter()
        .map(|v| {
            u8::try_from(v)
                .map_err(|_| BopError::Invalid { path: path.clone(), message: format!("label {v} above 255") })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_folder_round_trips_and_counts_its_pixels() {
        let dir = crate::bop::tests::TempDir::new("pseudo");
        let dir = dir.0.as_path();
        let mut w = PseudoLabelWriter::create(dir, Path::new("/data/split"), 8).unwrap();
        let labels = [0u8, 3, 3, UNKNOWN_LABEL, 0, 8];
        w.write_frame(2, 17, 3, 2, &labels, 2).unwrap();
        assert!(matches!(w.write_frame(2, 18, 3, 2, &[9, 0, 0, 0, 0, 0], 1), Err(BopError::BadFrame { .. })));
        w.finish().unwrap();
        let m = read_pseudo_manifest(dir).unwrap();
        assert_eq!(m.source_split, Path::new("/data/split"));
        assert_eq!(m.frames.len(), 1);
        let f = &m.frames[0];
        assert_eq!((f.object_px, f.background_px, f.unknown_px, f.poses), (3, 2, 1, 2));
        assert_eq!(read_pseudo_labels(dir, f, 3, 2).unwrap(), labels);
        assert!(read_pseudo_labels(dir, f, 2, 3).is_err(), "size checked");
        assert!(PseudoLabelWriter::create(dir, Path::new("x"), 8).is_err(), "no overwrite");
    }
}
