//! Wavefront OBJ + MTL loading through `tobj`: triangulated, one index per
//! vertex, diffuse colours and `map_Kd` textures (PNG/JPEG), vertex colours,
//! normals and UVs; one material index per triangle.
//!
//! As the MTL specification says, the diffuse texture is multiplied by `Kd`:
//! the loaded texture holds `Kd × texel` (in linear light), so a mesh looks as
//! it does in other tools. A material without `Kd` multiplies by 1.

use std::collections::HashMap;
use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};

use super::checks::TextureIssue;
use super::{MeshError, read_texture};
use crate::model::{Material, Mesh, Texture};

/// Grey used when a mesh has no usable material (linear RGB).
pub(crate) const DEFAULT_DIFFUSE: [f32; 3] = [0.6, 0.6, 0.6];

/// A `BufRead` that counts the lines its consumer has taken, so parse errors
/// can name a line even though `tobj` does not.
struct LineCounter<R> {
    inner: BufReader<R>,
    newlines: usize,
    last_byte: Option<u8>,
}

impl<R: Read> Read for LineCounter<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.newlines += buf[..n].iter().filter(|&&b| b == b'\n').count();
        if n > 0 {
            self.last_byte = Some(buf[n - 1]);
        }
        Ok(n)
    }
}

impl<R: Read> BufRead for LineCounter<R> {
    fn fill_buf(&mut self) -> std::io::Result<&[u8]> {
        self.inner.fill_buf()
    }
    fn consume(&mut self, amt: usize) {
        let taken = &self.inner.buffer()[..amt.min(self.inner.buffer().len())];
        self.newlines += taken.iter().filter(|&&b| b == b'\n').count();
        if let Some(&b) = taken.last() {
            self.last_byte = Some(b);
        }
        self.inner.consume(amt);
    }
}

impl<R> LineCounter<R> {
    /// 1-based number of the line being parsed when the consumer stopped.
    fn current_line(&self) -> usize {
        self.newlines + usize::from(self.last_byte != Some(b'\n'))
    }
}

/// Errors `tobj` raises while parsing one line (others arise after the last
/// line, when faces are assembled, and have no meaningful line).
fn is_line_error(e: &tobj::LoadError) -> bool {
    use tobj::LoadError::*;
    matches!(
        e,
        UnrecognizedCharacter
            | PositionParseError
            | ScalingByZeroError
            | ColorParseError
            | NormalParseError
            | TexcoordParseError
            | FaceParseError
            | InvalidObjectName
            | InvalidPolygon
    )
}

/// The mesh and the textures its MTL names that could not be used.
pub(super) fn load_obj(path: &Path) -> Result<(Mesh, Vec<TextureIssue>), MeshError> {
    let file = File::open(path).map_err(|error| MeshError::Io { path: path.to_owned(), error })?;
    let mut reader = LineCounter { inner: BufReader::new(file), newlines: 0, last_byte: None };
    let dir = path.parent().map(Path::to_owned).unwrap_or_default();
    // Triangulated, one index per vertex, points and lines dropped.
    let options = tobj::GPU_LOAD_OPTIONS;
    // tobj's materials do not say which MTL they came from: remember the libraries.
    let mtl_files = std::cell::RefCell::new(Vec::new());
    let (models, materials) = tobj::load_obj_buf(&mut reader, &options, |mtl| {
        mtl_files.borrow_mut().push(dir.join(mtl));
        tobj::load_mtl(dir.join(mtl))
    })
    .map_err(|e| MeshError::Parse {
        path: path.to_owned(),
        line: is_line_error(&e).then(|| reader.current_line()),
        message: format!("OBJ {e}"),
    })?;
    let tobj_materials = materials.unwrap_or_else(|e| {
        tracing::warn!("{}: material library unusable ({e}); using plain grey", path.display());
        Vec::new()
    });
    let mtl = mtl_files.into_inner().iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ");
    let (mut materials, issues) = convert_materials(Path::new(&mtl), &dir, &tobj_materials);
    Ok((assemble(path, &models, &mut materials)?, issues))
}

/// Materials, and the textures they name that are missing or do not decode.
fn convert_materials(mtl: &Path, dir: &Path, mats: &[tobj::Material]) -> (Vec<Material>, Vec<TextureIssue>) {
    let mut cache: HashMap<PathBuf, Option<Texture>> = HashMap::new();
    let mut issues: Vec<TextureIssue> = Vec::new();
    let out = mats
        .iter()
        .map(|m| {
            let texture = m.diffuse_texture.as_deref().filter(|t| !t.trim().is_empty()).and_then(|name| {
                let file = texture_path(dir, name);
                cache
                    .entry(file.clone())
                    .or_insert_with(|| match read_texture(&file) {
                        Ok(t) => Some(t),
                        Err(e) => {
                            issues.push(TextureIssue {
                                named_in: mtl.to_owned(),
                                missing: !file.exists(),
                                texture: file.clone(),
                                reason: e.to_string(),
                            });
                            None
                        }
                    })
                    .clone()
            });
            // map_Kd is multiplied by Kd (white when Kd is absent).
            let texture = match (texture, m.diffuse) {
                (Some(t), Some(kd)) if kd != [1.0; 3] => Some(tint_texture(&t, kd)),
                (t, _) => t,
            };
            Material { name: m.name.clone(), diffuse: m.diffuse.unwrap_or(DEFAULT_DIFFUSE), texture }
        })
        .collect();
    (out, issues)
}

/// sRGB byte → linear 0..1.
fn srgb_decode(c: u8) -> f32 {
    let c = c as f32 / 255.0;
    if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }
}

/// Linear 0..1 → sRGB byte.
fn srgb_encode(l: f32) -> u8 {
    let l = l.clamp(0.0, 1.0);
    let c = if l <= 0.003_130_8 { l * 12.92 } else { 1.055 * l.powf(1.0 / 2.4) - 0.055 };
    (c * 255.0).round() as u8
}

/// The texture multiplied by a linear colour `kd` (per channel, in linear light).
pub(crate) fn tint_texture(t: &Texture, kd: [f32; 3]) -> Texture {
    // One table per channel: 256 entries instead of a powf per texel.
    let lut: [[u8; 256]; 3] =
        std::array::from_fn(|c| std::array::from_fn(|v| srgb_encode(srgb_decode(v as u8) * kd[c])));
    let rgb = t
        .rgb
        .chunks_exact(3)
        .flat_map(|p| [lut[0][p[0] as usize], lut[1][p[1] as usize], lut[2][p[2] as usize]])
        .collect();
    Texture { width: t.width, height: t.height, rgb }
}

/// `map_Kd` may carry options before the file name (`-s 1 1 1 tex.png`):
/// use the whole string when it names a file, else its last word.
fn texture_path(dir: &Path, name: &str) -> PathBuf {
    let whole = dir.join(name.trim());
    if whole.exists() {
        return whole;
    }
    name.split_whitespace().last().map(|w| dir.join(w)).unwrap_or(whole)
}

/// Merges `tobj` models into one mesh; attributes present in only some models
/// are dropped (normals, colours) or zero-filled (UVs).
fn assemble(path: &Path, models: &[tobj::Model], materials: &mut Vec<Material>) -> Result<Mesh, MeshError> {
    let mut mesh = Mesh::default();
    let all_normals = models.iter().all(|m| !m.mesh.normals.is_empty());
    let all_colors = models.iter().all(|m| !m.mesh.vertex_color.is_empty());
    let any_uvs = models.iter().any(|m| !m.mesh.texcoords.is_empty());
    let mut default_material = None;
    for model in models {
        let m = &model.mesh;
        let n = m.positions.len() / 3;
        let base = mesh.positions.len() as u32;
        let bad = |what: &str| MeshError::Parse {
            path: path.to_owned(),
            line: None,
            message: format!("object '{}' has {what} not matching its {n} positions", model.name),
        };
        mesh.positions.extend(m.positions.chunks_exact(3).map(|c| [c[0], c[1], c[2]]));
        if all_normals {
            if m.normals.len() != 3 * n {
                return Err(bad("normals"));
            }
            mesh.normals.extend(m.normals.chunks_exact(3).map(|c| [c[0], c[1], c[2]]));
        }
        if all_colors {
            if m.vertex_color.len() != 3 * n {
                return Err(bad("vertex colours"));
            }
            let to_u8 = |x: f32| (x.clamp(0.0, 1.0) * 255.0).round() as u8;
            mesh.colors.extend(m.vertex_color.chunks_exact(3).map(|c| [to_u8(c[0]), to_u8(c[1]), to_u8(c[2])]));
        }
        if any_uvs {
            if m.texcoords.is_empty() {
                mesh.uvs.extend(std::iter::repeat_n([0.0, 0.0], n));
            } else if m.texcoords.len() != 2 * n {
                return Err(bad("texture coordinates"));
            } else {
                mesh.uvs.extend(m.texcoords.chunks_exact(2).map(|c| [c[0], c[1]]));
            }
        }
        let material = match m.material_id.filter(|&i| i < materials.len()) {
            Some(i) => i as u32,
            None => *default_material.get_or_insert_with(|| {
                materials.push(Material { name: "default".into(), diffuse: DEFAULT_DIFFUSE, texture: None });
                materials.len() as u32 - 1
            }),
        };
        for t in m.indices.chunks_exact(3) {
            mesh.triangles.push([base + t[0], base + t[1], base + t[2]]);
            mesh.triangle_materials.push(material);
        }
    }
    if materials.is_empty() {
        materials.push(Material { name: "default".into(), diffuse: DEFAULT_DIFFUSE, texture: None });
    }
    mesh.materials = std::mem::take(materials);
    Ok(mesh)
}
