//! Domain randomisation for sampled scenes ([`Randomize`] `Default` or
//! `Strong`; `Off` never reaches this module).
//!
//! Scene level, drawn in [`sample_scene`](super::sample_scene) from the scene
//! seed: 1–4 lights (point or directional, colour temperature, intensity,
//! ambient level, sometimes grazing), varied table / floor / wall textures,
//! a room of random size and sometimes a wall right behind the table,
//! distractor solids on the table, and camera views that keep clear of
//! solids and walls, some turned so an object is cut by the image edge.
//!
//! View level, drawn in [`render_view`](super::render_view) from the scene
//! seed and view index: intrinsics jitter, shadows for every light, specular
//! highlights of random glossiness, per-object albedo/hue jitter, white
//! balance, exposure, gamma, vignetting, defocus or motion blur, sensor noise,
//! JPEG artefacts, and sometimes an occluder near the image border.

use super::backdrop::Backdrop;
use super::distractors::{self, Distractor};
use super::instances;
use super::placement::{RestPose, rest_poses};
use super::viewpoint::{ViewRanges, random_view};
use super::{BACKGROUND_ITEMS, PlacedObject, SamplerConfig, SamplerError, Scene, draw_views, place_objects};
use crate::render::{
    Blur, CameraEffects, CameraResponse, DirectionalLight, ItemShading, Lighting, PointLight, Randomize, RenderItem,
    RenderSettings, ShadowSettings,
};
use crate::{Intrinsics, ObjectSet, Pose};
use nalgebra::{Point3, UnitQuaternion, Vector3};
use rand::Rng;
use rand_pcg::Pcg64Mcg;

/// Scene-level randomisation content kept in the [`Scene`].
#[derive(Clone, Debug, Default)]
pub struct SceneExtras {
    /// Solids on the table that are not object classes (label 0).
    pub distractors: Vec<Distractor>,
    /// Meshes a view may place near its image border (label 0).
    pub occluders: Vec<crate::Mesh>,
    /// The rules views of this scene follow (also for [`Scene::add_views`]).
    pub view_rules: Option<ViewRules>,
}

/// Constraints and habits of randomised camera views (table frame).
#[derive(Clone, Debug, PartialEq)]
pub struct ViewRules {
    pub level: Randomize,
    /// Spheres (centre, radius in metres) the camera must stay out of.
    pub keep_out: Vec<(Point3<f64>, f64)>,
    /// A wall plane `n·p = d` (unit n pointing into the room): eyes must have
    /// `n·eye > d + 0.05`.
    pub wall: Option<(Vector3<f64>, f64)>,
    /// Probability that a view is turned so an object lands at the image edge.
    pub edge_cut_probability: f64,
}

impl ViewRules {
    /// A random view that satisfies the rules (falls back to the last draw
    /// after 64 tries), sometimes turned to cut an object at the image edge.
    pub(super) fn draw(
        &self,
        rng: &mut Pcg64Mcg,
        ranges: &ViewRanges,
        target: Point3<f64>,
        objects: &[PlacedObject],
        k: &Intrinsics,
    ) -> Pose {
        let mut pose = random_view(rng, ranges, target);
        for _ in 0..64 {
            if self.allows(&pose) {
                break;
            }
            pose = random_view(rng, ranges, target);
        }
        if !objects.is_empty() && rng.random_bool(self.edge_cut_probability) {
            let o = &objects[rng.random_range(0..objects.len())];
            pose = turn_to_edge(rng, &pose, &Point3::from(o.table_from_object.translation.vector), k);
        }
        pose
    }

    fn allows(&self, cam_from_table: &Pose) -> bool {
        let eye = cam_from_table.inverse() * Point3::origin();
        if let Some((n, d)) = &self.wall
            && n.dot(&eye.coords) < d + 0.05
        {
            return false;
        }
        self.keep_out.iter().all(|(c, r)| (eye - c).norm() > *r)
    }
}

/// Rotates the camera about its centre so that `point` (table frame) projects
/// at a random spot near a random image border (a few pixels outside to 8 %
/// inside), so the object is cut by the edge.
fn turn_to_edge(rng: &mut Pcg64Mcg, cam_from_table: &Pose, point: &Point3<f64>, k: &Intrinsics) -> Pose {
    let (w, h) = (k.width as f64, k.height as f64);
    let near = |rng: &mut Pcg64Mcg, size: f64| rng.random_range(-0.03..0.08) * size;
    let (u, v) = match rng.random_range(0..4) {
        0 => (near(rng, w), rng.random_range(0.0..h)),
        1 => (w - 1.0 - near(rng, w), rng.random_range(0.0..h)),
        2 => (rng.random_range(0.0..w), near(rng, h)),
        _ => (rng.random_range(0.0..w), h - 1.0 - near(rng, h)),
    };
    let p = cam_from_table * point;
    let want = Vector3::new((u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0);
    match UnitQuaternion::rotation_between(&p.coords, &want) {
        Some(turn) if p.z > 0.0 => {
            Pose::from_parts((turn * cam_from_table.translation.vector).into(), turn * cam_from_table.rotation)
        }
        _ => *cam_from_table,
    }
}

/// `Default` value or `Strong` value.
fn pick<T>(level: Randomize, default: T, strong: T) -> T {
    if level == Randomize::Strong { strong } else { default }
}

fn uniform(rng: &mut Pcg64Mcg, (a, b): (f64, f64)) -> f64 {
    if b > a { rng.random_range(a..b) } else { a }
}

fn log_uniform(rng: &mut Pcg64Mcg, (a, b): (f64, f64)) -> f64 {
    uniform(rng, (a.ln(), b.ln())).exp()
}

/// Linear-sRGB colour of a black body at `kelvin` (1667–25000 K), with unit
/// luminance: CIE 1931 chromaticity of the Planckian locus (Kim et al.'s cubic
/// fits), then XYZ → linear sRGB, negatives clipped.
pub fn blackbody_rgb(kelvin: f64) -> [f32; 3] {
    let t = kelvin.clamp(1667.0, 25000.0);
    let (t2, t3) = (t * t, t * t * t);
    let x = if t <= 4000.0 {
        -0.266_123_9e9 / t3 - 0.234_358_9e6 / t2 + 0.877_695_6e3 / t + 0.179_910
    } else {
        -3.025_846_9e9 / t3 + 2.107_037_9e6 / t2 + 0.222_634_7e3 / t + 0.240_390
    };
    let (x2, x3) = (x * x, x * x * x);
    let y = if t <= 2222.0 {
        -1.106_381_4 * x3 - 1.348_110_20 * x2 + 2.185_558_32 * x - 0.202_196_83
    } else if t <= 4000.0 {
        -0.954_947_6 * x3 - 1.374_185_93 * x2 + 2.091_370_15 * x - 0.167_488_67
    } else {
        3.081_758_0 * x3 - 5.873_386_70 * x2 + 3.751_129_97 * x - 0.370_014_83
    };
    let (cx, cz) = (x / y, (1.0 - x - y) / y);
    let r = 3.2406 * cx - 1.5372 - 0.4986 * cz;
    let g = -0.9689 * cx + 1.8758 + 0.0415 * cz;
    let b = 0.0557 * cx - 0.2040 + 1.0570 * cz;
    let rgb = [r.max(0.0), g.max(0.0), b.max(0.0)];
    let lum = 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2];
    rgb.map(|c| (c / lum.max(1e-6)) as f32)
}

/// 1–4 lights in the table frame (z up): point or directional, colour
/// temperature 2700–6500 K (`Strong` 2000–10000 K), a total key intensity
/// 0.5–1.0 (`Strong` 0.3–1.6) split at random, ambient 0.12–0.4 (`Strong`
/// 0.03–0.55) tinted by a sky temperature, and in 20 % (`Strong` 35 %) of
/// scenes one grazing light 4–15° above the table. Point lights stand
/// 0.6–2.2 m from the table centre; their colour is scaled by the squared
/// distance so they deliver their share at the centre.
pub fn random_lighting(rng: &mut Pcg64Mcg, level: Randomize, room_height_m: f64) -> Lighting {
    let n = rng.random_range(1..=4usize);
    let temp = pick(level, (2700.0, 6500.0), (2000.0, 10000.0));
    let total = uniform(rng, pick(level, (0.5, 1.0), (0.3, 1.6))) as f32;
    let weights: Vec<f32> = (0..n).map(|_| rng.random_range(0.3f32..1.0)).collect();
    let wsum: f32 = weights.iter().sum();
    let ambient_level = uniform(rng, pick(level, (0.12, 0.4), (0.03, 0.55))) as f32;
    let sky = blackbody_rgb(uniform(rng, (4500.0, 9000.0)));
    let ambient = std::array::from_fn(|c| ambient_level * (0.5 + 0.5 * sky[c]));
    let grazing = rng.random_bool(pick(level, 0.2, 0.35));
    let mut lighting = Lighting { ambient, lights: Vec::new(), points: Vec::new() };
    for (i, wgt) in weights.iter().enumerate() {
        let share = total * wgt / wsum;
        let color = blackbody_rgb(uniform(rng, temp)).map(|c| c * share);
        let elev = if grazing && i == 0 { uniform(rng, (4.0, 15.0)) } else { uniform(rng, (20.0, 85.0)) }.to_radians();
        let azim = rng.random_range(0.0..std::f64::consts::TAU);
        let dir = Vector3::new(elev.cos() * azim.cos(), elev.cos() * azim.sin(), elev.sin());
        if rng.random_bool(0.5) {
            let mut dist = uniform(rng, (0.6, 2.2));
            // Stay below the ceiling (the floor is 0.75 m under the table top).
            let max_height = room_height_m - 0.75 - 0.1;
            if dist * dir.z > max_height {
                dist = max_height / dir.z.max(1e-3);
            }
            let d2 = (dist * dist) as f32;
            lighting.points.push(PointLight { position: Point3::from(dir * dist), color: color.map(|c| c * d2) });
        } else {
            lighting.lights.push(DirectionalLight { direction: dir, color });
        }
    }
    lighting
}

/// Draws a randomised scene (see the module doc).
pub(super) fn sample_randomized(
    rng: &mut Pcg64Mcg,
    set: &ObjectSet,
    cfg: &SamplerConfig,
    seed: u64,
) -> Result<Scene, SamplerError> {
    let level = cfg.randomize;
    let (backdrop, wall) = Backdrop::random_varied(rng, level);
    let lighting = random_lighting(rng, level, backdrop.room_height_m);
    let rests: Vec<Vec<RestPose>> = set.objects.iter().map(rest_poses).collect();
    let objects = if cfg.grouped() {
        instances::place_grouped(rng, set, &rests, backdrop.table_half_extent, cfg)?
    } else {
        place_objects(rng, set, &rests, &backdrop, cfg)?
    };
    let distractors = distractors::place_distractors(rng, set, &objects, &rests, backdrop.table_half_extent, level);
    let occluders = (0..2).map(|_| distractors::random_occluder_mesh(rng, set, level)).collect();
    let mut keep_out: Vec<(Point3<f64>, f64)> = objects
        .iter()
        .filter_map(|o| {
            let m = set.by_class(o.class_id)?;
            Some((Point3::from(o.table_from_object.translation.vector), 0.5 * m.diameter + 0.06))
        })
        .collect();
    keep_out
        .extend(distractors.iter().map(|d| (Point3::from(d.table_from_object.translation.vector), d.radius + 0.06)));
    let rules = ViewRules { level, keep_out, wall, edge_cut_probability: pick(level, 0.25, 0.4) };
    let views = draw_views(rng, set, &objects, cfg, cfg.views, Some(&rules))?;
    Ok(Scene {
        seed,
        objects,
        backdrop,
        lighting,
        views,
        randomize: cfg.randomize,
        depth_sensor: cfg.depth_sensor,
        extras: SceneExtras { distractors, occluders, view_rules: Some(rules) },
    })
}

/// The target camera with fx, fy scaled by a common 1 ± 5 % (`Strong` ± 8 %)
/// and ± 0.5 % aspect, cx, cy shifted by ± 10 px (`Strong` ± 20 px).
pub fn jitter_intrinsics(rng: &mut Pcg64Mcg, k: &Intrinsics, level: Randomize) -> Intrinsics {
    let s = 1.0 + uniform(rng, pick(level, (-0.05, 0.05), (-0.08, 0.08)));
    let aspect = 1.0 + uniform(rng, (-0.005, 0.005));
    let c = pick(level, 10.0, 20.0);
    Intrinsics {
        fx: k.fx * s,
        fy: k.fy * s * aspect,
        cx: k.cx + uniform(rng, (-c, c)),
        cy: k.cy + uniform(rng, (-c, c)),
        width: k.width,
        height: k.height,
    }
}

/// Draws a view's appearance randomisation into `settings` (shadows,
/// per-item shading, camera response), may append a border occluder to
/// `items`, and returns the post-processing effects.
#[allow(clippy::too_many_arguments)] // the view's whole context, in one place
pub(super) fn draw_view_effects<'a>(
    rng: &mut Pcg64Mcg,
    level: Randomize,
    scene: &'a Scene,
    set: &ObjectSet,
    k: &Intrinsics,
    cam: &Pose,
    first_extra: usize,
    items: &mut Vec<RenderItem<'a>>,
    settings: &mut RenderSettings,
) -> CameraEffects {
    // Occluder first, so the item shading below covers it. It floats near
    // the camera, so it does not cast shadows (the maps stay sharp).
    let end_caster = items.len();
    if !scene.extras.occluders.is_empty() && rng.random_bool(pick(level, 0.25, 0.4)) {
        let mesh = &scene.extras.occluders[rng.random_range(0..scene.extras.occluders.len())];
        if let Some(pose) = distractors::border_occluder_pose(rng, scene, set, mesh, k, cam) {
            items.push(RenderItem { mesh, pose, instance_label: 0, shadow_mesh: None });
        }
    }
    settings.shadows = ShadowSettings {
        enabled: true,
        map_size: if level == Randomize::Strong && rng.random_bool(0.5) { 256 } else { 512 },
        first_caster: BACKGROUND_ITEMS,
        end_caster,
        ..ShadowSettings::default()
    };
    let hue = pick(level, 6.0, 15.0);
    let sat = pick(level, (0.85, 1.15), (0.7, 1.3));
    let val = pick(level, (0.85, 1.15), (0.7, 1.3));
    let max_spec = pick(level, 0.35, 0.6);
    settings.item_shading = (0..items.len())
        .map(|i| {
            let glossy = if i < BACKGROUND_ITEMS { rng.random_bool(0.3) } else { rng.random_bool(0.7) };
            let specular =
                if glossy { uniform(rng, (0.02, if i < BACKGROUND_ITEMS { 0.15 } else { max_spec })) } else { 0.0 };
            let shininess = log_uniform(rng, (8.0, 200.0));
            let base = ItemShading { specular: specular as f32, shininess: shininess as f32, ..Default::default() };
            if i < BACKGROUND_ITEMS {
                base
            } else if i < first_extra {
                base.with_color_jitter(
                    uniform(rng, (-hue, hue)) as f32,
                    uniform(rng, sat) as f32,
                    uniform(rng, val) as f32,
                )
            } else {
                // Distractors and occluders: any hue.
                base.with_color_jitter(
                    rng.random_range(-180.0..180.0),
                    uniform(rng, sat) as f32,
                    uniform(rng, val) as f32,
                )
            }
        })
        .collect();
    let wb = pick(level, (0.85, 1.18), (0.7, 1.35));
    settings.camera_response = CameraResponse {
        white_balance: [uniform(rng, wb) as f32, 1.0, uniform(rng, wb) as f32],
        exposure: log_uniform(rng, pick(level, (0.7, 1.35), (0.45, 1.9))) as f32,
        vignetting: uniform(rng, pick(level, (0.0, 0.35), (0.0, 0.6))) as f32,
        gamma: uniform(rng, pick(level, (0.85, 1.18), (0.7, 1.4))) as f32,
    };
    let blur_roll: f64 = rng.random();
    let (p_defocus, p_motion) = pick(level, (0.25, 0.12), (0.35, 0.2));
    let blur = if blur_roll < p_defocus {
        Blur::Defocus { sigma_px: uniform(rng, pick(level, (0.4, 1.3), (0.4, 2.2))) as f32 }
    } else if blur_roll < p_defocus + p_motion {
        Blur::Motion {
            length_px: uniform(rng, pick(level, (1.5, 5.0), (1.5, 9.0))) as f32,
            angle_rad: rng.random_range(0.0..std::f32::consts::PI),
        }
    } else {
        Blur::None
    };
    let jpeg = rng.random_bool(pick(level, 0.5, 0.7)).then(|| rng.random_range(pick(level, 55..=95, 25..=95)) as u8);
    let _ = cam;
    CameraEffects {
        blur,
        read_noise: uniform(rng, pick(level, (0.8, 3.0), (0.5, 6.0))) as f32,
        shot_noise: uniform(rng, pick(level, (0.02, 0.25), (0.02, 0.6))) as f32,
        jpeg_quality: jpeg,
    }
}
