//! The estimator's output: one pose per object instance of a frame.

use nalgebra::{UnitQuaternion, Vector3};

/// One object's estimated pose in the camera optical frame (x right, y down, z forward).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ObjectPose {
    /// Class id (1-based index into the object set; 0 never appears here).
    pub class_id: u16,
    /// Instance index within the frame (order of [`crate::Workspace`] instances).
    pub instance_id: u16,
    /// Rotation object → camera.
    pub rotation: UnitQuaternion<f64>,
    /// Translation object → camera, metres.
    pub translation: Vector3<f64>,
    /// Estimator-specific confidence in [0, 1]; higher is better.
    pub confidence: f32,
    /// Pixels in the instance mask.
    pub mask_pixels: u32,
    /// Bounding box in pixels: [u_min, v_min, u_max, v_max] inclusive.
    pub bbox: [u16; 4],
    /// Iterations used (ICP iterations, or refiner iterations for the network).
    pub iterations: u16,
}

/// The poses of one frame; capacity fixed at construction so filling it never allocates.
#[derive(Clone, Debug)]
pub struct PoseSet {
    poses: Vec<ObjectPose>,
    capacity: usize,
}

impl PoseSet {
    pub fn with_capacity(capacity: usize) -> Self {
        Self { poses: Vec::with_capacity(capacity), capacity }
    }

    pub fn clear(&mut self) {
        self.poses.clear();
    }

    /// Adds a pose; returns false (and drops it) when the set is full.
    pub fn push(&mut self, pose: ObjectPose) -> bool {
        if self.poses.len() >= self.capacity {
            return false;
        }
        self.poses.push(pose);
        true
    }

    pub fn as_slice(&self) -> &[ObjectPose] {
        &self.poses
    }

    pub fn len(&self) -> usize {
        self.poses.len()
    }

    pub fn is_empty(&self) -> bool {
        self.poses.is_empty()
    }

    pub fn capacity(&self) -> usize {
        self.capacity
    }
}
