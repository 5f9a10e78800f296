//! The built-in object set: eight YCB-Video-like household objects generated
//! by code (no files), each with a procedural UV texture that identifies it and
//! a declared symmetry. Sizes are realistic, in metres.
//!
//! Object frame: origin at the bounding-box centre, +z along the object's
//! natural up axis (so a scene sampler can stand it on a table).
//!
//! Symmetry choices: the cans carry printed labels (brand panel, text), so they
//! are *not* symmetric, as in YCB-Video. The bowl's texture varies only with
//! height (rows of the texture are uniform), so it is honestly invariant under
//! any rotation about z. The wood block is an 85 x 85 x 200 mm box whose sides
//! share one grain pattern symmetric in both directions and whose ends share
//! centred rings, so the 7 non-identity rotations mapping the box to itself
//! are true symmetries.

mod paint;
mod shapes;

use std::f64::consts::FRAC_PI_2;

use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand_pcg::Pcg64;

use crate::model::{ObjectModel, ObjectSet, Symmetry};
use paint::{Canvas, Rgb, UvRect, hash_noise, shade};
use shapes::Assembly;

/// Segments around surfaces of revolution (keeps every object under 4k triangles).
const ROUND_SEGMENTS: usize = 48;

/// Names of the built-in objects in class-id order (class id = index + 1).
pub const BUILTIN_NAMES: [&str; 8] =
    ["cracker_box", "sugar_box", "tomato_soup_can", "coffee_can", "mustard_bottle", "mug", "bowl", "wood_block"];

/// The built-in object set (class ids 1..=8 in [`BUILTIN_NAMES`] order).
/// Deterministic: every call returns the same meshes, textures and samples.
pub fn builtin_objects() -> ObjectSet {
    let objects =
        [cracker_box(), sugar_box(), tomato_soup_can(), coffee_can(), mustard_bottle(), mug(), bowl(), wood_block()];
    ObjectSet {
        objects: objects
            .into_iter()
            .map(|(name, mesh, symmetry)| {
                ObjectModel::from_mesh(name, mesh, symmetry)
                    .unwrap_or_else(|e| panic!("built-in object {name} is malformed (a bug): {e}"))
            })
            .collect(),
    }
}

type Built = (&'static str, crate::model::Mesh, Symmetry);

fn linear(c: Rgb) -> [f32; 3] {
    c.map(|x| x as f32 / 255.0)
}

/// The six face cells of a box atlas: a 3 x 2 grid, order +x, -x, +y, -y, +z, -z.
fn box_cells() -> [UvRect; 6] {
    std::array::from_fn(|k| {
        let (col, row) = ((k % 3) as f64, (k / 3) as f64);
        [col / 3.0, 1.0 - (row + 1.0) / 2.0, (col + 1.0) / 3.0, 1.0 - row / 2.0]
    })
}

const BLACK: Rgb = [25, 25, 25];
const WHITE: Rgb = [245, 245, 240];

fn cracker_box() -> Built {
    let (red, yellow) = ([200, 30, 35], [250, 205, 40]);
    let mut rng = Pcg64::seed_from_u64(1);
    let cells = box_cells();
    let mut c = Canvas::new(768, 512, red);
    let [px, nx, py, ny, pz, nz] = cells;
    // Front (-y): yellow band, white oval "logo" with a red mark, text.
    c.fill(ny, red);
    c.paint(ny, |_, t| (0.55..0.75).contains(&t).then_some(yellow));
    c.ellipse(ny, (0.5, 0.65), (0.35, 0.12), WHITE);
    c.ellipse(ny, (0.5, 0.65), (0.2, 0.06), red);
    c.text_marks(ny, [0.1, 0.1, 0.9, 0.45], 5, yellow, &mut rng);
    // Back (+y): nutrition-panel-like block.
    c.fill(py, shade(red, 0.9));
    c.paint(py, |s, t| (s > 0.1 && s < 0.6 && t > 0.15 && t < 0.85).then_some(WHITE));
    c.text_marks(py, [0.12, 0.2, 0.58, 0.8], 12, BLACK, &mut rng);
    c.text_marks(py, [0.65, 0.5, 0.92, 0.85], 4, yellow, &mut rng);
    // Sides: yellow stripe and text.
    for side in [px, nx] {
        c.paint(side, |s, _| (s > 0.15 && s < 0.3).then_some(yellow));
        c.text_marks(side, [0.4, 0.2, 0.9, 0.8], 8, WHITE, &mut rng);
    }
    for end in [pz, nz] {
        c.text_marks(end, [0.1, 0.3, 0.9, 0.7], 3, WHITE, &mut rng);
    }
    let mut a = Assembly::default();
    a.cuboid([0.16, 0.06, 0.21], cells);
    ("cracker_box", a.finish("cracker_box", linear(red), c.into_texture()), Symmetry::None)
}

fn sugar_box() -> Built {
    let (yellow, blue) = ([245, 215, 50], [30, 50, 140]);
    let mut rng = Pcg64::seed_from_u64(2);
    let cells = box_cells();
    let mut c = Canvas::new(768, 512, WHITE);
    let [px, nx, py, ny, pz, nz] = cells;
    c.paint(ny, |_, t| (t > 0.4).then_some(yellow));
    c.paint(ny, |s, t| (s > 0.15 && s < 0.85 && t > 0.62 && t < 0.78).then_some(blue));
    c.text_marks(ny, [0.1, 0.08, 0.9, 0.32], 4, blue, &mut rng);
    c.text_marks(py, [0.1, 0.1, 0.9, 0.9], 14, BLACK, &mut rng);
    for side in [px, nx] {
        c.paint(side, |_, t| (t > 0.7).then_some(yellow));
        c.text_marks(side, [0.1, 0.1, 0.9, 0.6], 6, blue, &mut rng);
    }
    c.fill(pz, yellow);
    c.fill(nz, shade(WHITE, 0.9));
    let mut a = Assembly::default();
    a.cuboid([0.09, 0.04, 0.175], cells);
    ("sugar_box", a.finish("sugar_box", linear(yellow), c.into_texture()), Symmetry::None)
}

/// A closed can of radius `r` and height `h`: side label in the top 3/4 of
/// the texture, top lid in the bottom-left, bottom lid in the bottom-right.
fn can(r: f64, h: f64) -> Assembly {
    let mut a = Assembly::default();
    let (z0, z1) = (-h / 2.0, h / 2.0);
    a.lathe(&[(r, r, z0), (r, r, z1)], ROUND_SEGMENTS, CAN_LABEL);
    a.lathe(&[(r, r, z1), (0.0, 0.0, z1)], ROUND_SEGMENTS, CAN_TOP);
    a.lathe(&[(0.0, 0.0, z0), (r, r, z0)], ROUND_SEGMENTS, CAN_BOTTOM);
    a
}

const CAN_LABEL: UvRect = [0.0, 0.25, 1.0, 1.0];
const CAN_TOP: UvRect = [0.0, 0.0, 0.5, 0.25];
const CAN_BOTTOM: UvRect = [0.5, 0.0, 1.0, 0.25];

/// Metal lids: concentric rings (radial coordinate is the cell's t).
fn paint_lids(c: &mut Canvas, metal: Rgb) {
    for lid in [CAN_TOP, CAN_BOTTOM] {
        c.paint(lid, |_, t| Some(if (t * 8.0).fract() < 0.15 { shade(metal, 0.75) } else { metal }));
    }
}

fn tomato_soup_can() -> Built {
    let (red, gold) = ([205, 35, 40], [215, 170, 60]);
    let mut rng = Pcg64::seed_from_u64(3);
    let mut c = Canvas::new(512, 256, WHITE);
    c.paint(CAN_LABEL, |_, t| {
        Some(if t > 0.52 {
            red
        } else if t > 0.47 {
            gold
        } else {
            WHITE
        })
    });
    c.text_marks(CAN_LABEL, [0.3, 0.65, 0.7, 0.88], 2, WHITE, &mut rng);
    c.ellipse(CAN_LABEL, (0.5, 0.25), (0.07, 0.14), gold);
    c.text_marks(CAN_LABEL, [0.05, 0.08, 0.35, 0.38], 4, red, &mut rng);
    paint_lids(&mut c, [190, 190, 195]);
    let a = can(0.033, 0.10);
    ("tomato_soup_can", a.finish("tomato_soup_can", linear(red), c.into_texture()), Symmetry::None)
}

fn coffee_can() -> Built {
    let (blue, light, yellow) = ([25, 60, 150], [120, 170, 225], [240, 200, 60]);
    let mut rng = Pcg64::seed_from_u64(4);
    let mut c = Canvas::new(512, 256, blue);
    c.paint(CAN_LABEL, |_, t| ((0.35..0.6).contains(&t)).then_some(light));
    c.fill_rect_local(CAN_LABEL, [0.2, 0.38, 0.45, 0.57], WHITE);
    c.text_marks(CAN_LABEL, [0.22, 0.42, 0.43, 0.54], 2, blue, &mut rng);
    c.ellipse(CAN_LABEL, (0.33, 0.8), (0.08, 0.12), yellow);
    c.text_marks(CAN_LABEL, [0.6, 0.7, 0.95, 0.9], 3, WHITE, &mut rng);
    c.text_marks(CAN_LABEL, [0.6, 0.08, 0.95, 0.28], 3, WHITE, &mut rng);
    c.fill(CAN_TOP, shade(blue, 0.8));
    c.paint(CAN_BOTTOM, |_, t| Some(if (t * 6.0).fract() < 0.2 { [150, 150, 155] } else { [185, 185, 190] }));
    let a = can(0.05, 0.14);
    ("coffee_can", a.finish("coffee_can", linear(blue), c.into_texture()), Symmetry::None)
}

impl Canvas {
    /// Fills the local area `[s0, t0, s1, t1]` of `rect`.
    fn fill_rect_local(&mut self, rect: UvRect, area: [f64; 4], color: Rgb) {
        self.paint(rect, |s, t| (s >= area[0] && s <= area[2] && t >= area[1] && t <= area[3]).then_some(color));
    }
}

fn mustard_bottle() -> Built {
    let (yellow, red) = ([245, 200, 25], [210, 35, 30]);
    let mut rng = Pcg64::seed_from_u64(5);
    let (body, cap): (UvRect, UvRect) = ([0.0, 0.25, 1.0, 1.0], [0.0, 0.0, 1.0, 0.25]);
    let mut c = Canvas::new(512, 256, yellow);
    // Label on the front (-y is u = 0.75): red oval, white text, a red pennant.
    c.ellipse(body, (0.75, 0.55), (0.1, 0.14), red);
    c.text_marks(body, [0.69, 0.5, 0.81, 0.6], 2, WHITE, &mut rng);
    c.text_marks(body, [0.65, 0.2, 0.85, 0.35], 3, red, &mut rng);
    c.text_marks(body, [0.15, 0.3, 0.35, 0.7], 7, BLACK, &mut rng);
    c.paint(cap, |s, t| Some(if (s * 24.0).fract() < 0.2 && t < 0.7 { shade(red, 0.8) } else { red }));
    let mut a = Assembly::default();
    // Flattened body (95 x 58 mm) narrowing to a round neck.
    let profile = [
        (0.0, 0.0, 0.0),
        (0.040, 0.024, 0.0),
        (0.046, 0.028, 0.008),
        (0.0475, 0.029, 0.05),
        (0.047, 0.029, 0.10),
        (0.041, 0.026, 0.122),
        (0.027, 0.019, 0.138),
        (0.016, 0.016, 0.146),
    ];
    a.lathe(&profile, ROUND_SEGMENTS, body);
    // Cap: cylinder with a flat top, then an off-centre nozzle (breaks symmetry).
    a.lathe(&[(0.017, 0.017, 0.144), (0.017, 0.017, 0.172), (0.0, 0.0, 0.172)], 32, cap);
    let mut nozzle = Assembly::default();
    nozzle.lathe(&[(0.005, 0.005, 0.172), (0.004, 0.004, 0.19), (0.0, 0.0, 0.19)], 16, cap);
    a.append_shifted(nozzle, Vector3::new(0.008, 0.0, 0.0));
    ("mustard_bottle", a.finish("mustard_bottle", linear(yellow), c.into_texture()), Symmetry::None)
}

fn mug() -> Built {
    let (teal, inner, white) = ([25, 140, 150], [120, 200, 205], [240, 240, 235]);
    let mut rng = Pcg64::seed_from_u64(6);
    let (outside, inside, rest): (UvRect, UvRect, UvRect) =
        ([0.0, 0.5, 1.0, 1.0], [0.0, 0.25, 1.0, 0.5], [0.0, 0.0, 1.0, 0.25]);
    let mut c = Canvas::new(256, 256, teal);
    c.paint(outside, |_, t| (t > 0.85 && t < 0.92).then_some(white));
    // A small white logo opposite the handle (handle at +x, u = 0).
    c.ellipse(outside, (0.5, 0.45), (0.06, 0.15), white);
    c.text_marks(outside, [0.46, 0.4, 0.54, 0.5], 2, teal, &mut rng);
    c.fill(inside, inner);
    c.fill(rest, shade(teal, 0.9));
    let (ro, ri, h, floor) = (0.04, 0.036, 0.09, 0.006);
    let mut a = Assembly::default();
    a.lathe(&[(0.0, 0.0, 0.0), (ro, ro, 0.0)], ROUND_SEGMENTS, rest);
    a.lathe(&[(ro, ro, 0.0), (ro, ro, h)], ROUND_SEGMENTS, outside);
    a.lathe(&[(ro, ro, h), (ri, ri, h)], ROUND_SEGMENTS, rest);
    a.lathe(&[(ri, ri, h), (ri, ri, floor)], ROUND_SEGMENTS, inside);
    a.lathe(&[(ri, ri, floor), (0.0, 0.0, floor)], ROUND_SEGMENTS, inside);
    a.tube_arc(Point3::new(ro, 0.0, h / 2.0), 0.026, 0.006, (-FRAC_PI_2, FRAC_PI_2), (16, 12), rest);
    ("mug", a.finish("mug", linear(teal), c.into_texture()), Symmetry::None)
}

fn bowl() -> Built {
    let (green, cream) = ([55, 150, 70], [235, 225, 190]);
    let mut c = Canvas::new(256, 256, green);
    // Rows only: the texture is invariant under any rotation about z.
    c.paint([0.0, 0.0, 1.0, 1.0], |_, t| {
        Some(if (0.46..0.5).contains(&t) {
            cream
        } else if t > 0.5 {
            shade(green, 1.25)
        } else {
            green
        })
    });
    let steps = 10;
    let arc = |r0: f64, dr: f64, z0: f64, dz: f64, up: bool| -> Vec<(f64, f64, f64)> {
        (0..=steps)
            .map(|k| {
                let s = if up { k } else { steps - k } as f64 / steps as f64;
                let a = s * FRAC_PI_2;
                let r = r0 + dr * a.sin();
                let z = z0 + dz * (1.0 - a.cos());
                (r, r, z)
            })
            .collect()
    };
    let (outside, inside): (UvRect, UvRect) = ([0.0, 0.0, 1.0, 0.5], [0.0, 0.5, 1.0, 1.0]);
    let mut a = Assembly::default();
    a.lathe(&[(0.0, 0.0, 0.0), (0.035, 0.035, 0.0)], ROUND_SEGMENTS, outside);
    a.lathe(&arc(0.035, 0.045, 0.0, 0.053, true), ROUND_SEGMENTS, outside);
    a.lathe(&[(0.08, 0.08, 0.053), (0.074, 0.074, 0.053)], ROUND_SEGMENTS, [0.0, 0.46, 1.0, 0.5]);
    a.lathe(&arc(0.03, 0.044, 0.006, 0.047, false), ROUND_SEGMENTS, inside);
    a.lathe(&[(0.03, 0.03, 0.006), (0.0, 0.0, 0.006)], ROUND_SEGMENTS, inside);
    let symmetry = Symmetry::Continuous { axis: Vector3::z(), origin: Point3::origin() };
    ("bowl", a.finish("bowl", linear(green), c.into_texture()), symmetry)
}

fn wood_block() -> Built {
    let wood: Rgb = [200, 160, 105];
    let (side, end): (UvRect, UvRect) = ([0.0, 0.0, 0.5, 1.0], [0.5, 0.0, 1.0, 1.0]);
    let mut c = Canvas::new(512, 256, wood);
    // Grain along the block, symmetric about the face's centre line and
    // constant along it, so every side/flip looks the same.
    c.paint(side, |s, _| {
        let d = (s - 0.5).abs();
        let band = (d * 40.0).floor() as i64;
        Some(shade(wood, 0.85 + 0.25 * hash_noise(band)))
    });
    // End grain: rings centred on the face (invariant under its rotations).
    c.paint(end, |s, t| {
        let r = ((s - 0.5).powi(2) + (t - 0.5).powi(2)).sqrt();
        Some(shade(wood, if (r * 14.0).fract() < 0.25 { 0.78 } else { 0.95 }))
    });
    let size = [0.085, 0.085, 0.2];
    let mut a = Assembly::default();
    a.cuboid(size, [side, side, side, side, end, end]);
    ("wood_block", a.finish("wood_block", linear(wood), c.into_texture()), Symmetry::Discrete(box_symmetries(size)))
}

/// The rotations (identity excluded) mapping an axis-aligned box of `size`
/// centred at the origin onto itself: signed axis permutations with
/// determinant +1 that only swap equal extents.
pub fn box_symmetries(size: [f64; 3]) -> Vec<Isometry3<f64>> {
    let perms = [[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]];
    let mut out = Vec::new();
    for p in perms {
        if (0..3).any(|k| (size[p[k]] - size[k]).abs() > 1e-9) {
            continue;
        }
        for signs in 0..8 {
            let mut m = Matrix3::<f64>::zeros();
            for k in 0..3 {
                m[(k, p[k])] = if signs & (1 << k) != 0 { -1.0 } else { 1.0 };
            }
            if (m.determinant() - 1.0).abs() > 1e-9 || m == Matrix3::identity() {
                continue;
            }
            let r = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m));
            out.push(Isometry3::from_parts(nalgebra::Translation3::identity(), r));
        }
    }
    out
}

#[cfg(test)]
mod tests;
