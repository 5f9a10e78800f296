//! Segmenter cells regrouped by depth (`seg::DepthRegions`): a box standing on
//! a tilted table, its cells labelled partly background and partly a wrong
//! class, as the segmenter labels thin or untextured objects.

use fusepose_estimator::seg::{DepthRegionParams, DepthRegions, FrameMap, SegConfig};
use fusepose_estimator::{ColorFormat, DepthPlane, FrameView};
use fusepose_scene::Intrinsics;

const W: usize = 320;
const H: usize = 240;
/// The box's pixels (columns, rows).
const BOX_U: std::ops::Range<usize> = 140..188;
const BOX_V: std::ops::Range<usize> = 100..148;

fn intrinsics() -> Intrinsics {
    Intrinsics { fx: 262.5, fy: 262.5, cx: 159.5, cy: 119.5, width: W as u32, height: H as u32 }
}

/// Depth of a table tilted towards the camera (normal (0, −0.8, −0.6), through
/// (0, 0.1, 1.0) m) with a box whose top stands 6 cm nearer than the table.
fn depth() -> Vec<f32> {
    let k = intrinsics();
    let (n, d) = ([0.0f64, -0.8, -0.6], 0.68);
    let mut z = vec![0.0f32; W * H];
    for v in 0..H {
        for u in 0..W {
            let dir = [(u as f64 - k.cx) / k.fx, (v as f64 - k.cy) / k.fy, 1.0];
            let t = -d / (n[0] * dir[0] + n[1] * dir[1] + n[2] * dir[2]);
            let on_box = BOX_U.contains(&u) && BOX_V.contains(&v);
            z[v * W + u] = (t - if on_box { 0.06 } else { 0.0 }) as f32;
        }
    }
    z
}

/// Cell labels: the box's cells class 1, except its left two cell columns
/// (background, as a segmenter loses an object's rim) and a 3x3 patch of
/// class 2 (a grey object mistaken for another).
fn labels(map: &FrameMap) -> (Vec<u16>, Vec<bool>) {
    let (gw, gh) = map.grid_size();
    let mut cells = vec![0u16; gw * gh];
    let mut on_box = vec![false; gw * gh];
    let box_cells = |span: std::ops::Range<usize>, px: &std::ops::Range<usize>| {
        let centre = (span.start + span.end - 1) / 2;
        px.contains(&centre)
    };
    let (mut first_col, mut first_row) = (usize::MAX, usize::MAX);
    for y in 0..gh {
        for x in 0..gw {
            if box_cells(map.span_x(x), &BOX_U) && box_cells(map.span_y(y), &BOX_V) {
                on_box[y * gw + x] = true;
                first_col = first_col.min(x);
                first_row = first_row.min(y);
            }
        }
    }
    for (i, cell) in cells.iter_mut().enumerate() {
        if !on_box[i] {
            continue;
        }
        let (x, y) = (i % gw, i / gw);
        *cell = if x < first_col + 2 {
            0
        } else if (first_col + 5..first_col + 8).contains(&x) && (first_row + 4..first_row + 7).contains(&y) {
            2
        } else {
            1
        };
    }
    (cells, on_box)
}

fn frame(depth: &[f32]) -> FrameView<'_> {
    static COLOR: [u8; W * H * 3] = [0; W * H * 3];
    FrameView {
        intrinsics: intrinsics(),
        color_format: ColorFormat::Rgb8,
        color: &COLOR,
        depth: DepthPlane::F32(depth),
        labels: None,
    }
}

/// Segmenter logits (`[3, cells]`) that make each cell's label its argmax;
/// `torn`: in class-2 cells, class 1 scores nearly as high.
fn logits(cells: &[u16], torn: bool) -> Vec<f32> {
    let n = cells.len();
    let mut l = vec![0.0f32; 3 * n];
    for (i, &c) in cells.iter().enumerate() {
        l[c as usize * n + i] = 4.0;
        if torn && c == 2 {
            l[n + i] = 3.5;
        }
    }
    l
}

fn params(spec: &str) -> DepthRegionParams {
    spec.parse().unwrap()
}

/// The scene's cells before and after regrouping with `diameters` and
/// `spec`, which cells lie on the box, and how many changed.
struct Regrouped {
    before: Vec<u16>,
    after: Vec<u16>,
    on_box: Vec<bool>,
    changed: usize,
}

fn regroup(diameters: &[f32], spec: &str, torn: bool) -> Regrouped {
    let depth = depth();
    let map = FrameMap::new(W, H, &SegConfig::new(2));
    let (before, on_box) = labels(&map);
    let mut after = before.clone();
    let changed =
        DepthRegions::new(diameters, params(spec)).apply(&frame(&depth), &map, &logits(&before, torn), &mut after);
    Regrouped { before, after, on_box, changed }
}

#[test]
fn a_box_on_the_table_takes_its_majority_class_and_the_table_stays_background() {
    // Class 1 fits the box (a 17 cm square, 6 cm high); absorbing wherever
    // a class is a minority, whatever the segmenter's scores.
    let r = regroup(&[0.3, 0.3], "share=0.3,slack=1.3,absorb=0.5,absorb-p=0", false);
    assert!(r.before.iter().zip(&r.on_box).any(|(&c, &b)| b && c == 0) && r.before.contains(&2));
    for (i, (&c, &b)) in r.after.iter().zip(&r.on_box).enumerate() {
        assert_eq!(c, u16::from(b), "cell {i}");
    }
    assert_eq!(r.changed, r.before.iter().zip(&r.on_box).filter(|&(&c, &b)| b && c != 1).count());
}

#[test]
fn grow_only_keeps_the_other_class_and_fills_the_background_cells() {
    let r = regroup(&[0.3, 0.3], "share=0.3,slack=1.3,absorb=0", false);
    for i in 0..r.after.len() {
        let want = match (r.on_box[i], r.before[i]) {
            (false, _) => 0,
            (true, 2) => 2,
            (true, _) => 1,
        };
        assert_eq!(r.after[i], want, "cell {i}");
    }
}

#[test]
fn a_region_larger_than_its_class_is_left_as_labelled() {
    // Class 1 is a 5 cm object: the 17 cm box cannot be one.
    let r = regroup(&[0.05, 0.3], "share=0.3,slack=1.3,absorb=0.5", false);
    assert_eq!(r.changed, 0);
    assert_eq!(r.after, r.before);
}

#[test]
fn only_cells_where_the_segmenter_was_torn_are_absorbed() {
    let spec = "share=0.3,slack=1.3,absorb=0.5,absorb-p=0.1";
    // Sure of class 2 (class 1 at 1.7 %): kept, while the background cells grow.
    let sure = regroup(&[0.3, 0.3], spec, false);
    for i in 0..sure.after.len() {
        let want = if sure.before[i] == 2 { 2 } else { u16::from(sure.on_box[i]) };
        assert_eq!(sure.after[i], want, "cell {i}");
    }
    // Torn between 2 and 1 (class 1 at 37 %): absorbed.
    let torn = regroup(&[0.3, 0.3], spec, true);
    for i in 0..torn.after.len() {
        assert_eq!(torn.after[i], u16::from(torn.on_box[i]), "cell {i}");
    }
}

#[test]
fn no_plane_no_change() {
    let map = FrameMap::new(W, H, &SegConfig::new(2));
    let (mut cells, _) = labels(&map);
    let before = cells.clone();
    let mut regions = DepthRegions::new(&[0.3, 0.3], params("share=0.3,slack=1.3,absorb=0.5"));
    // No depth anywhere.
    let empty = vec![0.0f32; W * H];
    assert_eq!(regions.apply(&frame(&empty), &map, &logits(&before, false), &mut cells), 0);
    assert_eq!(cells, before);
    // Depth everywhere but every cell labelled: no background to fit a table to.
    let depth = depth();
    let mut all = vec![1u16; cells.len()];
    assert_eq!(regions.apply(&frame(&depth), &map, &logits(&all, false), &mut all), 0);
    assert!(all.iter().all(|&c| c == 1));
}

#[test]
fn parameter_strings() {
    let d = DepthRegionParams::default();
    assert_eq!(params("on"), d);
    let p = params("height=0.01,share=0.25,absorb=0.5,absorb-p=0.2,slack=1.2,step=0.03,step-per-m=0.01");
    assert_eq!(
        (p.min_height_m, p.min_majority_share, p.absorb_below_share, p.extent_slack, p.max_step_m, p.max_step_per_m),
        (0.01, 0.25, 0.5, 1.2, 0.03, 0.01)
    );
    assert_eq!(p.absorb_min_probability, 0.2);
    for bad in ["share", "share=x", "share=-1", "share=inf", "depth=0.1", ""] {
        let err = bad.parse::<DepthRegionParams>().unwrap_err();
        assert!(err.starts_with("depth regions:"), "{bad}: {err}");
    }
}
