//! Optional CPU pinning of the calling thread (Linux `sched_setaffinity`):
//! keeps the daemon's loop and network worker on their own cores, away from
//! each other's caches and from migrations.

/// Pins the calling thread to CPU `cpu`.
pub fn pin_current_thread(cpu: usize) -> std::io::Result<()> {
    if cpu >= libc::CPU_SETSIZE as usize {
        return Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, format!("cpu {cpu} out of range")));
    }
    // SAFETY: cpu_set_t is plain data; CPU_ZERO/CPU_SET write within it (cpu < CPU_SETSIZE).
    let rc = unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        libc::CPU_ZERO(&mut set);
        libc::CPU_SET(cpu, &mut set);
        libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set)
    };
    if rc == 0 { Ok(()) } else { Err(std::io::Error::last_os_error()) }
}

#[cfg(test)]
mod tests {
    #[test]
    fn pinning_to_cpu_0_works_and_a_huge_id_is_refused() {
        // On a separate thread so the test harness thread keeps its affinity.
        std::thread::spawn(|| super::pin_current_thread(0).unwrap()).join().unwrap();
        assert!(super::pin_current_thread(1 << 20).is_err());
    }
}
