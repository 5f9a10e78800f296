//! What an object model precomputes from its mesh: validation, smooth vertex
//! normals, surface area, area-weighted surface samples, the diameter and the
//! axis-aligned bounding box. All lengths in metres (object frame).

use nalgebra::{Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

use crate::model::{Mesh, ObjectModel, Symmetry};

/// Surface samples every [`ObjectModel`] carries (used by ADD/ADD-S and the losses).
pub const SURFACE_SAMPLES: usize = 2000;

/// Seed of the surface sampler: the samples of a mesh are the same on every run.
pub const SURFACE_SAMPLE_SEED: u64 = 0x5eed_f05e;

/// Why a mesh cannot become an object model.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SurfaceError {
    #[error("mesh has no triangles")]
    NoTriangles,
    #[error("triangle {triangle} refers to vertex {index}, but the mesh has {vertices} vertices")]
    IndexOutOfRange { triangle: usize, index: u32, vertices: usize },
    #[error("vertex {0} has a non-finite coordinate")]
    NonFinitePosition(usize),
    #[error("per-vertex {attribute} has {len} entries for {vertices} vertices (must be 0 or equal)")]
    AttributeLength { attribute: &'static str, len: usize, vertices: usize },
    #[error("triangle_materials has {len} entries for {triangles} triangles (must be 0 or equal)")]
    MaterialListLength { len: usize, triangles: usize },
    #[error("triangle {triangle} uses material {material}, but the mesh has {materials} materials")]
    MaterialOutOfRange { triangle: usize, material: u32, materials: usize },
    #[error("texture of material {material} is {width}x{height} but holds {len} bytes (expected w*h*3)")]
    TextureSize { material: usize, width: u32, height: u32, len: usize },
    #[error("mesh surface area is zero")]
    ZeroArea,
}

/// Checks that indices, attribute lengths, materials and textures are consistent
/// and positions finite, so renderers and samplers can index without checks.
pub fn validate_mesh(mesh: &Mesh) -> Result<(), SurfaceError> {
    let n = mesh.positions.len();
    if mesh.triangles.is_empty() {
        return Err(SurfaceError::NoTriangles);
    }
    for (attribute, len) in [("normals", mesh.normals.len()), ("uvs", mesh.uvs.len()), ("colors", mesh.colors.len())] {
        if len != 0 && len != n {
            return Err(SurfaceError::AttributeLength { attribute, len, vertices: n });
        }
    }
    if let Some(i) = mesh.positions.iter().position(|p| p.iter().any(|c| !c.is_finite())) {
        return Err(SurfaceError::NonFinitePosition(i));
    }
    for (t, tri) in mesh.triangles.iter().enumerate() {
        if let Some(&index) = tri.iter().find(|&&i| i as usize >= n) {
            return Err(SurfaceError::IndexOutOfRange { triangle: t, index, vertices: n });
        }
    }
    let tm = &mesh.triangle_materials;
    if !tm.is_empty() {
        if tm.len() != mesh.triangles.len() {
            return Err(SurfaceError::MaterialListLength { len: tm.len(), triangles: mesh.triangles.len() });
        }
        if let Some((t, &material)) = tm.iter().enumerate().find(|(_, m)| **m as usize >= mesh.materials.len()) {
            return Err(SurfaceError::MaterialOutOfRange { triangle: t, material, materials: mesh.materials.len() });
        }
    }
    for (i, m) in mesh.materials.iter().enumerate() {
        if let Some(tex) = &m.texture
            && (tex.rgb.len() != tex.width as usize * tex.height as usize * 3 || tex.width == 0 || tex.height == 0)
        {
            return Err(SurfaceError::TextureSize {
                material: i,
                width: tex.width,
                height: tex.height,
                len: tex.rgb.len(),
            });
        }
    }
    Ok(())
}

fn point(p: [f32; 3]) -> Point3<f64> {
    Point3::new(p[0] as f64, p[1] as f64, p[2] as f64)
}

/// The three corners of a triangle (indices must be valid: see [`validate_mesh`]).
fn corners(mesh: &Mesh, tri: [u32; 3]) -> [Point3<f64>; 3] {
    tri.map(|i| point(mesh.positions[i as usize]))
}

/// Twice-area-weighted face normal (cross product of two edges), counter-clockwise winding.
fn face_cross(c: &[Point3<f64>; 3]) -> Vector3<f64> {
    (c[1] - c[0]).cross(&(c[2] - c[0]))
}

/// Smooth per-vertex normals: the area-weighted mean of the adjacent faces'
/// normals (counter-clockwise = front). Vertices without area get +z.
/// Out-of-range indices are skipped, never a panic.
pub fn compute_vertex_normals(mesh: &Mesh) -> Vec<[f32; 3]> {
    let n = mesh.positions.len();
    let mut acc = vec![Vector3::<f64>::zeros(); n];
    for tri in &mesh.triangles {
        if tri.iter().any(|&i| i as usize >= n) {
            continue;
        }
        let cross = face_cross(&corners(mesh, *tri));
        for &i in tri {
            acc[i as usize] += cross;
        }
    }
    acc.into_iter()
        .map(|v| {
            let len = v.norm();
            if len > 0.0 && len.is_finite() {
                let u = v / len;
                [u.x as f32, u.y as f32, u.z as f32]
            } else {
                [0.0, 0.0, 1.0]
            }
        })
        .collect()
}

/// Total triangle area (square metres). Indices must be valid.
pub fn surface_area(mesh: &Mesh) -> f64 {
    mesh.triangles.iter().map(|t| 0.5 * face_cross(&corners(mesh, *t)).norm()).sum()
}

/// `count` points drawn uniformly over the surface (area-weighted triangle
/// choice, uniform barycentric point), deterministic for a given `seed`.
pub fn sample_surface(mesh: &Mesh, count: usize, seed: u64) -> Result<Vec<Point3<f64>>, SurfaceError> {
    validate_mesh(mesh)?;
    let mut cumulative = Vec::with_capacity(mesh.triangles.len());
    let mut total = 0.0;
    for t in &mesh.triangles {
        total += 0.5 * face_cross(&corners(mesh, *t)).norm();
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
        let c = corners(mesh, mesh.triangles[k]);
        let (r1, r2): (f64, f64) = (rng.random(), rng.random());
        let s = r1.sqrt();
        let (a, b) = (1.0 - s, s * (1.0 - r2));
        let p = c[0].coords * a + c[1].coords * b + c[2].coords * (1.0 - a - b);
        out.push(Point3::from(p));
    }
    Ok(out)
}

/// Exact largest pairwise distance (metres). Pairs are pruned with the bound
/// `|p - q| <= |p - c| + |q - c|` around the centroid `c`, so large point sets
/// stay fast in practice.
pub fn diameter(points: &[Point3<f64>]) -> f64 {
    if points.len() < 2 {
        return 0.0;
    }
    let centroid = points.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / points.len() as f64;
    let mut by_radius: Vec<(f64, Point3<f64>)> = points.iter().map(|p| ((p.coords - centroid).norm(), *p)).collect();
    by_radius.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut best_sq = 0.0f64;
    for i in 0..by_radius.len() {
        let (ri, pi) = by_radius[i];
        if 2.0 * ri <= best_sq.sqrt() {
            break;
        }
        for &(rj, pj) in &by_radius[i + 1..] {
            if ri + rj <= best_sq.sqrt() {
                break;
            }
            best_sq = best_sq.max((pi - pj).norm_squared());
        }
    }
    best_sq.sqrt()
}

/// Axis-aligned bounding box of the vertices the triangles use (metres).
pub fn bounding_box(mesh: &Mesh) -> (Point3<f64>, Point3<f64>) {
    let mut lo = Point3::new(f64::INFINITY, f64::INFINITY, f64::INFINITY);
    let mut hi = Point3::new(f64::NEG_INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY);
    for p in used_vertices(mesh) {
        lo = lo.inf(&p);
        hi = hi.sup(&p);
    }
    (lo, hi)
}

/// Positions of vertices referenced by at least one triangle, each once.
fn used_vertices(mesh: &Mesh) -> Vec<Point3<f64>> {
    let mut used = vec![false; mesh.positions.len()];
    for t in &mesh.triangles {
        for &i in t {
            if let Some(u) = used.get_mut(i as usize) {
                *u = true;
            }
        }
    }
    mesh.positions.iter().zip(used).filter(|(_, u)| *u).map(|(p, _)| point(*p)).collect()
}

impl ObjectModel {
    /// Builds an object model: validates the mesh, fills in smooth normals when
    /// absent, and precomputes [`SURFACE_SAMPLES`] surface samples, the exact
    /// diameter (over the mesh vertices, which span the convex hull) and the bbox.
    /// The mesh keeps its own frame (no re-centring).
    pub fn from_mesh(name: impl Into<String>, mut mesh: Mesh, symmetry: Symmetry) -> Result<Self, SurfaceError> {
        validate_mesh(&mesh)?;
        if mesh.normals.is_empty() {
            mesh.normals = compute_vertex_normals(&mesh);
        }
        let samples = sample_surface(&mesh, SURFACE_SAMPLES, SURFACE_SAMPLE_SEED)?;
        let diameter = diameter(&used_vertices(&mesh));
        let (bbox_min, bbox_max) = bounding_box(&mesh);
        let shadow_mesh = crate::shadow_mesh::shadow_mesh(&mesh, diameter / crate::shadow_mesh::CELLS_PER_DIAMETER);
        Ok(ObjectModel { name: name.into(), mesh, symmetry, samples, diameter, bbox_min, bbox_max, shadow_mesh })
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A closed axis-aligned box centred at the origin, 8 shared vertices, outward CCW faces.
    pub(crate) fn box_mesh(size: [f32; 3]) -> Mesh {
        let [hx, hy, hz] = size.map(|s| s / 2.0);
        let positions = vec![
            [-hx, -hy, -hz],
            [hx, -hy, -hz],
            [hx, hy, -hz],
            [-hx, hy, -hz],
            [-hx, -hy, hz],
            [hx, -hy, hz],
            [hx, hy, hz],
            [-hx, hy, hz],
        ];
        let triangles = vec![
            [0, 2, 1],
            [0, 3, 2], // -z
            [4, 5, 6],
            [4, 6, 7], // +z
            [0, 1, 5],
            [0, 5, 4], // -y
            [2, 3, 7],
            [2, 7, 6], // +y
            [1, 2, 6],
            [1, 6, 5], // +x
            [0, 4, 7],
            [0, 7, 3], // -x
        ];
        Mesh { positions, triangles, ..Default::default() }
    }

    #[test]
    fn unit_cube_samples_lie_on_faces() {
        let model = ObjectModel::from_mesh("cube", box_mesh([1.0, 1.0, 1.0]), Symmetry::None).unwrap();
        assert_eq!(model.samples.len(), SURFACE_SAMPLES);
        for p in &model.samples {
            let on_face = p.coords.iter().any(|c| (c.abs() - 0.5).abs() < 1e-9);
            let inside = p.coords.iter().all(|c| c.abs() <= 0.5 + 1e-9);
            assert!(on_face && inside, "{p} is not on the cube surface");
        }
        // Area-weighted: every face gets about 1/6 of the samples.
        let on_top = model.samples.iter().filter(|p| (p.z - 0.5).abs() < 1e-9).count();
        assert!((250..420).contains(&on_top), "top face got {on_top} of 2000");
    }

    #[test]
    fn samples_are_deterministic() {
        let a = sample_surface(&box_mesh([0.1, 0.2, 0.3]), 50, 7).unwrap();
        let b = sample_surface(&box_mesh([0.1, 0.2, 0.3]), 50, 7).unwrap();
        assert_eq!(a, b);
    }

    #[test]
    fn box_diameter_and_bbox_are_exact() {
        let model = ObjectModel::from_mesh("box", box_mesh([0.16, 0.06, 0.21]), Symmetry::None).unwrap();
        let expected = (0.16f64.powi(2) + 0.06f64.powi(2) + 0.21f64.powi(2)).sqrt();
        assert!((model.diameter - expected).abs() < 1e-6, "{} vs {expected}", model.diameter);
        assert!((model.bbox_max.x - 0.08).abs() < 1e-7 && (model.bbox_min.z + 0.105).abs() < 1e-7);
    }

    #[test]
    fn diameter_matches_brute_force() {
        let pts = sample_surface(&box_mesh([0.3, 0.1, 0.05]), 400, 3).unwrap();
        let mut brute = 0.0f64;
        for a in &pts {
            for b in &pts {
                brute = brute.max((a - b).norm());
            }
        }
        assert!((diameter(&pts) - brute).abs() < 1e-12);
    }

    #[test]
    fn generated_normals_point_outward_on_a_closed_box() {
        let mesh = box_mesh([1.0, 2.0, 3.0]);
        let normals = compute_vertex_normals(&mesh);
        for (p, n) in mesh.positions.iter().zip(&normals) {
            let dot: f32 = p.iter().zip(n).map(|(a, b)| a * b).sum();
            assert!(dot > 0.0);
            assert!((n.iter().map(|c| c * c).sum::<f32>() - 1.0).abs() < 1e-5);
        }
    }

    #[test]
    fn bad_meshes_are_errors_not_panics() {
        let mut m = box_mesh([1.0, 1.0, 1.0]);
        m.triangles.push([0, 1, 99]);
        assert!(matches!(validate_mesh(&m), Err(SurfaceError::IndexOutOfRange { index: 99, .. })));
        assert_eq!(validate_mesh(&Mesh::default()), Err(SurfaceError::NoTriangles));
        let mut flat = box_mesh([1.0, 1.0, 1.0]);
        flat.positions.iter_mut().for_each(|p| *p = [0.0; 3]);
        assert!(matches!(ObjectModel::from_mesh("f", flat, Symmetry::None), Err(SurfaceError::ZeroArea)));
        let mut nan = box_mesh([1.0, 1.0, 1.0]);
        nan.positions[3][1] = f32::NAN;
        assert_eq!(validate_mesh(&nan), Err(SurfaceError::NonFinitePosition(3)));
    }
}
