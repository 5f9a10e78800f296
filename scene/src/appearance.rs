//! Coloured surface samples: where an object's surface is, which way it faces
//! and what colour it is there (the albedo the renderer shades: texture texel,
//! else vertex colour, else material diffuse; linear RGB 0..1). The estimator
//! uses them to tell apart poses that geometry alone cannot (a box turned by
//! 180°, a can turned about its axis). Object frame, metres.

use nalgebra::{Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

use crate::model::{Mesh, Texture};
use crate::surface::{SurfaceError, validate_mesh};

/// One coloured surface sample (object frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AppearanceSample {
    /// Metres.
    pub position: Point3<f32>,
    /// Unit outward face normal.
    pub normal: Vector3<f32>,
    /// Linear RGB albedo, 0..1.
    pub albedo: [f32; 3],
}

/// sRGB byte → linear 0..1 (the renderer's decoding).
pub fn srgb_to_linear(c: u8) -> f32 {
    let c = c as f32 / 255.0;
    if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }
}

/// The texel nearest to `(u, v)` (v up, wrapped like the renderer), linear RGB.
fn texel(tex: &Texture, u: f32, v: f32) -> [f32; 3] {
    let (w, h) = (tex.width as usize, tex.height as usize);
    let fu = u - u.floor();
    let fv = 1.0 - (v - v.floor());
    let x = ((fu * w as f32) as usize).min(w - 1);
    let y = ((fv * h as f32) as usize).min(h - 1);
    let i = (y * w + x) * 3;
    [srgb_to_linear(tex.rgb[i]), srgb_to_linear(tex.rgb[i + 1]), srgb_to_linear(tex.rgb[i + 2])]
}

/// `count` coloured samples drawn uniformly over the surface (area-weighted
/// triangle choice, uniform barycentric point), deterministic for `seed`.
/// Degenerate (zero-area) triangles are never drawn.
pub fn sample_appearance(mesh: &Mesh, count: usize, seed: u64) -> Result<Vec<AppearanceSample>, SurfaceError> {
    validate_mesh(mesh)?;
    let p = |i: u32| Vector3::from(mesh.positions[i as usize]).cast::<f64>();
    let mut cumulative = Vec::with_capacity(mesh.triangles.len());
    let mut total = 0.0;
    for t in &mesh.triangles {
        total += 0.5 * (p(t[1]) - p(t[0])).cross(&(p(t[2]) - p(t[0]))).norm();
        cumulative.push(total);
    }
    if !total.is_finite() || total <= 0.0 {
        return Err(SurfaceError::ZeroArea);
    }
    let mut rng = Pcg64::seed_from_u64(seed);
    let mut out = Vec::with_capacity(count);
    for _ in 0..count {
        let target = rng.random::<f64>() * total;
        let k = cumulative.partition_point(|&c| c <= target).min(cumulative.len() - 1);
        let tri = mesh.triangles[k];
        let (r1, r2): (f64, f64) = (rng.random(), rng.random());
        let s = r1.sqrt();
        let w = [1.0 - s, s * (1.0 - r2), s * r2];
        let pos = p(tri[0]) * w[0] + p(tri[1]) * w[1] + p(tri[2]) * w[2];
        let normal = (p(tri[1]) - p(tri[0])).cross(&(p(tri[2]) - p(tri[0]))).normalize();
        let material = mesh
            .materials
            .get(mesh.triangle_materials.get(k).copied().unwrap_or(0) as usize);
        let texture = material.and_then(|m| m.texture.as_ref());
        let albedo = match texture {
            Some(tex) if !mesh.uvs.is_empty() => {
                let uv = |c: usize| mesh.uvs[tri[0] as usize][c] as f64 * w[0]
                    + mesh.uvs[tri[1] as usize][c] as f64 * w[1]
                    + mesh.uvs[tri[2] as usize][c] as f64 * w[2];
                texel(tex, uv(0) as f32, uv(1) as f32)
            }
            _ if !mesh.colors.is_empty() => {
                let c = |ch: usize| {
                    tri.iter()
                        .zip(w)
                        .map(|(&vi, wi)| srgb_to_linear(mesh.colors[vi as usize][ch]) as f64 * wi)
                        .sum::<f64>() as f32
                };
                [c(0), c(1), c(2)]
            }
            _ => material.map_or([0.5; 3], |m| m.diffuse),
        };
        out.push(AppearanceSample {
            position: Point3::from(pos.cast::<f32>()),
            normal: normal.cast::<f32>(),
            albedo,
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::builtin::builtin_objects;

    #[test]
    fn samples_lie_on_the_surface_with_outward_normals_and_texture_colours() {
        let set = builtin_objects();
        let cracker = &set.objects[0];
        let s = sample_appearance(&cracker.mesh, 3000, 1).unwrap();
        assert_eq!(s.len(), 3000);
        // The box is 0.16 x 0.06 x 0.21 centred at the origin: every sample
        // sits on one face, and the normal points out of that face.
        let half = [0.08f32, 0.03, 0.105];
        for a in &s {
            let i = a.normal.iamax();
            assert!((a.normal[i].abs() - 1.0).abs() < 1e-5, "{a:?}");
            assert!((a.position[i] - a.normal[i] * half[i]).abs() < 1e-5, "{a:?}");
            assert!((0..3).all(|j| a.position[j].abs() <= half[j] + 1e-5), "{a:?}");
        }
        // The front (-y) carries a yellow band, the back (+y) none: mostly red
        // with white and black; yellow (high R and G, low B) shows up on -y.
        let yellow = |c: &[f32; 3]| c[0] > 0.7 && c[1] > 0.45 && c[2] < 0.1;
        let front = s.iter().filter(|a| a.normal.y < -0.9).filter(|a| yellow(&a.albedo)).count();
        let back = s.iter().filter(|a| a.normal.y > 0.9).filter(|a| yellow(&a.albedo)).count();
        assert!(front > 50 && front > 2 * back, "front {front} back {back}");
    }

    #[test]
    fn vertex_colours_and_plain_materials_give_their_colour() {
        let mut mesh = crate::surface::tests::box_mesh([0.1, 0.1, 0.1]);
        mesh.colors = vec![[255, 0, 0]; mesh.positions.len()];
        let s = sample_appearance(&mesh, 10, 2).unwrap();
        assert!(s.iter().all(|a| (a.albedo[0] - 1.0).abs() < 1e-6 && a.albedo[1] == 0.0));
        mesh.colors.clear();
        let s = sample_appearance(&mesh, 10, 2).unwrap();
        assert!(s.iter().all(|a| a.albedo == [0.5; 3]), "no material: mid grey");
    }
}
