//! Training the built-in instance segmenter (`fusepose_estimator::seg`):
//! [`model`] (the encoder–decoder in burn), [`loss`] (class-weighted
//! cross-entropy), [`data`] (frames rendered on the fly, augmentation),
//! [`store`] (weight files and checkpoints), [`validate`] (held-out mIoU and
//! per-class IoU through the engine), [`certainty`] (how sure it is of real
//! objects, stored for the verifier), [`adapt`] (pseudo-labelled frames of
//! the camera it will serve), [`trainer`] (the loop).

pub mod adapt;
pub mod certainty;
pub mod data;
pub mod loss;
pub mod model;
pub mod store;
pub mod trainer;
pub mod validate;

pub use trainer::{SegTrainConfig, SegTrainReport, train_segmenter};
pub use validate::SegValidation;
