//! # fusepose-scene — the world the estimator is trained on and judged by
//!
//! Object models (OBJ/PLY loading, the built-in and procedural object sets), the CPU RGB-D
//! renderer and its sensor-noise model, the tabletop scene sampler, datasets
//! (BOP read/write, YCB-Video read) and pose metrics (ADD, ADD-S, AUC).
//!
//! This crate touches files and memory only: no IPC, no networks, no threads
//! that outlive a call. Every other fusepose crate may depend on it.
//!
//! Conventions used everywhere in fusepose:
//! - lengths in metres, times in seconds unless a name says `_ns`;
//! - the camera optical frame: x right, y down, z forward;
//! - a pose maps object coordinates into camera coordinates:
//!   `p_cam = R * p_obj + t`;
//! - quaternions on the wire are `[x, y, z, w]` (Hamilton, scalar last).

pub mod camera;
pub mod model;

pub use camera::Intrinsics;
pub use model::{Material, Mesh, ObjectModel, ObjectSet, Pose, Symmetry, Texture};
pub mod bop;
pub mod builtin;
pub mod contact_sheet;
pub mod export;
pub mod mesh_io;
pub mod metrics;
pub mod overlay;
pub mod procedural;
pub mod render;
pub mod sampler;
pub mod shadow_mesh;
pub mod surface;
pub mod symmetry_spec;
pub mod ycbv;
