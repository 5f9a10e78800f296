//! # fusepose-estimator — pure compute from one RGB-D frame to object poses
//!
//! Frame validation, instances from a label plane (pieces of one object
//! split by an occluder joined again), per-instance point sampling and colour crops in a preallocated [`Workspace`], the ICP
//! baseline, and the fusion-network and segmenter inference engines.
//!
//! This crate touches memory only: no IPC, no files except reading weight
//! files on request, no global state. After a warm-up frame, estimating a
//! frame performs no heap allocation. Depends on `fusepose-scene` for object
//! models and intrinsics; never on the daemon, client or trainer.

pub mod alternates;
pub mod contact_cut;
pub mod cpu_pin;
pub mod creases;
pub mod duplicates;
pub mod explained;
pub mod exposure;
pub mod frame;
pub mod icp;
pub mod instances;
pub mod interpenetration;
mod moments;
pub mod net;
pub mod parts;
pub mod pose_odds;
pub mod poses;
pub mod recut;
pub mod remask;
pub mod resident;
pub mod sample_normals;
pub mod sampling;
pub mod seg;
mod settings;
pub mod split;
pub mod support;
pub mod tracking;
pub mod verify;
pub mod white_balance;
pub mod workspace;

pub use frame::{ColorFormat, DepthCensus, DepthPlane, FrameError, FrameView, LabelPlane};
pub use icp::{IcpConfig, IcpEstimator};
pub use poses::{ObjectPose, PoseSet};
pub use workspace::{CutHint, HintedCut, Instance, PrepareStats, Workspace, WorkspaceConfig, WorkspaceConfigError};

/// Everything that turns a validated frame (with instances already in the
/// workspace) into poses. Implemented by the ICP baseline and the fusion network.
pub trait Estimator: Send {
    /// Short name for logs and tables (`icp`, `net`).
    fn name(&self) -> &str;

    /// Estimates one pose per instance prepared in `ws` (by
    /// [`Workspace::prepare`]) and writes them into `out` (cleared first).
    /// Must not allocate after the first call with the same workspace sizes.
    fn estimate(&mut self, frame: &FrameView<'_>, ws: &mut Workspace, out: &mut PoseSet) -> Result<(), EstimateError>;

    /// Caps the iterations (refiner steps for the network) of the next
    /// [`Estimator::estimate`] call only, e.g. when the daemon is behind its
    /// deadline. Estimators without iterations to trade ignore it.
    fn cap_next_frame(&mut self, _max_iterations: usize) {}

    /// The next [`Estimator::estimate`] call should end by `deadline` (None:
    /// no deadline). Estimators that can trade accuracy for time do so
    /// (the network: fewer refiner iterations, then fewer points).
    fn set_deadline(&mut self, _deadline: Option<std::time::Instant>) {}

    /// Instances the last [`Estimator::estimate`] left without a pose because
    /// its deadline did not pay for them (the smallest of the frame).
    fn shed(&self) -> usize {
        0
    }

    /// Whether the last [`Estimator::estimate`] shed an instance of class
    /// `class_id` ([`Estimator::shed`]): its absence from the poses says
    /// nothing about the object.
    fn shed_class(&self, _class_id: u16) -> bool {
        false
    }

    /// Whether the last [`Estimator::estimate`] gave up accuracy to meet its deadline.
    fn degraded(&self) -> bool {
        false
    }
}

/// Why an estimator could not produce poses for a frame.
#[derive(Debug, thiserror::Error)]
pub enum EstimateError {
    #[error("invalid frame: {0}")]
    Frame(#[from] FrameError),
    #[error("class id {0} is not in the estimator's object set")]
    UnknownClass(u16),
}
