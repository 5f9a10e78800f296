//! The built-in instance segmenter: a compact encoder–decoder over the whole
//! frame at reduced resolution (RGB + depth in, per-cell scores for the
//! objects and background out), whose argmax label plane feeds
//! [`crate::Workspace::prepare`] through [`crate::FrameView::labels`].
//!
//! Layout: [`config`] (architecture, tensor shapes, cost), [`file`](mod@file) (weight
//! file reading and object-set checks), [`input`] (frame ↔ grid tables:
//! network input, upsampling, training targets), [`engine`] (the forward pass
//! on preallocated buffers), [`boundary`] (cell labels → frame labels), [`depth_regions`] (cell labels regrouped by the depth image), [`voting`] (instances from centre-offset votes), [`merge`] (instances
//! closer in 3D than two copies of their object can be become one). The trainer is `fusepose_train::seg`.

pub mod boundary;
pub mod config;
pub mod depth_regions;
pub mod engine;
pub mod file;
pub mod input;
pub mod merge;
pub mod voting;

pub use boundary::Boundary;
pub use config::SegConfig;
pub use depth_regions::{DepthRegionParams, DepthRegions};
pub use engine::{FlipAverage, SegEngine, SegError};
pub use file::SegFile;
pub use input::FrameMap;
pub use voting::{VotingMode, VotingParams};
