//! `fusepose eval --per-object-csv`: one row per ground-truth object (with its
//! matched estimate, if any) and one per estimate matched to no object, so the
//! accuracy lost can be traced to visibility, confidence and mask size.

use std::io::Write;
use std::path::Path;

use fusepose_estimator::ObjectPose;
use fusepose_scene::metrics::PoseErrors;

use super::dataset::GtObject;

/// Writes the CSV; distances in metres, empty fields where a value is unknown.
pub struct PerObjectWriter<W: Write> {
    out: W,
}

impl PerObjectWriter<std::io::BufWriter<std::fs::File>> {
    pub fn create(path: &Path) -> std::io::Result<Self> {
        Self::new(std::io::BufWriter::new(std::fs::File::create(path)?))
    }
}

impl<W: Write> PerObjectWriter<W> {
    pub const HEADER: &'static str =
        "scene_id,im_id,obj_id,visible,found,add_m,add_s_m,add_or_add_s_m,confidence,mask_pixels,ghost";

    pub fn new(mut out: W) -> std::io::Result<Self> {
        writeln!(out, "{}", Self::HEADER)?;
        Ok(Self { out })
    }

    /// A ground-truth object (`gt`) with its matched estimate, or (`gt` = `None`)
    /// an estimate matched to no object (a ghost).
    pub fn write(
        &mut self,
        (scene_id, im_id): (u32, u32),
        gt: Option<&GtObject>,
        est: Option<&ObjectPose>,
        errors: Option<PoseErrors>,
    ) -> std::io::Result<()> {
        let opt = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.6}"));
        let class_id = gt.map(|g| g.class_id).or(est.map(|e| e.class_id)).unwrap_or(0);
        writeln!(
            self.out,
            "{},{},{},{},{},{},{},{},{},{},{}",
            scene_id,
            im_id,
            class_id,
            opt(gt.and_then(|g| g.visible)),
            u8::from(est.is_some()),
            opt(errors.map(|e| e.add)),
            opt(errors.map(|e| e.add_s)),
            opt(errors.map(|e| e.add_or_add_s)),
            opt(est.map(|e| e.confidence as f64)),
            est.map_or(String::new(), |e| e.mask_pixels.to_string()),
            u8::from(gt.is_none()),
        )
    }

    pub fn finish(mut self) -> std::io::Result<W> {
        self.out.flush()?;
        Ok(self.out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fusepose_scene::Pose;

    #[test]
    fn rows_for_a_match_a_miss_and_a_ghost() {
        let p = Pose::translation(0.0, 0.0, 0.5);
        let gt = GtObject { class_id: 3, pose: p, visible: Some(0.25) };
        let est = ObjectPose {
            class_id: 3,
            instance_id: 0,
            rotation: p.rotation,
            translation: p.translation.vector,
            confidence: 0.5,
            mask_pixels: 812,
            bbox: [0; 4],
            iterations: 2,
        };
        let errors = PoseErrors { add: 0.004, add_s: 0.002, add_or_add_s: 0.004 };
        let mut w = PerObjectWriter::new(Vec::new()).unwrap();
        w.write((1, 7), Some(&gt), Some(&est), Some(errors)).unwrap();
        w.write((1, 7), Some(&gt), None, None).unwrap();
        w.write((1, 7), None, Some(&est), None).unwrap();
        let text = String::from_utf8(w.finish().unwrap()).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], PerObjectWriter::<Vec<u8>>::HEADER);
        assert_eq!(lines[1], "1,7,3,0.250000,1,0.004000,0.002000,0.004000,0.500000,812,0");
        assert_eq!(lines[2], "1,7,3,0.250000,0,,,,,,0");
        assert_eq!(lines[3], "1,7,3,,1,,,,0.500000,812,1");
        assert_eq!(lines.len(), 4);
    }
}
