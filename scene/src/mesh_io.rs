//! Loading object meshes from disk: OBJ (+MTL, textures) and PLY (ASCII and
//! binary), single meshes, single objects, and whole object directories.
//!
//! Units: files are read as metres times `scale` (pass 0.001 for millimetre
//! models such as BOP's). Meshes keep the file's object frame.

pub mod checks;
mod obj;
mod ply;

use std::path::{Path, PathBuf};

use self::checks::{CheckError, CheckWarning, MissingTextures, TextureIssue};
use crate::export::ModelsInfo;
use crate::model::{Mesh, ObjectModel, ObjectSet, Symmetry, Texture};
use crate::surface::{SurfaceError, compute_vertex_normals, validate_mesh};

/// Why a mesh or an object could not be loaded. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    #[error("{path}: cannot read: {error}")]
    Io { path: PathBuf, error: std::io::Error },
    #[error("{path}: unsupported mesh format (expected .obj or .ply)")]
    UnsupportedFormat { path: PathBuf },
    #[error("{path}{}: {message}", line.map(|l| format!(", line {l}")).unwrap_or_default())]
    Parse { path: PathBuf, line: Option<usize>, message: String },
    #[error("{path}: invalid mesh: {error}")]
    Invalid { path: PathBuf, error: SurfaceError },
    #[error("{path}: scale must be finite and positive, got {scale}")]
    BadScale { path: PathBuf, scale: f64 },
    #[error("{path}: no .obj or .ply mesh found")]
    NoMesh { path: PathBuf },
    #[error("{path}: bad models_info.json: {error}")]
    ModelsInfo { path: PathBuf, error: serde_json::Error },
    /// A user's mesh failed a check of [`checks`] (units, textures, geometry, names).
    #[error(transparent)]
    Check(#[from] CheckError),
}

/// Loads a triangle mesh, choosing the parser by extension (`.obj`, `.ply`,
/// case-insensitive). Positions are multiplied by `scale` (metres per file
/// unit). Smooth vertex normals are computed when the file has none; the
/// result is validated (indices, attribute lengths) before it is returned.
pub fn load_mesh(path: &Path, scale: f64) -> Result<Mesh, MeshError> {
    let (mesh, textures) = read_mesh(path, scale)?;
    for t in &textures {
        tracing::warn!(
            "{}: texture {} named by {} unavailable ({}), using the material colour instead",
            path.display(),
            t.texture.display(),
            t.named_in.display(),
            t.reason
        );
    }
    finish_mesh(path, mesh)
}

/// Parses a mesh file and scales its positions; also returns the textures it
/// names that could not be used.
fn read_mesh(path: &Path, scale: f64) -> Result<(Mesh, Vec<TextureIssue>), MeshError> {
    if !(scale.is_finite() && scale > 0.0) {
        return Err(MeshError::BadScale { path: path.to_owned(), scale });
    }
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    let (mut mesh, textures) = match ext.as_deref() {
        Some("obj") => obj::load_obj(path)?,
        Some("ply") => ply::load_ply(path)?,
        _ => {
            return Err(MeshError::UnsupportedFormat { path: path.to_owned() });
        }
    };
    if scale != 1.0 {
        for p in &mut mesh.positions {
            *p = p.map(|c| (c as f64 * scale) as f32);
        }
    }
    Ok((mesh, textures))
}

/// Validates a read mesh and fills in smooth normals when it has none.
fn finish_mesh(path: &Path, mut mesh: Mesh) -> Result<Mesh, MeshError> {
    validate_mesh(&mesh).map_err(|error| MeshError::Invalid { path: path.to_owned(), error })?;
    if mesh.normals.is_empty() {
        mesh.normals = compute_vertex_normals(&mesh);
    }
    Ok(mesh)
}

/// Loads a mesh and precomputes its object model (samples, diameter, bbox).
pub fn load_object(path: &Path, scale: f64, name: &str, symmetry: Symmetry) -> Result<ObjectModel, MeshError> {
    let mesh = load_mesh(path, scale)?;
    ObjectModel::from_mesh(name, mesh, symmetry).map_err(|error| MeshError::Invalid { path: path.to_owned(), error })
}

/// Loads every object of a directory: one object per
/// subdirectory (its mesh file, preferring names containing `textured`) and
/// one per `.obj`/`.ply` file directly inside (named by the file stem).
///
/// Objects are sorted by name, except that a `models_info.json` in `dir` (as
/// written by [`crate::export::export_objects`]) fixes the order of the
/// objects it lists (by its class ids, so an exported set reloads with the
/// same class ids) and their symmetries; unlisted objects follow, by name,
/// with [`Symmetry::None`]. Symmetry translations in that file are in
/// metres and are multiplied by `scale` like the meshes.
///
/// Every mesh is checked ([`checks`]): wrong units, unreadable textures,
/// empty or degenerate meshes and duplicate names are errors naming the file
/// and the fix; huge meshes and missing textures are logged as warnings.
pub fn load_object_dir(dir: &Path, scale: f64) -> Result<ObjectSet, MeshError> {
    let (set, warnings) = load_object_dir_checked(dir, scale, MissingTextures::Warn)?;
    for w in warnings.iter().map(|w| w.to_string()).filter(|w| first_time(w)) {
        tracing::warn!("{w}");
    }
    Ok(set)
}

/// Whether this process has not logged `warning` yet: a folder loaded again
/// (each stage of `fusepose train --stage all`, its acceptance report) warns
/// once, not once per load.
fn first_time(warning: &str) -> bool {
    static LOGGED: std::sync::Mutex<std::collections::BTreeSet<String>> =
        std::sync::Mutex::new(std::collections::BTreeSet::new());
    let mut logged = LOGGED.lock().unwrap_or_else(|e| e.into_inner());
    logged.insert(warning.to_owned())
}

/// [`load_object_dir`], returning the check warnings instead of logging them;
/// `missing` says whether a texture file that does not exist is an error.
pub fn load_object_dir_checked(
    dir: &Path,
    scale: f64,
    missing: MissingTextures,
) -> Result<(ObjectSet, Vec<CheckWarning>), MeshError> {
    let io = |error| MeshError::Io { path: dir.to_owned(), error };
    let info = read_models_info(dir)?;
    let mut found: Vec<(String, PathBuf)> = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(io)? {
        let path = entry.map_err(io)?.path();
        let name = path.file_stem().and_then(|s| s.to_str()).unwrap_or_default().to_owned();
        if path.is_dir() {
            if let Some(mesh) = pick_mesh_file(&path)? {
                let dir_name = path.file_name().and_then(|s| s.to_str()).unwrap_or_default().to_owned();
                found.push((dir_name, mesh));
            }
        } else if is_mesh_file(&path) {
            found.push((name, path));
        }
    }
    if found.is_empty() {
        return Err(MeshError::NoMesh { path: dir.to_owned() });
    }
    checks::check_unique_names(&found)?;
    // Objects listed in models_info.json keep its class order; others follow by name.
    let class_of = |name: &str| {
        info.as_ref().and_then(|i| i.objects.iter().find(|o| o.name == name)).map_or(u32::MAX, |o| o.class_id as u32)
    };
    found.sort_by(|a, b| (class_of(&a.0), &a.0).cmp(&(class_of(&b.0), &b.0)));
    let mut set = ObjectSet::default();
    let mut warnings = Vec::new();
    for (name, path) in found {
        let symmetry = info
            .as_ref()
            .and_then(|i| i.symmetry_of(&name))
            .map(|s| scale_symmetry(s, scale))
            .unwrap_or(Symmetry::None);
        let (mesh, textures) = read_mesh(&path, scale)?;
        warnings.extend(checks::check_mesh(&path, &mesh, &textures, missing)?);
        let mesh = finish_mesh(&path, mesh)?;
        let object = ObjectModel::from_mesh(&name, mesh, symmetry)
            .map_err(|error| MeshError::Invalid { path: path.clone(), error })?;
        checks::check_units(&path, object.diameter, scale)?;
        set.objects.push(object);
    }
    Ok((set, warnings))
}

/// The object set named on a command line: `builtin` (the built-in set, in
/// metres; `scale` is ignored) or a directory for [`load_object_dir`].
pub fn load_object_set(source: &str, scale: f64) -> Result<ObjectSet, MeshError> {
    if source == "builtin" { Ok(crate::builtin::builtin_objects()) } else { load_object_dir(Path::new(source), scale) }
}

fn read_models_info(dir: &Path) -> Result<Option<ModelsInfo>, MeshError> {
    let path = dir.join("models_info.json");
    match std::fs::read_to_string(&path) {
        Ok(text) => serde_json::from_str(&text).map(Some).map_err(|error| MeshError::ModelsInfo { path, error }),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(error) => Err(MeshError::Io { path, error }),
    }
}

fn scale_symmetry(s: Symmetry, scale: f64) -> Symmetry {
    match s {
        Symmetry::None => Symmetry::None,
        Symmetry::Discrete(v) => Symmetry::Discrete(
            v.into_iter()
                .map(|mut t| {
                    t.translation.vector *= scale;
                    t
                })
                .collect(),
        ),
        Symmetry::Continuous { axis, origin } => Symmetry::Continuous { axis, origin: origin * scale },
    }
}

fn is_mesh_file(path: &Path) -> bool {
    path.is_file()
        && matches!(
            path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref(),
            Some("obj" | "ply")
        )
}

/// The mesh file of an object folder: the only one, else the first (sorted)
/// whose name contains `textured`, else the first sorted.
fn pick_mesh_file(dir: &Path) -> Result<Option<PathBuf>, MeshError> {
    let io = |error| MeshError::Io { path: dir.to_owned(), error };
    let mut meshes = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(io)? {
        let path = entry.map_err(io)?.path();
        if is_mesh_file(&path) {
            meshes.push(path);
        }
    }
    meshes.sort();
    let textured =
        meshes.iter().find(|p| p.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.contains("textured"))).cloned();
    Ok(textured.or_else(|| meshes.into_iter().next()))
}

/// Reads a PNG or JPEG texture as RGB8, top row first.
pub(crate) fn read_texture(path: &Path) -> Result<Texture, image::ImageError> {
    let img = image::ImageReader::open(path)?.with_guessed_format()?.decode()?.into_rgb8();
    Ok(Texture { width: img.width(), height: img.height(), rgb: img.into_raw() })
}

#[cfg(test)]
mod tests;
