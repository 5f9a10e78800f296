//! Rate-limited warnings: bad input from the DDS side is reported at most once
//! per interval per kind, with the number of repeats suppressed meanwhile.

use std::collections::HashMap;
use std::time::{Duration, Instant};

/// Per-key limiter for warning lines.
pub struct RateLog {
    interval: Duration,
    last: HashMap<&'static str, (Instant, u64)>,
}

impl Default for RateLog {
    fn default() -> Self {
        Self::new(Duration::from_secs(5))
    }
}

impl RateLog {
    pub fn new(interval: Duration) -> Self {
        Self { interval, last: HashMap::new() }
    }

    /// Logs `message` as a warning unless `key` was logged less than the interval ago.
    pub fn warn(&mut self, key: &'static str, message: impl FnOnce() -> String) {
        if let Some(line) = self.check(key, Instant::now(), message) {
            tracing::warn!("{line}");
        }
    }

    /// The line to log for `key` at `now`, if any (suppressed repeats counted in it).
    fn check(&mut self, key: &'static str, now: Instant, message: impl FnOnce() -> String) -> Option<String> {
        match self.last.get_mut(key) {
            Some((at, suppressed)) if now.duration_since(*at) < self.interval => {
                *suppressed += 1;
                None
            }
            Some((at, suppressed)) => {
                let n = std::mem::take(suppressed);
                *at = now;
                Some(if n > 0 { format!("{} ({n} more like it suppressed)", message()) } else { message() })
            }
            None => {
                self.last.insert(key, (now, 0));
                Some(message())
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn repeats_within_the_interval_are_counted_not_logged() {
        let mut log = RateLog::new(Duration::from_secs(5));
        let t0 = Instant::now();
        assert_eq!(log.check("enc", t0, || "bad".into()).as_deref(), Some("bad"));
        assert_eq!(log.check("enc", t0 + Duration::from_secs(1), || "bad".into()), None);
        assert_eq!(log.check("size", t0 + Duration::from_secs(1), || "other".into()).as_deref(), Some("other"));
        assert_eq!(log.check("enc", t0 + Duration::from_secs(2), || "bad".into()), None);
        assert_eq!(
            log.check("enc", t0 + Duration::from_secs(6), || "bad".into()).as_deref(),
            Some("bad (2 more like it suppressed)")
        );
    }
}
