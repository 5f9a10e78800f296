//! Segmenter regions completed by the depth image.
//!
//! The segmenter's colour evidence fails in ways depth does not: a thin or
//! partly hidden object loses cells to the background, and untextured objects
//! of one grey split into pieces of several classes. Depth says which cells
//! stand on the table together. [`DepthRegions::apply`] fits the supporting
//! plane (RANSAC over the background cells' 3D points), groups the cells above
//! it into depth-connected components (4-neighbours without a depth jump) and,
//! in a component that fits inside one object of its majority class and where
//! that class holds enough of the cells, gives that class to the component's
//! background cells (grow) and to cells of classes holding only a small share
//! of it where the segmenter also gave that class some probability (absorb:
//! its colour evidence was torn there). Components that are larger than one object (touching
//! objects, heaps) or where no class leads are left as the segmenter labelled
//! them, as is everything when no plane is found.
//!
//! Works on the output cell grid (80x60 for the shipped segmenter), one depth
//! sample per cell; buffers are sized on the first frame of a grid size and
//! never grown after that.

use nalgebra::Vector3;

use crate::frame::FrameView;
use crate::parts::ClassExtents;
use crate::sampling::back_project;
use crate::support::{self, SupportPlane};

use super::engine::softmax_terms;
use super::input::FrameMap;

/// Tunables of [`DepthRegions`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthRegionParams {
    /// Height above the plane from which a cell stands on it (metres).
    pub min_height_m: f32,
    /// Largest depth step between 4-neighbour cells of one component: metres
    /// plus this share of the depth.
    pub max_step_m: f32,
    pub max_step_per_m: f32,
    /// The majority class needs at least this share of the component's cells.
    pub min_majority_share: f32,
    /// Cells of another class are absorbed when that class holds less than
    /// this share of the component's labelled cells (0 = grow only).
    pub absorb_below_share: f32,
    /// ... and only where the segmenter gave the majority class at least
    /// this probability (its colour evidence was torn; 0 = everywhere).
    pub absorb_min_probability: f32,
    /// A component fits one object when its bounding box diagonal is within
    /// the class's diameter times this.
    pub extent_slack: f32,
}

/// The defaults were chosen on the tuning splits (docs/BENCHMARKS.md,
/// "Session 23"): a looser absorb (no probability condition) gained more on
/// the YCB meshes but merged small objects into larger neighbours on the
/// built-in ones.
impl Default for DepthRegionParams {
    fn default() -> Self {
        Self {
            min_height_m: 0.008,
            max_step_m: 0.02,
            max_step_per_m: 0.02,
            min_majority_share: 0.3,
            absorb_below_share: 0.5,
            absorb_min_probability: 0.1,
            extent_slack: 1.3,
        }
    }
}

impl DepthRegionParams {
    /// A setting as configs and flags spell it: `off` (`None`), `on` (the
    /// defaults) or `KEY=VALUE,…` over the defaults ([`std::str::FromStr`]).
    pub fn parse_setting(s: &str) -> Result<Option<Self>, String> {
        if s == "off" { Ok(None) } else { s.parse().map(Some) }
    }
}

impl std::str::FromStr for DepthRegionParams {
    type Err = String;

    /// `on` (the defaults) or a comma list of `KEY=VALUE` over the defaults:
    /// `height` (m), `step` (m), `step-per-m`, `share`, `absorb`, `absorb-p`, `slack`.
    fn from_str(s: &str) -> Result<Self, String> {
        let mut p = Self::default();
        if s == "on" {
            return Ok(p);
        }
        for item in s.split(',') {
            let (key, value) = item
                .split_once('=')
                .ok_or_else(|| format!("depth regions: `{item}` is not KEY=VALUE (or use `on` for the defaults)"))?;
            let v: f32 = value
                .parse()
                .ok()
                .filter(|v: &f32| v.is_finite() && *v >= 0.0)
                .ok_or_else(|| format!("depth regions: `{key}` needs a finite number >= 0, got `{value}`"))?;
            match key {
                "height" => p.min_height_m = v,
                "step" => p.max_step_m = v,
                "step-per-m" => p.max_step_per_m = v,
                "share" => p.min_majority_share = v,
                "absorb" => p.absorb_below_share = v,
                "absorb-p" => p.absorb_min_probability = v,
                "slack" => p.extent_slack = v,
                _ => {
                    return Err(format!(
                        "depth regions: unknown key `{key}`; expected height, step, step-per-m, share, absorb, absorb-p or slack"
                    ));
                }
            }
        }
        Ok(p)
    }
}

/// Per-frame scratch and the class extents; see the module doc.
#[derive(Debug)]
pub struct DepthRegions {
    params: DepthRegionParams,
    extents: ClassExtents,
    /// Per cell: camera-frame point (metres), z = 0 where the cell has no depth.
    points: Vec<Vector3<f32>>,
    /// Per cell: already in a component.
    seen: Vec<bool>,
    /// Cells of every component, component by component ([`Self::components`]).
    members: Vec<u32>,
    /// Start of each component in `members`, then the end of the last.
    bounds: Vec<u32>,
    /// Cells per class in the component being judged (index = class id).
    counts: Vec<u32>,
    /// Background cells' points (the plane's samples).
    background: Vec<Vector3<f32>>,
}

impl DepthRegions {
    /// `extents[k]`: the diameter of class id k + 1 in metres (see
    /// [`crate::parts::extents`] with factor 1).
    pub fn new(extents: &[f32], params: DepthRegionParams) -> Self {
        Self {
            params,
            extents: ClassExtents::new(extents),
            points: Vec::new(),
            seen: Vec::new(),
            members: Vec::new(),
            bounds: Vec::new(),
            counts: vec![0; extents.len() + 1],
            background: Vec::new(),
        }
    }

    pub fn params(&self) -> DepthRegionParams {
        self.params
    }

    fn fit(&mut self, n: usize) {
        if self.points.len() != n {
            self.points = vec![Vector3::zeros(); n];
            self.seen = vec![false; n];
            self.members = Vec::with_capacity(n);
            self.bounds = Vec::with_capacity(n + 1);
            self.background = Vec::with_capacity(n);
        }
    }

    /// Regroups `cells` (the `map`'s output grid, class ids, 0 = background)
    /// of `frame` as the module doc describes; `logits` are the segmenter's
    /// (`[classes + 1, cells]`, class-major). Returns how many cells changed.
    pub fn apply(&mut self, frame: &FrameView<'_>, map: &FrameMap, logits: &[f32], cells: &mut [u16]) -> usize {
        let (gw, gh) = map.grid_size();
        let n = gw * gh;
        if cells.len() != n || n == 0 || logits.len() < n * self.counts.len() {
            return 0;
        }
        self.fit(n);
        self.cell_points(frame, map, gw, gh);
        let Some(plane) = self.plane(cells) else { return 0 };
        self.components(&plane, gw, gh);
        self.relabel(logits, cells)
    }

    /// One depth sample per cell: the pixel at the cell's centre, back-projected.
    fn cell_points(&mut self, frame: &FrameView<'_>, map: &FrameMap, gw: usize, gh: usize) {
        let width = frame.width();
        for y in 0..gh {
            for x in 0..gw {
                let (u, v) = map.centre(x, y);
                let z = frame.depth.metres(v * width + u).unwrap_or(0.0);
                self.points[y * gw + x] =
                    if z.is_finite() && z > 0.0 { back_project(frame, u, v, z).into() } else { Vector3::zeros() };
            }
        }
    }

    /// The supporting plane (see [`crate::support`]) of the background
    /// cells with depth, or `None` when the background has none.
    fn plane(&mut self, cells: &[u16]) -> Option<SupportPlane> {
        self.background.clear();
        self.background.extend(cells.iter().zip(&self.points).filter(|(c, p)| **c == 0 && p.z > 0.0).map(|(_, p)| *p));
        support::fit(&self.background)
    }

    /// The components of the cells standing on the plane: their cells in
    /// `self.members`, component k at `self.bounds[k]..self.bounds[k + 1]`.
    fn components(&mut self, plane: &SupportPlane, gw: usize, gh: usize) {
        let p = self.params;
        let above = |q: &Vector3<f32>| q.z > 0.0 && plane.height(q) > p.min_height_m;
        self.seen.fill(false);
        self.members.clear();
        self.bounds.clear();
        for start in 0..gw * gh {
            if self.seen[start] || !above(&self.points[start]) {
                continue;
            }
            self.bounds.push(self.members.len() as u32);
            self.seen[start] = true;
            self.members.push(start as u32);
            let mut next = self.members.len() - 1;
            // Breadth-first over `members` itself: no second queue.
            while next < self.members.len() {
                let i = self.members[next] as usize;
                next += 1;
                let (x, y) = (i % gw, i / gw);
                let z = self.points[i].z;
                let step = p.max_step_m + p.max_step_per_m * z;
                let neighbours = [
                    (x > 0).then(|| i - 1),
                    (x + 1 < gw).then(|| i + 1),
                    (y > 0).then(|| i - gw),
                    (y + 1 < gh).then(|| i + gw),
                ];
                for j in neighbours.into_iter().flatten() {
                    let q = &self.points[j];
                    if !self.seen[j] && above(q) && (q.z - z).abs() <= step {
                        self.seen[j] = true;
                        self.members.push(j as u32);
                    }
                }
            }
        }
        self.bounds.push(self.members.len() as u32);
    }

    /// Relabels every component that passes; returns the changed cells.
    fn relabel(&mut self, logits: &[f32], cells: &mut [u16]) -> usize {
        let p = self.params;
        let (n, classes) = (cells.len(), self.counts.len());
        let mut changed = 0;
        for k in 0..self.bounds.len().saturating_sub(1) {
            let members = &self.members[self.bounds[k] as usize..self.bounds[k + 1] as usize];
            self.counts.fill(0);
            let (mut lo, mut hi) = (Vector3::repeat(f32::INFINITY), Vector3::repeat(f32::NEG_INFINITY));
            for &i in members {
                let i = i as usize;
                if let Some(c) = self.counts.get_mut(cells[i] as usize) {
                    *c += 1;
                }
                lo = lo.inf(&self.points[i]);
                hi = hi.sup(&self.points[i]);
            }
            let total = members.len() as u32;
            let labelled = total - self.counts[0];
            // The majority class (the lower id on a tie).
            let Some((class, &most)) =
                self.counts.iter().enumerate().skip(1).max_by_key(|&(c, &k)| (k, usize::MAX - c))
            else {
                continue;
            };
            if most == 0 || (most as f32) < p.min_majority_share * total as f32 {
                continue;
            }
            let diagonal = (hi - lo).norm();
            let extent = self.extents.of(class as u16);
            if extent <= 0.0 || diagonal.is_nan() || diagonal > extent * p.extent_slack {
                continue;
            }
            for &i in members {
                let own = cells[i as usize];
                let take = own == 0
                    || own as usize != class
                        && (self.counts.get(own as usize).copied().unwrap_or(0) as f32)
                            < p.absorb_below_share * labelled as f32
                        && probability(logits, n, classes, i as usize, class) >= p.absorb_min_probability;
                if take {
                    cells[i as usize] = class as u16;
                    changed += 1;
                }
            }
        }
        changed
    }
}

/// Softmax probability of `class` in cell `i` of class-major `logits` (`[classes, n]`).
fn probability(logits: &[f32], n: usize, classes: usize, i: usize, class: usize) -> f32 {
    let at = |c: usize| logits[c * n + i];
    let (max, sum) = softmax_terms(classes, at);
    (at(class) - max).exp() / sum
}
