//! A coarse copy of an object's mesh for its shadow maps.
//!
//! A shadow map needs where an object blocks light, not its 15 000
//! triangles: at a training frame's map resolution most of a scanned mesh's
//! triangles cover less than a texel, and rasterising them once per light is
//! the largest cost of a randomised training frame. Vertex clustering on a
//! grid of [`CELLS_PER_DIAMETER`] cells across the object merges the vertices
//! in each cell into their mean and drops the triangles that collapse; the
//! silhouette moves by less than a cell (≈ 2 % of the object's size).

use std::collections::HashMap;

use crate::model::Mesh;

/// Grid cells across the object's diameter.
pub const CELLS_PER_DIAMETER: f64 = 48.0;

/// A coarse copy is only kept when it has at most this share of the
/// original's triangles (small meshes cast their own shadows).
const MAX_KEPT_SHARE: f64 = 0.5;

/// Positions and triangles of `mesh` clustered on a grid of `cell_m`
/// metres, or `None` when that does not halve the triangle count (or the cell
/// is not a positive size). The copy has no normals, uvs, colours or materials:
/// shadow maps use none.
pub fn shadow_mesh(mesh: &Mesh, cell_m: f64) -> Option<Mesh> {
    if !(cell_m.is_finite() && cell_m > 0.0) || mesh.triangles.is_empty() {
        return None;
    }
    let cell_of = |p: &[f32; 3]| p.map(|c| (c as f64 / cell_m).floor() as i64);
    // Cluster id per vertex, and each cluster's position sum and count.
    let mut ids: HashMap<[i64; 3], u32> = HashMap::new();
    let mut sums: Vec<([f64; 3], u32)> = Vec::new();
    let cluster: Vec<u32> = mesh
        .positions
        .iter()
        .map(|p| {
            let id = *ids.entry(cell_of(p)).or_insert_with(|| {
                sums.push(([0.0; 3], 0));
                (sums.len() - 1) as u32
            });
            let (s, n) = &mut sums[id as usize];
            for j in 0..3 {
                s[j] += p[j] as f64;
            }
            *n += 1;
            id
        })
        .collect();
    let mut seen = std::collections::HashSet::new();
    let mut triangles = Vec::new();
    for t in &mesh.triangles {
        let c = t.map(|i| cluster[i as usize]);
        if c[0] == c[1] || c[1] == c[2] || c[0] == c[2] {
            continue;
        }
        // One copy of each triangle (same vertices in the same winding).
        let r = (0..3).min_by_key(|&i| c[i]).unwrap_or(0);
        let key = [c[r], c[(r + 1) % 3], c[(r + 2) % 3]];
        if seen.insert(key) {
            triangles.push(c);
        }
    }
    if triangles.len() as f64 > MAX_KEPT_SHARE * mesh.triangles.len() as f64 || triangles.is_empty() {
        return None;
    }
    let positions = sums.iter().map(|(s, n)| s.map(|v| (v / *n as f64) as f32)).collect();
    Some(Mesh { positions, triangles, ..Mesh::default() })
}

/// A UV sphere of `radius` metres with `n` rings and `2n` segments (tests).
#[cfg(test)]
pub(crate) fn sphere(n: usize, radius: f32) -> Mesh {
    let mut positions = Vec::new();
    for i in 0..=n {
        let th = std::f32::consts::PI * i as f32 / n as f32;
        for j in 0..2 * n {
            let ph = std::f32::consts::PI * j as f32 / n as f32;
            positions.push([radius * th.sin() * ph.cos(), radius * th.sin() * ph.sin(), radius * th.cos()]);
        }
    }
    let at = |i: usize, j: usize| (i * 2 * n + j % (2 * n)) as u32;
    let mut triangles = Vec::new();
    for i in 0..n {
        for j in 0..2 * n {
            triangles.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            triangles.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    Mesh { positions, triangles, ..Mesh::default() }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fine_mesh_keeps_its_shape_with_far_fewer_triangles() {
        let fine = sphere(160, 0.05);
        let cell = 0.1 / CELLS_PER_DIAMETER;
        let coarse = shadow_mesh(&fine, cell).expect("a 102 400-triangle sphere is worth a coarse copy");
        assert!(coarse.triangles.len() * 4 < fine.triangles.len(), "{} triangles", coarse.triangles.len());
        // Every vertex stays on the sphere within a cell, and the extent is kept.
        for p in &coarse.positions {
            let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() as f64;
            assert!((r - 0.05).abs() < cell, "vertex at radius {r}");
        }
        let max_x = coarse.positions.iter().map(|p| p[0]).fold(f32::MIN, f32::max) as f64;
        assert!((max_x - 0.05).abs() < cell, "extent {max_x}");
        // Indices are valid and no triangle is degenerate.
        for t in &coarse.triangles {
            assert!(t.iter().all(|&i| (i as usize) < coarse.positions.len()));
            assert!(t[0] != t[1] && t[1] != t[2] && t[0] != t[2]);
        }
    }

    #[test]
    fn a_coarse_mesh_is_left_as_it_is() {
        assert!(shadow_mesh(&sphere(6, 0.05), 0.1 / CELLS_PER_DIAMETER).is_none());
        assert!(shadow_mesh(&sphere(80, 0.05), 0.0).is_none());
        assert!(shadow_mesh(&sphere(80, 0.05), f64::NAN).is_none());
    }
}
