//! The `.hlog` file: HdrHistogram interval log (V2 compressed histograms, one
//! line per timeline per window, tagged `<camera>.<timeline>`), readable by
//! HdrHistogram's standard log processors.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use hdrhistogram::Histogram;
use hdrhistogram::serialization::interval_log::{IntervalLogWriterBuilder, Tag};
use hdrhistogram::serialization::{Serializer, V2DeflateSerializer};

/// Writes interval histograms as windows close; flushed after each window.
pub struct IntervalLog {
    path: PathBuf,
    file: BufWriter<File>,
    serializer: V2DeflateSerializer,
    /// CLOCK_MONOTONIC ns at the log's BaseTime.
    base_monotonic_ns: u64,
}

impl IntervalLog {
    /// Creates (truncates) the log and writes its header.
    pub fn create(path: &Path, base_monotonic_ns: u64, comment: &str) -> std::io::Result<Self> {
        let mut file = BufWriter::new(File::create(path)?);
        let mut serializer = V2DeflateSerializer::new();
        let now = SystemTime::now();
        IntervalLogWriterBuilder::new()
            .add_comment(comment)
            .add_comment("Values are nanoseconds; Interval_Max is in milliseconds (MaxValueDivisor 1e6).")
            .with_start_time(now)
            .with_base_time(now)
            .with_max_value_divisor(1e6)
            .begin_log_with(&mut file, &mut serializer)?;
        writeln!(file, "\"StartTimestamp\",\"Interval_Length\",\"Interval_Max\",\"Interval_Compressed_Histogram\"")?;
        file.flush()?;
        warm_up(&mut serializer)?;
        Ok(Self { path: path.to_owned(), file, serializer, base_monotonic_ns })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Appends one interval histogram (skipped when empty) and flushes.
    pub fn write(&mut self, tag: &str, start_ns: u64, end_ns: u64, histogram: &Histogram<u64>) -> std::io::Result<()> {
        if histogram.is_empty() {
            return Ok(());
        }
        let start = Duration::from_nanos(start_ns.saturating_sub(self.base_monotonic_ns));
        let duration = Duration::from_nanos(end_ns.saturating_sub(start_ns));
        let mut writer = IntervalLogWriterBuilder::new()
            .with_max_value_divisor(1e6)
            .begin_log_with(&mut self.file, &mut self.serializer)?;
        writer
            .write_histogram(histogram, start, duration, Tag::new(tag))
            .map_err(|e| std::io::Error::other(e.to_string()))?;
        self.file.flush()
    }
}

/// The serializer sizes (and zero-fills) its buffer for the highest value a
/// histogram holds, so the first window with a new longest latency (a
/// deadline miss) would grow the daemon's memory mid-run by hundreds of KiB.
/// Serializing the largest value the daemon records once at start-up sizes
/// it for every later window.
fn warm_up(serializer: &mut V2DeflateSerializer) -> std::io::Result<()> {
    let mut widest = crate::latency::new_histogram();
    widest.saturating_record(crate::latency::MAX_NS);
    serializer.serialize(&widest, &mut std::io::sink()).map_err(|e| std::io::Error::other(format!("{e:?}")))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use hdrhistogram::serialization::Deserializer;
    use hdrhistogram::serialization::interval_log::{IntervalLogIterator, LogEntry};

    #[test]
    fn written_log_reads_back_with_the_standard_parser() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.hlog");
        let mut log = IntervalLog::create(&path, 1_000, "test").unwrap();
        let mut h = Histogram::<u64>::new_with_bounds(1, 60_000_000_000, 3).unwrap();
        h.record(2_000_000).unwrap();
        h.record(3_000_000).unwrap();
        log.write("cam0.end_to_end", 1_000, 10_000_001_000, &h).unwrap();
        drop(log);
        let text = std::fs::read(&path).unwrap();
        let mut found = 0;
        for entry in IntervalLogIterator::new(&text) {
            if let LogEntry::Interval(i) = entry.unwrap() {
                assert_eq!(i.tag().unwrap().as_str(), "cam0.end_to_end");
                assert_eq!(i.duration(), Duration::from_secs(10));
                let bytes = base64_decode(i.encoded_histogram());
                let back: Histogram<u64> = Deserializer::new().deserialize(&mut &bytes[..]).unwrap();
                assert_eq!(back.len(), 2);
                found += 1;
            }
        }
        assert_eq!(found, 1);
    }

    /// Minimal standard base64 decoder for the test.
    fn base64_decode(s: &str) -> Vec<u8> {
        let val = |c: u8| match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            _ => 63,
        };
        let bytes: Vec<u8> = s.bytes().filter(|&c| c != b'=').collect();
        let mut out = Vec::new();
        for chunk in bytes.chunks(4) {
            let mut acc = 0u32;
            for (i, &c) in chunk.iter().enumerate() {
                acc |= (val(c) as u32) << (18 - 6 * i);
            }
            out.extend_from_slice(&acc.to_be_bytes()[1..chunk.len()]);
        }
        out
    }
}
