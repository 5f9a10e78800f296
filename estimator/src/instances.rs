//! Object instances from a label plane.
//!
//! **Class planes** (class id per pixel): connected components per class.
//! Connectivity is **4-connected** (left, right, up, down): two pixels belong
//! to the same instance when they share an edge and carry the same class id.
//! Diagonal-only contact does not join instances, so two touching objects of
//! one class that meet only at a corner stay separate, but two that share an
//! edge become one region (only an instance plane can tell them apart).
//!
//! **Instance planes** (instance id per pixel plus a class per id): the
//! producer's instance ids are authoritative. Every pixel of one instance id
//! is one instance, whether or not its pixels are connected (an object cut in
//! two by a nearer one is still one object), and two instance ids are two
//! instances however they touch. The component id of an instance is its
//! instance id. Pixels whose instance has no class in 1..=`num_classes`
//! (class 0, an unknown class, or an id past the class table) are skipped and
//! counted in [`LabelStats`].
//!
//! Either way, components smaller than `min_pixels` are dropped, at most
//! `max_instances` are kept (largest first; ties keep raster order of their
//! first pixel for class planes, instance-id order for instance planes), and
//! class ids above `num_classes` are skipped and counted in [`LabelStats`].
//!
//! Class planes are labelled by runs: each row's runs of one class are joined
//! to the touching runs of the same class in the row above (union–find, the
//! earlier run the root), then numbered in raster order of their first
//! pixel, as a flood fill from each unvisited pixel in raster order would
//! number them, at a fraction of its cost per pixel.
//!
//! Allocation: [`InstanceFinder`] keeps a component-id buffer of
//! `width * height` entries, room for as many runs as a frame can have, one
//! tally per component and one per instance-table entry.
//! They are sized on the first frame and reused; they grow (allocate) only
//! when a frame has more pixels (or a longer instance table, or more
//! components) than any frame before. Frames of a fixed size never allocate after the first.

use crate::frame::LabelPlane;

/// One connected component of a single class.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Component {
    pub class_id: u16,
    /// Id of the component in [`InstanceFinder::component_ids`] (≥ 1).
    pub component_id: u32,
    /// Pixels in the component.
    pub pixels: u32,
    /// [u_min, v_min, u_max, v_max] inclusive, pixels.
    pub bbox: [u16; 4],
}

/// Most pieces [`InstanceFinder::split`] cuts one component into.
pub const MAX_PIECES: usize = 8;

/// Limits applied while finding instances.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct InstanceLimits {
    /// Smallest component kept, pixels.
    pub min_pixels: usize,
    /// Most components kept (largest first).
    pub max_instances: usize,
    /// Largest valid class id; larger ids are skipped and counted. 0 accepts every id.
    pub num_classes: u16,
}

/// What was skipped in one label plane (for the daemon's counters).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LabelStats {
    /// Pixels whose class id exceeds `num_classes`.
    pub unknown_class_pixels: u32,
    /// Largest unknown class id seen (0 when none).
    pub max_unknown_class: u16,
    /// Components dropped for having fewer than `min_pixels` pixels.
    pub small_components: u32,
    /// Components large enough but beyond `max_instances`.
    pub over_max_instances: u32,
}

/// Pixel count and bounding box of one instance id while a plane is scanned.
#[derive(Clone, Copy, Debug)]
struct Tally {
    pixels: u32,
    /// [u_min, v_min, u_max, v_max] inclusive.
    bbox: [u16; 4],
}

impl Tally {
    const EMPTY: Tally = Tally { pixels: 0, bbox: [u16::MAX, u16::MAX, 0, 0] };

    fn add_row(&mut self, count: u32, u_first: usize, u_last: usize, v: usize) {
        let clamp = |x: usize| x.min(u16::MAX as usize) as u16;
        self.pixels += count;
        let b = &mut self.bbox;
        *b = [b[0].min(clamp(u_first)), b[1].min(clamp(v)), b[2].max(clamp(u_last)), b[3].max(clamp(v))];
    }
}

/// A run of pixels of one class in one row of a class plane.
#[derive(Clone, Copy, Debug)]
struct Run {
    /// Pixel index of its first pixel, and one past its last.
    start: u32,
    end: u32,
    class_id: u16,
    /// Union–find link (index into the runs; a root links to itself).
    parent: u32,
    /// Index of its component among the frame's components (set once numbered).
    component: u32,
}

/// Most runs, and components, a frame of `pixels` pixels can have (one per
/// pixel, on a checkerboard of two classes).
fn max_runs(pixels: usize) -> usize {
    pixels
}

/// Reusable buffers for connected-component labelling.
#[derive(Debug, Default)]
pub struct InstanceFinder {
    /// Per pixel: 0 = background/unknown/unvisited, otherwise the component id.
    ids: Vec<u32>,
    /// Class planes: the runs of the frame, in raster order.
    runs: Vec<Run>,
    /// Class planes: class and tally of each component, in raster order of its first pixel.
    components: Vec<(u16, Tally)>,
    /// Kept components, sorted by pixel count, descending.
    kept: Vec<Component>,
    /// Instance planes: one tally per instance-table entry.
    tallies: Vec<Tally>,
    width: usize,
    height: usize,
    stats: LabelStats,
    /// Smallest component id not yet used in this frame (class planes).
    next_id: u32,
}

impl InstanceFinder {
    /// Empty finder; buffers are sized on the first frame.
    pub fn new() -> Self {
        Self::default()
    }

    /// Finder with buffers preallocated for frames up to `pixels` pixels and
    /// up to `max_instances` instances.
    pub fn with_capacity(pixels: usize, max_instances: usize) -> Self {
        Self {
            ids: Vec::with_capacity(pixels),
            runs: Vec::with_capacity(max_runs(pixels)),
            components: Vec::with_capacity(max_runs(pixels)),
            kept: Vec::with_capacity(max_instances + 1),
            ..Self::default()
        }
    }

    /// Labels `labels` (`width * height` values, row-major) and returns the
    /// kept components, largest first. A plane shorter than `width * height`
    /// is read as background beyond its end (callers validate sizes first).
    pub fn find(
        &mut self,
        labels: &LabelPlane<'_>,
        width: usize,
        height: usize,
        limits: InstanceLimits,
    ) -> &[Component] {
        let n = width * height;
        self.width = width;
        self.height = height;
        self.stats = LabelStats::default();
        self.kept.clear();
        if self.kept.capacity() < limits.max_instances + 1 {
            self.kept.reserve(limits.max_instances + 1);
        }
        self.ids.clear();
        self.ids.resize(n, 0);
        let runs = max_runs(n);
        if self.runs.capacity() < runs {
            self.runs.reserve(runs - self.runs.len());
            self.components.reserve(runs.saturating_sub(self.components.len()));
        }
        match *labels {
            LabelPlane::U8(plane) => self.label_runs(|p| plane.get(p).map_or(0, |&c| c as u16), limits),
            LabelPlane::U16(plane) => self.label_runs(|p| plane.get(p).copied().unwrap_or(0), limits),
            LabelPlane::Instances { ids, classes } => {
                self.next_id = classes.len().max(1) as u32;
                self.find_instances(ids, classes, limits);
            }
        }
        &self.kept
    }

    /// Connected components of a class plane (`class_at(pixel index)`) by
    /// runs; see the module doc.
    fn label_runs(&mut self, class_at: impl Fn(usize) -> u16, limits: InstanceLimits) {
        let (w, h) = (self.width, self.height);
        self.runs.clear();
        let mut above = 0..0;
        for v in 0..h {
            let row = v * w;
            let first_of_row = self.runs.len();
            // The first run above that may touch the next run of this row.
            let mut j = above.start;
            let mut u = 0;
            while u < w {
                let class_id = class_at(row + u);
                let start = u;
                u += 1;
                while u < w && class_at(row + u) == class_id {
                    u += 1;
                }
                if class_id == 0 {
                    continue;
                }
                if limits.num_classes != 0 && class_id > limits.num_classes {
                    self.stats.unknown_class_pixels += (u - start) as u32;
                    self.stats.max_unknown_class = self.stats.max_unknown_class.max(class_id);
                    continue;
                }
                let me = self.runs.len() as u32;
                let (run_start, run_end) = ((row + start) as u32, (row + u) as u32);
                self.runs.push(Run { start: run_start, end: run_end, class_id, parent: me, component: 0 });
                // Runs above sharing a column with [start, u) touch this one.
                while j < above.end && self.runs[j].end - (row - w) as u32 <= start as u32 {
                    j += 1;
                }
                let mut k = j;
                while k < above.end && self.runs[k].start - ((row - w) as u32) < u as u32 {
                    if self.runs[k].class_id == class_id {
                        self.union(k as u32, me);
                    }
                    k += 1;
                }
            }
            above = first_of_row..self.runs.len();
        }
        // Number the components in raster order of their first pixel: a root
        // is its component's earliest run, met before the rest of it.
        self.components.clear();
        for i in 0..self.runs.len() {
            let root = self.root(i as u32) as usize;
            let run = self.runs[i];
            let component = if root == i {
                self.components.push((run.class_id, Tally::EMPTY));
                (self.components.len() - 1) as u32
            } else {
                self.runs[root].component
            };
            self.runs[i].component = component;
            let (start, end) = (run.start as usize, run.end as usize);
            self.components[component as usize].1.add_row((end - start) as u32, start % w, (end - 1) % w, start / w);
            self.ids[start..end].fill(component + 1);
        }
        self.next_id = self.components.len() as u32 + 1;
        for i in 0..self.components.len() {
            let (class_id, t) = self.components[i];
            self.offer(Component { class_id, component_id: i as u32 + 1, pixels: t.pixels, bbox: t.bbox }, limits);
        }
    }

    /// The root of run `i`'s set (halving the path on the way).
    fn root(&mut self, mut i: u32) -> u32 {
        while self.runs[i as usize].parent != i {
            let grand = self.runs[self.runs[i as usize].parent as usize].parent;
            self.runs[i as usize].parent = grand;
            i = grand;
        }
        i
    }

    /// Joins the sets of runs `a` and `b`; the earlier root stays the root.
    fn union(&mut self, a: u32, b: u32) {
        let (ra, rb) = (self.root(a), self.root(b));
        let (keep, join) = if ra < rb { (ra, rb) } else { (rb, ra) };
        self.runs[join as usize].parent = keep;
    }

    /// One instance per instance id (see the module doc): one pass tallies
    /// pixels and boxes per id, then the ids are offered in id order.
    fn find_instances(&mut self, ids: &[u16], classes: &[u16], limits: InstanceLimits) {
        self.tallies.clear();
        // Keeps its capacity: allocates only for a longer table than any before.
        self.tallies.resize(classes.len(), Tally::EMPTY);
        let w = self.width;
        let clamp = |x: usize| x.min(u16::MAX as usize) as u16;
        for (p, &id) in ids.iter().enumerate().take(self.ids.len()) {
            if id == 0 {
                continue;
            }
            let class_id = classes.get(id as usize).copied().unwrap_or(0);
            if class_id == 0 || (limits.num_classes != 0 && class_id > limits.num_classes) {
                self.stats.unknown_class_pixels += 1;
                self.stats.max_unknown_class = self.stats.max_unknown_class.max(class_id);
                continue;
            }
            self.ids[p] = id as u32;
            let (u, v) = (clamp(p % w), clamp(p / w));
            let t = &mut self.tallies[id as usize];
            t.pixels += 1;
            t.bbox = [t.bbox[0].min(u), t.bbox[1].min(v), t.bbox[2].max(u), t.bbox[3].max(v)];
        }
        // `tallies` has one entry per table entry.
        for (id, &class_id) in classes.iter().enumerate().skip(1) {
            let t = self.tallies[id];
            if t.pixels > 0 {
                let component = Component { class_id, component_id: id as u32, pixels: t.pixels, bbox: t.bbox };
                self.offer(component, limits);
            }
        }
    }

    /// The components kept by the last [`find`](Self::find), largest first.
    pub fn components(&self) -> &[Component] {
        &self.kept
    }

    /// What the last [`find`](Self::find) skipped.
    pub fn stats(&self) -> LabelStats {
        self.stats
    }

    /// Per-pixel component ids of the last frame (row-major, 0 = none).
    pub fn component_ids(&self) -> &[u32] {
        &self.ids
    }

    /// Size of the last frame, pixels.
    pub fn frame_size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// Joins component `from` into component `into` (both by component id):
    /// `from`'s pixels take `into`'s id, pixel counts add up, the boxes are
    /// united and `from` leaves the kept list. Kept components are re-sorted
    /// largest first (ties by component id, i.e. raster order). Returns false,
    /// changing nothing, when either id is not kept or they are equal or of
    /// different classes. (`Workspace` never joins the instances of an
    /// instance plane: they are the producer's.)
    pub fn join(&mut self, into: u32, from: u32) -> bool {
        let (Some(i), Some(f)) = (
            self.kept.iter().position(|c| c.component_id == into),
            self.kept.iter().position(|c| c.component_id == from),
        ) else {
            return false;
        };
        if i == f || self.kept[i].class_id != self.kept[f].class_id {
            return false;
        }
        let gone = self.kept[f];
        let [u0, v0, u1, v1] = gone.bbox.map(|x| x as usize);
        for v in v0..=v1.min(self.height.saturating_sub(1)) {
            for id in &mut self.ids[v * self.width + u0..=v * self.width + u1.min(self.width - 1)] {
                if *id == from {
                    *id = into;
                }
            }
        }
        let keep = &mut self.kept[i];
        keep.pixels += gone.pixels;
        keep.bbox = [
            keep.bbox[0].min(gone.bbox[0]),
            keep.bbox[1].min(gone.bbox[1]),
            keep.bbox[2].max(gone.bbox[2]),
            keep.bbox[3].max(gone.bbox[3]),
        ];
        self.kept.remove(f);
        // Unstable sort does not allocate; the key makes the order total.
        self.kept.sort_unstable_by_key(|c| (std::cmp::Reverse(c.pixels), c.component_id));
        true
    }

    /// The id [`split`](Self::split) gives its piece 1 next (piece k gets
    /// this + k − 1).
    pub fn next_split_id(&self) -> u32 {
        self.next_id
    }

    /// Splits kept component `id` into pieces: `piece_of(pixel index)` names
    /// the piece (0..[`MAX_PIECES`]) of each of its pixels, or `None` for a
    /// pixel that leaves the component (it becomes background). Piece 0 keeps the
    /// id; every other non-empty piece gets a new id and joins the kept list
    /// like a component of [`find`](Self::find) (pieces under `min_pixels`
    /// are dropped and counted, the `max_instances` largest are kept).
    /// Returns the number of new instances kept; 0, changing nothing, when
    /// `id` is not kept. Never allocates within the capacity `find` reserved.
    pub fn split(
        &mut self,
        id: u32,
        limits: InstanceLimits,
        mut piece_of: impl FnMut(usize) -> Option<usize>,
    ) -> usize {
        let Some(at) = self.kept.iter().position(|c| c.component_id == id) else {
            return 0;
        };
        let whole = self.kept.remove(at);
        let mut tallies = [Tally::EMPTY; MAX_PIECES];
        let first_new = self.next_id;
        let [u0, v0, u1, v1] = whole.bbox.map(|x| x as usize);
        let (w, h) = (self.width, self.height);
        for v in v0..=v1.min(h.saturating_sub(1)) {
            for u in u0..=u1.min(w.saturating_sub(1)) {
                let p = v * w + u;
                if self.ids[p] != id {
                    continue;
                }
                let Some(k) = piece_of(p).map(|k| k.min(MAX_PIECES - 1)) else {
                    self.ids[p] = 0;
                    continue;
                };
                if k > 0 {
                    self.ids[p] = first_new + k as u32 - 1;
                }
                let t = &mut tallies[k];
                let (u, v) = (u as u16, v as u16);
                t.pixels += 1;
                t.bbox = [t.bbox[0].min(u), t.bbox[1].min(v), t.bbox[2].max(u), t.bbox[3].max(v)];
            }
        }
        self.next_id += MAX_PIECES as u32 - 1;
        for (k, t) in tallies.iter().enumerate().filter(|(_, t)| t.pixels > 0) {
            let component_id = if k == 0 { id } else { first_new + k as u32 - 1 };
            self.offer(Component { class_id: whole.class_id, component_id, pixels: t.pixels, bbox: t.bbox }, limits);
        }
        let new = first_new..self.next_id;
        self.kept.iter().filter(|c| new.contains(&c.component_id)).count()
    }

    /// Keeps `c` if it is among the `max_instances` largest so far.
    fn offer(&mut self, c: Component, limits: InstanceLimits) {
        if (c.pixels as usize) < limits.min_pixels {
            self.stats.small_components += 1;
            return;
        }
        let at = self.kept.iter().position(|k| k.pixels < c.pixels).unwrap_or(self.kept.len());
        if at >= limits.max_instances {
            self.stats.over_max_instances += 1;
            return;
        }
        self.kept.insert(at, c);
        if self.kept.len() > limits.max_instances {
            self.kept.pop();
            self.stats.over_max_instances += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits(min_pixels: usize, max_instances: usize, num_classes: u16) -> InstanceLimits {
        InstanceLimits { min_pixels, max_instances, num_classes }
    }

    /// Paints a rectangle [u0, u1] x [v0, v1] inclusive.
    fn paint(plane: &mut [u8], w: usize, rect: [usize; 4], class: u8) {
        for v in rect[1]..=rect[3] {
            for u in rect[0]..=rect[2] {
                plane[v * w + u] = class;
            }
        }
    }

    /// Flood fill from each unvisited pixel in raster order (the labelling
    /// before runs): the component ids plane and each component's class,
    /// pixel count and box, in id order; unknown-class pixels counted.
    fn flood_fill_reference(plane: &[u16], w: usize, h: usize, num_classes: u16) -> (Vec<u32>, Vec<Component>, u32) {
        let mut ids = vec![0u32; w * h];
        let (mut found, mut unknown) = (Vec::new(), 0);
        for start in 0..w * h {
            let class_id = plane[start];
            if class_id == 0 || ids[start] != 0 {
                continue;
            }
            if num_classes != 0 && class_id > num_classes {
                unknown += 1;
                continue;
            }
            let id = found.len() as u32 + 1;
            let mut c = Component { class_id, component_id: id, pixels: 0, bbox: [u16::MAX, u16::MAX, 0, 0] };
            let mut stack = vec![start];
            ids[start] = id;
            while let Some(p) = stack.pop() {
                let (u, v) = (p % w, p / w);
                c.pixels += 1;
                c.bbox = [
                    c.bbox[0].min(u as u16),
                    c.bbox[1].min(v as u16),
                    c.bbox[2].max(u as u16),
                    c.bbox[3].max(v as u16),
                ];
                let mut visit = |q: usize| {
                    if ids[q] == 0 && plane[q] == class_id {
                        ids[q] = id;
                        stack.push(q);
                    }
                };
                if u > 0 {
                    visit(p - 1);
                }
                if u + 1 < w {
                    visit(p + 1);
                }
                if v > 0 {
                    visit(p - w);
                }
                if v + 1 < h {
                    visit(p + w);
                }
            }
            found.push(c);
        }
        (ids, found, unknown)
    }

    #[test]
    fn runs_label_as_a_raster_order_flood_fill_does() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg64::seed_from_u64(11);
        let mut f = InstanceFinder::new();
        for round in 0..400 {
            let (w, h) = (rng.random_range(1..40), rng.random_range(1..30));
            // Blobs of a few classes (4 is unknown below): runs of random
            // length, each row a shifted copy of the one above now and then,
            // so that regions wind, fork and join (U, spirals, combs).
            let mut plane = vec![0u16; w * h];
            for v in 0..h {
                if v > 0 && rng.random_bool(0.6) {
                    let shift = rng.random_range(0..3);
                    for u in 0..w {
                        plane[v * w + u] = plane[(v - 1) * w + (u + shift) % w];
                    }
                    continue;
                }
                let mut u = 0;
                while u < w {
                    let (class, run) = (rng.random_range(0..5u16), rng.random_range(1..9));
                    for x in u..(u + run).min(w) {
                        plane[v * w + x] = class;
                    }
                    u += run;
                }
            }
            if round % 4 == 0 {
                // A checkerboard of two classes: a component per pixel.
                plane.iter_mut().enumerate().for_each(|(p, c)| *c = 1 + ((p % w + p / w) % 2) as u16);
            }
            let (ids, all, unknown) = flood_fill_reference(&plane, w, h, 3);
            let mut expected = all.clone();
            // `offer` keeps the largest first, ties in id order.
            expected.sort_by_key(|c| (std::cmp::Reverse(c.pixels), c.component_id));
            let found = f.find(&LabelPlane::U16(&plane), w, h, limits(1, 100_000, 3)).to_vec();
            assert_eq!(f.component_ids(), &ids[..], "round {round}");
            assert_eq!(found, expected, "round {round}");
            assert_eq!(f.stats().unknown_class_pixels, unknown, "round {round}");
            assert_eq!(f.next_split_id(), all.len() as u32 + 1);
        }
    }

    #[test]
    fn finds_components_largest_first_with_bboxes() {
        let (w, h) = (20, 10);
        let mut l = vec![0u8; w * h];
        paint(&mut l, w, [1, 1, 3, 2], 2); // 3x2 = 6
        paint(&mut l, w, [10, 2, 17, 8], 1); // 8x7 = 56
        paint(&mut l, w, [5, 5, 7, 8], 2); // 3x4 = 12
        let mut f = InstanceFinder::new();
        let found = f.find(&LabelPlane::U8(&l), w, h, limits(1, 8, 0)).to_vec();
        assert_eq!(found.len(), 3);
        assert_eq!((found[0].class_id, found[0].pixels, found[0].bbox), (1, 56, [10, 2, 17, 8]));
        assert_eq!((found[1].class_id, found[1].pixels, found[1].bbox), (2, 12, [5, 5, 7, 8]));
        assert_eq!((found[2].class_id, found[2].pixels, found[2].bbox), (2, 6, [1, 1, 3, 2]));
        // Component ids mark exactly the component's pixels.
        let ids = f.component_ids();
        let marked = ids.iter().filter(|&&i| i == found[0].component_id).count();
        assert_eq!(marked, 56);
    }

    #[test]
    fn join_moves_pixels_unites_boxes_and_resorts() {
        let (w, h) = (20, 10);
        let mut l = vec![0u8; w * h];
        paint(&mut l, w, [0, 0, 3, 3], 1); // 16 px
        paint(&mut l, w, [10, 5, 12, 6], 1); // 6 px
        paint(&mut l, w, [15, 0, 17, 2], 2); // 9 px
        let mut f = InstanceFinder::new();
        let found = f.find(&LabelPlane::U8(&l), w, h, limits(1, 8, 0)).to_vec();
        let (big, other, small) = (found[0].component_id, found[1].component_id, found[2].component_id);
        assert_eq!((found[0].pixels, found[1].pixels, found[2].pixels), (16, 9, 6));
        assert!(!f.join(big, other), "different classes are not joined");
        assert!(!f.join(big, big));
        assert!(f.join(big, small));
        let kept = f.components().to_vec();
        assert_eq!(kept.len(), 2);
        assert_eq!((kept[0].component_id, kept[0].pixels, kept[0].bbox), (big, 22, [0, 0, 12, 6]));
        assert_eq!(kept[1].component_id, other);
        assert_eq!(f.component_ids().iter().filter(|&&i| i == big).count(), 22);
        assert_eq!(f.component_ids()[6 * w + 12], big);
        assert!(!f.join(big, small), "a joined component is gone");
    }

    #[test]
    fn min_pixels_and_max_instances_are_applied_and_counted() {
        let (w, h) = (30, 10);
        let mut l = vec![0u8; w * h];
        paint(&mut l, w, [0, 0, 1, 1], 1); // 4 px
        paint(&mut l, w, [5, 0, 8, 3], 1); // 16 px
        paint(&mut l, w, [10, 0, 14, 4], 1); // 25 px
        paint(&mut l, w, [20, 0, 25, 5], 1); // 36 px
        let mut f = InstanceFinder::new();
        let found = f.find(&LabelPlane::U8(&l), w, h, limits(10, 2, 0)).to_vec();
        assert_eq!(found.iter().map(|c| c.pixels).collect::<Vec<_>>(), vec![36, 25]);
        let s = f.stats();
        assert_eq!(s.small_components, 1);
        assert_eq!(s.over_max_instances, 1);
    }

    #[test]
    fn connectivity_is_four_neighbour_and_per_class() {
        let (w, h) = (6, 6);
        let mut l = vec![0u8; w * h];
        // Diagonal touch: two components.
        l[0] = 1;
        l[w + 1] = 1;
        // Adjacent pixels of different classes: two components.
        l[4] = 1;
        l[5] = 2;
        let mut f = InstanceFinder::new();
        let found = f.find(&LabelPlane::U8(&l), w, h, limits(1, 10, 0));
        assert_eq!(found.len(), 4);
        assert!(found.iter().all(|c| c.pixels == 1));
    }

    #[test]
    fn unknown_class_ids_are_skipped_and_counted() {
        let (w, h) = (10, 4);
        let mut l = vec![0u16; w * h];
        for p in &mut l[0..5] {
            *p = 3;
        }
        for p in &mut l[20..27] {
            *p = 9;
        }
        let mut f = InstanceFinder::new();
        let found = f.find(&LabelPlane::U16(&l), w, h, limits(1, 10, 3)).to_vec();
        assert_eq!(found.len(), 1);
        assert_eq!(found[0].class_id, 3);
        assert_eq!(f.stats().unknown_class_pixels, 7);
        assert_eq!(f.stats().max_unknown_class, 9);
    }

    #[test]
    fn reuse_on_a_new_frame_forgets_the_old_one() {
        let (w, h) = (8, 8);
        let mut a = vec![0u8; w * h];
        paint(&mut a, w, [0, 0, 3, 3], 1);
        let b = vec![0u8; w * h];
        let mut f = InstanceFinder::new();
        assert_eq!(f.find(&LabelPlane::U8(&a), w, h, limits(1, 4, 0)).len(), 1);
        assert_eq!(f.find(&LabelPlane::U8(&b), w, h, limits(1, 4, 0)).len(), 0);
        assert!(f.component_ids().iter().all(|&i| i == 0));
    }

    /// Paints a rectangle [u0, u1] x [v0, v1] inclusive into a u16 plane.
    fn paint16(plane: &mut [u16], w: usize, rect: [usize; 4], value: u16) {
        for v in rect[1]..=rect[3] {
            for u in rect[0]..=rect[2] {
                plane[v * w + u] = value;
            }
        }
    }

    #[test]
    fn touching_instances_of_one_class_stay_apart() {
        let (w, h) = (20, 10);
        let mut ids = vec![0u16; w * h];
        paint16(&mut ids, w, [2, 2, 7, 6], 1); // 30 px
        paint16(&mut ids, w, [8, 2, 12, 6], 2); // 25 px, sharing an edge with instance 1
        let classes = [0u16, 4, 4];
        let mut f = InstanceFinder::new();
        let found = f.find(&LabelPlane::Instances { ids: &ids, classes: &classes }, w, h, limits(1, 8, 0)).to_vec();
        assert_eq!(found.len(), 2);
        assert_eq!(
            (found[0].class_id, found[0].component_id, found[0].pixels, found[0].bbox),
            (4, 1, 30, [2, 2, 7, 6])
        );
        assert_eq!(
            (found[1].class_id, found[1].component_id, found[1].pixels, found[1].bbox),
            (4, 2, 25, [8, 2, 12, 6])
        );
        assert_eq!(f.component_ids()[2 * w + 8], 2);
        // The same pixels as a class plane: one region.
        let class_plane: Vec<u16> = ids.iter().map(|&i| classes[i as usize]).collect();
        let found = f.find(&LabelPlane::U16(&class_plane), w, h, limits(1, 8, 0)).to_vec();
        assert_eq!(found.len(), 1);
        assert_eq!((found[0].pixels, found[0].bbox), (55, [2, 2, 12, 6]));
    }

    #[test]
    fn an_instance_split_by_an_occluder_stays_one_instance() {
        let (w, h) = (20, 10);
        let mut ids = vec![0u16; w * h];
        paint16(&mut ids, w, [1, 1, 16, 4], 3); // instance 3 ...
        paint16(&mut ids, w, [7, 0, 9, 9], 1); // ... cut in two by instance 1 in front
        let classes = [0u16, 2, 0, 5];
        let mut f = InstanceFinder::new();
        let found = f.find(&LabelPlane::Instances { ids: &ids, classes: &classes }, w, h, limits(1, 8, 0)).to_vec();
        assert_eq!(found.len(), 2);
        let cut = found.iter().find(|c| c.component_id == 3).unwrap();
        assert_eq!((cut.class_id, cut.pixels, cut.bbox), (5, 13 * 4, [1, 1, 16, 4]));
        let ids_of_3 = f.component_ids().iter().filter(|&&i| i == 3).count();
        assert_eq!(ids_of_3, 52);
        assert_eq!((f.component_ids()[w + 1], f.component_ids()[w + 16]), (3, 3));
    }

    #[test]
    fn instances_without_a_known_class_are_skipped_and_counted() {
        let (w, h) = (10, 4);
        let mut ids = vec![0u16; w * h];
        paint16(&mut ids, w, [0, 0, 1, 1], 1); // class 2: kept
        paint16(&mut ids, w, [3, 0, 3, 2], 2); // class 0: no class
        paint16(&mut ids, w, [5, 0, 5, 1], 3); // class 9 > 3
        paint16(&mut ids, w, [7, 0, 9, 0], 8); // past the 4-entry table
        let classes = [0u16, 2, 0, 9];
        let mut f = InstanceFinder::new();
        let found = f.find(&LabelPlane::Instances { ids: &ids, classes: &classes }, w, h, limits(1, 8, 3)).to_vec();
        assert_eq!(found.len(), 1);
        assert_eq!((found[0].class_id, found[0].component_id, found[0].pixels), (2, 1, 4));
        assert_eq!(f.stats().unknown_class_pixels, 3 + 2 + 3);
        assert_eq!(f.stats().max_unknown_class, 9);
        assert!(f.component_ids()[3] == 0 && f.component_ids()[7] == 0);
    }

    #[test]
    fn instance_limits_keep_the_largest_and_break_ties_by_id() {
        let (w, h) = (30, 4);
        let mut ids = vec![0u16; w * h];
        paint16(&mut ids, w, [0, 0, 1, 1], 4); // 4 px
        paint16(&mut ids, w, [5, 0, 6, 1], 2); // 4 px
        paint16(&mut ids, w, [10, 0, 12, 3], 1); // 12 px
        paint16(&mut ids, w, [20, 0, 20, 0], 3); // 1 px
        let classes = [0u16, 1, 1, 1, 1];
        let mut f = InstanceFinder::new();
        let plane = LabelPlane::Instances { ids: &ids, classes: &classes };
        let found = f.find(&plane, w, h, limits(2, 2, 0)).to_vec();
        assert_eq!(found.iter().map(|c| c.component_id).collect::<Vec<_>>(), vec![1, 2]);
        assert_eq!((f.stats().small_components, f.stats().over_max_instances), (1, 1));
        // A frame with a shorter table and no instances forgets everything.
        let empty = vec![0u16; w * h];
        assert!(f.find(&LabelPlane::Instances { ids: &empty, classes: &[0] }, w, h, limits(1, 4, 0)).is_empty());
        assert!(f.component_ids().iter().all(|&i| i == 0));
    }
}
