//! The support floor (`WorkspaceConfig::support_floor_m`): pixels of a mask
//! lying on the plane the objects stand on are not the object's points.
//! A box on a tilted table; its mask bleeds onto the table around it, and a
//! second region (a shadow taken for an object) lies on the table only. A
//! table given an object's class leaves the box's top as the background: a
//! plane the objects lie under is no support.

mod common;

use common::{BoxObject, object_set};
use fusepose_estimator::support::class_floors;
use fusepose_estimator::{ColorFormat, DepthPlane, FrameView, LabelPlane, Workspace, WorkspaceConfig};
use fusepose_scene::Intrinsics;

const W: usize = 320;
const H: usize = 240;
/// The box's pixels (columns, rows) and its mask, 6 px wider on every side.
const BOX_U: std::ops::Range<usize> = 140..188;
const BOX_V: std::ops::Range<usize> = 100..148;
const BLEED: usize = 6;
/// The shadow's pixels, on the table.
const SHADOW_U: std::ops::Range<usize> = 30..70;
const SHADOW_V: std::ops::Range<usize> = 180..210;
/// The table: normal (0, −0.8, −0.6) (towards the camera), offset 0.68 m.
const NORMAL: [f32; 3] = [0.0, -0.8, -0.6];
const OFFSET: f32 = 0.68;

fn intrinsics() -> Intrinsics {
    Intrinsics { fx: 262.5, fy: 262.5, cx: 159.5, cy: 119.5, width: W as u32, height: H as u32 }
}

fn on_box(u: usize, v: usize) -> bool {
    BOX_U.contains(&u) && BOX_V.contains(&v)
}

/// Depth in 0.1 mm: the table, and the box's top `lift` metres nearer along each ray.
fn depth(with_table: bool) -> Vec<u16> {
    depth_lifted(with_table, 0.06)
}

fn depth_lifted(with_table: bool, lift: f64) -> Vec<u16> {
    let k = intrinsics();
    let mut z = vec![0u16; W * H];
    for v in 0..H {
        for u in 0..W {
            let dir = [(u as f64 - k.cx) / k.fx, (v as f64 - k.cy) / k.fy, 1.0];
            let n = NORMAL.map(f64::from);
            let t = -(OFFSET as f64) / (n[0] * dir[0] + n[1] * dir[1] + n[2] * dir[2]);
            let metres = if on_box(u, v) {
                t - lift
            } else if with_table {
                t
            } else {
                0.0
            };
            z[v * W + u] = (metres * 10_000.0).round() as u16;
        }
    }
    z
}

fn labels() -> Vec<u8> {
    let mut l = vec![0u8; W * H];
    for v in BOX_V.start - BLEED..BOX_V.end + BLEED {
        for u in BOX_U.start - BLEED..BOX_U.end + BLEED {
            l[v * W + u] = 1;
        }
    }
    for v in SHADOW_V {
        for u in SHADOW_U.clone() {
            l[v * W + u] = 2;
        }
    }
    l
}

fn height(p: &[f32; 3]) -> f32 {
    NORMAL[0] * p[0] + NORMAL[1] * p[1] + NORMAL[2] * p[2] + OFFSET
}

/// Prepares the scene with `floor` and returns the workspace.
fn prepare(floor: f32, depth: &[u16]) -> Workspace {
    prepare_with(floor, &[], depth)
}

/// As [`prepare`], with per-class floors (`Workspace::support_floors`).
fn prepare_with(floor: f32, class_floors: &[f32], depth: &[u16]) -> Workspace {
    let (color, labels) = (vec![90u8; W * H * 3], labels());
    let frame = FrameView {
        intrinsics: intrinsics(),
        color_format: ColorFormat::Rgb8,
        color: &color,
        depth: DepthPlane::U16 { data: depth, scale: 0.0001 },
        labels: Some(LabelPlane::U8(&labels)),
    };
    let config =
        WorkspaceConfig { num_classes: 2, num_points: 256, support_floor_m: floor, ..WorkspaceConfig::default() };
    let mut ws = Workspace::new(config).unwrap();
    ws.support_floors(class_floors);
    ws.prepare(&frame, 3).unwrap();
    ws
}

#[test]
fn points_on_the_table_leave_the_mask_and_a_region_lying_on_it_is_dropped() {
    let depth = depth(true);
    let off = prepare(0.0, &depth);
    assert_eq!(off.instances.len(), 2, "without the floor the shadow is an instance");
    let class1 = off.instances.iter().position(|i| i.class_id == 1).unwrap();
    let lowest = off.instance_points(class1).iter().map(height).fold(f32::INFINITY, f32::min);
    assert!(lowest < 0.002, "the bled mask samples the table: lowest point {lowest} m above it");

    let on = prepare(0.004, &depth);
    assert_eq!(on.instances.len(), 1, "the shadow has no point off the table");
    let inst = on.instances[0];
    assert_eq!(inst.class_id, 1);
    // Every valid pixel left is the box's own: its mask's table rim is gone.
    assert_eq!(inst.valid_depth_pixels as usize, BOX_U.len() * BOX_V.len());
    // The mask itself is unchanged (the floor only chooses points).
    assert_eq!(inst.pixels as usize, (BOX_U.len() + 2 * BLEED) * (BOX_V.len() + 2 * BLEED));
    let lowest = on.instance_points(0).iter().map(height).fold(f32::INFINITY, f32::min);
    assert!(lowest > 0.03, "every point on the box's top: lowest {lowest} m above the table");
}

#[test]
fn without_a_background_plane_nothing_is_left_out() {
    // No table depth: the background has no points, so no plane is fitted.
    let depth = depth(false);
    let on = prepare(0.004, &depth);
    let off = prepare(0.0, &depth);
    assert_eq!(on.instances, off.instances);
    assert_eq!(on.points, off.points);
}

#[test]
fn a_negative_or_nan_floor_is_refused() {
    for bad in [-0.001, f32::NAN, f32::INFINITY] {
        let config = WorkspaceConfig { support_floor_m: bad, ..WorkspaceConfig::default() };
        assert!(Workspace::new(config).is_err(), "{bad}");
    }
}

#[test]
fn a_part_thinner_than_four_floors_keeps_its_points() {
    // A 3 mm plate (a circuit board) lying on the table: its top lies about
    // 2 mm above it, under the 4 mm floor.
    let plate = BoxObject { name: "plate", boxes: vec![([-0.05, -0.04, 0.0], [0.05, 0.04, 0.003])] };
    let block = BoxObject { name: "block", boxes: vec![([-0.03, -0.03, -0.03], [0.03, 0.03, 0.03])] };
    let floors = class_floors(&object_set(&[plate, block]), 0.004);
    assert!(floors[0] < 0.001, "the plate's floor is a quarter of its thickness: {floors:?}");
    assert_eq!(floors[1], 0.004, "a 6 cm block keeps the whole floor");

    let depth = depth_lifted(true, 0.0035);
    let uniform = prepare(0.004, &depth);
    assert!(uniform.instances.iter().all(|i| i.class_id != 1), "one floor for all loses the plate");
    let per_class = prepare_with(0.004, &floors, &depth);
    let plate = per_class.instances.iter().find(|i| i.class_id == 1).expect("the plate keeps an instance");
    assert_eq!(plate.valid_depth_pixels as usize, BOX_U.len() * BOX_V.len(), "its own pixels, not the bled rim");
    // The floor is still capped by the configuration: 0 turns it off for every class.
    let off = prepare_with(0.0, &floors, &depth);
    assert_eq!(off.instances.len(), 2);
}

#[test]
fn a_plane_the_objects_stand_under_is_refused() {
    // The segmenter gave the table a class (the green bowl on a green table)
    // and left only the box's top as background: that top is a plane 6 cm
    // above the table, with the whole table under it. It is not the support:
    // the frame gets none, and no region loses its points to it.
    let depth = depth(true);
    let labels: Vec<u8> = (0..W * H).map(|p| if on_box(p % W, p / W) { 0 } else { 2 }).collect();
    let color = vec![90u8; W * H * 3];
    let frame = FrameView {
        intrinsics: intrinsics(),
        color_format: ColorFormat::Rgb8,
        color: &color,
        depth: DepthPlane::U16 { data: &depth, scale: 0.0001 },
        labels: Some(LabelPlane::U8(&labels)),
    };
    let prepared = |floor: f32| {
        let config = WorkspaceConfig { num_classes: 2, num_points: 256, support_floor_m: floor, ..Default::default() };
        let mut ws = Workspace::new(config).unwrap();
        ws.prepare(&frame, 3).unwrap();
        ws
    };
    let (on, off) = (prepared(0.004), prepared(0.0));
    assert_eq!(on.support_plane(), None);
    assert_eq!(on.instances, off.instances);
    assert_eq!(on.points, off.points);
    // With the table's own pixels as background the table is found.
    assert!(prepare(0.004, &depth).support_plane().is_some());
}
