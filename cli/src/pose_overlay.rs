//! `--overlay DIR` of `fusepose eval` and `fusepose watch`: one PNG per frame
//! with the label plane tinted in class colours, each estimated pose drawn
//! (silhouette outline and axes, `fusepose_scene::overlay`), and a legend of
//! the classes present.

use std::path::Path;

use anyhow::Context;
use fusepose_scene::overlay::{self, OverlayObject, OverlayStyle};
use fusepose_scene::{Intrinsics, ObjectSet, Pose};

/// Label tint strength.
const LABEL_ALPHA: f32 = 0.45;

/// Writes `path`: the RGB8 frame `rgb`, tinted by `labels` when given, with
/// `poses` (class id, object → camera) drawn; class ids outside `objects` are skipped.
pub fn write(
    path: &Path,
    k: &Intrinsics,
    rgb: &[u8],
    labels: Option<&[u16]>,
    poses: &[(u16, Pose)],
    objects: &ObjectSet,
) -> anyhow::Result<()> {
    let mut img = overlay::rgb_image(k.width, k.height, rgb)?;
    let mut classes: Vec<u16> = poses.iter().map(|(c, _)| *c).collect();
    if let Some(labels) = labels {
        overlay::tint_labels(&mut img, labels, LABEL_ALPHA)?;
        let mut seen = vec![false; objects.len() + 1];
        for &l in labels {
            if let Some(s) = seen.get_mut(l as usize) {
                *s = true;
            }
        }
        classes.extend((1..seen.len()).filter(|&c| seen[c]).map(|c| c as u16));
    }
    let drawn: Vec<OverlayObject<'_>> =
        poses.iter().filter_map(|(c, p)| objects.by_class(*c).map(|m| OverlayObject::new(m, *c, *p))).collect();
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
