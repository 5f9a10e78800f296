//! # fusepose-train — the trainer
//!
//! Trains the fusion network and its integrated refiner with burn (flex CPU
//! backend; a Vulkan GPU with the opt-in `gpu` feature, [`device`]) on scenes rendered on the fly, and writes the safetensors file the
//! estimator engine loads. Touches files and CPU threads; never IPC.
//!
//! Modules: [`model`] (the network), [`geometry`] (rotations), [`loss`]
//! (DenseFusion loss, symmetry-aware), [`data`] (background sample generation),
//! [`store`] (checkpoints and the shipped weight file), [`trainer`] (the loop),
//! [`validate`] (held-out metrics), [`seg`] (the instance segmenter's trainer),
//! [`seeded_workers`] (frames rendered on several threads, in seed order).

pub mod bench;
pub mod data;
pub mod device;
pub mod geometry;
pub mod loss;
pub mod model;
pub mod seeded_workers;
pub mod seg;
pub mod store;
pub mod trainer;
pub mod validate;
pub mod warm_start;
