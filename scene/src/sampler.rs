//! YCB-Video-like tabletop scenes: a textured table in a room, 3–8 objects
//! resting on it in stable orientations with random yaw (no interpenetration,
//! often close enough to occlude each other), random lighting, and cameras on
//! a hemisphere 0.5–1.5 m away looking at the objects. A seed fixes everything.
//!
//! [`sample_scene`] draws a [`Scene`]; [`render_view`] renders one of its
//! camera views (with optional sensor noise) and returns the [`FrameTruth`].
//!
//! Table frame: origin at the centre of the table top, z up, metres.

pub mod backdrop;
pub mod distractors;
mod instances;
pub mod placement;
pub mod randomization;
pub mod viewpoint;

use crate::render::{
    self, DepthSensor, ItemCoverage, Lighting, NoiseConfig, PixelBox, Randomize, RenderError, RenderItem,
    RenderSettings, RenderTarget,
};
use crate::{Intrinsics, ObjectSet, Pose};
use backdrop::Backdrop;
use nalgebra::{Point3, Translation3, UnitQuaternion, Vector2, Vector3};
use placement::{Footprint, RestPose, rest_poses};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use viewpoint::{ViewRanges, random_view};

/// What [`sample_scene`] draws from. Defaults give YCB-Video-like scenes.
#[derive(Clone, Debug, PartialEq)]
pub struct SamplerConfig {
    /// Objects per scene, inclusive range (3..=8).
    pub min_objects: usize,
    pub max_objects: usize,
    /// Whether a class may appear twice in a scene (false; forced true when
    /// the set has fewer classes than objects requested).
    pub allow_duplicates: bool,
    /// Probability that an object rests on its bottom face (−z of its frame);
    /// otherwise a bounding-box face is drawn with probability ∝ its area (0.6).
    pub upright_probability: f64,
    /// Objects are first placed within this radius of the table centre; it
    /// grows when a dense scene does not fit (metres, 0.18).
    pub cluster_radius_m: f64,
    /// Minimum gap between object footprints (metres, 0.003).
    pub min_gap_m: f64,
    /// Camera distance from the look-at point (metres, 0.5..1.5).
    pub camera_distance_m: (f64, f64),
    /// Camera elevation above the table plane (degrees, 15..75).
    pub camera_elevation_deg: (f64, f64),
    /// Camera roll: uniform in ±this (degrees, 5).
    pub camera_max_roll_deg: f64,
    /// The look-at point is the objects' centroid 5 cm above the table plus
    /// a uniform jitter of ±this per axis (metres, 0.05).
    pub look_at_jitter_m: f64,
    /// Camera views per scene (1).
    pub views: usize,
    /// If set, each view is redrawn (at most `occlusion_tries` times) until at
    /// least one object has a hidden fraction in this range, e.g. (0.3, 0.7).
    pub target_occlusion: Option<(f64, f64)>,
    pub occlusion_tries: usize,
    /// Camera used to evaluate occlusion (rendered at a quarter resolution).
    pub intrinsics: Intrinsics,
    /// Domain randomisation (`Off`): lights, textures, walls, distractors,
    /// border occluders and edge-cut views in [`sample_scene`]; shadows,
    /// specular highlights, colour jitter, the camera pipeline and intrinsics
    /// jitter in [`render_view`]. `Off` keeps the pre-randomisation scenes.
    pub randomize: Randomize,
    /// The depth-sensor model [`render_view`] applies (`Basic`, the original model).
    pub depth_sensor: DepthSensor,
    /// Copies of each drawn class, inclusive range (1, 1); copies are placed
    /// independently. `min_objects..=max_objects` counts drawn classes.
    pub instances_per_class: (usize, usize),
    /// Probability that a scene contains a pair: one drawn class appears as two
    /// identical copies side by side, `pair_gap_m` apart (0).
    pub pair_probability: f64,
    /// Gap between the two copies of a pair (metres, 0..0.003).
    pub pair_gap_m: (f64, f64),
    /// Probability that a scene contains a heap: one drawn class appears as
    /// `heap_size` copies touching each other (gap 0), some lying on top (0).
    pub heap_probability: f64,
    /// Copies in a heap, inclusive range (4, 8).
    pub heap_size: (usize, usize),
    /// With randomisation on, the share of scenes (chosen by seed) drawn in
    /// the original domain instead: `Randomize::Off` and the `Basic` sensor,
    /// other settings kept (0). Keeps the plain-scene accuracy a randomised
    /// retraining would otherwise trade away.
    pub plain_share: f64,
}

impl Default for SamplerConfig {
    fn default() -> Self {
        SamplerConfig {
            min_objects: 3,
            max_objects: 8,
            allow_duplicates: false,
            upright_probability: 0.6,
            cluster_radius_m: 0.18,
            min_gap_m: 0.003,
            camera_distance_m: (0.5, 1.5),
            camera_elevation_deg: (15.0, 75.0),
            camera_max_roll_deg: 5.0,
            look_at_jitter_m: 0.05,
            views: 1,
            target_occlusion: None,
            occlusion_tries: 40,
            intrinsics: Intrinsics::YCB_VIDEO,
            randomize: Randomize::Off,
            depth_sensor: DepthSensor::Basic,
            instances_per_class: (1, 1),
            pair_probability: 0.0,
            pair_gap_m: (0.0, 0.003),
            heap_probability: 0.0,
            heap_size: (4, 8),
            plain_share: 0.0,
        }
    }
}

impl SamplerConfig {
    /// The recommended training configuration: `Randomize::Default`, the
    /// structured-light depth sensor, 3–6 classes each appearing once or
    /// twice, a touching pair in 35 % and a heap of 4–8 copies in 15 % of
    /// scenes, cameras 0.3–1.5 m from the objects at 8–88° elevation (grazing
    /// to top-down), roll ±10° and a ±8 cm look-at jitter.
    pub fn training() -> SamplerConfig {
        SamplerConfig {
            min_objects: 3,
            max_objects: 6,
            camera_distance_m: (0.3, 1.5),
            camera_elevation_deg: (8.0, 88.0),
            camera_max_roll_deg: 10.0,
            look_at_jitter_m: 0.08,
            randomize: Randomize::Default,
            depth_sensor: DepthSensor::StructuredLight,
            instances_per_class: (1, 2),
            pair_probability: 0.35,
            heap_probability: 0.15,
            plain_share: 0.25,
            ..SamplerConfig::default()
        }
    }

    /// Whether the grouped (multi-instance) placement is needed.
    fn grouped(&self) -> bool {
        self.instances_per_class != (1, 1) || self.pair_probability > 0.0 || self.heap_probability > 0.0
    }
}

/// Why a scene could not be sampled or rendered.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SamplerError {
    #[error("the object set is empty")]
    EmptyObjectSet,
    #[error("invalid sampler config: {0}")]
    InvalidConfig(&'static str),
    #[error("could place only {placed} of the {required} objects required")]
    Placement { placed: usize, required: usize },
    #[error("scene object {index} has class {class_id}, which the object set lacks")]
    UnknownClass { index: usize, class_id: u16 },
    #[error("view {index} requested, the scene has {count}")]
    NoSuchView { index: usize, count: usize },
    #[error(transparent)]
    Render(#[from] RenderError),
}

/// One object instance on the table.
#[derive(Clone, Debug, PartialEq)]
pub struct PlacedObject {
    /// Class id (1-based index into the [`ObjectSet`]).
    pub class_id: u16,
    /// Label of this instance in rendered label maps (1, 2, … in order).
    pub instance_label: u16,
    /// Object → table pose (metres).
    pub table_from_object: Pose,
}

/// One camera of a scene.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraView {
    /// Table → camera pose (metres).
    pub camera_from_table: Pose,
    /// False when `target_occlusion` was set and no try reached it (the view
    /// closest to the target is kept); true otherwise.
    pub occlusion_target_met: bool,
}

/// A sampled tabletop scene.
#[derive(Clone, Debug)]
pub struct Scene {
    pub seed: u64,
    pub objects: Vec<PlacedObject>,
    pub backdrop: Backdrop,
    /// Lights in the table frame.
    pub lighting: Lighting,
    pub views: Vec<CameraView>,
    /// The randomisation level the scene was drawn with; [`render_view`]
    /// applies the per-view randomisation of this level.
    pub randomize: Randomize,
    /// The depth-sensor model [`render_view`] applies.
    pub depth_sensor: DepthSensor,
    /// Scene-level randomisation content (distractors, …); empty when `Off`.
    pub extras: randomization::SceneExtras,
}

/// Ground truth of one object in one rendered frame.
#[derive(Clone, Debug, PartialEq)]
pub struct ObjectTruth {
    pub class_id: u16,
    pub instance_label: u16,
    /// Object → camera pose (metres).
    pub pose: Pose,
    /// Visible pixels / pixels covered when alone (see [`ItemCoverage`]).
    pub visible_fraction: f64,
    pub visible_pixels: u32,
    pub alone_pixels: u32,
    /// Bounding box of the visible pixels; `None` when hidden or off-image.
    pub bbox: Option<PixelBox>,
}

/// Ground truth of one rendered frame.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameTruth {
    pub view_index: usize,
    pub camera_from_table: Pose,
    pub intrinsics: Intrinsics,
    /// In instance-label order (`objects[i].instance_label == i + 1`).
    pub objects: Vec<ObjectTruth>,
}

impl FrameTruth {
    /// Lookup table instance label → class id (index 0 = background → 0), for
    /// [`RenderTarget::map_labels`] / [`RenderTarget::map_labels_in_place`].
    pub fn class_lut(&self) -> Vec<u16> {
        let max = self.objects.iter().map(|o| o.instance_label).max().unwrap_or(0) as usize;
        let mut lut = vec![0u16; max + 1];
        for o in &self.objects {
            lut[o.instance_label as usize] = o.class_id;
        }
        lut
    }
}

/// Which ids a label map carries.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LabelKind {
    /// One label per object instance (1, 2, …; 0 = background).
    #[default]
    Instance,
    /// The object's class id (what the estimator consumes; 0 = background).
    Class,
}

impl SamplerConfig {
    fn validate(&self) -> Result<(), SamplerError> {
        use SamplerError::InvalidConfig as E;
        if self.min_objects == 0 || self.min_objects > self.max_objects {
            return Err(E("need 1 <= min_objects <= max_objects"));
        }
        if self.max_objects > 1000 {
            return Err(E("max_objects must be at most 1000"));
        }
        if !(0.0..=1.0).contains(&self.upright_probability) {
            return Err(E("upright_probability must be in 0..=1"));
        }
        if !(self.cluster_radius_m > 0.0 && self.cluster_radius_m.is_finite()) {
            return Err(E("cluster_radius_m must be > 0"));
        }
        if !(self.min_gap_m >= 0.0 && self.min_gap_m.is_finite()) {
            return Err(E("min_gap_m must be >= 0"));
        }
        let (d0, d1) = self.camera_distance_m;
        if !(d0 > 0.0 && d1 >= d0 && d1.is_finite()) {
            return Err(E("camera_distance_m must be 0 < min <= max"));
        }
        let (e0, e1) = self.camera_elevation_deg;
        if !(e0 > 0.0 && e1 >= e0 && e1 < 89.5) {
            return Err(E("camera_elevation_deg must be 0 < min <= max < 89.5"));
        }
        if !(self.camera_max_roll_deg.is_finite() && self.look_at_jitter_m.is_finite() && self.look_at_jitter_m >= 0.0)
        {
            return Err(E("camera_max_roll_deg and look_at_jitter_m must be finite (jitter >= 0)"));
        }
        if self.views == 0 {
            return Err(E("views must be >= 1"));
        }
        let (i0, i1) = self.instances_per_class;
        if i0 == 0 || i1 < i0 || i1 > 100 {
            return Err(E("instances_per_class must be 1 <= min <= max <= 100"));
        }
        let (h0, h1) = self.heap_size;
        if h0 < 2 || h1 < h0 || h1 > 100 {
            return Err(E("heap_size must be 2 <= min <= max <= 100"));
        }
        if !(0.0..=1.0).contains(&self.pair_probability) || !(0.0..=1.0).contains(&self.heap_probability) {
            return Err(E("pair_probability and heap_probability must be in 0..=1"));
        }
        let (g0, g1) = self.pair_gap_m;
        if !(g0 >= 0.0 && g1 >= g0 && g1 < 0.1) {
            return Err(E("pair_gap_m must be 0 <= min <= max < 0.1"));
        }
        if !(0.0..=1.0).contains(&self.plain_share) {
            return Err(E("plain_share must be within 0..=1"));
        }
        if let Some((lo, hi)) = self.target_occlusion {
            if !(0.0..=1.0).contains(&lo) || !(lo..=1.0).contains(&hi) {
                return Err(E("target_occlusion must be 0 <= lo <= hi <= 1"));
            }
            if self.occlusion_tries == 0 {
                return Err(E("occlusion_tries must be >= 1"));
            }
        }
        Ok(())
    }
}

/// Draws a scene from `set`; the same set, config and seed give the same scene.
pub fn sample_scene(set: &ObjectSet, cfg: &SamplerConfig, seed: u64) -> Result<Scene, SamplerError> {
    cfg.validate()?;
    if set.is_empty() {
        return Err(SamplerError::EmptyObjectSet);
    }
    if cfg.randomize.is_on() && plain_draw(seed) < cfg.plain_share {
        let plain = SamplerConfig {
            randomize: Randomize::Off,
            depth_sensor: DepthSensor::Basic,
            plain_share: 0.0,
            ..cfg.clone()
        };
        return sample_scene(set, &plain, seed);
    }
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    if cfg.randomize.is_on() {
        return randomization::sample_randomized(&mut rng, set, cfg, seed);
    }
    let backdrop = Backdrop::random(&mut rng);
    let lighting = Lighting::random_z_up(&mut rng);
    let rests: Vec<Vec<RestPose>> = set.objects.iter().map(rest_poses).collect();
    let objects = if cfg.grouped() {
        instances::place_grouped(&mut rng, set, &rests, backdrop.table_half_extent, cfg)?
    } else {
        place_objects(&mut rng, set, &rests, &backdrop, cfg)?
    };

    let views = draw_views(&mut rng, set, &objects, cfg, cfg.views, None)?;
    Ok(Scene {
        seed,
        objects,
        backdrop,
        lighting,
        views,
        randomize: cfg.randomize,
        depth_sensor: cfg.depth_sensor,
        extras: randomization::SceneExtras::default(),
    })
}

/// A uniform draw in [0, 1) from `seed` alone, so choosing plain scenes does
/// not shift any other draw of the scene.
fn plain_draw(seed: u64) -> f64 {
    let mut rng = Pcg64Mcg::seed_from_u64(seed ^ 0x706c_6169_6e5f_7368);
    rng.random::<f64>()
}

/// Draws `count` camera views of `objects` (see [`SamplerConfig`]); with
/// `rules` (randomised scenes) views must keep clear of the scene's solids and
/// some are turned so an object is cut by the image edge.
fn draw_views(
    rng: &mut Pcg64Mcg,
    set: &ObjectSet,
    objects: &[PlacedObject],
    cfg: &SamplerConfig,
    count: usize,
    rules: Option<&randomization::ViewRules>,
) -> Result<Vec<CameraView>, SamplerError> {
    let centroid = objects.iter().fold(Vector3::zeros(), |acc, o| acc + o.table_from_object.translation.vector)
        / objects.len().max(1) as f64;
    let ranges = ViewRanges {
        distance_m: cfg.camera_distance_m,
        elevation_deg: cfg.camera_elevation_deg,
        max_roll_deg: cfg.camera_max_roll_deg,
    };
    let draw = |rng: &mut Pcg64Mcg| {
        let j = cfg.look_at_jitter_m;
        let jitter = if j > 0.0 {
            Vector3::new(rng.random_range(-j..j), rng.random_range(-j..j), rng.random_range(-j..j))
        } else {
            Vector3::zeros()
        };
        let target = Point3::new(centroid.x, centroid.y, 0.05) + jitter;
        match rules {
            None => random_view(rng, &ranges, target),
            Some(r) => r.draw(rng, &ranges, target, objects, &cfg.intrinsics),
        }
    };
    let mut occlusion = cfg.target_occlusion.map(|range| OcclusionProbe::new(&cfg.intrinsics, range));
    let mut views = Vec::with_capacity(count);
    for _ in 0..count {
        let first = draw(rng);
        let view = match occlusion.as_mut() {
            None => CameraView { camera_from_table: first, occlusion_target_met: true },
            Some(probe) => {
                // Keep the first view that meets the target, else the closest miss.
                let (mut best, mut best_miss) = (first, probe.miss(set, objects, &first)?);
                for _ in 1..cfg.occlusion_tries {
                    if best_miss == 0.0 {
                        break;
                    }
                    let pose = draw(rng);
                    let miss = probe.miss(set, objects, &pose)?;
                    if miss < best_miss {
                        (best, best_miss) = (pose, miss);
                    }
                }
                CameraView { camera_from_table: best, occlusion_target_met: best_miss == 0.0 }
            }
        };
        views.push(view);
    }
    Ok(views)
}

/// Places objects by rejection sampling of footprints; retries the layout a
/// few times before giving up on `min_objects`.
fn place_objects(
    rng: &mut Pcg64Mcg,
    set: &ObjectSet,
    rests: &[Vec<RestPose>],
    backdrop: &Backdrop,
    cfg: &SamplerConfig,
) -> Result<Vec<PlacedObject>, SamplerError> {
    const LAYOUT_ATTEMPTS: usize = 8;
    const TRIES_PER_RADIUS: usize = 40;
    const RADIUS_STEPS: usize = 4;
    let [tx, ty] = backdrop.table_half_extent;
    let mut best: Vec<PlacedObject> = Vec::new();
    for _ in 0..LAYOUT_ATTEMPTS {
        let n = rng.random_range(cfg.min_objects..=cfg.max_objects);
        let classes: Vec<u16> = if !cfg.allow_duplicates && set.len() >= n {
            rand::seq::index::sample(rng, set.len(), n).into_iter().map(|i| i as u16 + 1).collect()
        } else {
            (0..n).map(|_| rng.random_range(0..set.len()) as u16 + 1).collect()
        };
        let mut placed: Vec<PlacedObject> = Vec::with_capacity(n);
        let mut footprints: Vec<Footprint> = Vec::with_capacity(n);
        for class_id in classes {
            let options = &rests[class_id as usize - 1];
            let mut radius = cfg.cluster_radius_m;
            'radius: for _ in 0..RADIUS_STEPS {
                for _ in 0..TRIES_PER_RADIUS {
                    let rest = choose_rest(rng, options, cfg.upright_probability);
                    let yaw = rng.random_range(0.0..std::f64::consts::TAU);
                    let (r, phi) = (radius * rng.random::<f64>().sqrt(), rng.random_range(0.0..std::f64::consts::TAU));
                    let pos = Vector2::new(r * phi.cos(), r * phi.sin());
                    let fp = Footprint::of(rest, yaw, pos);
                    let fr = fp.radius();
                    if fp.centre.x.abs() + fr > tx || fp.centre.y.abs() + fr > ty {
                        continue;
                    }
                    if footprints.iter().any(|o| o.overlaps(&fp, cfg.min_gap_m)) {
                        continue;
                    }
                    let rotation = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw) * rest.rotation;
                    let pose = Pose::from_parts(Translation3::new(pos.x, pos.y, rest.lift), rotation);
                    footprints.push(fp);
                    placed.push(PlacedObject {
                        class_id,
                        instance_label: placed.len() as u16 + 1,
                        table_from_object: pose,
                    });
                    break 'radius;
                }
                radius *= 1.3;
            }
        }
        if placed.len() >= cfg.min_objects {
            return Ok(placed);
        }
        if placed.len() > best.len() {
            best = placed;
        }
    }
    Err(SamplerError::Placement { placed: best.len(), required: cfg.min_objects })
}

/// Upright with probability `p_upright`, else a face with probability ∝ area.
fn choose_rest<'r>(rng: &mut Pcg64Mcg, options: &'r [RestPose], p_upright: f64) -> &'r RestPose {
    if rng.random_bool(p_upright)
        && let Some(r) = options.iter().find(|r| r.upright)
    {
        return r;
    }
    let total: f64 = options.iter().map(|r| r.face_area).sum();
    if total > 0.0 {
        let mut x = rng.random::<f64>() * total;
        for r in options {
            if x < r.face_area {
                return r;
            }
            x -= r.face_area;
        }
    }
    &options[rng.random_range(0..options.len())]
}

/// Renders the objects alone at quarter resolution to measure occlusion.
struct OcclusionProbe {
    k: Intrinsics,
    range: (f64, f64),
    target: RenderTarget,
    settings: RenderSettings,
}

impl OcclusionProbe {
    /// Objects smaller than this (pixels at quarter resolution) are ignored.
    const MIN_PIXELS: u32 = 24;

    fn new(k: &Intrinsics, range: (f64, f64)) -> OcclusionProbe {
        let s = 0.25;
        let k = Intrinsics {
            fx: k.fx * s,
            fy: k.fy * s,
            cx: (k.cx + 0.5) * s - 0.5,
            cy: (k.cy + 0.5) * s - 0.5,
            width: (k.width / 4).max(1),
            height: (k.height / 4).max(1),
        };
        OcclusionProbe { k, range, target: RenderTarget::for_intrinsics(&k), settings: RenderSettings::default() }
    }

    /// 0 when some object's hidden fraction is inside the range; else the
    /// smallest distance of any object's hidden fraction to it.
    fn miss(&mut self, set: &ObjectSet, objects: &[PlacedObject], cam: &Pose) -> Result<f64, SamplerError> {
        let mut items = Vec::with_capacity(objects.len());
        push_object_items(set, objects, cam, &mut items)?;
        render::render_scene(&items, &self.k, &self.settings, &mut self.target)?;
        let (lo, hi) = self.range;
        let mut best = f64::INFINITY;
        for c in self.target.coverage() {
            if c.alone_pixels < Self::MIN_PIXELS {
                continue;
            }
            let hidden = 1.0 - c.visible_fraction();
            let d = if hidden < lo {
                lo - hidden
            } else if hidden > hi {
                hidden - hi
            } else {
                0.0
            };
            best = best.min(d);
        }
        Ok(best)
    }
}

/// The seed of the sensor noise for a scene's view.
fn noise_seed(scene_seed: u64, view: usize) -> u64 {
    let mut h = scene_seed ^ 0x9E37_79B9_7F4A_7C15u64.wrapping_mul(view as u64 + 1);
    h ^= h >> 31;
    h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    h ^ (h >> 29)
}

/// The seed of a view's randomisation (effects, intrinsics jitter), independent
/// of the noise seed.
fn view_seed(scene_seed: u64, view: usize) -> u64 {
    noise_seed(scene_seed ^ 0x005E_ED0F_71E7_5EED, view).rotate_left(23)
}

impl Scene {
    /// Appends `count` more camera views drawn from `seed` with the camera
    /// rules of `cfg` (distance, elevation, roll, occlusion target), e.g. for
    /// multi-frame scenes. Deterministic for the scene, config and seed.
    pub fn add_views(
        &mut self,
        set: &ObjectSet,
        cfg: &SamplerConfig,
        count: usize,
        seed: u64,
    ) -> Result<(), SamplerError> {
        cfg.validate()?;
        let mut rng = Pcg64Mcg::seed_from_u64(seed ^ self.seed.rotate_left(17));
        let rules = self.extras.view_rules.as_ref();
        let views = draw_views(&mut rng, set, &self.objects, cfg, count, rules)?;
        self.views.extend(views);
        Ok(())
    }

    /// Object → camera pose of every object in view `view` (`None` if no such view).
    pub fn object_poses(&self, view: usize) -> Option<Vec<Pose>> {
        let cam = self.views.get(view)?.camera_from_table;
        Some(self.objects.iter().map(|o| cam * o.table_from_object).collect())
    }

    /// The render list of a view: table and room (label 0), then the objects
    /// (their instance labels) in scene order, then distractors (label 0).
    pub fn render_items<'a>(&'a self, set: &'a ObjectSet, view: usize) -> Result<Vec<RenderItem<'a>>, SamplerError> {
        let cam = self
            .views
            .get(view)
            .ok_or(SamplerError::NoSuchView { index: view, count: self.views.len() })?
            .camera_from_table;
        let mut items = Vec::with_capacity(self.objects.len() + 2 + self.extras.distractors.len());
        items.push(RenderItem { mesh: &self.backdrop.table, pose: cam, instance_label: 0, shadow_mesh: None });
        items.push(RenderItem { mesh: &self.backdrop.room, pose: cam, instance_label: 0, shadow_mesh: None });
        push_object_items(set, &self.objects, &cam, &mut items)?;
        for d in &self.extras.distractors {
            items.push(RenderItem {
                mesh: &d.mesh,
                pose: cam * d.table_from_object,
                instance_label: 0,
                shadow_mesh: None,
            });
        }
        Ok(items)
    }
}

/// Number of background items [`Scene::render_items`] puts before the objects.
const BACKGROUND_ITEMS: usize = 2;

/// Per-call options of [`render_view_with`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewOptions {
    /// The target camera. With randomisation on, fx and fy are jittered per
    /// view (±5 %, `Strong` ±8 %) and cx, cy (±10 px, `Strong` ±20 px);
    /// [`FrameTruth::intrinsics`] reports the camera actually used.
    pub intrinsics: Intrinsics,
    /// Depth model: `Ideal` leaves depth exact, `Basic` is the original model.
    pub depth_sensor: DepthSensor,
    /// Per-view randomisation level (shadows, specular, colour jitter, camera
    /// pipeline, intrinsics jitter, border occluders). Scene-level content
    /// (lights, textures, distractors) comes from the scene as sampled.
    pub randomize: Randomize,
}

impl ViewOptions {
    /// The scene's own randomisation level and depth sensor, camera `k`.
    pub fn for_scene(scene: &Scene, k: &Intrinsics) -> ViewOptions {
        ViewOptions { intrinsics: *k, depth_sensor: scene.depth_sensor, randomize: scene.randomize }
    }
}

/// How the depth of a frame is corrupted.
#[derive(Clone, Copy, Debug)]
enum DepthNoise<'a> {
    Exact,
    Basic(&'a NoiseConfig),
    Sensor(DepthSensor),
}

/// Renders view `view` of `scene` into `target` (instance labels), applies
/// sensor noise and returns the truth.
///
/// With the scene drawn at `Randomize::Off` and `DepthSensor::Basic` this is
/// the original renderer: `noise` applied with a seed from the scene seed and
/// view index. Otherwise the scene's randomisation level and depth sensor
/// apply (see [`render_view_with`]); `noise` then only switches noise off
/// (`enabled == false`: exact depth, no colour noise) or, for the `Basic`
/// sensor, gives its parameters. `k` is the target camera; the truth reports
/// the (possibly jittered) camera actually used.
pub fn render_view(
    scene: &Scene,
    set: &ObjectSet,
    view: usize,
    k: &Intrinsics,
    noise: &NoiseConfig,
    target: &mut RenderTarget,
) -> Result<FrameTruth, SamplerError> {
    let depth = if !noise.enabled {
        DepthNoise::Exact
    } else if scene.depth_sensor == DepthSensor::Basic {
        DepthNoise::Basic(noise)
    } else {
        DepthNoise::Sensor(scene.depth_sensor)
    };
    render_view_inner(scene, set, view, k, scene.randomize, depth, noise.enabled.then_some(noise), target)
}

/// Renders view `view` of `scene` with explicit options: the randomisation
/// level and depth sensor of `opts` instead of the scene's. With
/// `Randomize::Off` colour gets the original blur and noise
/// (`NoiseConfig::default()`); otherwise the randomised camera pipeline.
/// `Off` + `Basic` equals `render_view(.., &NoiseConfig::default(), ..)`.
pub fn render_view_with(
    scene: &Scene,
    set: &ObjectSet,
    view: usize,
    opts: &ViewOptions,
    target: &mut RenderTarget,
) -> Result<FrameTruth, SamplerError> {
    let basic = NoiseConfig::default();
    let depth = match opts.depth_sensor {
        DepthSensor::Ideal => DepthNoise::Exact,
        DepthSensor::Basic => DepthNoise::Basic(&basic),
        other => DepthNoise::Sensor(other),
    };
    render_view_inner(scene, set, view, &opts.intrinsics, opts.randomize, depth, Some(&basic), target)
}

/// Index of the first item after the objects in a view's render list.
fn first_non_object(scene: &Scene) -> usize {
    BACKGROUND_ITEMS + scene.objects.len()
}

#[allow(clippy::too_many_arguments)] // one private entry point behind the two public ones
fn render_view_inner(
    scene: &Scene,
    set: &ObjectSet,
    view: usize,
    k: &Intrinsics,
    randomize: Randomize,
    depth: DepthNoise<'_>,
    colour: Option<&NoiseConfig>,
    target: &mut RenderTarget,
) -> Result<FrameTruth, SamplerError> {
    let mut items = scene.render_items(set, view)?;
    let cam = scene.views[view].camera_from_table;
    let mut settings = RenderSettings {
        lighting: scene.lighting.transformed(&cam),
        background_rgb: [90, 90, 90],
        ..RenderSettings::default()
    };
    let mut k_used = *k;
    let mut effects = None;
    if randomize.is_on() {
        let mut rng = Pcg64Mcg::seed_from_u64(view_seed(scene.seed, view));
        k_used = randomization::jitter_intrinsics(&mut rng, k, randomize);
        effects = Some(randomization::draw_view_effects(
            &mut rng,
            randomize,
            scene,
            set,
            &k_used,
            &cam,
            first_non_object(scene),
            &mut items,
            &mut settings,
        ));
    }
    if target.width() != k_used.width || target.height() != k_used.height {
        target.resize(k_used.width, k_used.height);
    }
    render::render_scene(&items, &k_used, &settings, target)?;
    let seed = noise_seed(scene.seed, view);
    match (depth, colour, &effects) {
        // The original renderer: one noise call, bit for bit.
        (DepthNoise::Basic(d), Some(c), None) if std::ptr::eq(d, c) => render::apply_noise(target, d, seed),
        _ => {
            match depth {
                DepthNoise::Exact => {}
                DepthNoise::Basic(cfg) => render::apply_noise_depth(target, cfg, seed),
                DepthNoise::Sensor(sensor) => render::apply_depth_sensor(target, sensor, seed),
            }
            match (&effects, colour) {
                (Some(e), _) => render::apply_camera_effects(target, e, seed.rotate_left(7) ^ 0xC0_1011),
                (None, Some(c)) => render::apply_noise_colour(target, c, seed.rotate_left(7)),
                (None, None) => {}
            }
        }
    }
    let objects = scene
        .objects
        .iter()
        .zip(&target.coverage()[BACKGROUND_ITEMS..])
        .zip(&items[BACKGROUND_ITEMS..])
        .map(|((o, c), item): ((&PlacedObject, &ItemCoverage), &RenderItem)| ObjectTruth {
            class_id: o.class_id,
            instance_label: o.instance_label,
            pose: item.pose,
            visible_fraction: c.visible_fraction(),
            visible_pixels: c.visible_pixels,
            alone_pixels: c.alone_pixels,
            bbox: c.bbox,
        })
        .collect();
    Ok(FrameTruth { view_index: view, camera_from_table: cam, intrinsics: k_used, objects })
}

/// Like [`render_view`], then rewrites the label map as `kind` asks (class
/// ids through [`FrameTruth::class_lut`]; one cheap pass).
pub fn render_view_labelled(
    scene: &Scene,
    set: &ObjectSet,
    view: usize,
    k: &Intrinsics,
    noise: &NoiseConfig,
    kind: LabelKind,
    target: &mut RenderTarget,
) -> Result<FrameTruth, SamplerError> {
    let truth = render_view(scene, set, view, k, noise, target)?;
    if kind == LabelKind::Class {
        target.map_labels_in_place(&truth.class_lut());
    }
    Ok(truth)
}

/// Like [`render_view_with`], then rewrites the label map as `kind` asks.
pub fn render_view_with_labelled(
    scene: &Scene,
    set: &ObjectSet,
    view: usize,
    opts: &ViewOptions,
    kind: LabelKind,
    target: &mut RenderTarget,
) -> Result<FrameTruth, SamplerError> {
    let truth = render_view_with(scene, set, view, opts, target)?;
    if kind == LabelKind::Class {
        target.map_labels_in_place(&truth.class_lut());
    }
    Ok(truth)
}

/// Appends each placed object's mesh, posed in the camera `cam` (camera ← table),
/// with its instance label.
fn push_object_items<'a>(
    set: &'a ObjectSet,
    objects: &[PlacedObject],
    cam: &Pose,
    items: &mut Vec<RenderItem<'a>>,
) -> Result<(), SamplerError> {
    for (i, o) in objects.iter().enumerate() {
        let model = set.by_class(o.class_id).ok_or(SamplerError::UnknownClass { index: i, class_id: o.class_id })?;
        items.push(RenderItem {
            mesh: &model.mesh,
            pose: cam * o.table_from_object,
            instance_label: o.instance_label,
            shadow_mesh: model.shadow_mesh.as_ref(),
        });
    }
    Ok(())
}

#[cfg(test)]
mod golden;
#[cfg(test)]
mod tests;
