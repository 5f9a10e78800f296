//! Region borders at frame resolution from the segmenter's cell grid.
//!
//! The network labels cells of 8x8 pixels (640x480 frame, default config).
//! Copying a cell's label to all its pixels puts up to half a cell of the
//! neighbour (often background far behind the object) into a mask; eroding
//! one cell removes that but also the object's rim and every region thinner
//! than three cells. [`Boundary::Refine`] keeps the cell labels inside regions
//! and, in cells whose 3x3 neighbourhood holds more than one label, gives
//! each pixel the class whose logit, interpolated bilinearly between cell
//! centres, is highest among the labels of that neighbourhood (so a class
//! that the cell clean-up removed does not come back), then clears `erode_px`
//! pixels along every border.

use super::input::FrameMap;

/// How cell labels become the frame's label plane. The default,
/// `Refine { erode_px: 3 }`, was chosen on the tuning split (docs/BENCHMARKS.md,
/// "Segmenter borders").
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Boundary {
    /// Each pixel takes its cell's label (nearest upsampling).
    Cells,
    /// Cells with a 4-neighbour of another label become background, then nearest upsampling.
    ErodeCells,
    /// Bilinear logit argmax in border cells, then `erode_px` pixels of every
    /// labelled region's border become background.
    Refine { erode_px: u8 },
}

impl Default for Boundary {
    fn default() -> Self {
        Self::Refine { erode_px: 3 }
    }
}

impl std::str::FromStr for Boundary {
    type Err = String;

    /// `cells`, `erode-cells`, `refine` (= `refine:0`) or `refine:N` (N pixels eroded, 0..=255).
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "cells" => Ok(Self::Cells),
            "erode-cells" => Ok(Self::ErodeCells),
            "refine" => Ok(Self::Refine { erode_px: 0 }),
            _ => match s.strip_prefix("refine:").map(str::parse::<u8>) {
                Some(Ok(erode_px)) => Ok(Self::Refine { erode_px }),
                _ => Err(format!("unknown boundary mode `{s}`: expected cells, erode-cells, refine or refine:N")),
            },
        }
    }
}

impl std::fmt::Display for Boundary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Cells => write!(f, "cells"),
            Self::ErodeCells => write!(f, "erode-cells"),
            Self::Refine { erode_px } => write!(f, "refine:{erode_px}"),
        }
    }
}

/// Scratch for [`refine`], sized for one frame (allocated by [`BoundaryScratch::fit`] only when the size changes).
#[derive(Default)]
pub struct BoundaryScratch {
    /// Per cell: its 3x3 neighbourhood holds more than one label.
    border: Vec<bool>,
    /// Per cell: a border cell lies in its 3x3 neighbourhood (only such
    /// cells have pixels near another label, for erosions up to a cell).
    near: Vec<bool>,
    /// A copy of the label plane before erosion.
    before: Vec<u16>,
    /// Per frame column: the pixel of the row being eroded has another label in its window.
    hit: Vec<bool>,
}

impl BoundaryScratch {
    /// Makes room for `cells` grid cells and `pixels` frame pixels in rows of `width`.
    pub fn fit(&mut self, cells: usize, pixels: usize, width: usize) {
        if self.border.len() != cells {
            self.border = vec![false; cells];
            self.near = vec![false; cells];
        }
        if self.before.len() != pixels {
            self.before = vec![0; pixels];
        }
        if self.hit.len() != width {
            self.hit = vec![false; width];
        }
    }
}

/// The distinct labels of the 3x3 cell neighbourhood of (x, y) (at most 9).
fn neighbourhood_labels(cells: &[u16], w: usize, h: usize, x: usize, y: usize, out: &mut [u16; 9]) -> usize {
    let mut n = 0;
    for yy in y.saturating_sub(1)..(y + 2).min(h) {
        for xx in x.saturating_sub(1)..(x + 2).min(w) {
            let c = cells[yy * w + xx];
            if !out[..n].contains(&c) {
                out[n] = c;
                n += 1;
            }
        }
    }
    n
}

/// Writes the frame's label plane (`labels_out`, width * height) from cell
/// labels `cells` (`[out_h * out_w]`, after clean-up) and the network's
/// `logits` (`[classes, out_h * out_w]`), as [`Boundary::Refine`] describes.
/// Works cell by cell: interior cells are filled, border cells interpolated.
pub fn refine(
    map: &FrameMap,
    cells: &[u16],
    logits: &[f32],
    erode_px: u8,
    scratch: &mut BoundaryScratch,
    labels_out: &mut [u16],
) {
    let (w, h) = map.grid_size();
    let (width, height) = map.frame_size();
    let n = w * h;
    scratch.fit(n, width * height, width);
    let mut labels = [0u16; 9];
    for (i, b) in scratch.border.iter_mut().enumerate() {
        *b = neighbourhood_labels(cells, w, h, i % w, i / w, &mut labels) > 1;
    }
    for cy in 0..h {
        let rows = map.span_y(cy);
        for cx in 0..w {
            let cell = cy * w + cx;
            let cols = map.span_x(cx);
            if !scratch.border[cell] {
                for v in rows.clone() {
                    labels_out[v * width + cols.start..v * width + cols.end].fill(cells[cell]);
                }
                continue;
            }
            let k = neighbourhood_labels(cells, w, h, cx, cy, &mut labels);
            for v in rows.clone() {
                let (y0, y1, fy) = map.interp_y(v);
                for u in cols.clone() {
                    let (x0, x1, fx) = map.interp_x(u);
                    let mut best = (f32::NEG_INFINITY, cells[cell]);
                    for &c in &labels[..k] {
                        let p = &logits[c as usize * n..(c as usize + 1) * n];
                        let top = p[y0 * w + x0] + fx * (p[y0 * w + x1] - p[y0 * w + x0]);
                        let bottom = p[y1 * w + x0] + fx * (p[y1 * w + x1] - p[y1 * w + x0]);
                        let value = top + fy * (bottom - top);
                        if value > best.0 {
                            best = (value, c);
                        }
                    }
                    labels_out[v * width + u] = best.1;
                }
            }
        }
    }
    if erode_px == 0 {
        return;
    }
    let r = erode_px as usize;
    // Cells are at least floor(len / n) pixels wide; within that distance of an
    // interior cell that is not near a border every pixel has its label, so
    // rows of cells none of which is near a border have nothing to erode.
    let within_a_cell = width >= w && height >= h && r <= width / w && r <= height / h;
    for (i, near) in scratch.near.iter_mut().enumerate() {
        let (x, y) = (i % w, i / w);
        *near = !within_a_cell
            || (y.saturating_sub(1)..(y + 2).min(h))
                .any(|yy| (x.saturating_sub(1)..(x + 2).min(w)).any(|xx| scratch.border[yy * w + xx]));
    }
    scratch.before.copy_from_slice(labels_out);
    for cy in 0..h {
        if scratch.near[cy * w..(cy + 1) * w].iter().any(|&n| n) {
            erode_rows(&scratch.before, width, height, map.span_y(cy), r, &mut scratch.hit, labels_out);
        }
    }
}

/// Clears (sets to 0) each labelled pixel of `rows` that has another label
/// within `r` pixels in its row or column of `before` (the frame's ends are
/// not a difference), writing into `out`. A pixel has one exactly when two
/// neighbouring pixels of its window differ, so each row ORs the label
/// changes between `2r` pairs of rows and `2r` shifts of itself: plain slice
/// comparisons the compiler vectorises, with no per-pixel window scan.
/// `hit`: scratch of `width`.
fn erode_rows(
    before: &[u16],
    width: usize,
    height: usize,
    rows: std::ops::Range<usize>,
    r: usize,
    hit: &mut [bool],
    out: &mut [u16],
) {
    let line = |v: usize| &before[v * width..(v + 1) * width];
    for v in rows {
        hit.fill(false);
        // Pairs of rows (a, a + 1) inside the column window [v - r, v + r].
        for a in v.saturating_sub(r)..(v + r).min(height - 1) {
            for ((h, x), y) in hit.iter_mut().zip(line(a)).zip(line(a + 1)) {
                *h |= x != y;
            }
        }
        // Pairs of pixels (u + d, u + d + 1), d in -r..r, inside the row window.
        let row = line(v);
        for d in -(r as isize)..r as isize {
            let first = (-d).max(0) as usize;
            let end = (width as isize - 1 - d).clamp(0, width as isize) as usize;
            if first >= end {
                continue;
            }
            let pairs = &row[(first as isize + d) as usize..(end as isize + d) as usize + 1];
            for (h, pair) in hit[first..end].iter_mut().zip(pairs.windows(2)) {
                *h |= pair[0] != pair[1];
            }
        }
        for ((o, &c), &h) in out[v * width..(v + 1) * width].iter_mut().zip(row).zip(hit.iter()) {
            if h && c != 0 {
                *o = 0;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::seg::SegConfig;

    /// A frame of 640x480 over the default 80x60 grid; `logit(class, x, y)` per cell.
    fn setup(logit: impl Fn(usize, f32, f32) -> f32, classes: usize) -> (FrameMap, Vec<u16>, Vec<f32>) {
        let cfg = SegConfig::new(classes - 1);
        let map = FrameMap::new(640, 480, &cfg);
        let (w, h) = map.grid_size();
        let n = w * h;
        let mut logits = vec![0.0f32; classes * n];
        for c in 0..classes {
            for i in 0..n {
                logits[c * n + i] = logit(c, (i % w) as f32, (i / w) as f32);
            }
        }
        let mut cells = vec![0u16; n];
        // Argmax, the first maximum winning (as the engine's).
        for (i, cell) in cells.iter_mut().enumerate() {
            for c in 1..classes {
                if logits[c * n + i] > logits[*cell as usize * n + i] {
                    *cell = c as u16;
                }
            }
        }
        (map, cells, logits)
    }

    #[test]
    fn border_follows_the_interpolated_logits_not_the_cell_steps() {
        // Class 1 wins where cell x < 20.3 (logit difference linear in x):
        // its border lies 0.3 cells (2.4 px) right of the centre of cell 20,
        // at u = (20.3 + 0.5) * 8 = 166.4, so pixel 165 (centre 165.5) is
        // the last of class 1.
        let (map, cells, logits) = setup(|c, x, _| if c == 1 { 20.3 - x } else { 0.0 }, 2);
        let mut out = vec![9u16; 640 * 480];
        let mut scratch = BoundaryScratch::default();
        refine(&map, &cells, &logits, 0, &mut scratch, &mut out);
        for v in [0usize, 240, 479] {
            let row = &out[v * 640..(v + 1) * 640];
            let last_one = row.iter().rposition(|&l| l == 1).unwrap_or(0);
            assert_eq!(last_one, 165, "row {v}");
            assert!(row[..=165].iter().all(|&l| l == 1) && row[166..].iter().all(|&l| l == 0));
        }
        // Nearest upsampling puts it at the edge of cell 20 (pixels 160..=167).
        let mut nearest = vec![0u16; 640 * 480];
        map.upsample(&cells, &mut nearest);
        assert_eq!(nearest[..640].iter().rposition(|&l| l == 1), Some(167));
    }

    #[test]
    fn erosion_clears_r_pixels_on_each_side_of_a_border() {
        let (map, cells, logits) = setup(|c, x, _| if c == 1 { 20.3 - x } else { 0.0 }, 2);
        let mut out = vec![0u16; 640 * 480];
        let mut scratch = BoundaryScratch::default();
        refine(&map, &cells, &logits, 2, &mut scratch, &mut out);
        let row = &out[240 * 640..241 * 640];
        // Pixels 164 and 165 see the background within 2 px; 163 does not.
        assert_eq!(row.iter().rposition(|&l| l == 1), Some(163));
        // The frame edge is not a border.
        assert_eq!(row[0], 1);
        assert_eq!(out[0], 1);
    }

    #[test]
    fn classes_removed_from_the_cells_do_not_come_back() {
        // Class 2 wins cells (30, 30) and (31, 30), on class 1's border, but
        // the clean-up removed them; interpolation alone would bring it back.
        let (map, mut cells, logits) = setup(
            |c, x, y| match c {
                1 => 30.5 - x,
                2 if (x - 30.5).abs() < 1.0 && y == 30.0 => 100.0,
                _ => 0.0,
            },
            3,
        );
        assert_eq!(cells.iter().filter(|c| **c == 2).count(), 2);
        for c in cells.iter_mut().filter(|c| **c == 2) {
            *c = 0;
        }
        let mut out = vec![0u16; 640 * 480];
        let mut scratch = BoundaryScratch::default();
        refine(&map, &cells, &logits, 0, &mut scratch, &mut out);
        assert!(!out.contains(&2));
        assert!(out.contains(&1));
    }

    /// Brute force: every labelled pixel with another label within `r` in its row or column.
    fn eroded_reference(labels: &[u16], width: usize, height: usize, r: usize) -> Vec<u16> {
        let mut out = labels.to_vec();
        for v in 0..height {
            for u in 0..width {
                let c = labels[v * width + u];
                let near = (u.saturating_sub(r)..(u + r + 1).min(width)).any(|x| labels[v * width + x] != c)
                    || (v.saturating_sub(r)..(v + r + 1).min(height)).any(|y| labels[y * width + u] != c);
                if c != 0 && near {
                    out[v * width + u] = 0;
                }
            }
        }
        out
    }

    #[test]
    fn erosion_matches_brute_force_on_a_busy_frame() {
        // Three classes in rings and stripes: many borders in many directions.
        let logit = |c: usize, x: f32, y: f32| {
            let ring = ((x - 40.0).powi(2) + (y - 30.0).powi(2)).sqrt();
            match c {
                1 => 6.0 - (ring - 12.0).abs(),
                2 => 2.0 * (x * 0.7 + y * 0.3).sin(),
                _ => 0.5,
            }
        };
        for r in [1u8, 3, 8, 9, 20] {
            let (map, cells, logits) = setup(logit, 3);
            let mut plain = vec![0u16; 640 * 480];
            let mut scratch = BoundaryScratch::default();
            refine(&map, &cells, &logits, 0, &mut scratch, &mut plain);
            let mut eroded = vec![0u16; 640 * 480];
            refine(&map, &cells, &logits, r, &mut scratch, &mut eroded);
            assert!(plain.contains(&1) && plain.contains(&2));
            assert_eq!(eroded, eroded_reference(&plain, 640, 480, r as usize), "r = {r}");
        }
    }

    #[test]
    fn erosion_matches_brute_force_on_random_planes() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
        for _ in 0..300 {
            let (width, height) = (rng.random_range(1..30), rng.random_range(1..30));
            // Runs of few labels, so that windows both fit in regions and cross them.
            let mut plane = Vec::with_capacity(width * height);
            while plane.len() < width * height {
                let (label, run) = (rng.random_range(0..3u16), rng.random_range(1..12));
                plane.extend(std::iter::repeat_n(label, run.min(width * height - plane.len())));
            }
            let r = rng.random_range(0..6);
            let mut out = plane.clone();
            erode_rows(&plane, width, height, 0..height, r, &mut vec![false; width], &mut out);
            assert_eq!(out, eroded_reference(&plane, width, height, r), "{width}x{height} r {r}");
        }
    }

    /// `cargo test --release -p fusepose-estimator refine_speed -- --ignored --nocapture`:
    /// borders and erosion of the busy frame above, best of 7 × 50.
    #[test]
    #[ignore = "timing; prints numbers"]
    fn refine_speed() {
        let logit = |c: usize, x: f32, y: f32| {
            let ring = ((x - 40.0).powi(2) + (y - 30.0).powi(2)).sqrt();
            match c {
                1 => 6.0 - (ring - 12.0).abs(),
                2 => 2.0 * (x * 0.3 + y * 0.1).sin(),
                _ => 0.5,
            }
        };
        let (map, cells, logits) = setup(logit, 3);
        let mut out = vec![0u16; 640 * 480];
        let mut scratch = BoundaryScratch::default();
        for r in [0u8, 3] {
            let mut best = f64::MAX;
            for _ in 0..7 {
                let t = std::time::Instant::now();
                (0..50).for_each(|_| refine(&map, &cells, &logits, r, &mut scratch, &mut out));
                best = best.min(t.elapsed().as_secs_f64() * 1e3 / 50.0);
            }
            let border = scratch.border.iter().filter(|b| **b).count();
            println!("refine 640x480, erode {r} px: {best:.3} ms ({border} of {} cells on a border)", cells.len());
        }
    }

    #[test]
    fn modes_parse_and_print() {
        for mode in [Boundary::Cells, Boundary::ErodeCells, Boundary::Refine { erode_px: 3 }] {
            assert_eq!(mode.to_string().parse::<Boundary>(), Ok(mode));
        }
        assert_eq!("refine".parse::<Boundary>(), Ok(Boundary::Refine { erode_px: 0 }));
        assert!("refine:300".parse::<Boundary>().is_err());
        assert!("erode".parse::<Boundary>().is_err());
    }

    #[test]
    fn uniform_cells_upsample_exactly() {
        let (map, cells, logits) = setup(|c, x, y| if c == 1 && x < 10.0 && y < 10.0 { 1.0 } else { 0.0 }, 2);
        let mut refined = vec![0u16; 640 * 480];
        let mut nearest = vec![0u16; 640 * 480];
        let mut scratch = BoundaryScratch::default();
        refine(&map, &cells, &logits, 0, &mut scratch, &mut refined);
        map.upsample(&cells, &mut nearest);
        // Away from the region's border (cells 0..8 in both axes), labels agree.
        for v in 0..64 {
            for u in 0..64 {
                assert_eq!(refined[v * 640 + u], nearest[v * 640 + u]);
            }
        }
        assert_eq!(refined[240 * 640 + 320], 0);
    }
}
