//! Stats wire format: request and snapshot of the daemon's counters and latency histograms.

use iceoryx2::prelude::ZeroCopySend;

use crate::InvalidReason;

/// Pipeline stages timed per frame (index into `stage_ns` and the stats arrays).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    /// Take the newest frame from shared memory, validate it, build the view.
    Ingest = 0,
    /// Segmentation network (0 when the producer supplies labels).
    Segmentation = 1,
    /// Instances from labels, point sampling, colour crops (`Workspace::prepare`).
    Sampling = 2,
    /// Pose network (the fusion estimator).
    Network = 3,
    /// Iterative refinement (ICP, or the network's refiner when reported apart).
    Refine = 4,
    /// Write the pose message into shared memory, send, notify.
    Publish = 5,
}

/// Number of [`Stage`]s.
pub const STAGE_COUNT: usize = 6;
/// Stages plus end-to-end (capture → publish), the last entry of the stats arrays.
pub const TIMELINE_COUNT: usize = STAGE_COUNT + 1;

impl Stage {
    pub const ALL: [Stage; STAGE_COUNT] =
        [Self::Ingest, Self::Segmentation, Self::Sampling, Self::Network, Self::Refine, Self::Publish];

    pub fn name(self) -> &'static str {
        match self {
            Self::Ingest => "ingest",
            Self::Segmentation => "segmentation",
            Self::Sampling => "sampling",
            Self::Network => "network",
            Self::Refine => "refine",
            Self::Publish => "publish",
        }
    }

    /// Names of the stats timelines: the stages, then `end_to_end`.
    pub fn timeline_names() -> [&'static str; TIMELINE_COUNT] {
        ["ingest", "segmentation", "sampling", "network", "refine", "publish", "end_to_end"]
    }
}

/// A stats query (the daemon answers with one [`StatsSnapshot`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, ZeroCopySend)]
#[type_name("fusepose::StatsRequest")]
pub struct StatsRequest {
    pub format_version: u16,
    pub _reserved: [u8; 6],
}

impl Default for StatsRequest {
    fn default() -> Self {
        Self { format_version: crate::WIRE_VERSION, _reserved: [0; 6] }
    }
}

/// Percentiles of one latency histogram, ns (all 0 when `count` is 0).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("fusepose::LatencySummary")]
pub struct LatencySummary {
    pub count: u64,
    pub p50_ns: u64,
    pub p90_ns: u64,
    pub p99_ns: u64,
    pub p999_ns: u64,
    pub max_ns: u64,
}

/// The daemon's counters and latency percentiles for one camera.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, ZeroCopySend)]
#[type_name("fusepose::StatsSnapshot")]
pub struct StatsSnapshot {
    pub format_version: u16,
    pub _reserved: u16,
    pub camera_id: u32,
    /// Daemon uptime, ns.
    pub uptime_ns: u64,
    /// Length of the window `last_window` covers (the last completed one), ns.
    pub window_ns: u64,
    /// Deadline from capture to publish, ns.
    pub deadline_ns: u64,
    /// Frames taken from shared memory and handled: processed, refused, or
    /// dropped as stale (a frame waiting for its turn counts once handled).
    pub frames_received: u64,
    /// Frames run through the estimator and published as poses.
    pub frames_processed: u64,
    /// Frames received but superseded by a newer one before processing.
    pub frames_skipped_stale: u64,
    /// Sequence numbers never received (gaps: dropped by the producer or overwritten in the buffer).
    pub frames_missed_sequence: u64,
    /// Frames rejected as invalid (sum of `invalid_by_reason`).
    pub frames_invalid: u64,
    /// Rejections per [`InvalidReason`] code.
    pub invalid_by_reason: [u64; InvalidReason::COUNT],
    /// Published later than `deadline_ns` after capture.
    pub deadline_misses: u64,
    /// Frames where the estimator failed.
    pub estimator_failures: u64,
    /// Object poses the estimator returned with a NaN/infinite value, dropped
    /// instead of published.
    pub poses_non_finite: u64,
    /// Times a frame came from a new publisher (producer restarted).
    pub producer_restarts: u64,
    /// Per [`Stage`] then end-to-end, since the daemon started.
    pub since_start: [LatencySummary; TIMELINE_COUNT],
    /// Per [`Stage`] then end-to-end, over `window_ns`.
    pub last_window: [LatencySummary; TIMELINE_COUNT],
    /// Poses the depth check failed (`estimator.verify`): dropped with
    /// `drop`, published without the VERIFIED flag with `flag`.
    pub poses_failed_verification: u64,
    /// Instances left without a pose because the frame's deadline did not
    /// pay for them (they take turns across frames; the message is DEGRADED).
    pub objects_shed: u64,
    /// Messages flagged DEGRADED.
    pub frames_degraded: u64,
}

impl Default for StatsSnapshot {
    fn default() -> Self {
        Self {
            format_version: crate::WIRE_VERSION,
            _reserved: 0,
            camera_id: 0,
            uptime_ns: 0,
            window_ns: 0,
            deadline_ns: 0,
            frames_received: 0,
            frames_processed: 0,
            frames_skipped_stale: 0,
            frames_missed_sequence: 0,
            frames_invalid: 0,
            invalid_by_reason: [0; InvalidReason::COUNT],
            deadline_misses: 0,
            estimator_failures: 0,
            poses_non_finite: 0,
            producer_restarts: 0,
            since_start: [LatencySummary::default(); TIMELINE_COUNT],
            last_window: [LatencySummary::default(); TIMELINE_COUNT],
            poses_failed_verification: 0,
            objects_shed: 0,
            frames_degraded: 0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::mem::{align_of, offset_of, size_of};

    /// The `## Stats` section of docs/PROTOCOL.md.
    fn stats_section() -> &'static str {
        let doc = include_str!("../../docs/PROTOCOL.md");
        let start = doc.find("\n## Stats\n").expect("PROTOCOL.md has a Stats section");
        let rest = &doc[start + 1..];
        let end = rest[3..].find("\n## ").map_or(rest.len(), |i| i + 3);
        &rest[..end]
    }

    /// (size, alignment, [(field, offset)]) of the table introduced by `` `Name` (`fusepose::Name` ``.
    fn documented(section: &str, name: &str) -> (usize, usize, Vec<(String, usize)>) {
        let intro = format!("`{name}` (`fusepose::{name}`");
        let at = section.find(&intro).unwrap_or_else(|| panic!("no table for {name}"));
        let text = &section[at..];
        let number_after = |key: &str| -> usize {
            let i = text.find(key).unwrap_or_else(|| panic!("{name}: no `{key}`")) + key.len();
            text[i..]
                .trim_start_matches(['*', ' '])
                .chars()
                .take_while(char::is_ascii_digit)
                .collect::<String>()
                .parse()
                .unwrap()
        };
        let (size, align) = (number_after("size "), number_after("alignment "));
        let table = &text[text.find("\n|").expect("a table")..];
        let mut fields = Vec::new();
        for line in table.lines().skip(1) {
            if !line.starts_with('|') {
                break;
            }
            let cells: Vec<&str> = line.split('|').map(str::trim).collect();
            if let (Ok(offset), Some(field)) = (cells[1].parse::<usize>(), cells.get(2)) {
                fields.push((field.trim_matches('`').to_owned(), offset));
            }
        }
        (size, align, fields)
    }

    #[test]
    fn protocol_doc_tables_match_the_stats_layouts() {
        let section = stats_section();
        let (size, align, fields) = documented(section, "StatsSnapshot");
        assert_eq!((size, align), (size_of::<StatsSnapshot>(), align_of::<StatsSnapshot>()), "StatsSnapshot size");
        let actual = [
            ("format_version", offset_of!(StatsSnapshot, format_version)),
            ("_reserved", offset_of!(StatsSnapshot, _reserved)),
            ("camera_id", offset_of!(StatsSnapshot, camera_id)),
            ("uptime_ns", offset_of!(StatsSnapshot, uptime_ns)),
            ("window_ns", offset_of!(StatsSnapshot, window_ns)),
            ("deadline_ns", offset_of!(StatsSnapshot, deadline_ns)),
            ("frames_received", offset_of!(StatsSnapshot, frames_received)),
            ("frames_processed", offset_of!(StatsSnapshot, frames_processed)),
            ("frames_skipped_stale", offset_of!(StatsSnapshot, frames_skipped_stale)),
            ("frames_missed_sequence", offset_of!(StatsSnapshot, frames_missed_sequence)),
            ("frames_invalid", offset_of!(StatsSnapshot, frames_invalid)),
            ("invalid_by_reason", offset_of!(StatsSnapshot, invalid_by_reason)),
            ("deadline_misses", offset_of!(StatsSnapshot, deadline_misses)),
            ("estimator_failures", offset_of!(StatsSnapshot, estimator_failures)),
            ("poses_non_finite", offset_of!(StatsSnapshot, poses_non_finite)),
            ("producer_restarts", offset_of!(StatsSnapshot, producer_restarts)),
            ("since_start", offset_of!(StatsSnapshot, since_start)),
            ("last_window", offset_of!(StatsSnapshot, last_window)),
            ("poses_failed_verification", offset_of!(StatsSnapshot, poses_failed_verification)),
            ("objects_shed", offset_of!(StatsSnapshot, objects_shed)),
            ("frames_degraded", offset_of!(StatsSnapshot, frames_degraded)),
        ];
        let want: Vec<(String, usize)> = actual.iter().map(|(f, o)| (f.to_string(), *o)).collect();
        assert_eq!(fields, want, "PROTOCOL.md StatsSnapshot table vs the Rust type");
        assert!(
            section.contains(&format!("[u64; {}]", InvalidReason::COUNT)),
            "invalid_by_reason is documented with {} entries",
            InvalidReason::COUNT
        );

        let (size, align, fields) = documented(section, "LatencySummary");
        assert_eq!((size, align), (size_of::<LatencySummary>(), align_of::<LatencySummary>()));
        let want: Vec<(String, usize)> = [
            ("count", offset_of!(LatencySummary, count)),
            ("p50_ns", offset_of!(LatencySummary, p50_ns)),
            ("p90_ns", offset_of!(LatencySummary, p90_ns)),
            ("p99_ns", offset_of!(LatencySummary, p99_ns)),
            ("p999_ns", offset_of!(LatencySummary, p999_ns)),
            ("max_ns", offset_of!(LatencySummary, max_ns)),
        ]
        .iter()
        .map(|(f, o)| (f.to_string(), *o))
        .collect();
        assert_eq!(fields, want);

        let (size, align, fields) = documented(section, "StatsRequest");
        assert_eq!((size, align), (size_of::<StatsRequest>(), align_of::<StatsRequest>()));
        assert_eq!(fields, [("format_version".to_string(), 0), ("_reserved".to_string(), 2)]);
        assert!(section.contains(&format!("wire version ({})", crate::WIRE_VERSION)), "the documented wire version");
    }

    #[test]
    fn timelines_are_the_stages_then_end_to_end() {
        let names = Stage::timeline_names();
        for (i, stage) in Stage::ALL.iter().enumerate() {
            assert_eq!(*stage as usize, i);
            assert_eq!(names[i], stage.name());
        }
        assert_eq!(names[TIMELINE_COUNT - 1], "end_to_end");
    }
}
