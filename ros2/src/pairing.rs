//! Pairs colour and depth images by stamp (approximate time with a slop).
//!
//! Each side keeps its few newest unmatched messages. A new message pairs
//! with the other side's nearest one within the slop; everything older than
//! a pair on either side can no longer pair and is dropped (counted).

use std::collections::VecDeque;

/// How many unmatched messages each side keeps.
const KEEP: usize = 4;

/// A colour + depth pair, colour stamp first.
pub struct Pair<T> {
    pub color: T,
    pub depth: T,
}

/// Approximate-time pairing of two streams of stamped messages.
pub struct Pairer<T> {
    slop_ns: i64,
    color: VecDeque<(i64, T)>,
    depth: VecDeque<(i64, T)>,
    /// Messages dropped unpaired since the last [`Pairer::take_dropped`].
    dropped: u64,
}

impl<T> Pairer<T> {
    pub fn new(slop_ns: i64) -> Self {
        Self { slop_ns, color: VecDeque::new(), depth: VecDeque::new(), dropped: 0 }
    }

    pub fn push_color(&mut self, stamp_ns: i64, msg: T) -> Option<Pair<T>> {
        self.push(true, stamp_ns, msg)
    }

    pub fn push_depth(&mut self, stamp_ns: i64, msg: T) -> Option<Pair<T>> {
        self.push(false, stamp_ns, msg)
    }

    /// Unpaired messages dropped since the last call.
    pub fn take_dropped(&mut self) -> u64 {
        std::mem::take(&mut self.dropped)
    }

    fn push(&mut self, is_color: bool, stamp_ns: i64, msg: T) -> Option<Pair<T>> {
        let slop = self.slop_ns;
        let (mine, other) =
            if is_color { (&mut self.color, &mut self.depth) } else { (&mut self.depth, &mut self.color) };
        let best = other
            .iter()
            .enumerate()
            .map(|(i, (s, _))| (i, (s - stamp_ns).abs()))
            .filter(|(_, d)| *d <= slop)
            .min_by_key(|(_, d)| *d)
            .map(|(i, _)| i);
        let Some(i) = best else {
            if mine.len() == KEEP {
                mine.pop_front();
                self.dropped += 1;
            }
            mine.push_back((stamp_ns, msg));
            return None;
        };
        // Older entries on the other side, and all of mine older than this one, can no longer pair.
        self.dropped += i as u64;
        let (_, matched) = other.drain(..=i).last().expect("index i exists");
        let before = mine.len();
        mine.retain(|(s, _)| *s > stamp_ns);
        self.dropped += (before - mine.len()) as u64;
        Some(if is_color { Pair { color: msg, depth: matched } } else { Pair { color: matched, depth: msg } })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_stamps_within_the_slop_pair_and_stragglers_are_dropped() {
        let mut p = Pairer::new(5);
        assert!(p.push_color(100, "c100").is_none());
        let pair = p.push_depth(103, "d103").expect("3 ns apart");
        assert_eq!((pair.color, pair.depth), ("c100", "d103"));
        // A colour frame whose depth never comes, then the next pair.
        assert!(p.push_color(140, "c140").is_none());
        assert!(p.push_color(180, "c180").is_none());
        let pair = p.push_depth(181, "d181").unwrap();
        assert_eq!((pair.color, pair.depth), ("c180", "d181"));
        assert_eq!(p.take_dropped(), 1, "c140 can no longer pair");
        // Too far apart: nothing pairs.
        assert!(p.push_depth(300, "d300").is_none());
        assert!(p.push_color(310, "c310").is_none());
        assert_eq!(p.take_dropped(), 0);
    }

    #[test]
    fn each_side_keeps_only_a_few_unmatched_messages() {
        let mut p = Pairer::new(1);
        for i in 0..10 {
            assert!(p.push_color(i * 100, i).is_none());
        }
        assert_eq!(p.take_dropped(), 10 - KEEP as u64);
        assert!(p.push_depth(900, 99).is_some(), "the newest is still there");
    }
}
