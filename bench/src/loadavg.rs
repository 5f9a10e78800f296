//! The machine load, read from `/proc/loadavg` (printed before and after a run).

/// The 1, 5 and 15 minute load averages and runnable/total tasks, or `n/a`.
pub fn loadavg() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(4).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "n/a".into())
}

/// Logical CPUs available to this process.
pub fn cpus() -> usize {
    // Online CPUs of the machine, not this (possibly pinned) thread's share.
    // SAFETY: sysconf has no preconditions.
    let n = unsafe { libc::sysconf(libc::_SC_NPROCESSORS_ONLN) };
    if n > 0 { n as usize } else { std::thread::available_parallelism().map_or(1, |n| n.get()) }
}
