//! Several instances per class: scattered copies, touching pairs and dense
//! heaps of one object, for instance-segmentation training.
//!
//! A pair is two copies with the same rest and nearly the same yaw, side by
//! side with a 0–3 mm gap. A heap is 4–8 copies: a base layer where each new
//! copy slides in from outside until its footprint touches the cluster (gap 0),
//! plus up to two copies lying on top of the base (resting on the highest
//! bounding box below them), so copies touch and hide each other.
//! Footprints are the conservative bounding rectangles of `placement`, so no
//! two copies interpenetrate.

use super::placement::{Footprint, RestPose};
use super::{PlacedObject, SamplerConfig, SamplerError, choose_rest};
use crate::{ObjectSet, Pose};
use nalgebra::{Translation3, UnitQuaternion, Vector2, Vector3};
use rand::Rng;
use rand_pcg::Pcg64Mcg;

/// Slide resolution when searching for contact (metres).
const CONTACT_TOLERANCE_M: f64 = 1e-4;

/// A placed copy: its pose, footprint and the z of its top (table frame).
#[derive(Clone, Copy, Debug)]
struct Slot {
    pose: Pose,
    footprint: Footprint,
    top_z: f64,
    bottom_z: f64,
}

/// What one drawn class becomes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Group {
    /// `n` copies placed independently.
    Scattered(usize),
    Pair,
    Heap(usize),
}

/// The layout state shared by all groups of a scene.
struct Layout<'c> {
    cfg: &'c SamplerConfig,
    table_half: [f64; 2],
    /// Every footprint placed so far (all layers), for the gap test.
    footprints: Vec<Footprint>,
}

impl Layout<'_> {
    fn on_table(&self, fp: &Footprint) -> bool {
        let r = fp.radius();
        fp.centre.x.abs() + r <= self.table_half[0] && fp.centre.y.abs() + r <= self.table_half[1]
    }

    fn free(&self, fp: &Footprint, gap: f64) -> bool {
        self.on_table(fp) && !self.footprints.iter().any(|o| o.overlaps(fp, gap))
    }
}

fn pose_of(rest: &RestPose, yaw: f64, pos: Vector2<f64>, z: f64) -> Pose {
    let rotation = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw) * rest.rotation;
    Pose::from_parts(Translation3::new(pos.x, pos.y, z + rest.lift), rotation)
}

fn slot(rest: &RestPose, yaw: f64, pos: Vector2<f64>, z: f64) -> Slot {
    Slot {
        pose: pose_of(rest, yaw, pos, z),
        footprint: Footprint::of(rest, yaw, pos),
        top_z: z + rest.height,
        bottom_z: z,
    }
}

/// One copy anywhere within the (growing) cluster radius, as the plain sampler does.
fn place_single(rng: &mut Pcg64Mcg, options: &[RestPose], layout: &Layout<'_>) -> Option<(Slot, RestPose, f64)> {
    const TRIES_PER_RADIUS: usize = 40;
    const RADIUS_STEPS: usize = 4;
    let cfg = layout.cfg;
    let mut radius = cfg.cluster_radius_m;
    for _ in 0..RADIUS_STEPS {
        for _ in 0..TRIES_PER_RADIUS {
            let rest = *choose_rest(rng, options, cfg.upright_probability);
            let yaw = rng.random_range(0.0..std::f64::consts::TAU);
            let (r, phi) = (radius * rng.random::<f64>().sqrt(), rng.random_range(0.0..std::f64::consts::TAU));
            let pos = Vector2::new(r * phi.cos(), r * phi.sin());
            let s = slot(&rest, yaw, pos, 0.0);
            if layout.free(&s.footprint, cfg.min_gap_m) {
                return Some((s, rest, yaw));
            }
        }
        radius *= 1.3;
    }
    None
}

/// Slides a footprint of `rest`/`yaw` from far out along `dir` towards
/// `centre` and returns the object position where it first comes within `gap`
/// of any of `members` (so it touches them with that gap), or `None` if it
/// never does.
fn slide_to_contact(
    rest: &RestPose,
    yaw: f64,
    centre: Vector2<f64>,
    dir: Vector2<f64>,
    members: &[Footprint],
    gap: f64,
) -> Option<Vector2<f64>> {
    let probe = Footprint::of(rest, yaw, Vector2::zeros());
    let reach = members.iter().map(|m| (m.centre - centre).norm() + m.radius()).fold(0.0, f64::max);
    let far = reach + probe.radius() + probe.centre.norm() + gap + 0.01;
    let hits = |s: f64| {
        let fp = Footprint::of(rest, yaw, centre + dir * s);
        members.iter().any(|m| m.overlaps(&fp, gap))
    };
    // March inward in steps smaller than any footprint, then bisect.
    let step = 0.004;
    let (mut free, mut hit) = (far, None);
    let mut s = far;
    while s > -far {
        if hits(s) {
            hit = Some(s);
            break;
        }
        free = s;
        s -= step;
    }
    let mut hit = hit?;
    while free - hit > CONTACT_TOLERANCE_M {
        let mid = 0.5 * (free + hit);
        if hits(mid) {
            hit = mid;
        } else {
            free = mid;
        }
    }
    Some(centre + dir * free)
}

fn random_dir(rng: &mut Pcg64Mcg) -> Vector2<f64> {
    let a = rng.random_range(0.0..std::f64::consts::TAU);
    Vector2::new(a.cos(), a.sin())
}

/// Two touching copies (gap drawn from `cfg.pair_gap_m`).
fn place_pair(rng: &mut Pcg64Mcg, options: &[RestPose], layout: &mut Layout<'_>) -> Vec<Slot> {
    let Some((first, rest, yaw)) = place_single(rng, options, layout) else {
        return Vec::new();
    };
    layout.footprints.push(first.footprint);
    let mut out = vec![first];
    let (g0, g1) = layout.cfg.pair_gap_m;
    for _ in 0..30 {
        let gap = if g1 > g0 { rng.random_range(g0..g1) } else { g0 };
        let yaw2 = yaw + rng.random_range(-0.14..0.14);
        let dir = random_dir(rng);
        let Some(pos) = slide_to_contact(&rest, yaw2, first.footprint.centre, dir, &[first.footprint], gap) else {
            continue;
        };
        let s = slot(&rest, yaw2, pos, 0.0);
        // Its partner is `gap` away by construction; everything else keeps the usual gap.
        let others_ok = layout.footprints[..layout.footprints.len() - 1]
            .iter()
            .all(|o| !o.overlaps(&s.footprint, layout.cfg.min_gap_m));
        if layout.on_table(&s.footprint) && others_ok && !first.footprint.overlaps(&s.footprint, gap * 0.5) {
            layout.footprints.push(s.footprint);
            out.push(s);
            break;
        }
    }
    out
}

/// A heap of `count` copies: a touching base layer plus up to two copies on top.
fn place_heap(rng: &mut Pcg64Mcg, options: &[RestPose], count: usize, layout: &mut Layout<'_>) -> Vec<Slot> {
    let Some((first, _, _)) = place_single(rng, options, layout) else {
        return Vec::new();
    };
    let before = layout.footprints.len();
    layout.footprints.push(first.footprint);
    let mut heap = vec![first];
    let top = if count >= 5 { rng.random_range(0..=2usize) } else { 0 };
    let base = count - top;
    let centre = first.footprint.centre;
    for _ in 1..base {
        for _ in 0..30 {
            let rest = *choose_rest(rng, options, layout.cfg.upright_probability);
            let yaw = rng.random_range(0.0..std::f64::consts::TAU);
            let members: Vec<Footprint> = heap.iter().map(|s| s.footprint).collect();
            let Some(pos) = slide_to_contact(&rest, yaw, centre, random_dir(rng), &members, 0.0) else {
                continue;
            };
            let s = slot(&rest, yaw, pos, 0.0);
            let others_ok = layout.footprints[..before].iter().all(|o| !o.overlaps(&s.footprint, layout.cfg.min_gap_m));
            if layout.on_table(&s.footprint) && others_ok {
                layout.footprints.push(s.footprint);
                heap.push(s);
                break;
            }
        }
    }
    // Lying copies on top, each resting on the highest box beneath it.
    let lying = options.iter().copied().max_by(|a, b| a.face_area.total_cmp(&b.face_area));
    if let Some(rest) = lying {
        for _ in 0..top {
            if heap.len() < 2 {
                break;
            }
            let under = heap[rng.random_range(0..heap.len())];
            let jitter = Vector2::new(rng.random_range(-0.3..0.3), rng.random_range(-0.3..0.3))
                .component_mul(&Vector2::new(under.footprint.half[0], under.footprint.half[1]));
            let yaw = rng.random_range(0.0..std::f64::consts::TAU);
            // Put the footprint centre (not the origin) over the chosen copy.
            let probe = Footprint::of(&rest, yaw, Vector2::zeros());
            let pos = under.footprint.centre + jitter - probe.centre;
            let fp = Footprint::of(&rest, yaw, pos);
            if !layout.on_table(&fp)
                || layout.footprints[..before].iter().any(|o| o.overlaps(&fp, layout.cfg.min_gap_m))
            {
                continue;
            }
            let support = heap.iter().filter(|s| s.footprint.overlaps(&fp, 0.0)).map(|s| s.top_z).fold(0.0, f64::max);
            let s = slot(&rest, yaw, pos, support);
            layout.footprints.push(s.footprint);
            heap.push(s);
        }
    }
    heap
}

/// The grouped layout: `min_objects..=max_objects` classes are drawn as the
/// plain sampler does; one may become a heap (`heap_probability`), another a
/// pair (`pair_probability`); every other class appears `instances_per_class`
/// times, scattered. Heaps are placed first (they need the most room).
pub(super) fn place_grouped(
    rng: &mut Pcg64Mcg,
    set: &ObjectSet,
    rests: &[Vec<RestPose>],
    table_half: [f64; 2],
    cfg: &SamplerConfig,
) -> Result<Vec<PlacedObject>, SamplerError> {
    const LAYOUT_ATTEMPTS: usize = 8;
    let mut best = 0;
    for _ in 0..LAYOUT_ATTEMPTS {
        let n = rng.random_range(cfg.min_objects..=cfg.max_objects);
        let classes: Vec<u16> = if !cfg.allow_duplicates && set.len() >= n {
            rand::seq::index::sample(rng, set.len(), n).into_iter().map(|i| i as u16 + 1).collect()
        } else {
            (0..n).map(|_| rng.random_range(0..set.len()) as u16 + 1).collect()
        };
        let (i0, i1) = cfg.instances_per_class;
        let mut groups: Vec<(u16, Group)> =
            classes.iter().map(|&c| (c, Group::Scattered(rng.random_range(i0..=i1.max(i0))))).collect();
        let mut heap_at = None;
        if cfg.heap_probability > 0.0 && rng.random_bool(cfg.heap_probability) {
            let i = rng.random_range(0..groups.len());
            let (h0, h1) = cfg.heap_size;
            groups[i].1 = Group::Heap(rng.random_range(h0..=h1.max(h0)));
            heap_at = Some(i);
        }
        if cfg.pair_probability > 0.0 && rng.random_bool(cfg.pair_probability) {
            let free: Vec<usize> = (0..groups.len()).filter(|&i| Some(i) != heap_at).collect();
            if !free.is_empty() {
                groups[free[rng.random_range(0..free.len())]].1 = Group::Pair;
            }
        }
        groups.sort_by_key(|(_, g)| match g {
            Group::Heap(_) => 0,
            Group::Pair => 1,
            Group::Scattered(_) => 2,
        });
        let mut layout = Layout { cfg, table_half, footprints: Vec::new() };
        let mut placed: Vec<PlacedObject> = Vec::new();
        for (class_id, group) in groups {
            let options = &rests[class_id as usize - 1];
            let slots = match group {
                Group::Heap(count) => place_heap(rng, options, count, &mut layout),
                Group::Pair => place_pair(rng, options, &mut layout),
                Group::Scattered(count) => (0..count)
                    .filter_map(|_| {
                        let (s, _, _) = place_single(rng, options, &layout)?;
                        layout.footprints.push(s.footprint);
                        Some(s)
                    })
                    .collect(),
            };
            for s in slots {
                debug_assert!(s.bottom_z >= 0.0);
                placed.push(PlacedObject {
                    class_id,
                    instance_label: placed.len() as u16 + 1,
                    table_from_object: s.pose,
                });
            }
        }
        if placed.len() >= cfg.min_objects {
            return Ok(placed);
        }
        best = best.max(placed.len());
    }
    Err(SamplerError::Placement { placed: best, required: cfg.min_objects })
}
