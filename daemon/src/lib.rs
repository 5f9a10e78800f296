//! # fusepose-daemon — `fuseposed`, the loop that turns frames into poses
//!
//! Ingest from iceoryx2, validation, the estimator on preallocated buffers,
//! deadline accounting, HdrHistogram latency histograms and stats. May touch
//! the client (IPC) and the estimator; never the trainer.
//!
//! The loop is single-threaded: iceoryx2 `ipc` ports are not `Send`, and a
//! frame is processed while its shared-memory sample is borrowed. One daemon
//! serves several cameras: their frames take turns, earliest deadline first,
//! on one copy of the weights, and their poses meet in one cell frame.

pub mod camera;
pub mod camera_lock;
pub mod camera_set;
pub mod cell;
pub mod cell_output;
pub mod config;
pub mod confirm;
pub mod counters;
pub mod engine;
pub mod event_loop;
pub mod frame_view;
pub mod interval_log;
pub mod ipc_root;
pub mod latency;
pub mod rate_limited_log;
pub mod reload;
pub mod schedule;
pub mod stable_ids;
pub mod startup_cost;

pub use config::{DaemonConfig, EstimatorKind};
pub use event_loop::{RunOptions, RunReport, run, run_with};
