//! Training frames produced on several threads and delivered in seed order.
//!
//! Worker `i` of `n` makes the items of seeds `first + i`, `first + i + n`, …
//! into its own bounded channel; the reader takes one seed from each channel
//! in turn. So the sequence a trainer sees is the one a single thread would
//! make, whatever `n` is: more threads change the speed of a run, never its
//! data (a seed the producer skips is passed on as `None` and stepped over).
//! Used where rendering, not the network, bounds a trainer's speed.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crossbeam::channel::{Receiver, RecvTimeoutError, bounded};

/// Why [`SeededWorkers::recv_timeout`] returned no item.
#[derive(Debug, thiserror::Error)]
pub enum RecvError {
    #[error("no training data for {0:?}")]
    Timeout(Duration),
    #[error("data thread: {0:#}")]
    Worker(anyhow::Error),
    #[error("a data thread panicked")]
    Panicked,
    #[error("the data threads stopped")]
    Stopped,
}

type Worker = JoinHandle<anyhow::Result<()>>;

/// `n` producer threads merged back into seed order.
pub struct SeededWorkers<T> {
    rxs: Vec<Receiver<Option<T>>>,
    next: usize,
    stop: Arc<AtomicBool>,
    handles: Vec<Option<Worker>>,
}

impl<T: Send + 'static> SeededWorkers<T> {
    /// Starts `threads` (at least 1) workers. Each builds its own state with
    /// `init` (render targets, scratch) and then calls `produce(&mut state,
    /// seed)` for its seeds until the reader is dropped; `capacity` items are
    /// buffered in all.
    pub fn spawn<S, I, P>(
        name: &str,
        threads: usize,
        first_seed: u64,
        capacity: usize,
        init: I,
        produce: P,
    ) -> anyhow::Result<Self>
    where
        I: Fn() -> anyhow::Result<S> + Send + Sync + 'static,
        P: Fn(&mut S, u64) -> anyhow::Result<Option<T>> + Send + Sync + 'static,
    {
        let n = threads.max(1);
        let per = capacity.div_ceil(n).max(1);
        let stop = Arc::new(AtomicBool::new(false));
        let (init, produce) = (Arc::new(init), Arc::new(produce));
        let mut rxs = Vec::with_capacity(n);
        let mut handles = Vec::with_capacity(n);
        for i in 0..n {
            let (tx, rx) = bounded(per);
            let (stop, init, produce) = (stop.clone(), init.clone(), produce.clone());
            let handle = std::thread::Builder::new()
                .name(format!("{name}-{i}"))
                .spawn(move || -> anyhow::Result<()> {
                    let mut state = init()?;
                    let mut seed = first_seed + i as u64;
                    while !stop.load(Ordering::Relaxed) {
                        if tx.send(produce(&mut state, seed)?).is_err() {
                            return Ok(());
                        }
                        seed += n as u64;
                    }
                    Ok(())
                })
                .map_err(|e| anyhow::anyhow!("spawning data thread {name}-{i}: {e}"))?;
            rxs.push(rx);
            handles.push(Some(handle));
        }
        Ok(Self { rxs, next: 0, stop, handles })
    }

    /// The next item in seed order, waiting at most `timeout` for it.
    pub fn recv_timeout(&mut self, timeout: Duration) -> Result<T, RecvError> {
        let deadline = Instant::now() + timeout;
        loop {
            let i = self.next;
            let left = deadline.saturating_duration_since(Instant::now());
            match self.rxs[i].recv_timeout(left) {
                Ok(item) => {
                    self.next = (i + 1) % self.rxs.len();
                    if let Some(item) = item {
                        return Ok(item);
                    }
                }
                Err(RecvTimeoutError::Timeout) => {
                    self.check()?;
                    return Err(RecvError::Timeout(timeout));
                }
                Err(RecvTimeoutError::Disconnected) => {
                    // Its sender is gone, so worker `i` has returned or is returning.
                    return Err(match self.handles[i].take().map(JoinHandle::join) {
                        Some(Ok(Err(e))) => RecvError::Worker(e),
                        Some(Err(_)) => RecvError::Panicked,
                        Some(Ok(Ok(()))) | None => RecvError::Stopped,
                    });
                }
            }
        }
    }

    /// A worker's error, if one has died.
    pub fn check(&mut self) -> Result<(), RecvError> {
        for slot in &mut self.handles {
            if slot.as_ref().is_some_and(JoinHandle::is_finished)
                && let Some(h) = slot.take()
            {
                match h.join() {
                    Ok(Ok(())) => {}
                    Ok(Err(e)) => return Err(RecvError::Worker(e)),
                    Err(_) => return Err(RecvError::Panicked),
                }
            }
        }
        Ok(())
    }
}

impl<T> Drop for SeededWorkers<T> {
    fn drop(&mut self) {
        // Workers see the flag after their current item; dropping the
        // receivers (after this) fails a send they are blocked in.
        self.stop.store(true, Ordering::Relaxed);
        for rx in &self.rxs {
            while rx.try_recv().is_ok() {}
        }
    }
}

/// Data threads for a trainer on this machine: one per core.
pub fn default_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn squares(threads: usize, count: usize) -> Vec<u64> {
        // Seeds divisible by 5 are skipped, as a sampler skips scenes it cannot place.
        let mut w = SeededWorkers::spawn(
            "test",
            threads,
            100,
            8,
            || Ok(0u64),
            |calls, seed| {
                *calls += 1;
                // Uneven work so that the threads finish out of order.
                std::thread::sleep(Duration::from_micros((seed * 7919 % 13) * 50));
                Ok((seed % 5 != 0).then_some(seed * seed))
            },
        )
        .unwrap();
        (0..count).map(|_| w.recv_timeout(Duration::from_secs(10)).unwrap()).collect()
    }

    #[test]
    fn any_thread_count_gives_the_single_thread_sequence() {
        let one = squares(1, 40);
        assert_eq!(one[..4], [101 * 101, 102 * 102, 103 * 103, 104 * 104]);
        assert!(!one.contains(&(105 * 105)), "a skipped seed is stepped over");
        for n in [2, 3, 5] {
            assert_eq!(squares(n, 40), one, "{n} threads");
        }
    }

    #[test]
    fn a_worker_error_reaches_the_reader() {
        let mut w = SeededWorkers::spawn(
            "test",
            2,
            0,
            4,
            || Ok(()),
            |_, seed| if seed == 3 { anyhow::bail!("scene {seed} has no table") } else { Ok(Some(seed)) },
        )
        .unwrap();
        let got: Vec<_> = (0..3).map(|_| w.recv_timeout(Duration::from_secs(10)).unwrap()).collect();
        assert_eq!(got, [0, 1, 2]);
        let err = w.recv_timeout(Duration::from_secs(10)).unwrap_err();
        assert!(err.to_string().contains("scene 3 has no table"), "{err}");
    }

    #[test]
    fn a_failing_init_is_reported() {
        let mut w = SeededWorkers::<u64>::spawn(
            "test",
            2,
            0,
            4,
            || -> anyhow::Result<()> { anyhow::bail!("no memory for the render target") },
            |_, s| Ok(Some(s)),
        )
        .unwrap();
        let err = w.recv_timeout(Duration::from_secs(10)).unwrap_err();
        assert!(err.to_string().contains("no memory for the render target"), "{err}");
    }
}
