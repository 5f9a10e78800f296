//! Buffers whose pages are resident before the first frame.
//!
//! Zeroed allocations (`vec![0.0; n]`, `Array::zeros`) come from `calloc`,
//! whose large blocks are fresh mappings that the kernel backs page by page
//! on first write. A preallocated buffer whose last rows are first used
//! minutes into a run (more sampled points after a degraded stretch, one
//! more instance than any frame before) then takes page faults inside the
//! frame loop and shows up as growth of the daemon's private memory
//! (`tests/tests/reliability_soak_net.rs` measured a 624 KiB step at 80 s).
//! Writing one element per page at construction moves that cost to start-up.

use std::hint::black_box;

/// Bytes per page assumed when touching (the smallest page size of the
/// platforms served; larger pages are touched more than once, harmlessly).
const PAGE: usize = 4096;

/// Writes one element of every page of `buf` (its own value back, through
/// [`black_box`] so the store is not elided), making the pages resident.
pub fn touch<T: Copy>(buf: &mut [T]) {
    let step = (PAGE / std::mem::size_of::<T>().max(1)).max(1);
    for x in buf.iter_mut().step_by(step) {
        *x = black_box(*x);
    }
    if let Some(last) = buf.last_mut() {
        *last = black_box(*last);
    }
}

/// `vec![zero; n]` with every page resident.
pub fn vec<T: Copy>(zero: T, n: usize) -> Vec<T> {
    let mut v = vec![zero; n];
    touch(&mut v);
    v
}

/// Reserves room for `additional` more elements of `v` and makes the pages
/// of its whole spare capacity resident.
pub fn reserve<T: Copy + Default>(v: &mut Vec<T>, additional: usize) {
    v.reserve(additional);
    let spare = v.spare_capacity_mut();
    let step = (PAGE / std::mem::size_of::<T>().max(1)).max(1);
    for x in spare.iter_mut().step_by(step) {
        x.write(T::default());
    }
    black_box(spare);
}

/// An array of `shape` filled with `value`, with every page resident.
pub fn array<A: Copy, Sh: ndarray::ShapeBuilder<Dim = D>, D: ndarray::Dimension>(
    shape: Sh,
    value: A,
) -> ndarray::Array<A, D> {
    let mut a = ndarray::Array::from_elem(shape, value);
    touch(a.as_slice_memory_order_mut().expect("a new array is contiguous"));
    a
}

#[cfg(test)]
mod tests {
    /// Resident-set size of this process in KiB (Linux), for the test below.
    fn rss_anon_kib() -> Option<u64> {
        let status = std::fs::read_to_string("/proc/self/status").ok()?;
        let line = status.lines().find(|l| l.starts_with("RssAnon:"))?;
        line.split_whitespace().nth(1)?.parse().ok()
    }

    #[test]
    fn a_resident_buffer_is_backed_by_memory_before_it_is_used() {
        let Some(before) = rss_anon_kib() else {
            eprintln!("skipped: no /proc/self/status RssAnon on this platform");
            return;
        };
        // 64 MiB each, judged with 16 MiB of room either way: other tests of
        // this binary allocate and free meanwhile, by far less.
        let lazy = vec![0.0f32; 16 << 20];
        let after_lazy = rss_anon_kib().unwrap();
        let touched = super::vec(0.0f32, 16 << 20);
        let after_touched = rss_anon_kib().unwrap();
        let a = super::array((4096, 4096), 0u32);
        let after_array = rss_anon_kib().unwrap();
        assert!(after_lazy < before + 16 * 1024, "calloc'd buffer already resident: {before} -> {after_lazy} KiB");
        assert!(
            after_touched >= after_lazy + 48 * 1024,
            "touched buffer not resident: {after_lazy} -> {after_touched} KiB"
        );
        assert!(
            after_array >= after_touched + 48 * 1024,
            "touched array not resident: {after_touched} -> {after_array} KiB"
        );
        assert!(touched.iter().all(|&v| v == 0.0) && a.iter().all(|&v| v == 0));
        drop((lazy, touched, a));
    }
}
