//! Writes BOP model files `models/obj_NNNNNN.ply`: binary little-endian PLY
//! in millimetres with per-vertex normals and colours, as the BOP toolkit
//! reads them. Colours are the mesh's vertex colours, else the diffuse colour
//! of a triangle's material using the vertex (textures are not baked).

use std::io::Write;
use std::path::Path;

use super::BopError;
use super::error::io_err;
use crate::Mesh;

fn srgb8(linear: f32) -> u8 {
    let c = linear.clamp(0.0, 1.0);
    let s = if c <= 0.003_130_8 { 12.92 * c } else { 1.055 * c.powf(1.0 / 2.4) - 0.055 };
    (s * 255.0).round() as u8
}

fn vertex_colours(mesh: &Mesh) -> Vec<[u8; 3]> {
    if mesh.colors.len() == mesh.positions.len() {
        return mesh.colors.clone();
    }
    let mut out = vec![[128u8; 3]; mesh.positions.len()];
    for (t, tri) in mesh.triangles.iter().enumerate() {
        let m = mesh.triangle_materials.get(t).copied().unwrap_or(0) as usize;
        if let Some(mat) = mesh.materials.get(m) {
            let c = mat.diffuse.map(srgb8);
            for &i in tri {
                if let Some(v) = out.get_mut(i as usize) {
                    *v = c;
                }
            }
        }
    }
    out
}

/// Writes `mesh` (metres) to `path` as a BOP PLY model in millimetres.
pub(crate) fn write_model_ply(path: &Path, mesh: &Mesh) -> Result<(), BopError> {
    let has_normals = mesh.normals.len() == mesh.positions.len();
    let colours = vertex_colours(mesh);
    let mut buf = Vec::with_capacity(64 + mesh.positions.len() * 27 + mesh.triangles.len() * 13);
    let mut header = String::from("ply\nformat binary_little_endian 1.0\ncomment written by fusepose (units: mm)\n");
    header +=
        &format!("element vertex {}\nproperty float x\nproperty float y\nproperty float z\n", mesh.positions.len());
    if has_normals {
        header += "property float nx\nproperty float ny\nproperty float nz\n";
    }
    header += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
    header += &format!("element face {}\nproperty list uchar int vertex_indices\nend_header\n", mesh.triangles.len());
    buf.extend_from_slice(header.as_bytes());
    for (i, p) in mesh.positions.iter().enumerate() {
        for c in p {
            buf.extend_from_slice(&(c * 1000.0).to_le_bytes());
        }
        if has_normals {
            for c in &mesh.normals[i] {
                buf.extend_from_slice(&c.to_le_bytes());
            }
        }
        buf.extend_from_slice(&colours[i]);
    }
    for t in &mesh.triangles {
        buf.push(3);
        for &i in t {
            buf.extend_from_slice(&(i as i32).to_le_bytes());
        }
    }
    let mut f = std::fs::File::create(path).map_err(io_err(path))?;
    f.write_all(&buf).map_err(io_err(path))
}
