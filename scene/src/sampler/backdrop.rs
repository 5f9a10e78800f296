//! Background geometry for sampled scenes: mesh primitives (box, quad), the
//! procedural textures, and the textured table top plus a room around it
//! (for randomised scenes also a room of random size and a wall close behind
//! the table).
//! All in the table frame: origin at the centre of the table top, z up, metres.

use crate::render::Randomize;
use crate::{Material, Mesh, Texture};
use nalgebra::Vector3;
use rand::Rng;

/// An axis-aligned box centred at the origin with half extents `half` (metres):
/// 24 vertices (flat normals per face), 12 outward counter-clockwise
/// triangles, uvs 0..`uv_repeat` per face, one material.
pub fn box_mesh(half: [f32; 3], uv_repeat: f32, material: Material) -> Mesh {
    let mut m = Mesh { materials: vec![material], ..Default::default() };
    // (normal axis, sign, u axis, v axis) with u × v = sign · e_axis.
    let faces = [(0, 1.0, 1, 2), (0, -1.0, 2, 1), (1, 1.0, 2, 0), (1, -1.0, 0, 2), (2, 1.0, 0, 1), (2, -1.0, 1, 0)];
    for (a, s, u, v) in faces {
        let base = m.positions.len() as u32;
        for (i, j) in [(0, 0), (1, 0), (1, 1), (0, 1)] {
            let mut p = [0.0f32; 3];
            p[a] = s * half[a];
            p[u] = (2 * i - 1) as f32 * half[u];
            p[v] = (2 * j - 1) as f32 * half[v];
            let mut n = [0.0f32; 3];
            n[a] = s;
            m.positions.push(p);
            m.normals.push(n);
            m.uvs.push([i as f32 * uv_repeat, j as f32 * uv_repeat]);
        }
        m.triangles.push([base, base + 1, base + 2]);
        m.triangles.push([base, base + 2, base + 3]);
    }
    m
}

/// A rectangle in the z = 0 plane, normal +z, corners (±half_x, ±half_y),
/// uv (0, 0) at (−x, −y) to (`uv_repeat`, `uv_repeat`) at (+x, +y).
pub fn quad_mesh(half_x: f32, half_y: f32, uv_repeat: f32, material: Material) -> Mesh {
    Mesh {
        positions: vec![[-half_x, -half_y, 0.0], [half_x, -half_y, 0.0], [half_x, half_y, 0.0], [-half_x, half_y, 0.0]],
        normals: vec![[0.0, 0.0, 1.0]; 4],
        uvs: vec![[0.0, 0.0], [uv_repeat, 0.0], [uv_repeat, uv_repeat], [0.0, uv_repeat]],
        colors: Vec::new(),
        triangles: vec![[0, 1, 2], [0, 2, 3]],
        triangle_materials: Vec::new(),
        materials: vec![material],
    }
}

/// A plain material (linear diffuse colour, no texture).
pub fn plain_material(name: &str, diffuse: [f32; 3]) -> Material {
    Material { name: name.to_string(), diffuse, texture: None }
}

/// A textured material.
pub fn textured_material(name: &str, texture: Texture) -> Material {
    Material { name: name.to_string(), diffuse: [1.0; 3], texture: Some(texture) }
}

/// Random sRGB base colour with moderate saturation and value.
fn random_colour(rng: &mut impl Rng, value: (f32, f32), saturation: (f32, f32)) -> [f32; 3] {
    let h = rng.random_range(0.0..6.0f32);
    let s = rng.random_range(saturation.0..saturation.1);
    let v = rng.random_range(value.0..value.1);
    let c = v * s;
    let x = c * (1.0 - ((h % 2.0) - 1.0).abs());
    let (r, g, b) = match h as u32 {
        0 => (c, x, 0.0),
        1 => (x, c, 0.0),
        2 => (0.0, c, x),
        3 => (0.0, x, c),
        4 => (x, 0.0, c),
        _ => (c, 0.0, x),
    };
    let m = v - c;
    [(r + m) * 255.0, (g + m) * 255.0, (b + m) * 255.0]
}

/// Periodic value noise: hashed values on an integer lattice that wraps
/// every `period` cells (so textures tile seamlessly), smoothly blended.
/// `x`, `y` ≥ 0.
fn value_noise(seed: u32, x: f32, y: f32, period: u32) -> f32 {
    let hash = |ix: u32, iy: u32| -> f32 {
        let (ix, iy) = (ix % period, iy % period);
        let mut h = ix.wrapping_mul(0x27d4_eb2d) ^ iy.wrapping_mul(0x1656_67b1) ^ seed;
        h ^= h >> 15;
        h = h.wrapping_mul(0x85eb_ca6b);
        h ^= h >> 13;
        (h & 0xFFFF) as f32 / 65535.0
    };
    let (ix, iy) = (x as u32, y as u32);
    let (tx, ty) = (x - ix as f32, y - iy as f32);
    let (tx, ty) = (tx * tx * (3.0 - 2.0 * tx), ty * ty * (3.0 - 2.0 * ty));
    let a = hash(ix, iy) * (1.0 - tx) + hash(ix + 1, iy) * tx;
    let b = hash(ix, iy + 1) * (1.0 - tx) + hash(ix + 1, iy + 1) * tx;
    a * (1.0 - ty) + b * ty
}

/// Which procedural pattern a background texture shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pattern {
    /// Wood-like grain along u.
    Grain,
    /// Square tiles with grout lines.
    Tiles,
    /// Smooth mottled paint.
    Mottled,
    /// A checkerboard of two strong colours (2–8 squares per tile).
    Checker,
    /// Straight stripes (possibly diagonal) of two or three strong colours.
    Stripes,
    /// Blotchy noise between strongly coloured hues.
    ColourNoise,
}

impl Pattern {
    /// Every pattern.
    pub const ALL: [Pattern; 6] =
        [Pattern::Grain, Pattern::Tiles, Pattern::Mottled, Pattern::Checker, Pattern::Stripes, Pattern::ColourNoise];
}

/// A seamless `size x size` procedural texture with a random base colour.
pub fn procedural_texture(rng: &mut impl Rng, pattern: Pattern, size: u32) -> Texture {
    procedural_texture_with(rng, pattern, size, None)
}

/// Like [`procedural_texture`], with the base colour (sRGB 0..255) given
/// instead of drawn when `base` is set.
pub fn procedural_texture_with(rng: &mut impl Rng, pattern: Pattern, size: u32, base: Option<[f32; 3]>) -> Texture {
    if matches!(pattern, Pattern::Checker | Pattern::Stripes | Pattern::ColourNoise) {
        return strong_texture(rng, pattern, size, base);
    }
    let base = match base {
        Some(b) => b,
        None => random_colour(rng, (0.35, 0.9), (0.05, 0.55)),
    };
    let accent = random_colour(rng, (0.2, 0.8), (0.05, 0.5));
    let seed: u32 = rng.random();
    let contrast: f32 = rng.random_range(0.1..0.35);
    let n = size as usize;
    let mut rgb = vec![0u8; n * n * 3];
    // Noise with `f` lattice cells across the texture tiles seamlessly.
    let noise = |f: u32, u: f32, v: f32| value_noise(seed, u * f as f32, v * f as f32, f);
    for y in 0..n {
        for x in 0..n {
            let (u, v) = (x as f32 / n as f32, y as f32 / n as f32);
            let t = match pattern {
                Pattern::Grain => {
                    // Rings of a grain along u, disturbed by noise; 20 periods across v.
                    let g = noise(4, u, v) * 6.0 + v * 40.0;
                    0.5 + 0.3 * (g * std::f32::consts::PI).sin() + 0.4 * noise(16, u, v) - 0.2
                }
                Pattern::Tiles => {
                    let (fu, fv) = ((u * 4.0).fract(), (v * 4.0).fract());
                    let grout = fu < 0.04 || fv < 0.04;
                    if grout { -1.0 } else { 0.3 + 0.4 * noise(8, u, v) }
                }
                Pattern::Mottled | Pattern::Checker | Pattern::Stripes | Pattern::ColourNoise => {
                    noise(4, u, v) * 0.7 + noise(16, u, v) * 0.3
                }
            };
            let i = (y * n + x) * 3;
            for c in 0..3 {
                let col =
                    if t < 0.0 { accent[c] * 0.6 } else { base[c] * (1.0 - contrast) + accent[c] * contrast * t * 2.0 };
                rgb[i + c] = col.round().clamp(0.0, 255.0) as u8;
            }
        }
    }
    Texture { width: size, height: size, rgb }
}

/// The strongly coloured patterns: checker, stripes and colour noise.
fn strong_texture(rng: &mut impl Rng, pattern: Pattern, size: u32, base: Option<[f32; 3]>) -> Texture {
    let c0 = base.unwrap_or_else(|| random_colour(rng, (0.4, 1.0), (0.5, 1.0)));
    let c1 = random_colour(rng, (0.1, 1.0), (0.3, 1.0));
    let c2 = random_colour(rng, (0.3, 1.0), (0.5, 1.0));
    let seed: u32 = rng.random();
    let cells = rng.random_range(2..=8u32);
    // Integer frequencies keep stripes seamless when the texture tiles.
    let (fu, fv) = (rng.random_range(0..=6i32), rng.random_range(1..=8i32));
    let three = rng.random_bool(0.4);
    let n = size as usize;
    let mut rgb = vec![0u8; n * n * 3];
    for y in 0..n {
        for x in 0..n {
            let (u, v) = (x as f32 / n as f32, y as f32 / n as f32);
            let col = match pattern {
                Pattern::Checker => {
                    let (i, j) = ((u * cells as f32) as u32, (v * cells as f32) as u32);
                    if (i + j) % 2 == 0 { c0 } else { c1 }
                }
                Pattern::Stripes => {
                    let t = (fu as f32 * u + fv as f32 * v).rem_euclid(1.0);
                    let k = if three { (t * 3.0) as u32 } else { (t * 2.0) as u32 };
                    [c0, c1, c2][k.min(2) as usize]
                }
                _ => {
                    let a = value_noise(seed, u * 6.0, v * 6.0, 6);
                    let b = value_noise(seed ^ 0x9e37, u * 24.0, v * 24.0, 24);
                    let t = (0.75 * a + 0.25 * b).clamp(0.0, 1.0);
                    let (lo, hi, s) = if t < 0.5 { (c0, c1, t * 2.0) } else { (c1, c2, t * 2.0 - 1.0) };
                    std::array::from_fn(|c| lo[c] + (hi[c] - lo[c]) * s)
                }
            };
            let i = (y * n + x) * 3;
            for c in 0..3 {
                rgb[i + c] = col[c].round().clamp(0.0, 255.0) as u8;
            }
        }
    }
    Texture { width: size, height: size, rgb }
}

/// The static background of a scene, all in the table frame (label 0).
#[derive(Clone, Debug)]
pub struct Backdrop {
    /// The table top: a thin textured box whose top face is z = 0.
    pub table: Mesh,
    /// Table top extent: half sizes along x and y (metres).
    pub table_half_extent: [f64; 2],
    /// Floor and four walls of the room (inward-facing boxes), plus in some
    /// randomised scenes a wall right behind the table.
    pub room: Mesh,
    /// Height of the room's walls above its floor (metres; the floor is
    /// 0.75 m below the table top).
    pub room_height_m: f64,
}

impl Backdrop {
    /// A random table (1.0–1.6 m × 0.7–1.1 m, 3 cm thick, grain texture) in a
    /// 6 m × 6 m room whose floor is 0.75 m below the table top.
    pub fn random(rng: &mut impl Rng) -> Backdrop {
        let hx = rng.random_range(0.5..0.8f32);
        let hy = rng.random_range(0.35..0.55f32);
        let thickness = 0.03f32;
        let table_tex = procedural_texture(rng, Pattern::Grain, 256);
        let mut table = box_mesh([hx, hy, thickness / 2.0], 1.0, textured_material("table", table_tex));
        for p in table.positions.iter_mut() {
            p[2] -= thickness / 2.0;
        }
        // Tile the top face texture about every 0.5 m.
        for (p, uv) in table.positions.iter().zip(table.uvs.iter_mut()) {
            *uv = [p[0] / 0.5 + 0.5, p[1] / 0.5 + 0.5];
        }
        let floor_tex = procedural_texture(rng, Pattern::Tiles, 256);
        let wall_tex = procedural_texture(rng, Pattern::Mottled, 128);
        let room = room_mesh(3.0, 0.75, 2.5, floor_tex, wall_tex);
        Backdrop { table, table_half_extent: [hx as f64, hy as f64], room, room_height_m: 2.5 }
    }

    /// A randomised backdrop: a table 0.9–1.8 m × 0.7–1.2 m with any pattern,
    /// a room 4–7 m wide and 2.5–3.2 m high with any patterns on floor and
    /// walls, and in 50 % (`Strong` 60 %) of scenes a wall 0–0.25 m behind a
    /// random table edge, up to 1.6 m above the table. Returns the backdrop
    /// and that wall's plane `(n, d)` (n into the room: inside is `n·p > d`).
    pub fn random_varied(rng: &mut impl Rng, level: Randomize) -> (Backdrop, Option<(Vector3<f64>, f64)>) {
        let hx = rng.random_range(0.45..0.9f32);
        let hy = rng.random_range(0.35..0.6f32);
        let thickness = 0.03f32;
        fn any(rng: &mut impl Rng) -> Pattern {
            Pattern::ALL[rng.random_range(0..Pattern::ALL.len())]
        }
        let pattern = any(rng);
        let table_tex = procedural_texture(rng, pattern, 256);
        let mut table = box_mesh([hx, hy, thickness / 2.0], 1.0, textured_material("table", table_tex));
        for p in table.positions.iter_mut() {
            p[2] -= thickness / 2.0;
        }
        let tile = rng.random_range(0.25..0.8f32);
        for (p, uv) in table.positions.iter().zip(table.uvs.iter_mut()) {
            *uv = [p[0] / tile + 0.5, p[1] / tile + 0.5];
        }
        let pattern = any(rng);
        let floor_tex = procedural_texture(rng, pattern, 128);
        let pattern = any(rng);
        let wall_tex = procedural_texture(rng, pattern, 128);
        let half = rng.random_range(2.0..3.5f32);
        let height = rng.random_range(2.5..3.2f32);
        let mut room = room_mesh(half, 0.75, height, floor_tex, wall_tex);
        let p_wall = if level == Randomize::Strong { 0.6 } else { 0.5 };
        let mut plane = None;
        if rng.random_bool(p_wall) {
            let side = rng.random_range(0..4u32);
            let gap = rng.random_range(0.0..0.25f32);
            let (edge, along) = if side < 2 { (hx + gap, hy) } else { (hy + gap, hx) };
            let sign = if side % 2 == 0 { 1.0f32 } else { -1.0 };
            let top = 1.6f32;
            let w = along + 1.0;
            // Corners in (along, across) then mapped to xy, wall facing the table.
            let map = |a: f32, z: f32| if side < 2 { [sign * edge, a, z] } else { [a, sign * edge, z] };
            let normal = if side < 2 { [-sign, 0.0, 0.0] } else { [0.0, -sign, 0.0] };
            let pattern = any(rng);
            let tex = procedural_texture(rng, pattern, 128);
            let mi = room.materials.len() as u32;
            room.materials.push(textured_material("near_wall", tex));
            let base = room.positions.len() as u32;
            let uv_s = 1.0 / rng.random_range(0.4..1.2f32);
            for (a, z) in [(-w, -0.75), (w, -0.75), (w, top), (-w, top)] {
                room.positions.push(map(a, z));
                room.normals.push(normal);
                room.uvs.push([a * uv_s, z * uv_s]);
            }
            room.triangles.push([base, base + 1, base + 2]);
            room.triangles.push([base, base + 2, base + 3]);
            room.triangle_materials.extend([mi, mi]);
            let n = Vector3::new(normal[0] as f64, normal[1] as f64, normal[2] as f64);
            plane = Some((n, -(edge as f64)));
        }
        (Backdrop { table, table_half_extent: [hx as f64, hy as f64], room, room_height_m: height as f64 }, plane)
    }
}

/// Floor (z = −floor_depth) and four walls of a square room of half size
/// `half` around the origin, up to `height` above the floor, facing inward.
fn room_mesh(half: f32, floor_depth: f32, height: f32, floor_tex: Texture, wall_tex: Texture) -> Mesh {
    let mut m = Mesh {
        materials: vec![textured_material("floor", floor_tex), textured_material("wall", wall_tex)],
        ..Default::default()
    };
    let z0 = -floor_depth;
    let z1 = z0 + height;
    let mut quad = |corners: [[f32; 3]; 4], normal: [f32; 3], uv_size: [f32; 2], material: u32| {
        let base = m.positions.len() as u32;
        for (c, uv) in corners.iter().zip([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]) {
            m.positions.push(*c);
            m.normals.push(normal);
            m.uvs.push([uv[0] * uv_size[0], uv[1] * uv_size[1]]);
        }
        m.triangles.push([base, base + 1, base + 2]);
        m.triangles.push([base, base + 2, base + 3]);
        m.triangle_materials.extend([material, material]);
    };
    let h = half;
    let tiles = 2.0 * h / 1.2; // 4 tiles per texture → 0.3 m tiles
    quad([[-h, -h, z0], [h, -h, z0], [h, h, z0], [-h, h, z0]], [0.0, 0.0, 1.0], [tiles, tiles], 0);
    let wall_uv = [2.0 * h / 1.5, height / 1.5];
    quad([[-h, h, z0], [h, h, z0], [h, h, z1], [-h, h, z1]], [0.0, -1.0, 0.0], wall_uv, 1);
    quad([[h, -h, z0], [-h, -h, z0], [-h, -h, z1], [h, -h, z1]], [0.0, 1.0, 0.0], wall_uv, 1);
    quad([[h, h, z0], [h, -h, z0], [h, -h, z1], [h, h, z1]], [-1.0, 0.0, 0.0], wall_uv, 1);
    quad([[-h, -h, z0], [-h, h, z0], [-h, h, z1], [-h, -h, z1]], [1.0, 0.0, 0.0], wall_uv, 1);
    m
}
