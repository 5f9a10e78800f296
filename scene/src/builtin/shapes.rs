//! Procedural mesh parts for the built-in objects (metres): UV-mapped grids
//! that make box faces, surfaces of revolution and tube arcs, assembled into
//! one single-material mesh whose origin is its bounding-box centre.

use std::f64::consts::TAU;

use nalgebra::{Point3, Vector3};

use super::paint::UvRect;
use crate::model::{Material, Mesh, Texture};
use crate::surface::compute_vertex_normals;

/// One smooth-shaded part: its own vertices, so edges between parts are sharp.
struct Part {
    positions: Vec<[f32; 3]>,
    uvs: Vec<[f32; 2]>,
    triangles: Vec<[u32; 3]>,
    normals: Vec<[f32; 3]>,
}

/// Collects parts into one mesh.
#[derive(Default)]
pub(crate) struct Assembly {
    parts: Vec<Part>,
}

fn p32(p: Point3<f64>) -> [f32; 3] {
    [p.x as f32, p.y as f32, p.z as f32]
}

impl Assembly {
    /// A `(rows+1) x (cols+1)` vertex grid; `at(i, j)` gives vertex (row i,
    /// column j) and its UV. Front faces are where `d/dcol x d/drow` points.
    /// `wrap_cols`: column `cols` coincides with column 0 (seam normals are
    /// averaged so shading has no seam). Degenerate triangles are dropped.
    pub(crate) fn grid(
        &mut self,
        rows: usize,
        cols: usize,
        wrap_cols: bool,
        at: impl Fn(usize, usize) -> (Point3<f64>, [f64; 2]),
    ) {
        let idx = |i: usize, j: usize| (i * (cols + 1) + j) as u32;
        let mut points = Vec::new();
        let mut uvs = Vec::new();
        for i in 0..=rows {
            for j in 0..=cols {
                let (p, uv) = at(i, j);
                points.push(p);
                uvs.push([uv[0] as f32, uv[1] as f32]);
            }
        }
        let mut triangles = Vec::new();
        for i in 0..rows {
            for j in 0..cols {
                let (a, b, c, d) = (idx(i, j), idx(i, j + 1), idx(i + 1, j + 1), idx(i + 1, j));
                for tri in [[a, b, c], [a, c, d]] {
                    let [p, q, r] = tri.map(|k| points[k as usize]);
                    if (q - p).cross(&(r - p)).norm() > 1e-12 {
                        triangles.push(tri);
                    }
                }
            }
        }
        let mut part =
            Part { positions: points.iter().map(|p| p32(*p)).collect(), uvs, triangles, normals: Vec::new() };
        let mesh = Mesh { positions: part.positions.clone(), triangles: part.triangles.clone(), ..Default::default() };
        part.normals = compute_vertex_normals(&mesh);
        if wrap_cols {
            for i in 0..=rows {
                let (first, last) = (idx(i, 0) as usize, idx(i, cols) as usize);
                let sum = Vector3::from(part.normals[first]) + Vector3::from(part.normals[last]);
                if sum.norm() > 0.0 {
                    let n = sum.normalize();
                    part.normals[first] = [n.x, n.y, n.z];
                    part.normals[last] = [n.x, n.y, n.z];
                }
            }
        }
        self.parts.push(part);
    }

    /// One flat rectangular face of half extents `(hu, hv)` centred at
    /// `centre`, spanned by unit axes `u_axis`, `v_axis` (front = `u x v`),
    /// mapped onto `uv` (u along `u_axis`, v along `v_axis`).
    pub(crate) fn face(
        &mut self,
        centre: Point3<f64>,
        u_axis: Vector3<f64>,
        v_axis: Vector3<f64>,
        half: (f64, f64),
        uv: UvRect,
    ) {
        self.grid(1, 1, false, |i, j| {
            let (s, t) = (j as f64, i as f64);
            let p = centre + u_axis * (2.0 * s - 1.0) * half.0 + v_axis * (2.0 * t - 1.0) * half.1;
            (p, [uv[0] + s * (uv[2] - uv[0]), uv[1] + t * (uv[3] - uv[1])])
        });
    }

    /// A closed box of full `size` centred at the origin. `faces` gives the UV
    /// rect of the +x, -x, +y, -y, +z, -z faces. Side faces have v along +z
    /// and u running counter-clockwise seen from above; +z/-z have v along +y.
    pub(crate) fn cuboid(&mut self, size: [f64; 3], faces: [UvRect; 6]) {
        let h = size.map(|s| s / 2.0);
        let (x, y, z) = (Vector3::x(), Vector3::y(), Vector3::z());
        let specs = [
            (x, z, h[0], h[1], h[2]),
            (-x, z, h[0], h[1], h[2]),
            (y, z, h[1], h[0], h[2]),
            (-y, z, h[1], h[0], h[2]),
            (z, y, h[2], h[0], h[1]),
            (-z, y, h[2], h[0], h[1]),
        ];
        for ((n, v_axis, depth, hu, hv), uv) in specs.into_iter().zip(faces) {
            let u_axis = v_axis.cross(&n);
            self.face(Point3::from(n * depth), u_axis, v_axis, (hu, hv), uv);
        }
    }

    /// A surface of revolution about +z: `profile` is a polyline of rings
    /// `(radius_x, radius_y, z)` (elliptic rings when the radii differ).
    /// Front faces are on the left of the profile direction in the (r, z)
    /// half-plane: upward = outward, inward along a top = up. u follows the
    /// angle from +x counter-clockwise (seen from +z), v the profile's arc length.
    pub(crate) fn lathe(&mut self, profile: &[(f64, f64, f64)], segments: usize, uv: UvRect) {
        let mut arc = vec![0.0];
        for w in profile.windows(2) {
            let d = ((w[1].0 - w[0].0).powi(2) + (w[1].2 - w[0].2).powi(2)).sqrt();
            arc.push(arc.last().copied().unwrap_or(0.0) + d);
        }
        let total = arc.last().copied().unwrap_or(1.0).max(1e-12);
        self.grid(profile.len().saturating_sub(1), segments, true, |i, j| {
            let (rx, ry, z) = profile[i];
            let s = j as f64 / segments as f64;
            let a = TAU * s;
            let t = arc[i] / total;
            (Point3::new(rx * a.cos(), ry * a.sin(), z), [uv[0] + s * (uv[2] - uv[0]), uv[1] + t * (uv[3] - uv[1])])
        });
    }

    /// A tube of radius `minor` around the arc `centre + major (cos phi, 0, sin phi)`
    /// in the x-z plane for `phi` in `phi_range`; open ends.
    pub(crate) fn tube_arc(
        &mut self,
        centre: Point3<f64>,
        major: f64,
        minor: f64,
        phi_range: (f64, f64),
        segments: (usize, usize),
        uv: UvRect,
    ) {
        let (along, around) = segments;
        self.grid(along, around, true, |i, j| {
            let phi = phi_range.0 + (phi_range.1 - phi_range.0) * i as f64 / along as f64;
            let psi = TAU * j as f64 / around as f64;
            let radial = Vector3::new(phi.cos(), 0.0, phi.sin());
            let p = centre + radial * major + (radial * psi.cos() + Vector3::y() * psi.sin()) * minor;
            let (s, t) = (j as f64 / around as f64, i as f64 / along as f64);
            (p, [uv[0] + s * (uv[2] - uv[0]), uv[1] + t * (uv[3] - uv[1])])
        });
    }

    /// Adds the parts of `other`, translated by `offset` (metres).
    pub(crate) fn append_shifted(&mut self, other: Assembly, offset: Vector3<f64>) {
        for mut part in other.parts {
            for p in &mut part.positions {
                *p = [p[0] + offset.x as f32, p[1] + offset.y as f32, p[2] + offset.z as f32];
            }
            self.parts.push(part);
        }
    }

    /// The assembled mesh, moved so its bounding-box centre is the origin,
    /// with one textured material and no unreferenced vertices.
    pub(crate) fn finish(self, material_name: &str, diffuse: [f32; 3], texture: Texture) -> Mesh {
        let mut mesh = Mesh::default();
        for part in self.parts {
            let mut remap = vec![u32::MAX; part.positions.len()];
            for tri in &part.triangles {
                let mut out = [0u32; 3];
                for (k, &v) in tri.iter().enumerate() {
                    let v = v as usize;
                    if remap[v] == u32::MAX {
                        remap[v] = mesh.positions.len() as u32;
                        mesh.positions.push(part.positions[v]);
                        mesh.uvs.push(part.uvs[v]);
                        mesh.normals.push(part.normals[v]);
                    }
                    out[k] = remap[v];
                }
                mesh.triangles.push(out);
            }
        }
        let (lo, hi) = mesh.positions.iter().fold(([f32::MAX; 3], [f32::MIN; 3]), |(lo, hi), p| {
            (std::array::from_fn(|k| lo[k].min(p[k])), std::array::from_fn(|k| hi[k].max(p[k])))
        });
        let centre: [f32; 3] = std::array::from_fn(|k| (lo[k] + hi[k]) / 2.0);
        for p in &mut mesh.positions {
            *p = std::array::from_fn(|k| p[k] - centre[k]);
        }
        mesh.materials = vec![Material { name: material_name.into(), diffuse, texture: Some(texture) }];
        mesh
    }
}
