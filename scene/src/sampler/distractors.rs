//! Distractors: solids that are not object classes (boxes, cylinders,
//! spheres, tori, cones) with random procedural textures, some tinted with an
//! object class's mean colour, resting on the table between the objects; and
//! occluders, larger solids a view may float near its image border between
//! the camera and the table. Both render with label 0 and never appear in
//! the frame truth.

use super::backdrop::{Pattern, box_mesh, procedural_texture_with, textured_material};
use super::placement::{Footprint, RestPose};
use super::{PlacedObject, Scene};
use crate::render::Randomize;
use crate::{Intrinsics, Material, Mesh, ObjectSet, Pose};
use nalgebra::{Point3, Translation3, UnitQuaternion, Vector2, Vector3};
use rand::Rng;
use rand_pcg::Pcg64Mcg;
use std::f32::consts::TAU;

/// A distractor on the table.
#[derive(Clone, Debug)]
pub struct Distractor {
    pub mesh: Mesh,
    /// Object → table pose (metres).
    pub table_from_object: Pose,
    /// Bounding-sphere radius about the object origin (metres).
    pub radius: f64,
}

/// Solids a distractor or occluder can be.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Solid {
    Box,
    Cylinder,
    Sphere,
    Torus,
    Cone,
}

/// A surface of revolution about z from a profile of (radius, z) points,
/// `segments` around, with normals from the profile and cylindrical uvs.
/// Caps are added where the profile starts or ends off the axis.
fn lathe(profile: &[(f32, f32)], segments: usize, uv_repeat: f32, material: Material) -> Mesh {
    let mut m = Mesh { materials: vec![material], ..Default::default() };
    let n = profile.len();
    // Profile normals (2D, outward) from neighbouring points.
    let pn: Vec<(f32, f32)> = (0..n)
        .map(|i| {
            let (a, b) = (profile[i.saturating_sub(1)], profile[(i + 1).min(n - 1)]);
            let (dr, dz) = (b.0 - a.0, b.1 - a.1);
            let len = (dr * dr + dz * dz).sqrt().max(1e-9);
            (dz / len, -dr / len)
        })
        .collect();
    for s in 0..=segments {
        let a = TAU * s as f32 / segments as f32;
        let (sa, ca) = a.sin_cos();
        for (i, &(r, z)) in profile.iter().enumerate() {
            m.positions.push([r * ca, r * sa, z]);
            let (nr, nz) = pn[i];
            m.normals.push([nr * ca, nr * sa, nz]);
            m.uvs.push([uv_repeat * s as f32 / segments as f32, i as f32 / (n - 1) as f32]);
        }
    }
    for s in 0..segments {
        for i in 0..n - 1 {
            let a = (s * n + i) as u32;
            let b = ((s + 1) * n + i) as u32;
            m.triangles.push([a, b, b + 1]);
            m.triangles.push([a, b + 1, a + 1]);
        }
    }
    for (end, sign) in [(0usize, -1.0f32), (n - 1, 1.0)] {
        let (r, z) = profile[end];
        if r <= 1e-6 {
            continue;
        }
        let centre = m.positions.len() as u32;
        m.positions.push([0.0, 0.0, z]);
        m.normals.push([0.0, 0.0, sign]);
        m.uvs.push([0.5, 0.5]);
        let ring = m.positions.len() as u32;
        for s in 0..=segments {
            let a = TAU * s as f32 / segments as f32;
            let (sa, ca) = a.sin_cos();
            m.positions.push([r * ca, r * sa, z]);
            m.normals.push([0.0, 0.0, sign]);
            m.uvs.push([0.5 + 0.5 * ca, 0.5 + 0.5 * sa]);
        }
        for s in 0..segments as u32 {
            if sign > 0.0 {
                m.triangles.push([centre, ring + s, ring + s + 1]);
            } else {
                m.triangles.push([centre, ring + s + 1, ring + s]);
            }
        }
    }
    m
}

/// A torus about z (ring radius `big`, tube radius `small`).
fn torus(big: f32, small: f32, material: Material) -> Mesh {
    let (seg, ring) = (32usize, 12usize);
    let mut m = Mesh { materials: vec![material], ..Default::default() };
    for s in 0..=seg {
        let a = TAU * s as f32 / seg as f32;
        let (sa, ca) = a.sin_cos();
        for r in 0..=ring {
            let b = TAU * r as f32 / ring as f32;
            let (sb, cb) = b.sin_cos();
            m.positions.push([(big + small * cb) * ca, (big + small * cb) * sa, small * sb]);
            m.normals.push([cb * ca, cb * sa, sb]);
            m.uvs.push([2.0 * s as f32 / seg as f32, r as f32 / ring as f32]);
        }
    }
    let stride = (ring + 1) as u32;
    for s in 0..seg as u32 {
        for r in 0..ring as u32 {
            let a = s * stride + r;
            let b = a + stride;
            m.triangles.push([a, b, b + 1]);
            m.triangles.push([a, b + 1, a + 1]);
        }
    }
    m
}

/// A solid of about `size` metres across, centred on its bounding box.
pub fn solid_mesh(kind: Solid, size: [f32; 3], material: Material) -> Mesh {
    let [sx, sy, sz] = size;
    let mut m = match kind {
        Solid::Box => box_mesh([sx / 2.0, sy / 2.0, sz / 2.0], 1.0, material),
        Solid::Cylinder => lathe(&[(sx / 2.0, -sz / 2.0), (sx / 2.0, sz / 2.0)], 32, 2.0, material),
        Solid::Cone => lathe(&[(sx / 2.0, -sz / 2.0), (sx * 0.08, sz / 2.0)], 32, 2.0, material),
        Solid::Sphere => {
            let r = sx / 2.0;
            let profile: Vec<(f32, f32)> = (0..=16)
                .map(|i| {
                    let a = std::f32::consts::PI * (i as f32 / 16.0 - 0.5);
                    (r * a.cos(), r * a.sin())
                })
                .collect();
            lathe(&profile, 32, 2.0, material)
        }
        Solid::Torus => torus(sx / 2.0 - sz / 2.0, sz / 2.0, material),
    };
    recentre_on_bbox(&mut m);
    m
}

/// Moves a mesh so that its bounding box is centred on the origin.
pub fn recentre_on_bbox(m: &mut Mesh) {
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for p in &m.positions {
        for c in 0..3 {
            lo[c] = lo[c].min(p[c]);
            hi[c] = hi[c].max(p[c]);
        }
    }
    for p in m.positions.iter_mut() {
        for c in 0..3 {
            p[c] -= (lo[c] + hi[c]) / 2.0;
        }
    }
}

/// Mean linear albedo of an object class: its textures (subsampled),
/// vertex colours or material colours.
pub fn mean_albedo(mesh: &Mesh) -> [f32; 3] {
    let dec = |c: u8| {
        let c = c as f32 / 255.0;
        if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }
    };
    let mut sum = [0.0f64; 3];
    let mut n = 0.0f64;
    if !mesh.uvs.is_empty() {
        for t in mesh.materials.iter().filter_map(|m| m.texture.as_ref()) {
            let px = t.rgb.len() / 3;
            let stride = (px / 1024).max(1);
            for texel in t.rgb.chunks_exact(3).step_by(stride) {
                for (s, &c) in sum.iter_mut().zip(texel) {
                    *s += dec(c) as f64;
                }
                n += 1.0;
            }
        }
    }
    if n == 0.0 && !mesh.colors.is_empty() {
        for col in mesh.colors.iter().step_by((mesh.colors.len() / 1024).max(1)) {
            for (s, &c) in sum.iter_mut().zip(col) {
                *s += dec(c) as f64;
            }
            n += 1.0;
        }
    }
    if n == 0.0 {
        for m in &mesh.materials {
            for (s, &c) in sum.iter_mut().zip(&m.diffuse) {
                *s += c as f64;
            }
            n += 1.0;
        }
    }
    if n == 0.0 {
        return [0.5; 3];
    }
    sum.map(|s| (s / n) as f32)
}

/// A random texture for a distractor: one of all procedural patterns with
/// strong colours, or (35 %) tinted with an object class's mean colour.
fn random_material(rng: &mut Pcg64Mcg, set: &ObjectSet) -> Material {
    let pattern = Pattern::ALL[rng.random_range(0..Pattern::ALL.len())];
    let like_class = !set.is_empty() && rng.random_bool(0.35);
    if like_class {
        let m = &set.objects[rng.random_range(0..set.len())].mesh;
        let mean = mean_albedo(m);
        let enc = |l: f32| {
            let c = if l <= 0.003_130_8 { l * 12.92 } else { 1.055 * l.powf(1.0 / 2.4) - 0.055 };
            c * 255.0
        };
        if rng.random_bool(0.5) {
            return Material { name: "distractor".into(), diffuse: mean, texture: None };
        }
        let base = mean.map(enc);
        let tex = procedural_texture_with(rng, pattern, 64, Some(base));
        return textured_material("distractor", tex);
    }
    textured_material("distractor", procedural_texture_with(rng, pattern, 64, None))
}

fn random_solid(rng: &mut Pcg64Mcg) -> Solid {
    [Solid::Box, Solid::Cylinder, Solid::Sphere, Solid::Torus, Solid::Cone][rng.random_range(0..5)]
}

/// A random size for a `kind` solid ([`solid_mesh`]'s `size`), each drawn
/// extent in `lo..hi` metres; a torus is at least `torus_min` across.
pub fn random_solid_size(rng: &mut Pcg64Mcg, kind: Solid, lo: f32, hi: f32, torus_min: f32) -> [f32; 3] {
    let mut d = || rng.random_range(lo..hi);
    match kind {
        Solid::Sphere => {
            let s = d();
            [s, s, s]
        }
        Solid::Torus => {
            let s = d().max(torus_min);
            [s, s, s * 0.3]
        }
        Solid::Cylinder | Solid::Cone => {
            let r = d();
            [r, r, d()]
        }
        Solid::Box => [d(), d(), d()],
    }
}

/// A distractor mesh 3–14 cm across (`Strong` up to 20 cm).
fn random_distractor_mesh(rng: &mut Pcg64Mcg, set: &ObjectSet, level: Randomize) -> Mesh {
    let kind = random_solid(rng);
    let max: f32 = if level == Randomize::Strong { 0.2 } else { 0.14 };
    let size = random_solid_size(rng, kind, 0.03, max, 0.05);
    solid_mesh(kind, size, random_material(rng, set))
}

/// An occluder mesh: a box or cylinder 4–12 cm thick and 15–40 cm long
/// (`Strong` up to 50 cm), like an arm, a pole or a box in front of the camera.
pub fn random_occluder_mesh(rng: &mut Pcg64Mcg, set: &ObjectSet, level: Randomize) -> Mesh {
    let thick = rng.random_range(0.04..0.12f32);
    let long = rng.random_range(0.15..if level == Randomize::Strong { 0.5 } else { 0.4f32 });
    let kind = if rng.random_bool(0.5) { Solid::Box } else { Solid::Cylinder };
    let size = if kind == Solid::Box { [thick, rng.random_range(0.04..0.2), long] } else { [thick, thick, long] };
    solid_mesh(kind, size, random_material(rng, set))
}

/// Conservative footprint of a placed object: the xy rectangle of its model
/// bounding box corners in the table frame.
fn object_footprint(set: &ObjectSet, o: &PlacedObject) -> Option<Footprint> {
    let m = set.by_class(o.class_id)?;
    let (mut lo, mut hi) = (Vector2::repeat(f64::INFINITY), Vector2::repeat(f64::NEG_INFINITY));
    for c in 0..8 {
        let p = Point3::new(
            if c & 1 == 0 { m.bbox_min.x } else { m.bbox_max.x },
            if c & 2 == 0 { m.bbox_min.y } else { m.bbox_max.y },
            if c & 4 == 0 { m.bbox_min.z } else { m.bbox_max.z },
        );
        let q = o.table_from_object * p;
        lo = lo.inf(&q.xy().coords);
        hi = hi.sup(&q.xy().coords);
    }
    let rest = RestPose {
        rotation: UnitQuaternion::identity(),
        lift: 0.0,
        footprint_centre: [0.0, 0.0],
        footprint_half: [(hi.x - lo.x) / 2.0, (hi.y - lo.y) / 2.0],
        face_area: 0.0,
        upright: true,
        height: 0.0,
    };
    Some(Footprint::of(&rest, 0.0, (lo + hi) / 2.0))
}

/// 0–4 distractors (`Strong` 1–6) resting on the table near the objects,
/// never overlapping them (3 mm gap) or each other.
pub(super) fn place_distractors(
    rng: &mut Pcg64Mcg,
    set: &ObjectSet,
    objects: &[PlacedObject],
    _rests: &[Vec<RestPose>],
    table_half: [f64; 2],
    level: Randomize,
) -> Vec<Distractor> {
    let count = if level == Randomize::Strong { rng.random_range(1..=6) } else { rng.random_range(0..=4) };
    let mut taken: Vec<Footprint> = objects.iter().filter_map(|o| object_footprint(set, o)).collect();
    let centre = objects.iter().fold(Vector2::zeros(), |a, o| a + o.table_from_object.translation.vector.xy())
        / objects.len().max(1) as f64;
    let mut out = Vec::with_capacity(count);
    for _ in 0..count {
        let mesh = random_distractor_mesh(rng, set, level);
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for p in &mesh.positions {
            for c in 0..3 {
                lo[c] = lo[c].min(p[c]);
                hi[c] = hi[c].max(p[c]);
            }
        }
        let half = [(hi[0] - lo[0]) as f64 / 2.0, (hi[1] - lo[1]) as f64 / 2.0];
        let radius = (0..3).map(|c| (hi[c].abs().max(lo[c].abs()) as f64).powi(2)).sum::<f64>().sqrt();
        let rest = RestPose {
            rotation: UnitQuaternion::identity(),
            lift: -lo[2] as f64,
            footprint_centre: [0.0, 0.0],
            footprint_half: half,
            face_area: 0.0,
            upright: true,
            height: (hi[2] - lo[2]) as f64,
        };
        for _ in 0..30 {
            let yaw = rng.random_range(0.0..std::f64::consts::TAU);
            let (r, phi) = (rng.random_range(0.08..0.4), rng.random_range(0.0..std::f64::consts::TAU));
            let pos = centre + Vector2::new(r * phi.cos(), r * phi.sin());
            let fp = Footprint::of(&rest, yaw, pos);
            let fr = fp.radius();
            if fp.centre.x.abs() + fr > table_half[0] || fp.centre.y.abs() + fr > table_half[1] {
                continue;
            }
            if taken.iter().any(|o| o.overlaps(&fp, 0.003)) {
                continue;
            }
            taken.push(fp);
            let rotation = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw);
            let table_from_object = Pose::from_parts(Translation3::new(pos.x, pos.y, rest.lift), rotation);
            out.push(Distractor { mesh, table_from_object, radius });
            break;
        }
    }
    out
}

/// A camera → object pose for an occluder floating near a random image
/// border, closer to the camera than the objects (0.05 m + its radius up to
/// 70 % of the objects' distance), its centre placed so that at most 5–30 %
/// of the image width (height) is covered from that border; `None` when the
/// objects are too close for one.
pub(super) fn border_occluder_pose(
    rng: &mut Pcg64Mcg,
    scene: &Scene,
    _set: &ObjectSet,
    mesh: &Mesh,
    k: &Intrinsics,
    cam: &Pose,
) -> Option<Pose> {
    let centroid = scene.objects.iter().fold(Vector3::zeros(), |a, o| a + o.table_from_object.translation.vector)
        / scene.objects.len().max(1) as f64;
    let scene_z = (cam * Point3::from(centroid)).z;
    let radius =
        mesh.positions.iter().map(|p| ((p[0] * p[0] + p[1] * p[1] + p[2] * p[2]) as f64).sqrt()).fold(0.0, f64::max);
    let (near, far) = (radius + 0.05, 0.7 * scene_z - radius);
    if far <= near {
        return None;
    }
    let d = rng.random_range(near..far);
    // Projected bounding radius (pixels); the centre sits outside the border
    // far enough that at most `reach` of the image is covered.
    let rho = k.fx * radius / d;
    let (w, h) = (k.width as f64, k.height as f64);
    let side = rng.random_range(0..4);
    let reach = rng.random_range(0.05..0.3) * if side < 2 { w } else { h };
    let inside = reach - rho;
    let (u, v) = match side {
        0 => (inside, rng.random_range(0.0..h)),
        1 => (w - 1.0 - inside, rng.random_range(0.0..h)),
        2 => (rng.random_range(0.0..w), inside),
        _ => (rng.random_range(0.0..w), h - 1.0 - inside),
    };
    let centre = k.back_project(u, v, d);
    let rotation = UnitQuaternion::from_euler_angles(
        rng.random_range(-3.2..3.2),
        rng.random_range(-3.2..3.2),
        rng.random_range(-3.2..3.2),
    );
    Some(Pose::from_parts(Translation3::from(centre.coords), rotation))
}
