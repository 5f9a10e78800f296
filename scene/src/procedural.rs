//! Procedural object sets: many varied, textured objects made by code, for
//! pretraining a trunk that new object sets warm-start from (issue 20). Each
//! object is a body solid with up to two smaller solids attached off-centre
//! (so almost none is symmetric), every part with its own procedural texture
//! or plain colour, 4–22 cm across. Deterministic per (count, seed).
//!
//! Object frame as the built-ins: origin at the bounding-box centre, +z up.

use nalgebra::{Rotation3, Vector3};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;

use crate::model::{Material, Mesh, ObjectModel, ObjectSet, Symmetry};
use crate::sampler::backdrop::{Pattern, plain_material, procedural_texture_with, textured_material};
use crate::sampler::distractors::{Solid, random_solid_size, recentre_on_bbox, solid_mesh};

/// Texture edge length (pixels) of each part.
const TEXTURE_SIZE: u32 = 128;

/// `count` procedural objects named `proc_000`, `proc_001`, … (class ids in
/// that order). The same (count, seed) always gives the same set, and object
/// `i` does not depend on `count`.
pub fn procedural_objects(count: usize, seed: u64) -> ObjectSet {
    let objects = (0..count)
        .map(|i| {
            let mut rng = Pcg64Mcg::seed_from_u64(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ (i as u64 + 1));
            let name = format!("proc_{i:03}");
            let mesh = procedural_mesh(&mut rng);
            ObjectModel::from_mesh(&name, mesh, Symmetry::None)
                .unwrap_or_else(|e| panic!("procedural object {name} is malformed (a bug): {e}"))
        })
        .collect();
    ObjectSet { objects }
}

fn random_part_material(rng: &mut Pcg64Mcg, name: &str) -> Material {
    if rng.random_bool(0.2) {
        // Plain colours make the untextured case (grey, single-colour parts) common too.
        let grey = rng.random_bool(0.4);
        let c: [f32; 3] = if grey {
            let g = rng.random_range(0.05..0.8f32);
            [g, g, g]
        } else {
            std::array::from_fn(|_| rng.random_range(0.02..0.9f32))
        };
        return plain_material(name, c);
    }
    let pattern = Pattern::ALL[rng.random_range(0..Pattern::ALL.len())];
    textured_material(name, procedural_texture_with(rng, pattern, TEXTURE_SIZE, None))
}

fn random_solid(rng: &mut Pcg64Mcg, body: bool) -> Solid {
    // Tori and spheres make poor bodies (little to hold parts); boxes and cylinders are common.
    let kinds: &[Solid] = if body {
        &[Solid::Box, Solid::Box, Solid::Cylinder, Solid::Cylinder, Solid::Cone, Solid::Sphere]
    } else {
        &[Solid::Box, Solid::Cylinder, Solid::Sphere, Solid::Torus, Solid::Cone]
    };
    kinds[rng.random_range(0..kinds.len())]
}

/// Half extents of a mesh's bounding box about the origin (parts are centred).
fn half_extents(m: &Mesh) -> [f32; 3] {
    let mut h = [0.0f32; 3];
    for p in &m.positions {
        for c in 0..3 {
            h[c] = h[c].max(p[c].abs());
        }
    }
    h
}

fn procedural_mesh(rng: &mut Pcg64Mcg) -> Mesh {
    let kind = random_solid(rng, true);
    let size = random_solid_size(rng, kind, 0.05, 0.2, 0.04);
    let body = solid_mesh(kind, size, random_part_material(rng, "body"));
    let body_half = half_extents(&body);
    let mut out = Mesh::default();
    append(&mut out, &body, &Rotation3::identity(), Vector3::zeros());
    let parts = [0usize, 1, 1, 2, 2][rng.random_range(0..5)];
    for p in 0..parts {
        let kind = random_solid(rng, false);
        let size = random_solid_size(rng, kind, 0.02, 0.08, 0.04);
        let part = solid_mesh(kind, size, random_part_material(rng, &format!("part{p}")));
        let rot = Rotation3::from_euler_angles(
            rng.random_range(-3.2..3.2f32),
            rng.random_range(-3.2..3.2f32),
            rng.random_range(-3.2..3.2f32),
        );
        // Attach to one face of the body's box, off-centre along the face and
        // sunk a little into the body so the two read as one object.
        let axis = rng.random_range(0..3usize);
        let sign = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
        let part_half = half_extents(&part);
        let mut at = Vector3::zeros();
        for c in 0..3 {
            at[c] = if c == axis {
                sign * (body_half[c] + part_half.iter().cloned().fold(0.0, f32::max) * 0.5)
            } else {
                rng.random_range(-0.7..0.7f32) * body_half[c]
            };
        }
        append(&mut out, &part, &rot, at);
    }
    recentre_on_bbox(&mut out);
    out
}

/// Appends `src` rotated by `rot` and moved by `at`, keeping its materials.
fn append(dst: &mut Mesh, src: &Mesh, rot: &Rotation3<f32>, at: Vector3<f32>) {
    let base = dst.positions.len() as u32;
    let mat_base = dst.materials.len() as u32;
    for p in &src.positions {
        let q = rot * Vector3::from(*p) + at;
        dst.positions.push([q.x, q.y, q.z]);
    }
    for n in &src.normals {
        let q = rot * Vector3::from(*n);
        dst.normals.push([q.x, q.y, q.z]);
    }
    dst.uvs.extend_from_slice(&src.uvs);
    dst.triangles.extend(src.triangles.iter().map(|t| t.map(|i| i + base)));
    if src.triangle_materials.is_empty() {
        dst.triangle_materials.extend(std::iter::repeat_n(mat_base, src.triangles.len()));
    } else {
        dst.triangle_materials.extend(src.triangle_materials.iter().map(|m| m + mat_base));
    }
    dst.materials.extend(src.materials.iter().cloned());
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn objects_are_deterministic_and_independent_of_count() {
        let a = procedural_objects(6, 11);
        let b = procedural_objects(3, 11);
        for (x, y) in a.objects.iter().zip(&b.objects) {
            assert_eq!(x.name, y.name);
            assert_eq!(x.mesh, y.mesh);
        }
        let c = procedural_objects(3, 12);
        assert_ne!(a.objects[0].mesh, c.objects[0].mesh, "another seed gives other objects");
    }

    #[test]
    fn objects_are_well_formed_table_sized_and_centred() {
        let set = procedural_objects(40, 3);
        assert_eq!(set.len(), 40);
        let mut multi_part = 0;
        for o in &set.objects {
            let m = &o.mesh;
            assert_eq!(m.triangle_materials.len(), m.triangles.len(), "{}", o.name);
            assert_eq!(m.normals.len(), m.positions.len());
            assert_eq!(m.uvs.len(), m.positions.len());
            assert!(m.triangle_materials.iter().all(|&i| (i as usize) < m.materials.len()));
            assert!((0.04..0.4).contains(&o.diameter), "{}: diameter {} m", o.name, o.diameter);
            let centre = (o.bbox_min.coords + o.bbox_max.coords) / 2.0;
            assert!(centre.norm() < 1e-4, "{}: bbox centre {centre:?}", o.name);
            multi_part += usize::from(m.materials.len() > 1);
        }
        assert!(multi_part >= 24, "most objects have parts attached: {multi_part} of 40");
    }
}
