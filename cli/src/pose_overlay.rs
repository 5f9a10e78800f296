//! `--overlay DIR` of `fusepose eval` and `fusepose watch`: one PNG per frame
//! with the masks tinted, each estimated pose drawn (silhouette outline and
//! axes, `fusepose_scene::overlay`), and a legend of the classes present.
//!
//! Masks are tinted per class ([`Tint::Classes`]) or, where the instances are
//! known, per instance ([`Tint::Instances`]: each copy of a class its own
//! shade, a white line where two meet), and each pose's outline takes its
//! instance's shade, so two touching copies and their two poses read as two.

use std::path::Path;

use anyhow::Context;
use fusepose_scene::overlay::{self, OverlayObject, OverlayStyle};
use fusepose_scene::{Intrinsics, ObjectSet, Pose};

/// Mask tint strength.
const LABEL_ALPHA: f32 = 0.45;

/// What the masks of the frame are.
#[derive(Clone, Copy, Debug)]
pub enum Tint<'a> {
    /// Nothing is tinted.
    None,
    /// A class id per pixel (0 = background).
    Classes(&'a [u16]),
    /// An instance id per pixel (0 = none) and the instances to draw as
    /// `(id, class id)`; pixels of other ids are not tinted.
    Instances { ids: &'a [u32], instances: &'a [(u32, u16)] },
}

/// One estimated pose: its class, the pose (object → camera), and the id of
/// the [`Tint::Instances`] instance it was estimated from, when known.
#[derive(Clone, Copy, Debug)]
pub struct DrawnPose {
    pub class_id: u16,
    pub pose: Pose,
    pub instance: Option<u32>,
}

/// Writes `path`: the RGB8 frame `rgb` with `tint` and `poses` drawn; class
/// ids outside `objects` are skipped. A pose without a known instance is
/// drawn in the shade of its rank among such poses of its class.
pub fn write(
    path: &Path,
    k: &Intrinsics,
    rgb: &[u8],
    tint: Tint<'_>,
    poses: &[DrawnPose],
    objects: &ObjectSet,
) -> anyhow::Result<()> {
    let mut img = overlay::rgb_image(k.width, k.height, rgb)?;
    let mut classes: Vec<u16> = poses.iter().map(|p| p.class_id).collect();
    let mut instance_colours: Vec<(u32, [u8; 3])> = Vec::new();
    match tint {
        Tint::None => {}
        Tint::Classes(labels) => {
            overlay::tint_labels(&mut img, labels, LABEL_ALPHA)?;
            let mut seen = vec![false; objects.len() + 1];
            for &l in labels {
                if let Some(s) = seen.get_mut(l as usize) {
                    *s = true;
                }
            }
            classes.extend((1..seen.len()).filter(|&c| seen[c]).map(|c| c as u16));
        }
        Tint::Instances { ids, instances } => {
            let colours = overlay::tint_instances(&mut img, ids, instances, LABEL_ALPHA)?;
            instance_colours.extend(instances.iter().map(|&(id, _)| id).zip(colours));
            classes.extend(instances.iter().map(|&(_, c)| c).filter(|&c| c != 0));
        }
    }
    let mut drawn: Vec<OverlayObject<'_>> = Vec::with_capacity(poses.len());
    for (i, p) in poses.iter().enumerate() {
        let Some(model) = objects.by_class(p.class_id) else { continue };
        let known = p.instance.and_then(|id| instance_colours.iter().find(|(i, _)| *i == id)).map(|&(_, c)| c);
        let colour = known.unwrap_or_else(|| {
            let rank = poses[..i].iter().filter(|q| q.class_id == p.class_id && q.instance.is_none()).count();
            overlay::instance_colour(p.class_id, rank)
        });
        drawn.push(OverlayObject::new(model, p.class_id, p.pose).with_colour(colour));
    }
    overlay::draw_poses(&mut img, k, &drawn, &OverlayStyle::default());
    classes.sort_unstable();
    classes.dedup();
    overlay::draw_legend(&mut img, &classes);
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    overlay::save_png(&img, path).with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use fusepose_scene::builtin::builtin_objects;

    /// Pixels of exactly `colour` in the PNG at `path`.
    fn count(path: &Path, colour: [u8; 3]) -> usize {
        let img = image::open(path).unwrap().to_rgb8();
        img.pixels().filter(|p| p.0 == colour).count()
    }

    #[test]
    fn touching_copies_and_their_poses_are_drawn_in_their_own_shades() {
        let objects = builtin_objects();
        let k = Intrinsics { fx: 300.0, fy: 300.0, cx: 80.0, cy: 60.0, width: 160, height: 120 };
        let (w, h) = (k.width as usize, k.height as usize);
        // Two copies of class 3 side by side (ids 7 and 9), meeting at u = 80.
        let ids: Vec<u32> = (0..w * h)
            .map(|p| {
                if p / w < 30 || p / w > 90 {
                    0
                } else if p % w < 80 {
                    7
                } else {
                    9
                }
            })
            .collect();
        let at = |x: f64| Pose::translation(x, 0.0, 0.5);
        let poses = [
            DrawnPose { class_id: 3, pose: at(-0.06), instance: Some(7) },
            DrawnPose { class_id: 3, pose: at(0.06), instance: Some(9) },
        ];
        let dir = std::env::temp_dir().join(format!("fusepose_pose_overlay_{}", std::process::id()));
        let path = dir.join("overlay.png");
        let (first, second) = (overlay::instance_colour(3, 0), overlay::instance_colour(3, 1));
        // Without instances (class labels), two poses of a class still get two shades.
        let labels: Vec<u16> = ids.iter().map(|&id| if id == 0 { 0 } else { 3 }).collect();
        let unknown = poses.map(|p| DrawnPose { instance: None, ..p });
        write(&path, &k, &vec![90u8; w * h * 3], Tint::Classes(&labels), &unknown, &objects).unwrap();
        assert!(count(&path, first) > 20 && count(&path, second) > 20);
        let legend_white = count(&path, overlay::INSTANCE_BORDER);
        // With instances: each pose's outline in its instance's shade, and a
        // white line (two pixels wide, rows 30..=90) where the copies meet.
        let tint = Tint::Instances { ids: &ids, instances: &[(7, 3), (9, 3)] };
        write(&path, &k, &vec![90u8; w * h * 3], tint, &poses, &objects).unwrap();
        assert!(count(&path, first) > 20, "first copy's outline");
        assert!(count(&path, second) > 20, "second copy's outline");
        let line = count(&path, overlay::INSTANCE_BORDER) - legend_white;
        assert!((100..=2 * 61).contains(&line), "{line} white pixels where the copies meet");
        std::fs::remove_dir_all(&dir).ok();
    }
}
