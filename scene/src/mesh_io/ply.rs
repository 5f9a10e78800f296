//! Stanford PLY loading through `ply-rs` (ASCII, binary little- and big-endian):
//! positions, optional normals (`nx ny nz`), vertex colours (`red green blue`,
//! integer 0..255 or float 0..1), texture coordinates (`s t`, `u v`,
//! `texture_u texture_v`), polygon faces (`vertex_indices`/`vertex_index`,
//! fan-triangulated) and a MeshLab/BOP `comment TextureFile name.png` texture.

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use ply_rs::parser::Parser;
use ply_rs::ply::{DefaultElement, Property};

use super::checks::TextureIssue;
use super::obj::DEFAULT_DIFFUSE;
use super::{MeshError, read_texture};
use crate::model::{Material, Mesh};

fn scalar(p: &Property) -> Option<f64> {
    Some(match *p {
        Property::Char(v) => v as f64,
        Property::UChar(v) => v as f64,
        Property::Short(v) => v as f64,
        Property::UShort(v) => v as f64,
        Property::Int(v) => v as f64,
        Property::UInt(v) => v as f64,
        Property::Float(v) => v as f64,
        Property::Double(v) => v,
        _ => return None,
    })
}

fn index_list(p: &Property) -> Option<Vec<i64>> {
    Some(match p {
        Property::ListChar(v) => v.iter().map(|&x| x as i64).collect(),
        Property::ListUChar(v) => v.iter().map(|&x| x as i64).collect(),
        Property::ListShort(v) => v.iter().map(|&x| x as i64).collect(),
        Property::ListUShort(v) => v.iter().map(|&x| x as i64).collect(),
        Property::ListInt(v) => v.iter().map(|&x| x as i64).collect(),
        Property::ListUInt(v) => v.iter().map(|&x| x as i64).collect(),
        _ => return None,
    })
}

/// A colour channel as 0..255: integers as they are, floats scaled from 0..1.
fn channel(p: &Property) -> Option<u8> {
    match p {
        Property::Float(_) | Property::Double(_) => scalar(p).map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8),
        _ => scalar(p).map(|v| v.clamp(0.0, 255.0) as u8),
    }
}

/// The first of `names` the element has, read with `read`.
fn first_of<T>(e: &DefaultElement, names: &[&str], read: impl Fn(&Property) -> Option<T>) -> Option<T> {
    names.iter().find_map(|n| e.get(*n)).and_then(read)
}

/// `ply-rs` reports ASCII errors as "Line N: ..." (N is the file's line
/// number for payload lines): split that off the message.
fn split_line(message: &str) -> (Option<usize>, String) {
    let parsed = message.strip_prefix("Line ").and_then(|rest| {
        let (n, tail) = rest.split_once(':')?;
        Some((n.trim().parse::<usize>().ok()?, tail.trim()))
    });
    let (line, text) = match parsed {
        Some((n, tail)) => (Some(n), tail),
        None => (None, message),
    };
    (line, text.replace("\n\t", "; ").replace('\n', " "))
}

/// The mesh and, if its `TextureFile` could not be used, why.
pub(super) fn load_ply(path: &Path) -> Result<(Mesh, Vec<TextureIssue>), MeshError> {
    let file = File::open(path).map_err(|error| MeshError::Io { path: path.to_owned(), error })?;
    let ply = Parser::<DefaultElement>::new().read_ply(&mut BufReader::new(file)).map_err(|e| {
        let (line, message) = split_line(&e.to_string());
        MeshError::Parse { path: path.to_owned(), line, message: format!("PLY {message}") }
    })?;
    let parse_err = |message: String| MeshError::Parse { path: path.to_owned(), line: None, message };

    let vertices = ply.payload.get("vertex").ok_or_else(|| parse_err("no 'vertex' element".into()))?;
    let mut mesh = Mesh::default();
    for (i, v) in vertices.iter().enumerate() {
        let coord = |name: &str| {
            first_of(v, &[name], scalar).ok_or_else(|| parse_err(format!("vertex {i} has no numeric '{name}'")))
        };
        mesh.positions.push([coord("x")? as f32, coord("y")? as f32, coord("z")? as f32]);
        let normal = [first_of(v, &["nx"], scalar), first_of(v, &["ny"], scalar), first_of(v, &["nz"], scalar)];
        if let [Some(x), Some(y), Some(z)] = normal {
            mesh.normals.push([x as f32, y as f32, z as f32]);
        }
        let color = [
            first_of(v, &["red", "diffuse_red", "r"], channel),
            first_of(v, &["green", "diffuse_green", "g"], channel),
            first_of(v, &["blue", "diffuse_blue", "b"], channel),
        ];
        if let [Some(r), Some(g), Some(b)] = color {
            mesh.colors.push([r, g, b]);
        }
        let uv = [
            first_of(v, &["s", "u", "texture_u", "texture_s"], scalar),
            first_of(v, &["t", "v", "texture_v", "texture_t"], scalar),
        ];
        if let [Some(s), Some(t)] = uv {
            mesh.uvs.push([s as f32, t as f32]);
        }
    }
    let n = mesh.positions.len();
    for (attr, len) in
        [("normals", mesh.normals.len()), ("colours", mesh.colors.len()), ("texture coordinates", mesh.uvs.len())]
    {
        if len != 0 && len != n {
            return Err(parse_err(format!("only {len} of {n} vertices have {attr}")));
        }
    }

    let faces = ply.payload.get("face").map(Vec::as_slice).unwrap_or_default();
    for (f, face) in faces.iter().enumerate() {
        let indices = first_of(face, &["vertex_indices", "vertex_index"], index_list)
            .ok_or_else(|| parse_err(format!("face {f} has no integer list 'vertex_indices'")))?;
        let to_u32 = |i: i64| {
            u32::try_from(i)
                .ok()
                .filter(|&i| (i as usize) < n)
                .ok_or_else(|| parse_err(format!("face {f} refers to vertex {i}, but there are {n} vertices")))
        };
        if indices.len() < 3 {
            continue; // points and lines carry no surface
        }
        let a = to_u32(indices[0])?;
        for pair in indices[1..].windows(2) {
            mesh.triangles.push([a, to_u32(pair[0])?, to_u32(pair[1])?]);
        }
    }

    let mut issues = Vec::new();
    let texture = ply
        .header
        .comments
        .iter()
        .find_map(|c| c.trim().strip_prefix("TextureFile").map(|name| name.trim().to_owned()))
        .filter(|name| !name.is_empty())
        .and_then(|name| {
            let file = path.parent().unwrap_or(Path::new("")).join(&name);
            match read_texture(&file) {
                Ok(t) => Some(t),
                Err(e) => {
                    issues.push(TextureIssue {
                        named_in: path.to_owned(),
                        missing: !file.exists(),
                        texture: file,
                        reason: e.to_string(),
                    });
                    None
                }
            }
        });
    mesh.materials.push(Material { name: "default".into(), diffuse: DEFAULT_DIFFUSE, texture });
    Ok((mesh, issues))
}
