//! # fusepose-bench — benchmarks that print measured numbers
//!
//! Every benchmark prints medians and tail percentiles with units and the
//! machine load before and after; none asserts on timings.
//!
//! - [`estimator`]: per-stage latency of sampling, the fusion network (pose
//!   net, refiner) and the ICP baseline on rendered frames, GEMM peak and
//!   achieved GFLOP/s, allocations per steady-state frame, a PNG plot.
//! - [`transport`]: one-way frame latency, iceoryx2 (three receive
//!   strategies) against a Unix-socket copy, in the same run.
//! - [`e2e`]: daemon + producer (rendered video) + consumer processes at
//!   given frame rates: latency, achieved FPS, skipped and late frames.
//! - [`tracking`]: the network with and without tracking mode on rendered
//!   videos: time per object, poses/s, accuracy, allocations.
//! - [`ros2_bridges`]: latency and CPU of the ROS 2 bridges (DDS in, DDS out)
//!   around a real daemon, this process playing the ROS 2 graph.
//! - [`alloc_count`]: the counting global allocator the binary installs.
//! - [`cpu_time`]: the calling thread's CPU time, beside wall time.
//! - [`summary`]: median / p90 / p99 of a sample.
//! - [`loadavg`]: `/proc/loadavg`, printed around every run.

pub mod alloc_count;
pub mod child;
pub mod cpu_time;
pub mod e2e;
pub mod estimator;
pub mod latency;
pub mod loadavg;
pub mod ros2_bridges;
pub mod summary;
pub mod tracking;
pub mod transport;
pub mod video;
