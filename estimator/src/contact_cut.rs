//! Cutting one region into copies along the segmenter's contacts: where two
//! object instances touch ([`crate::seg::SegConfig::contacts`]).
//!
//! The second look ([`crate::recut`]) cuts a region its pose leaves
//! unexplained. k-means on its 3D points cuts between point clusters, not
//! where the copies meet, and a piece holding parts of two copies is posed
//! between them (docs/BENCHMARKS.md, session 35). The contact band marks
//! the meeting line from colour and depth: the region's pixels off the band
//! fall into one connected part per copy, and each part is grown back over
//! the band (breadth first, so every band pixel joins the part nearest it
//! within the region). Where the band has gaps and parts nothing,
//! [`ContactCut::grow`] floods pieces from given seeds (the second look's
//! k-means centres) in order of the contact probability, so they meet on
//! the band rather than halfway between the centres.
//!
//! Buffers are sized per frame size ([`ContactCut::resize`]); a cut
//! allocates nothing. A cut may run on cells of `scale` × `scale` pixels
//! ([`ContactCut::resize_scaled`]; each cell read at its top-left pixel), a
//! quarter of the work at scale 2 for a band several pixels wide.

/// Where two object instances touch: the probability per frame pixel, or
/// `None` where unknown ([`crate::seg::SegEngine::contact_at`]).
pub trait ContactMap {
    fn contact_at(&self, u: usize, v: usize) -> Option<f32>;
}

impl ContactMap for crate::seg::SegEngine {
    fn contact_at(&self, u: usize, v: usize) -> Option<f32> {
        crate::seg::SegEngine::contact_at(self, u, v)
    }
}

/// A pixel is on the contact band from this probability.
pub const CONTACT_PROBABILITY: f32 = 0.5;
/// A part off the band is a copy's when it holds at least this share of the
/// region's pixels (smaller parts are specks between band pixels).
pub const MIN_PART_SHARE: f32 = 0.08;
/// Contact levels of [`ContactCut::grow`]'s flooding.
pub const LEVELS: usize = 10;
/// Most connected parts counted per cut; further specks are not labelled.
const MAX_PARTS: usize = 1024;

/// The cut's buffers and its last result.
#[derive(Default)]
pub struct ContactCut {
    /// Per cell (within the cut region's box): part id during the
    /// cut, then piece + 1 (0 = not in the region).
    label: Vec<u16>,
    queue: Vec<u32>,
    /// Pixels per part (index = part id − 1).
    sizes: Vec<u32>,
    /// Piece + 1 of each part, 0 for parts not kept.
    piece_of_part: Vec<u16>,
    /// Cells per row.
    width: usize,
    /// Pixels per cell side (0 or 1: a cell is a pixel).
    scale: usize,
    /// Pixels per frame row.
    frame_width: usize,
}

impl ContactCut {
    /// Sizes the buffers for frames of `width` × `height` (allocates only
    /// when the size changes).
    pub fn resize(&mut self, width: usize, height: usize) {
        self.resize_scaled(width, height, 1);
    }

    /// As [`ContactCut::resize`], cutting on cells of `scale` × `scale` pixels.
    pub fn resize_scaled(&mut self, width: usize, height: usize, scale: usize) {
        let scale = scale.max(1);
        let (cols, rows) = (width.div_ceil(scale), height.div_ceil(scale));
        let n = cols * rows;
        if self.label.len() != n {
            self.label = vec![0; n];
            self.queue = Vec::with_capacity(n);
        }
        (self.width, self.scale, self.frame_width) = (cols, scale, width);
        if self.sizes.capacity() < MAX_PARTS {
            self.sizes = Vec::with_capacity(MAX_PARTS);
            self.piece_of_part = Vec::with_capacity(MAX_PARTS);
        }
    }

    /// Cuts the region of the pixels `in_region` within `bbox` (`[u0, v0,
    /// u1, v1]`, inclusive) along `contacts` into its largest parts off the
    /// contact band, at most `most`, each holding [`MIN_PART_SHARE`] of the
    /// region or more. `None` when fewer than two such parts exist (no
    /// contact crosses the region, or the map has no value there); then
    /// [`ContactCut::piece_at`] is meaningless. Call [`ContactCut::resize`]
    /// for the frame first.
    pub fn cut(
        &mut self,
        bbox: [usize; 4],
        in_region: impl Fn(usize) -> bool,
        contacts: &dyn ContactMap,
        most: usize,
    ) -> Option<usize> {
        let (w, s, fw) = (self.width, self.scale.max(1), self.frame_width);
        let in_region = |c: usize| in_region((c / w) * s * fw + (c % w) * s);
        let contact_at = |u: usize, v: usize| contacts.contact_at(u * s, v * s);
        let [u0, v0, u1, v1] = bbox.map(|x| x / s);
        let bbox = [u0, v0, u1, v1];
        if w == 0 || u1 >= w || (v1 + 1) * w > self.label.len() || u0 > u1 || v0 > v1 {
            return None;
        }
        let pixels = || (v0..=v1).flat_map(move |v| (u0..=u1).map(move |u| (u, v, v * w + u)));
        let mut region = 0usize;
        for (_, _, p) in pixels() {
            self.label[p] = 0;
            region += usize::from(in_region(p));
        }
        // Parts off the band: 4-connected flood fills.
        self.sizes.clear();
        for (u, v, p) in pixels() {
            if self.label[p] != 0 || !in_region(p) || !contact_at(u, v).is_some_and(|c| c < CONTACT_PROBABILITY) {
                continue;
            }
            if self.sizes.len() == MAX_PARTS {
                break;
            }
            let id = self.sizes.len() as u16 + 1;
            let mut size = 0u32;
            self.queue.clear();
            self.queue.push(p as u32);
            self.label[p] = id;
            while let Some(q) = self.queue.pop() {
                size += 1;
                let (qu, qv) = (q as usize % w, q as usize / w);
                for (nu, nv) in neighbours(qu, qv, bbox) {
                    let n = nv * w + nu;
                    if self.label[n] == 0 && in_region(n) && contact_at(nu, nv).is_some_and(|c| c < CONTACT_PROBABILITY)
                    {
                        self.label[n] = id;
                        self.queue.push(n as u32);
                    }
                }
            }
            self.sizes.push(size);
        }
        // The largest parts that are a copy's.
        let floor = (MIN_PART_SHARE * region as f32).ceil() as u32;
        self.piece_of_part.clear();
        self.piece_of_part.resize(self.sizes.len(), 0);
        let mut pieces = 0usize;
        while pieces < most.max(2) {
            let best = (0..self.sizes.len())
                .filter(|&i| self.piece_of_part[i] == 0 && self.sizes[i] >= floor.max(1))
                .max_by_key(|&i| (self.sizes[i], std::cmp::Reverse(i)));
            let Some(i) = best else { break };
            pieces += 1;
            self.piece_of_part[i] = pieces as u16;
        }
        if pieces < 2 {
            return None;
        }
        // Kept parts seed a breadth-first growth over the rest of the region.
        self.queue.clear();
        for (_, _, p) in pixels() {
            let part = self.label[p];
            self.label[p] = if part == 0 { 0 } else { self.piece_of_part[part as usize - 1] };
            if self.label[p] != 0 {
                self.queue.push(p as u32);
            }
        }
        self.flood(bbox, in_region);
        // Region pixels no path reaches (the region is not connected within
        // its box) join the first piece: they are too few to change a pose.
        for (_, _, p) in pixels() {
            if self.label[p] == 0 && in_region(p) {
                self.label[p] = 1;
            }
        }
        Some(pieces)
    }

    /// Grows `seeds` (frame pixel, piece) over the region of the pixels
    /// `in_region` within `bbox` in order of the contact probability
    /// (marker-controlled watershed in [`LEVELS`] levels): at each level
    /// every piece floods, breadth first, the pixels it reaches whose
    /// contact is within the level, so that a ridge of contacts between two
    /// seeds is crossed last and becomes the border even where the band has
    /// gaps. Region pixels no seed reaches join piece 0. Then
    /// [`ContactCut::piece_at`] gives every region pixel's piece.
    pub fn grow(
        &mut self,
        bbox: [usize; 4],
        in_region: impl Fn(usize) -> bool,
        contacts: &dyn ContactMap,
        seeds: impl Iterator<Item = (usize, u16)>,
    ) {
        let (w, s, fw) = (self.width, self.scale.max(1), self.frame_width);
        let in_region = |c: usize| in_region((c / w) * s * fw + (c % w) * s);
        let [u0, v0, u1, v1] = bbox.map(|x| x / s);
        let bbox = [u0, v0, u1, v1];
        if w == 0 || u1 >= w || (v1 + 1) * w > self.label.len() || u0 > u1 || v0 > v1 {
            return;
        }
        let pixels = || (v0..=v1).flat_map(move |v| (u0..=u1).map(move |u| v * w + u));
        for p in pixels() {
            self.label[p] = 0;
        }
        for (p, piece) in seeds {
            let c = self.cell_of(p);
            if c < self.label.len() && in_region(c) {
                self.label[c] = piece + 1;
            }
        }
        let level = |p: usize| {
            let c = contacts.contact_at((p % w) * s, (p / w) * s).unwrap_or(0.0);
            ((c * LEVELS as f32) as usize).min(LEVELS - 1)
        };
        for l in 0..LEVELS {
            self.queue.clear();
            self.queue.extend(pixels().filter(|&p| self.label[p] != 0).map(|p| p as u32));
            self.flood(bbox, |n| in_region(n) && level(n) <= l);
        }
        for p in pixels() {
            if self.label[p] == 0 && in_region(p) {
                self.label[p] = 1;
            }
        }
    }

    /// The piece of each frame pixel `(u, v)` of `pixels` into `out` (as far as both reach).
    pub fn pieces_of(&self, pixels: &[[u16; 2]], out: &mut [u8]) {
        for (m, &[u, v]) in out.iter_mut().zip(pixels) {
            *m = self.piece_at(v as usize * self.frame_width + u as usize) as u8;
        }
    }

    /// The cell of frame pixel `p`.
    fn cell_of(&self, p: usize) -> usize {
        let (s, fw) = (self.scale.max(1), self.frame_width.max(1));
        (p / fw / s) * self.width + (p % fw) / s
    }

    /// Breadth first from the queued pixels: each unlabelled pixel of `bbox`
    /// that `admit`s takes the label of the neighbour that reached it first.
    fn flood(&mut self, bbox: [usize; 4], admit: impl Fn(usize) -> bool) {
        let w = self.width;
        let mut head = 0;
        while head < self.queue.len() {
            let q = self.queue[head] as usize;
            head += 1;
            let piece = self.label[q];
            for (nu, nv) in neighbours(q % w, q / w, bbox) {
                let n = nv * w + nu;
                if self.label[n] == 0 && admit(n) {
                    self.label[n] = piece;
                    self.queue.push(n as u32);
                }
            }
        }
    }

    /// The piece (0-based) of region pixel `p` after a successful [`ContactCut::cut`] or a [`ContactCut::grow`].
    pub fn piece_at(&self, p: usize) -> usize {
        let c = self.cell_of(p);
        let label = |c: usize| self.label.get(c).copied().unwrap_or(0);
        let mut l = label(c);
        // A region pixel whose cell's top-left pixel lay outside the region
        // takes a neighbouring cell's piece.
        if l == 0 && self.scale > 1 {
            let w = self.width;
            l = [c.wrapping_sub(1), c + 1, c.wrapping_sub(w), c + w]
                .into_iter()
                .map(label)
                .find(|&l| l != 0)
                .unwrap_or(0);
        }
        l.saturating_sub(1) as usize
    }
}

/// The 4-neighbours of `(u, v)` within `bbox`.
fn neighbours(u: usize, v: usize, bbox: [usize; 4]) -> impl Iterator<Item = (usize, usize)> {
    let [u0, v0, u1, v1] = bbox;
    [
        (u > u0).then(|| (u - 1, v)),
        (u < u1).then(|| (u + 1, v)),
        (v > v0).then(|| (u, v - 1)),
        (v < v1).then(|| (u, v + 1)),
    ]
    .into_iter()
    .flatten()
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Band(fn(usize, usize) -> Option<f32>);
    impl ContactMap for Band {
        fn contact_at(&self, u: usize, v: usize) -> Option<f32> {
            (self.0)(u, v)
        }
    }

    /// A 20x10 region cut by a contact band at columns 9-10 (in a 30x12 frame).
    #[test]
    fn a_band_across_the_region_cuts_it_in_two_and_the_band_is_shared() {
        let mut cut = ContactCut::default();
        cut.resize(30, 12);
        let in_region = |p: usize| (2..22).contains(&(p % 30)) && (1..11).contains(&(p / 30));
        let band = Band(|u, _| Some(if (11..=12).contains(&u) { 0.9 } else { 0.1 }));
        assert_eq!(cut.cut([0, 0, 29, 11], in_region, &band, 4), Some(2));
        for v in 1..11 {
            for u in 2..22 {
                let want = if u <= 11 { 0 } else { 1 };
                assert_eq!(cut.piece_at(v * 30 + u), want, "pixel ({u}, {v})");
            }
        }
    }

    /// The same cut on 2 × 2 cells: every region pixel off the band gets
    /// its side's piece, the border cells' pixels included.
    #[test]
    fn a_cut_on_cells_gives_every_region_pixel_its_piece() {
        let mut cut = ContactCut::default();
        cut.resize_scaled(30, 12, 2);
        // Starts on an odd column and row: the left column's cells read outside.
        let in_region = |p: usize| (3..22).contains(&(p % 30)) && (1..11).contains(&(p / 30));
        let band = Band(|u, _| Some(if (12..=13).contains(&u) { 0.9 } else { 0.1 }));
        assert_eq!(cut.cut([0, 0, 29, 11], in_region, &band, 4), Some(2));
        for v in 1..11 {
            for u in 3..22 {
                if !(11..=14).contains(&u) {
                    assert_eq!(cut.piece_at(v * 30 + u), usize::from(u > 13), "pixel ({u}, {v})");
                }
            }
        }
        let mut out = [9u8; 2];
        cut.pieces_of(&[[3, 1], [21, 10]], &mut out);
        assert_eq!(out, [0, 1]);
    }

    #[test]
    fn no_band_or_a_band_that_stops_short_leaves_the_region_whole() {
        let mut cut = ContactCut::default();
        cut.resize(30, 12);
        let in_region = |p: usize| (2..22).contains(&(p % 30)) && (1..11).contains(&(p / 30));
        assert_eq!(cut.cut([0, 0, 29, 11], in_region, &Band(|_, _| Some(0.0)), 4), None);
        // Band from the top down to row 7 only: the parts stay connected below it.
        let short = Band(|u, v| Some(if (11..=12).contains(&u) && v < 8 { 0.9 } else { 0.1 }));
        assert_eq!(cut.cut([0, 0, 29, 11], in_region, &short, 4), None);
        // No contact map there (a file without the branch): no cut.
        assert_eq!(cut.cut([0, 0, 29, 11], in_region, &Band(|_, _| None), 4), None);
    }

    /// Seeds on either side of a contact ridge at column 14 (columns 3 and
    /// 20, row 2) flood a 24x12 region: where the ridge stands (rows 0-6) the
    /// border is the ridge, not the midway column 11 that nearest-centre
    /// assignment gives; through its gap (rows 9-11) the nearer seed floods.
    #[test]
    fn growth_from_seeds_meets_on_the_ridge() {
        let mut cut = ContactCut::default();
        cut.resize(24, 12);
        let in_region = |_: usize| true;
        let ridge = Band(|u, v| Some(if u == 14 && v < 9 { 0.8 } else { 0.1 }));
        let seeds = [(2 * 24 + 3, 0u16), (2 * 24 + 20, 1u16)];
        cut.grow([0, 0, 23, 11], in_region, &ridge, seeds.into_iter());
        for v in 0..7 {
            for u in 0..24 {
                let want = usize::from(u > 14);
                if u != 14 {
                    assert_eq!(cut.piece_at(v * 24 + u), want, "pixel ({u}, {v})");
                }
            }
        }
        // Without the ridge the pieces meet halfway between the seeds.
        cut.grow([0, 0, 23, 11], in_region, &Band(|_, _| Some(0.0)), seeds.into_iter());
        assert_eq!((cut.piece_at(2 * 24 + 11), cut.piece_at(2 * 24 + 12)), (0, 1));
        // A seed outside the region, or none at all: every region pixel still gets piece 0 or 1.
        cut.grow([0, 0, 23, 11], |p| p % 24 > 0, &ridge, [(0, 1u16)].into_iter());
        assert!((0..288).filter(|p| p % 24 > 0).all(|p| cut.piece_at(p) == 0));
    }

    #[test]
    fn specks_between_band_pixels_are_not_copies_and_most_caps_the_pieces() {
        let mut cut = ContactCut::default();
        cut.resize(40, 10);
        let in_region = |p: usize| p % 40 < 36;
        // Bands at columns 8, 17 and 26 make four parts of 8 columns; a 1-pixel
        // speck enclosed by band pixels at (31, 5) is no part.
        let band = Band(|u, v| {
            let speck_ring = (30..=32).contains(&u) && (4..=6).contains(&v) && !(u == 31 && v == 5);
            Some(if u == 8 || u == 17 || u == 26 || speck_ring { 0.9 } else { 0.0 })
        });
        assert_eq!(cut.cut([0, 0, 39, 9], in_region, &band, 6), Some(4));
        assert_eq!(cut.cut([0, 0, 39, 9], in_region, &band, 3), Some(3), "capped at the most asked");
        // The three kept are the largest; the fourth part's pixels join their nearest piece.
        let pieces: std::collections::BTreeSet<usize> =
            (0..400).filter(|&p| in_region(p)).map(|p| cut.piece_at(p)).collect();
        assert_eq!(pieces.len(), 3);
    }
}
