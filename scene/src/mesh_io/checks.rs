//! Checks on users' own meshes, run when a folder of objects is loaded: units
//! (a millimetre mesh read as metres), missing or unreadable textures, empty,
//! degenerate and huge meshes, and duplicate object names. Each failure names
//! the file and the fix; a symmetry suggestion is computed from geometry.

use std::path::{Path, PathBuf};

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{Matrix3, Point3, Unit, UnitQuaternion, Vector3};

use crate::model::{Mesh, ObjectModel};
use crate::surface::{SURFACE_SAMPLE_SEED, sample_surface, surface_area};

/// Graspable objects measure 1 cm to 1 m across (diameter, metres).
pub const PLAUSIBLE_DIAMETER_M: (f64, f64) = (0.01, 1.0);
/// Above this diameter (metres) a mesh is taken to be in the wrong units.
pub const TOO_LARGE_DIAMETER_M: f64 = 3.0;
/// Below this diameter (metres) a mesh is taken to be in the wrong units.
pub const TOO_SMALL_DIAMETER_M: f64 = 0.005;
/// Above this many triangles a mesh slows rendering (and training) for no gain.
pub const HUGE_TRIANGLES: usize = 2_000_000;

/// A texture a mesh file names but that could not be used.
#[derive(Clone, Debug, PartialEq)]
pub struct TextureIssue {
    /// The file that names the texture: the MTL (OBJ) or the PLY itself.
    pub named_in: PathBuf,
    pub texture: PathBuf,
    /// True when the file does not exist; false when it exists but does not decode.
    pub missing: bool,
    pub reason: String,
}

/// Why a user's mesh is refused. Every variant names the file and the fix.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum CheckError {
    #[error(
        "{path}: the mesh is {diameter_m:.3} m across as loaded (scale {scale}); it looks like it is in {unit}. \
         Graspable objects are 1 cm – 1 m: load it with `--scale {suggested}` (it would be {suggested_m:.3} m){alternative}"
    )]
    WrongUnits {
        path: PathBuf,
        diameter_m: f64,
        scale: f64,
        unit: &'static str,
        suggested: f64,
        suggested_m: f64,
        /// The other plausible reading, if any ("; if it is in centimetres, ...").
        alternative: String,
    },
    #[error(
        "{path}: the mesh is {diameter_m:.3} m across as loaded (scale {scale}), implausible for a graspable \
         object (1 cm – 1 m) and not explained by mm/cm units; rescale the file so that it is in metres"
    )]
    ImplausibleSize { path: PathBuf, diameter_m: f64, scale: f64 },
    #[error(
        "{obj}: texture {texture} named by {mtl} {}; put the image there, or delete the {} line \
         from {mtl} to render the material colour instead",
        if *missing { "does not exist".to_string() } else { format!("cannot be decoded ({reason})") },
        texture_line(mtl)
    )]
    Texture { obj: PathBuf, mtl: PathBuf, texture: PathBuf, missing: bool, reason: String },
    #[error("{path}: the mesh has no triangles (points or lines only?); export it as a triangle or polygon mesh")]
    Empty { path: PathBuf },
    #[error("{path}: vertex {vertex} has a non-finite coordinate (NaN or infinite); repair or re-export the mesh")]
    NonFinite { path: PathBuf, vertex: usize },
    #[error(
        "{path}: all {triangles} triangles have zero area (flat or collapsed geometry); re-export the mesh with its surface"
    )]
    Degenerate { path: PathBuf, triangles: usize },
    #[error(
        "two meshes give the object name '{name}': {first} and {second}; rename or remove one \
         (names must differ in more than letter case)"
    )]
    DuplicateName { name: String, first: PathBuf, second: PathBuf },
}

/// The line that names a texture: `map_Kd` in an MTL, a header comment in a PLY.
fn texture_line(named_in: &Path) -> &'static str {
    let ply = named_in.extension().is_some_and(|e| e.eq_ignore_ascii_case("ply"));
    if ply { "`comment TextureFile`" } else { "`map_Kd`" }
}

/// Something worth telling the user that does not stop loading.
#[derive(Clone, Debug, PartialEq)]
pub enum CheckWarning {
    /// More than [`HUGE_TRIANGLES`] triangles.
    Huge { path: PathBuf, triangles: usize },
    /// A texture file that does not exist: the mesh renders in its material colour.
    MissingTexture { path: PathBuf, issue: TextureIssue },
}

impl std::fmt::Display for CheckWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CheckWarning::Huge { path, triangles } => write!(
                f,
                "{}: {triangles} triangles (more than {HUGE_TRIANGLES}) slow rendering and training; \
                 decimate it (e.g. MeshLab's quadric edge collapse to ~100 k triangles)",
                path.display()
            ),
            CheckWarning::MissingTexture { path, issue } => write!(
                f,
                "{}: texture {} named by {} does not exist; rendering the material colour instead \
                 (put the image there, or delete the {} line to silence this)",
                path.display(),
                issue.texture.display(),
                issue.named_in.display(),
                texture_line(&issue.named_in)
            ),
        }
    }
}

/// Whether a texture that does not exist stops loading (it always does when the
/// file exists but does not decode).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MissingTextures {
    /// Warn and render the material colour (published meshes often name absent textures).
    #[default]
    Warn,
    /// Refuse the mesh.
    Fail,
}

/// Checks a freshly read mesh (positions already scaled) before it is validated:
/// textures, empty, non-finite, degenerate and huge meshes.
pub fn check_mesh(
    path: &Path,
    mesh: &Mesh,
    textures: &[TextureIssue],
    missing: MissingTextures,
) -> Result<Vec<CheckWarning>, CheckError> {
    let mut warnings = Vec::new();
    for issue in textures {
        if issue.missing && missing == MissingTextures::Warn {
            warnings.push(CheckWarning::MissingTexture { path: path.to_owned(), issue: issue.clone() });
        } else {
            return Err(CheckError::Texture {
                obj: path.to_owned(),
                mtl: issue.named_in.clone(),
                texture: issue.texture.clone(),
                missing: issue.missing,
                reason: issue.reason.clone(),
            });
        }
    }
    if mesh.triangles.is_empty() {
        return Err(CheckError::Empty { path: path.to_owned() });
    }
    if let Some(vertex) = mesh.positions.iter().position(|p| p.iter().any(|c| !c.is_finite())) {
        return Err(CheckError::NonFinite { path: path.to_owned(), vertex });
    }
    // Out-of-range indices are validate_mesh's to report; only measure a valid mesh.
    let n = mesh.positions.len();
    if mesh.triangles.iter().all(|t| t.iter().all(|&i| (i as usize) < n)) && surface_area(mesh) <= 0.0 {
        return Err(CheckError::Degenerate { path: path.to_owned(), triangles: mesh.triangles.len() });
    }
    if mesh.triangles.len() > HUGE_TRIANGLES {
        warnings.push(CheckWarning::Huge { path: path.to_owned(), triangles: mesh.triangles.len() });
    }
    Ok(warnings)
}

/// Checks an object's size for wrong units: `diameter_m` as loaded with `scale`.
pub fn check_units(path: &Path, diameter_m: f64, scale: f64) -> Result<(), CheckError> {
    let (lo, hi) = PLAUSIBLE_DIAMETER_M;
    let plausible = |d: f64| (lo..=hi).contains(&d);
    let candidates: &[(f64, &str)] = if diameter_m > TOO_LARGE_DIAMETER_M {
        &[(0.001, "millimetres"), (0.01, "centimetres")]
    } else if diameter_m < TOO_SMALL_DIAMETER_M {
        // Typically a file already in metres loaded with --scale 0.001.
        &[(1000.0, "metres but was loaded as millimetres")]
    } else {
        return Ok(());
    };
    // Of the plausible readings, prefer the one nearest a typical 10 cm object (in log scale).
    let typical = |f: &f64| (diameter_m * f / 0.1).ln().abs();
    let mut plausible_readings: Vec<&(f64, &str)> =
        candidates.iter().filter(|(f, _)| plausible(diameter_m * f)).collect();
    plausible_readings.sort_by(|a, b| typical(&a.0).total_cmp(&typical(&b.0)));
    match plausible_readings.as_slice() {
        [] => Err(CheckError::ImplausibleSize { path: path.to_owned(), diameter_m, scale }),
        [(factor, unit), rest @ ..] => Err(CheckError::WrongUnits {
            path: path.to_owned(),
            diameter_m,
            scale,
            unit,
            suggested: scale * factor,
            suggested_m: diameter_m * factor,
            alternative: rest
                .iter()
                .map(|(f, u)| format!("; if it is in {u}, `--scale {}` ({:.3} m)", scale * f, diameter_m * f))
                .collect(),
        }),
    }
}

/// Object names must be unique ignoring case (`a.obj` and `a/a.obj` clash; so
/// do `Mug` and `mug`, which collide on case-insensitive file systems).
pub fn check_unique_names(found: &[(String, PathBuf)]) -> Result<(), CheckError> {
    for (i, (name, first)) in found.iter().enumerate() {
        if let Some((_, second)) = found[i + 1..].iter().find(|(other, _)| other.eq_ignore_ascii_case(name)) {
            let (first, second) = if first <= second { (first, second) } else { (second, first) };
            return Err(CheckError::DuplicateName { name: name.clone(), first: first.clone(), second: second.clone() });
        }
    }
    Ok(())
}

/// A symmetry the geometry suggests (applied only when asked:
/// [`crate::symmetry_spec`]). Axes pass through the centroid of the surface samples.
#[derive(Clone, Debug, PartialEq)]
pub enum SymmetrySuggestion {
    None,
    /// Near-invariant under every rotation about `axis` through the centroid.
    Continuous {
        axis: Vector3<f64>,
    },
    /// Near-invariant under rotations by 360°/`order` about `axis`.
    Discrete {
        axis: Vector3<f64>,
        order: u32,
    },
    /// Near-invariant under half-turns about each of three orthogonal axes.
    Box {
        axes: [Vector3<f64>; 3],
    },
}

impl std::fmt::Display for SymmetrySuggestion {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let axis = |a: &Vector3<f64>| format!("({:.2}, {:.2}, {:.2})", a.x, a.y, a.z);
        match self {
            SymmetrySuggestion::None => write!(f, "none"),
            SymmetrySuggestion::Continuous { axis: a } => write!(f, "continuous about {}", axis(a)),
            SymmetrySuggestion::Discrete { axis: a, order } => write!(f, "{order}-fold about {}", axis(a)),
            SymmetrySuggestion::Box { .. } => write!(f, "box (half-turns about 3 orthogonal axes)"),
        }
    }
}

/// A rotated copy of the surface samples counts as the same shape when its
/// 99th-percentile nearest-neighbour distance to the samples is at most this multiple of
/// what an independent resampling of the same surface gives (sampling noise).
pub const SYMMETRY_TOLERANCE: f64 = 1.5;

/// Suggests a rotational symmetry about the principal axes (through the
/// centroid of the surface samples) and the object frame's axes, comparing
/// the samples with themselves rotated by nearest-neighbour distance, as ADD-S
/// does. Continuous symmetry wins over discrete, higher orders over lower.
/// Geometry only: a texture may break the symmetry, so this is a suggestion.
pub fn suggest_symmetry(object: &ObjectModel) -> SymmetrySuggestion {
    let pts = &object.samples;
    let Ok(resampled) = sample_surface(&object.mesh, pts.len(), SURFACE_SAMPLE_SEED ^ 0x5a5a) else {
        return SymmetrySuggestion::None;
    };
    if pts.len() < 10 {
        return SymmetrySuggestion::None;
    }
    let centroid = pts.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / pts.len() as f64;
    let cov = pts.iter().fold(Matrix3::zeros(), |a, p| {
        let d = p.coords - centroid;
        a + d * d.transpose()
    }) / pts.len() as f64;
    let eig = cov.symmetric_eigen();
    let coords: Vec<[f64; 3]> = pts.iter().map(|p| [p.x, p.y, p.z]).collect();
    let tree: ImmutableKdTree<f64, 3> = ImmutableKdTree::new_from_slice(&coords);
    // 99th percentile of nearest-neighbour distances: a mean (or a lower
    // percentile) hides a small feature the rotation moves, such as a mug's handle.
    let spread = |points: &mut dyn Iterator<Item = Point3<f64>>| {
        let mut d: Vec<f64> =
            points.map(|q| tree.nearest_one::<SquaredEuclidean>(&[q.x, q.y, q.z]).distance.sqrt()).collect();
        d.sort_by(f64::total_cmp);
        d.get(d.len() * 99 / 100).copied().unwrap_or(0.0)
    };
    let tolerance = SYMMETRY_TOLERANCE * spread(&mut resampled.iter().copied());
    let matches = |axis: &Unit<Vector3<f64>>, angle: f64| {
        let r = UnitQuaternion::from_axis_angle(axis, angle);
        let d = spread(&mut pts.iter().map(|p| Point3::from(r * (p.coords - centroid) + centroid)));
        d <= tolerance
    };
    let tau = std::f64::consts::TAU;
    // Two families of candidate axes: the principal axes (through the
    // centroid), and the object frame's x, y, z (meshes are often modelled
    // aligned, and a principal axis is ill-defined when two spreads are alike).
    let principal: [Vector3<f64>; 3] = std::array::from_fn(|k| eig.eigenvectors.column(k).into_owned());
    let families = [principal, [Vector3::x(), Vector3::y(), Vector3::z()]];
    let mut best = SymmetrySuggestion::None;
    let mut best_order = 0;
    for family in families {
        let mut half_turns = 0;
        for v in family {
            // Canonical sign: the largest component positive.
            let axis = Unit::new_normalize(if v[v.iamax()] < 0.0 { -v } else { v });
            // Continuous: invariant at several unrelated angles.
            if [1.1, 2.3, 3.9].iter().all(|&a| matches(&axis, a)) {
                return SymmetrySuggestion::Continuous { axis: axis.into_inner() };
            }
            let order =
                [6u32, 4, 3, 2].into_iter().find(|&o| (1..o).all(|i| matches(&axis, tau * i as f64 / o as f64)));
            if let Some(order) = order {
                half_turns += usize::from(order % 2 == 0);
                if order > best_order {
                    (best, best_order) = (SymmetrySuggestion::Discrete { axis: axis.into_inner(), order }, order);
                }
            }
        }
        if half_turns == 3 && best_order == 2 {
            return SymmetrySuggestion::Box { axes: family };
        }
    }
    best
}
