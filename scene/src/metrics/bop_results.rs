//! The BOP challenge results CSV: one line per estimate,
//! `scene_id,im_id,obj_id,score,R,t,time` with `R` the row-major rotation (9
//! numbers, space-separated), `t` the translation in millimetres (3 numbers,
//! space-separated) and `time` the image's processing time in seconds
//! (BOP asks for the same time on every line of an image; -1 when unknown).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use super::MetricsError;
use crate::Pose;

/// One pose estimate in a BOP results file.
#[derive(Clone, Debug, PartialEq)]
pub struct BopResult {
    pub scene_id: u32,
    pub im_id: u32,
    pub obj_id: u16,
    /// Confidence, higher is better.
    pub score: f64,
    /// Object → camera, metres (written in millimetres).
    pub pose: Pose,
    /// Seconds spent on the whole image; negative when unknown.
    pub time_s: f64,
}

impl BopResult {
    /// The CSV line, without the newline.
    pub fn to_csv_line(&self) -> String {
        let r = self.pose.rotation.to_rotation_matrix();
        let m = r.matrix();
        let rot: Vec<String> =
            (0..3).flat_map(|i| (0..3).map(move |j| (i, j))).map(|(i, j)| format!("{}", m[(i, j)])).collect();
        let t = self.pose.translation.vector * 1000.0;
        let time = if self.time_s < 0.0 { -1.0 } else { self.time_s };
        format!(
            "{},{},{},{},{},{} {} {},{}",
            self.scene_id,
            self.im_id,
            self.obj_id,
            self.score,
            rot.join(" "),
            t.x,
            t.y,
            t.z,
            time
        )
    }
}

/// Writes a BOP results CSV (header first). Call [`BopResultsWriter::finish`]
/// to flush and see write errors.
pub struct BopResultsWriter {
    path: PathBuf,
    out: BufWriter<File>,
}

impl BopResultsWriter {
    /// Creates (truncates) `path` and writes the header.
    pub fn create(path: impl AsRef<Path>) -> Result<Self, MetricsError> {
        let path = path.as_ref().to_path_buf();
        let io = |source| MetricsError::Io { path: path.clone(), source };
        let mut out = BufWriter::new(File::create(&path).map_err(io)?);
        writeln!(out, "scene_id,im_id,obj_id,score,R,t,time").map_err(io)?;
        Ok(Self { path, out })
    }

    /// Appends one estimate.
    pub fn write(&mut self, result: &BopResult) -> Result<(), MetricsError> {
        writeln!(self.out, "{}", result.to_csv_line())
            .map_err(|source| MetricsError::Io { path: self.path.clone(), source })
    }

    /// Flushes the file.
    pub fn finish(mut self) -> Result<(), MetricsError> {
        self.out.flush().map_err(|source| MetricsError::Io { path: self.path.clone(), source })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    #[test]
    fn line_has_row_major_rotation_and_millimetres() {
        // 90° about z: R = [0 -1 0; 1 0 0; 0 0 1].
        let pose = Pose::from_parts(
            Translation3::new(0.1, -0.025, 0.75),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2),
        );
        let r = BopResult { scene_id: 48, im_id: 1, obj_id: 5, score: 0.5, pose, time_s: 0.125 };
        let line = r.to_csv_line();
        let fields: Vec<&str> = line.split(',').collect();
        assert_eq!(&fields[..4], &["48", "1", "5", "0.5"]);
        let rot: Vec<f64> = fields[4].split(' ').map(|s| s.parse().unwrap()).collect();
        let expected = [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0];
        assert!(rot.iter().zip(expected).all(|(a, b)| (a - b).abs() < 1e-12), "{rot:?}");
        let t: Vec<f64> = fields[5].split(' ').map(|s| s.parse().unwrap()).collect();
        assert!((t[0] - 100.0).abs() < 1e-9 && (t[1] + 25.0).abs() < 1e-9 && (t[2] - 750.0).abs() < 1e-9);
        assert_eq!(fields[6], "0.125");
    }

    #[test]
    fn writer_writes_header_and_lines() {
        let dir = std::env::temp_dir().join(format!("fusepose-bop-results-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("results.csv");
        let mut w = BopResultsWriter::create(&path).unwrap();
        let r = BopResult { scene_id: 1, im_id: 2, obj_id: 3, score: 1.0, pose: Pose::identity(), time_s: -5.0 };
        w.write(&r).unwrap();
        w.finish().unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(text, "scene_id,im_id,obj_id,score,R,t,time\n1,2,3,1,1 0 0 0 1 0 0 0 1,0 0 0,-1\n");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn unwritable_path_is_an_error_naming_it() {
        let err = BopResultsWriter::create("/nonexistent-dir-fusepose/x.csv").err().unwrap();
        assert!(err.to_string().contains("/nonexistent-dir-fusepose/x.csv"));
    }
}
