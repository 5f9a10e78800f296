//! CPU time of the calling thread (`CLOCK_THREAD_CPUTIME_ID`): on a loaded
//! machine the wall time of a stage includes the time other processes held
//! the core; its CPU time does not.

/// Milliseconds of CPU time this thread has used (0 where the clock is unavailable).
pub fn thread_cpu_ms() -> f64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid, writable timespec.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    if rc != 0 {
        return 0.0;
    }
    ts.tv_sec as f64 * 1e3 + ts.tv_nsec as f64 * 1e-6
}
