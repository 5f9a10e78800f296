//! Instances from the segmenter's centre-offset head: every labelled cell
//! votes for the centre of its object (its position plus its predicted
//! offset); per class the votes are accumulated on the cell grid, peaks of
//! the accumulator become instance centres, and each cell joins the centre
//! nearest its vote. Two touching objects of one class vote for two centres
//! and become two instances; the pieces of one object cut apart by an
//! occluder vote for one centre and stay one instance.
//!
//! All buffers are sized once per grid ([`Voting::new`]); [`Voting::assign`]
//! does not allocate.

use super::config::OFFSET_UNIT_CELLS;

/// Tuning of the peak search (cells of the output grid).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VotingParams {
    /// A centre needs at least this many votes within its 3x3 cell window.
    pub min_votes: f32,
    /// Peaks closer than this (cells) to a stronger peak of the class are
    /// the same instance.
    pub merge_radius_cells: f32,
    /// Instances with fewer cells than this are given to the nearest other
    /// centre of their class.
    pub min_cells: usize,
}

impl Default for VotingParams {
    fn default() -> Self {
        Self { min_votes: 6.0, merge_radius_cells: 3.0, min_cells: 6 }
    }
}

/// `min_votes,merge_radius_cells,min_cells`, e.g. `6,3,6` (the default).
impl std::str::FromStr for VotingParams {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let usage = || format!("voting {s:?}: expected MIN_VOTES,MERGE_RADIUS_CELLS,MIN_CELLS, e.g. 6,3,6");
        let parts: Vec<&str> = s.split(',').map(str::trim).collect();
        let [votes, radius, cells] = parts[..] else { return Err(usage()) };
        let (votes, radius): (f32, f32) = (votes.parse().map_err(|_| usage())?, radius.parse().map_err(|_| usage())?);
        let min_cells = cells.parse().map_err(|_| usage())?;
        if !(votes.is_finite() && votes >= 0.0 && radius.is_finite() && radius >= 0.0) {
            return Err(usage());
        }
        Ok(Self { min_votes: votes, merge_radius_cells: radius, min_cells })
    }
}

/// What the segmenter does with its centre-offset head: vote instances
/// (`On`), or ignore the head and split each class into connected regions
/// as for a file without it (`Off`; join-parts then rejoins split objects).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum VotingMode {
    On(VotingParams),
    Off,
}

/// `on` (the default peak search), `off`, or a peak search of [`VotingParams`] (`6,3,6`).
impl std::str::FromStr for VotingMode {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim() {
            "off" => Ok(Self::Off),
            "on" => Ok(Self::On(VotingParams::default())),
            other => other.parse().map(Self::On).map_err(|e| format!("{e}, or on, or off")),
        }
    }
}

/// Upper bound on instances per frame ([`Voting::assign`] stops adding centres beyond it).
pub const MAX_INSTANCES: usize = 255;

/// One instance centre found by [`Voting::assign`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Centre {
    pub class_id: u16,
    /// Centre on the cell grid (cell units, cell centres at integers).
    pub x: f32,
    pub y: f32,
    /// Accumulated votes in its 3x3 window.
    pub strength: f32,
    /// Cells assigned to it.
    pub cells: u32,
}

/// Reusable buffers of the voting step for one grid size.
#[derive(Clone, Debug)]
pub struct Voting {
    width: usize,
    height: usize,
    params: VotingParams,
    /// Vote accumulator of the class being processed.
    acc: Vec<f32>,
    /// Vote position of every cell (cell units).
    votes: Vec<[f32; 2]>,
    /// Centres of the whole frame; index + 1 is the instance id.
    centres: Vec<Centre>,
    /// Candidate peaks of the class being processed: (strength, cell index).
    peaks: Vec<(f32, u32)>,
    /// Per class id: whether a cell carries it (sized `max class + 1` on first use).
    present: Vec<bool>,
}

impl Voting {
    /// Buffers for a `width` x `height` cell grid.
    pub fn new(width: usize, height: usize, params: VotingParams) -> Self {
        let n = width * height;
        Self {
            width,
            height,
            params,
            acc: vec![0.0; n],
            votes: vec![[0.0; 2]; n],
            centres: Vec::with_capacity(MAX_INSTANCES),
            peaks: Vec::with_capacity(n),
            present: Vec::with_capacity(u16::MAX as usize + 1),
        }
    }

    pub fn params(&self) -> VotingParams {
        self.params
    }

    pub fn set_params(&mut self, params: VotingParams) {
        self.params = params;
    }

    /// The centres of the last [`Voting::assign`]; instance id `i + 1` is `centres()[i]`.
    pub fn centres(&self) -> &[Centre] {
        &self.centres
    }

    /// Groups the labelled cells of `cells` (class ids, 0 = background) into
    /// instances using `offsets` (`[2, cells]`: x then y, in units of
    /// [`OFFSET_UNIT_CELLS`]); writes each cell's instance id (1-based, 0 for
    /// background) into `ids` and returns the instance count. Instance `i`'s
    /// class is `centres()[i - 1].class_id`.
    pub fn assign(&mut self, cells: &[u16], offsets: &[f32], ids: &mut [u16]) -> usize {
        let (w, h) = (self.width, self.height);
        let n = w * h;
        debug_assert!(cells.len() == n && offsets.len() == 2 * n && ids.len() == n);
        self.centres.clear();
        ids.fill(0);
        let max_class = cells.iter().copied().max().unwrap_or(0) as usize;
        self.present.clear();
        self.present.resize(max_class + 1, false);
        for (i, &c) in cells.iter().enumerate() {
            if c == 0 {
                continue;
            }
            self.present[c as usize] = true;
            let (x, y) = ((i % w) as f32, (i / w) as f32);
            let (dx, dy) = (offsets[i], offsets[n + i]);
            let (dx, dy) = if dx.is_finite() && dy.is_finite() { (dx, dy) } else { (0.0, 0.0) };
            self.votes[i] = [x + dx * OFFSET_UNIT_CELLS, y + dy * OFFSET_UNIT_CELLS];
        }
        for class in 1..=max_class {
            if self.present[class] && self.centres.len() < MAX_INSTANCES {
                self.assign_class(class as u16, cells, ids);
            }
        }
        self.centres.len()
    }

    fn assign_class(&mut self, class: u16, cells: &[u16], ids: &mut [u16]) {
        let (w, h) = (self.width, self.height);
        let p = self.params;
        // Bilinear splat of the class's votes (votes off the grid are clamped to its edge).
        self.acc.fill(0.0);
        let mut total = 0usize;
        for (i, &c) in cells.iter().enumerate() {
            if c != class {
                continue;
            }
            total += 1;
            let [vx, vy] = self.votes[i];
            let vx = vx.clamp(0.0, (w - 1) as f32);
            let vy = vy.clamp(0.0, (h - 1) as f32);
            let (x0, y0) = (vx as usize, vy as usize);
            let (fx, fy) = (vx - x0 as f32, vy - y0 as f32);
            let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
            self.acc[y0 * w + x0] += (1.0 - fx) * (1.0 - fy);
            self.acc[y0 * w + x1] += fx * (1.0 - fy);
            self.acc[y1 * w + x0] += (1.0 - fx) * fy;
            self.acc[y1 * w + x1] += fx * fy;
        }
        // Peaks: 3x3 window sums that are the largest in their 5x5 neighbourhood.
        self.peaks.clear();
        let window = |acc: &[f32], x: usize, y: usize| -> f32 {
            let mut s = 0.0;
            for yy in y.saturating_sub(1)..=(y + 1).min(h - 1) {
                for xx in x.saturating_sub(1)..=(x + 1).min(w - 1) {
                    s += acc[yy * w + xx];
                }
            }
            s
        };
        for y in 0..h {
            for x in 0..w {
                if self.acc[y * w + x] <= 0.0 {
                    continue;
                }
                let s = window(&self.acc, x, y);
                if s < p.min_votes {
                    continue;
                }
                let mut is_max = true;
                'n: for yy in y.saturating_sub(2)..=(y + 2).min(h - 1) {
                    for xx in x.saturating_sub(2)..=(x + 2).min(w - 1) {
                        if (xx, yy) == (x, y) || self.acc[yy * w + xx] <= 0.0 {
                            continue;
                        }
                        let t = window(&self.acc, xx, yy);
                        // Ties: the first in raster order wins.
                        if t > s || (t == s && (yy * w + xx) < (y * w + x)) {
                            is_max = false;
                            break 'n;
                        }
                    }
                }
                if is_max {
                    self.peaks.push((s, (y * w + x) as u32));
                }
            }
        }
        self.peaks.sort_unstable_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        let first = self.centres.len();
        let r2 = p.merge_radius_cells * p.merge_radius_cells;
        for k in 0..self.peaks.len() {
            if self.centres.len() >= MAX_INSTANCES {
                break;
            }
            let (s, i) = self.peaks[k];
            let (x, y) = ((i as usize % w) as f32, (i as usize / w) as f32);
            let near = self.centres[first..].iter().any(|c| (c.x - x).powi(2) + (c.y - y).powi(2) < r2);
            if !near {
                self.centres.push(Centre { class_id: class, x, y, strength: s, cells: 0 });
            }
        }
        if self.centres.len() == first {
            // No peak strong enough (a small or scattered region): one instance for the class.
            if total == 0 || self.centres.len() >= MAX_INSTANCES {
                return;
            }
            self.centres.push(Centre { class_id: class, x: 0.0, y: 0.0, strength: 0.0, cells: 0 });
        }
        self.nearest(class, first, cells, ids);
        // Centres that won too few cells give them to the others (strongest kept last).
        loop {
            let group = &self.centres[first..];
            if group.len() <= 1 {
                break;
            }
            let Some((weak, _)) = group
                .iter()
                .enumerate()
                .filter(|(_, c)| (c.cells as usize) < p.min_cells)
                .min_by(|a, b| a.1.strength.total_cmp(&b.1.strength))
            else {
                break;
            };
            self.centres.remove(first + weak);
            self.nearest(class, first, cells, ids);
        }
    }

    /// Gives every cell of `class` the id of the nearest centre `first..` (by its vote).
    fn nearest(&mut self, class: u16, first: usize, cells: &[u16], ids: &mut [u16]) {
        for c in &mut self.centres[first..] {
            c.cells = 0;
        }
        let single = self.centres.len() - first == 1;
        for (i, &c) in cells.iter().enumerate() {
            if c != class {
                continue;
            }
            let [vx, vy] = self.votes[i];
            let mut best = first;
            if !single {
                let mut best_d = f32::INFINITY;
                for (k, ctr) in self.centres.iter().enumerate().skip(first) {
                    let d = (ctr.x - vx).powi(2) + (ctr.y - vy).powi(2);
                    if d < best_d {
                        (best, best_d) = (k, d);
                    }
                }
            }
            self.centres[best].cells += 1;
            ids[i] = best as u16 + 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn voting_modes_parse_and_bad_ones_name_both_forms() {
        assert_eq!("off".parse::<VotingMode>(), Ok(VotingMode::Off));
        assert_eq!(
            "12,6,6".parse::<VotingMode>(),
            Ok(VotingMode::On(VotingParams { min_votes: 12.0, merge_radius_cells: 6.0, min_cells: 6 }))
        );
        let e = "of".parse::<VotingMode>().unwrap_err();
        assert!(e.contains("MIN_VOTES") && e.contains("or off"), "{e}");
        assert_eq!("on".parse::<VotingMode>(), Ok(VotingMode::On(VotingParams::default())));
    }

    /// Cells of two touching 6x6 squares of `class` side by side, each cell's
    /// offset pointing at its own square's centre (plus `noise`).
    fn two_squares(w: usize, h: usize, class: u16, same_centre: bool) -> (Vec<u16>, Vec<f32>) {
        let n = w * h;
        let (mut cells, mut off) = (vec![0u16; n], vec![0f32; 2 * n]);
        for y in 4..10 {
            for x in 4..16 {
                let i = y * w + x;
                cells[i] = class;
                let cx = if same_centre || x < 10 { 6.5 } else { 12.5 };
                off[i] = (cx - x as f32) / OFFSET_UNIT_CELLS;
                off[n + i] = (6.5 - y as f32) / OFFSET_UNIT_CELLS;
            }
        }
        (cells, off)
    }

    #[test]
    fn touching_objects_of_one_class_become_two_instances() {
        let (w, h) = (20, 14);
        let (cells, off) = two_squares(w, h, 3, false);
        let mut v = Voting::new(w, h, VotingParams::default());
        let mut ids = vec![0u16; w * h];
        assert_eq!(v.assign(&cells, &off, &mut ids), 2);
        let left = ids[5 * w + 5];
        let right = ids[5 * w + 14];
        assert!(left != 0 && right != 0 && left != right);
        // Every cell of a square carries its square's id.
        for y in 4..10 {
            for x in 4..16 {
                assert_eq!(ids[y * w + x], if x < 10 { left } else { right }, "cell ({x}, {y})");
            }
        }
        assert!(v.centres().iter().all(|c| c.class_id == 3 && c.cells == 36));
        assert_eq!(ids.iter().filter(|&&i| i == 0).count(), w * h - 72);
    }

    #[test]
    fn one_object_voting_one_centre_stays_one_instance_even_when_cut_apart() {
        let (w, h) = (20, 14);
        let (mut cells, off) = two_squares(w, h, 2, true);
        // An occluder cuts the region in two: columns 9 and 10 are background.
        for y in 0..h {
            cells[y * w + 9] = 0;
            cells[y * w + 10] = 0;
        }
        let mut v = Voting::new(w, h, VotingParams::default());
        let mut ids = vec![0u16; w * h];
        assert_eq!(v.assign(&cells, &off, &mut ids), 1);
        assert!(cells.iter().zip(&ids).all(|(&c, &i)| (c == 0) == (i == 0)));
    }

    #[test]
    fn classes_are_kept_apart_and_weak_regions_still_get_an_instance() {
        let (w, h) = (20, 14);
        let n = w * h;
        let (mut cells, mut off) = two_squares(w, h, 1, true);
        // A 2x2 class-4 blob whose votes scatter (no peak reaches min_votes).
        for (k, (x, y)) in [(18, 1), (19, 1), (18, 2), (19, 2)].into_iter().enumerate() {
            cells[y * w + x] = 4;
            off[y * w + x] = (k as f32 - 1.5) * 0.5;
            off[n + y * w + x] = 0.0;
        }
        let mut v = Voting::new(w, h, VotingParams::default());
        let mut ids = vec![0u16; n];
        assert_eq!(v.assign(&cells, &off, &mut ids), 2);
        let classes: Vec<u16> = v.centres().iter().map(|c| c.class_id).collect();
        assert_eq!(classes, vec![1, 4]);
        assert_eq!(ids[w + 18], 2);
        // Non-finite offsets vote in place instead of poisoning the accumulator.
        off[5 * w + 5] = f32::NAN;
        assert_eq!(v.assign(&cells, &off, &mut ids), 2);
    }
}
