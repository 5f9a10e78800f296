//! The fusion-network inference engine: loads the trainer's safetensors file,
//! checks it against the object set, and runs the pose net and the integrated
//! refiner on buffers allocated once.
//!
//! Layout: [`config`] (hyper-parameters), [`meta`] (metadata keys, object
//! hashes), [`weights`] (loading with typed errors), [`gemm`] (fused
//! GEMM + bias + ReLU, im2col convolutions), [`engine`] (the forward pass),
//! [`estimator`] (the [`crate::Estimator`] implementation), [`budget`] and
//! [`shed_order`] (what a late frame gives up, and which instances first).

pub mod budget;
pub mod config;
pub mod engine;
pub mod estimator;
pub mod gemm;
pub mod meta;
pub mod shed_order;
pub mod weights;

pub use config::NetConfig;
pub use engine::{Engine, Scratch};
pub use estimator::{NetEstimator, NetOptions};
pub use meta::{ObjectEntry, TrainRecord};
pub use weights::{NetLoadError, WeightFile};
