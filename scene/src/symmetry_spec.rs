//! Symmetries named on a command line (`--symmetry NAME=KIND`): what a user
//! declares for their own meshes, turned into [`Symmetry`] transforms in the
//! object frame. Axes are the mesh file's x, y, z through the centroid of the
//! object's surface samples (the centre of a can's cross-section, of a box);
//! `suggested` takes what the geometry suggests ([`suggest_symmetry`]).
//!
//! Kinds: `none`, `continuous:AXIS`, `N-fold:AXIS` (N = 2..12, rotations by
//! 360°/N), `box` (half-turns about x, y and z), `suggested`. A bare
//! `suggested` applies every object's suggestion; named specs given with it win.

use std::fmt;
use std::str::FromStr;

use nalgebra::{Isometry3, Point3, Unit, UnitQuaternion, Vector3};

use crate::mesh_io::checks::{SymmetrySuggestion, suggest_symmetry};
use crate::{ObjectModel, ObjectSet, Symmetry};

/// One of the mesh frame's axes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Axis {
    X,
    Y,
    Z,
}

impl Axis {
    fn vector(self) -> Vector3<f64> {
        match self {
            Axis::X => Vector3::x(),
            Axis::Y => Vector3::y(),
            Axis::Z => Vector3::z(),
        }
    }
}

/// What an object is declared to be.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SymmetryKind {
    None,
    Continuous(Axis),
    /// Rotations by 360°/order about the axis.
    Fold(u32, Axis),
    /// Half-turns about x, y and z.
    Box,
    Suggested,
}

/// `NAME=KIND`, or a bare `suggested` (`name` = `None`: every object).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SymmetrySpec {
    pub name: Option<String>,
    pub kind: SymmetryKind,
}

/// A symmetry spec that cannot be used; each message names the spec and the fix.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum SymmetrySpecError {
    #[error(
        "--symmetry {spec:?}: expected NAME=KIND (KIND: none, continuous:x|y|z, N-fold:x|y|z with N 2..12, box, suggested) or a bare `suggested`"
    )]
    Syntax { spec: String },
    #[error(
        "--symmetry {spec:?}: unknown kind {kind:?}; use none, continuous:x|y|z, N-fold:x|y|z (N 2..12, e.g. 2-fold:z), box or suggested"
    )]
    Kind { spec: String, kind: String },
    #[error("--symmetry names object {name:?}, which is not in the object set; its objects: {known}")]
    UnknownObject { name: String, known: String },
    #[error("--symmetry names object {name:?} twice; give one kind per object")]
    Duplicate { name: String },
}

fn parse_axis(s: &str) -> Option<Axis> {
    match s {
        "x" | "X" => Some(Axis::X),
        "y" | "Y" => Some(Axis::Y),
        "z" | "Z" => Some(Axis::Z),
        _ => None,
    }
}

fn parse_kind(spec: &str, kind: &str) -> Result<SymmetryKind, SymmetrySpecError> {
    let bad = || SymmetrySpecError::Kind { spec: spec.to_owned(), kind: kind.to_owned() };
    Ok(match kind {
        "none" => SymmetryKind::None,
        "box" => SymmetryKind::Box,
        "suggested" => SymmetryKind::Suggested,
        _ => {
            let (what, axis) = kind.split_once(':').ok_or_else(bad)?;
            let axis = parse_axis(axis).ok_or_else(bad)?;
            if what == "continuous" {
                SymmetryKind::Continuous(axis)
            } else {
                let order: u32 = what.strip_suffix("-fold").and_then(|n| n.parse().ok()).ok_or_else(bad)?;
                if !(2..=12).contains(&order) {
                    return Err(bad());
                }
                SymmetryKind::Fold(order, axis)
            }
        }
    })
}

impl FromStr for SymmetrySpec {
    type Err = SymmetrySpecError;

    fn from_str(spec: &str) -> Result<Self, Self::Err> {
        let spec = spec.trim();
        if spec == "suggested" {
            return Ok(Self { name: None, kind: SymmetryKind::Suggested });
        }
        let (name, kind) = spec.split_once('=').ok_or_else(|| SymmetrySpecError::Syntax { spec: spec.to_owned() })?;
        let name = name.trim();
        if name.is_empty() {
            return Err(SymmetrySpecError::Syntax { spec: spec.to_owned() });
        }
        Ok(Self { name: Some(name.to_owned()), kind: parse_kind(spec, kind.trim())? })
    }
}

/// Centroid of the surface samples (where the suggestion's axes pass).
fn centroid(object: &ObjectModel) -> Point3<f64> {
    let n = object.samples.len().max(1) as f64;
    Point3::from(object.samples.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n)
}

/// Rotation by `angle` about `axis` through `centre`: p -> R (p - c) + c.
fn rotation_about(axis: &Vector3<f64>, angle: f64, centre: &Point3<f64>) -> Isometry3<f64> {
    let r = UnitQuaternion::from_axis_angle(&Unit::new_normalize(*axis), angle);
    Isometry3::from_parts((centre.coords - r * centre.coords).into(), r)
}

fn folds(axis: &Vector3<f64>, order: u32, centre: &Point3<f64>) -> Vec<Isometry3<f64>> {
    let step = std::f64::consts::TAU / order as f64;
    (1..order).map(|i| rotation_about(axis, step * i as f64, centre)).collect()
}

fn half_turns(axes: &[Vector3<f64>; 3], centre: &Point3<f64>) -> Vec<Isometry3<f64>> {
    axes.iter().map(|a| rotation_about(a, std::f64::consts::PI, centre)).collect()
}

/// The symmetry `kind` declares for `object`.
pub fn symmetry_of(object: &ObjectModel, kind: SymmetryKind) -> Symmetry {
    let c = centroid(object);
    match kind {
        SymmetryKind::None => Symmetry::None,
        SymmetryKind::Continuous(axis) => Symmetry::Continuous { axis: axis.vector(), origin: c },
        SymmetryKind::Fold(order, axis) => Symmetry::Discrete(folds(&axis.vector(), order, &c)),
        SymmetryKind::Box => Symmetry::Discrete(half_turns(&[Vector3::x(), Vector3::y(), Vector3::z()], &c)),
        SymmetryKind::Suggested => match suggest_symmetry(object) {
            SymmetrySuggestion::None => Symmetry::None,
            SymmetrySuggestion::Continuous { axis } => Symmetry::Continuous { axis, origin: c },
            SymmetrySuggestion::Discrete { axis, order } => Symmetry::Discrete(folds(&axis, order, &c)),
            SymmetrySuggestion::Box { axes } => Symmetry::Discrete(half_turns(&axes, &c)),
        },
    }
}

/// One line per symmetry for listings: `none`, `continuous about (x, y, z) through (x, y, z) mm`,
/// `discrete (N + identity)`.
pub struct Describe<'a>(pub &'a Symmetry);

impl fmt::Display for Describe<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            Symmetry::None => write!(f, "none"),
            Symmetry::Continuous { axis, origin } => write!(
                f,
                "continuous about ({:.2}, {:.2}, {:.2}) through ({:.1}, {:.1}, {:.1}) mm",
                axis.x,
                axis.y,
                axis.z,
                origin.x * 1e3,
                origin.y * 1e3,
                origin.z * 1e3
            ),
            Symmetry::Discrete(v) => write!(f, "discrete ({} + identity)", v.len()),
        }
    }
}

/// Applies `specs` to `set` (a bare `suggested` first, then the named ones)
/// and returns each changed object's name with its new symmetry. Nothing is
/// changed when any spec is unusable.
pub fn apply_symmetry_specs(
    set: &mut ObjectSet,
    specs: &[SymmetrySpec],
) -> Result<Vec<(String, Symmetry)>, SymmetrySpecError> {
    let mut plan: Vec<Option<SymmetryKind>> = vec![None; set.objects.len()];
    if specs.iter().any(|s| s.name.is_none() && s.kind == SymmetryKind::Suggested) {
        plan.fill(Some(SymmetryKind::Suggested));
    }
    let mut named = Vec::new();
    for spec in specs {
        let Some(name) = &spec.name else { continue };
        let Some(i) = set.objects.iter().position(|o| &o.name == name) else {
            let known = set.objects.iter().map(|o| o.name.as_str()).collect::<Vec<_>>().join(", ");
            return Err(SymmetrySpecError::UnknownObject { name: name.clone(), known });
        };
        if named.contains(&i) {
            return Err(SymmetrySpecError::Duplicate { name: name.clone() });
        }
        named.push(i);
        plan[i] = Some(spec.kind);
    }
    let mut changed = Vec::new();
    for (object, kind) in set.objects.iter_mut().zip(plan) {
        if let Some(kind) = kind {
            object.symmetry = symmetry_of(object, kind);
            changed.push((object.name.clone(), object.symmetry.clone()));
        }
    }
    Ok(changed)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::builtin::builtin_objects;
    use crate::metrics::ObjectMetric;

    fn spec(s: &str) -> SymmetrySpec {
        s.parse().unwrap()
    }

    #[test]
    fn specs_parse_and_bad_ones_name_the_fix() {
        assert_eq!(
            spec("can=continuous:z"),
            SymmetrySpec { name: Some("can".into()), kind: SymmetryKind::Continuous(Axis::Z) }
        );
        assert_eq!(spec("brick=2-fold:x").kind, SymmetryKind::Fold(2, Axis::X));
        assert_eq!(spec("b = box").kind, SymmetryKind::Box);
        assert_eq!(spec("suggested"), SymmetrySpec { name: None, kind: SymmetryKind::Suggested });
        let e = "can=cylinder".parse::<SymmetrySpec>().unwrap_err();
        assert!(matches!(&e, SymmetrySpecError::Kind { kind, .. } if kind == "cylinder"), "{e}");
        assert!(e.to_string().contains("2-fold:z"), "{e}");
        for bad in ["can=1-fold:z", "can=13-fold:z", "can=continuous:w", "can=continuous"] {
            assert!(matches!(bad.parse::<SymmetrySpec>(), Err(SymmetrySpecError::Kind { .. })), "{bad}");
        }
        assert!(matches!("continuous:z".parse::<SymmetrySpec>(), Err(SymmetrySpecError::Syntax { .. })));
        assert!(matches!("=box".parse::<SymmetrySpec>(), Err(SymmetrySpecError::Syntax { .. })));
    }

    #[test]
    fn unknown_or_repeated_objects_are_refused_and_nothing_changes() {
        let mut set = builtin_objects();
        let before: Vec<Symmetry> = set.objects.iter().map(|o| o.symmetry.clone()).collect();
        let e = apply_symmetry_specs(&mut set, &[spec("mug=box"), spec("teapot=box")]).unwrap_err();
        assert!(e.to_string().contains("teapot") && e.to_string().contains("mug"), "{e}");
        let e = apply_symmetry_specs(&mut set, &[spec("mug=box"), spec("mug=none")]).unwrap_err();
        assert_eq!(e, SymmetrySpecError::Duplicate { name: "mug".into() });
        assert_eq!(set.objects.iter().map(|o| o.symmetry.clone()).collect::<Vec<_>>(), before);
    }

    /// A declared symmetry must map the object onto itself: ADD-S of the
    /// object under each transform is ~0, while ADD sees the rotation.
    #[test]
    fn declared_symmetries_map_the_object_onto_itself() {
        let mut set = builtin_objects();
        let names = ["bowl", "wood_block"];
        let changed =
            apply_symmetry_specs(&mut set, &[spec("bowl=continuous:z"), spec("wood_block=box"), spec("mug=none")])
                .unwrap();
        assert_eq!(changed.len(), 3);
        for name in names {
            let o = &set.objects[set.class_of(name).unwrap() as usize - 1];
            assert!(o.symmetry.is_symmetric(), "{name}");
            let metric = ObjectMetric::new(&o.samples, true).unwrap();
            // What ADD-S gives for a turn that is no symmetry (the sample spacing sets the floor).
            let other = metric.add_s(&rotation_about(&Vector3::x(), 0.8, &centroid(o)), &Isometry3::identity());
            for t in o.symmetry.sampled(8).iter().skip(1) {
                let e = metric.errors(t, &Isometry3::identity());
                assert!(e.add_s < 0.5 * other, "{name}: ADD-S {} m (no symmetry: {other} m)", e.add_s);
                assert!(e.add > 0.1 * o.diameter, "{name}: ADD {} m", e.add);
            }
        }
        let mug = &set.objects[set.class_of("mug").unwrap() as usize - 1];
        assert_eq!(mug.symmetry, Symmetry::None);
    }

    #[test]
    fn bare_suggested_applies_the_geometry_and_named_specs_win() {
        let mut set = builtin_objects();
        for o in &mut set.objects {
            o.symmetry = Symmetry::None;
        }
        apply_symmetry_specs(&mut set, &[spec("suggested"), spec("wood_block=none")]).unwrap();
        let of = |n: &str| set.objects[set.class_of(n).unwrap() as usize - 1].symmetry.clone();
        match of("bowl") {
            Symmetry::Continuous { axis, origin } => {
                assert!(axis.z.abs() > 0.99, "{axis:?}");
                assert!(origin.x.abs() < 0.002 && origin.y.abs() < 0.002, "{origin:?}");
            }
            other => panic!("bowl: {}", Describe(&other)),
        }
        assert_eq!(of("mug"), Symmetry::None);
        assert_eq!(of("wood_block"), Symmetry::None);
    }
}
