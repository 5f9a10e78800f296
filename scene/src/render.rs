//! CPU RGB-D renderer: a z-buffered triangle rasteriser with exact pinhole
//! intrinsics, near-plane clipping, perspective-correct texture and colour
//! interpolation and Lambert + ambient shading, plus a sensor-noise model.
//!
//! Output (RGB8, depth in metres, depth as u16 in units of 0.1 mm, a label map
//! and per-item visibility) goes into a reusable [`RenderTarget`].
//!
//! Geometry convention: pixel (u, v) is covered by a triangle when its centre,
//! the image of the ray ((u - cx) / fx, (v - cy) / fy, 1), hits the triangle
//! (top-left fill rule on shared edges). Depth is the camera-frame z of the hit
//! point, evaluated exactly (perspective-correct) at the pixel centre.
//!
//! Shading is deferred: the raster pass writes inverse depth and a triangle id
//! per pixel; one final pass shades each visible pixel exactly once.
//!
//! Two shading modes. With the default settings (directional lights only, no
//! shadows, no per-item shading, identity camera response) lighting is
//! Lambert + ambient per vertex (Gouraud), as the renderer always did. Any of
//! point lights, [`ShadowSettings`], [`ItemShading`] or a [`CameraResponse`]
//! switches to per-pixel lighting: interpolated normals, Lambert + Blinn-Phong
//! specular per light, shadow-map visibility per light, per-item albedo
//! transform, then white balance, exposure, vignetting and gamma.
//!
//! Sensor models: [`apply_noise`] (the original generic model), the depth
//! models of [`apply_depth_sensor`] and the colour pipeline of
//! [`apply_camera_effects`].

mod camera_pipeline;
pub mod cast;
mod jpeg_artefacts;
mod lighting;
mod modes;
mod noise;
mod raster;
pub mod sensor;
mod shading;
mod shadow;
pub mod srgb;
mod target;

pub use camera_pipeline::{Blur, CameraEffects, apply_camera_effects};
pub use modes::{DepthSensor, ParseModeError, Randomize};
pub use noise::{GAUSS_BITS, NoiseConfig, apply_noise, apply_noise_colour, apply_noise_depth, gauss_table};
pub use sensor::{DepthSensorModel, StructuredLightParams, TofParams, apply_depth_sensor, apply_depth_sensor_model};
pub use target::{ItemCoverage, PixelBox, RenderTarget};

use crate::{Intrinsics, Mesh, Pose};
use nalgebra::{Point3, Rotation3, Vector3};
use rand::Rng;

/// Depth-u16 units per metre (YCB-Video convention: 1 unit = 0.1 mm):
/// `depth_u16 = round(z_m * 10000)`, saturating at 65535 (6.5535 m); 0 = missing.
pub const DEPTH_U16_PER_METRE: f64 = 10_000.0;

/// Default near clipping distance (metres): geometry closer than this is clipped.
pub const DEFAULT_Z_NEAR_M: f64 = 0.05;

/// Converts a depth in metres to the u16 encoding (0.1 mm units, saturating; 0 = missing).
#[inline]
pub fn depth_to_u16(z_m: f64) -> u16 {
    // Float → int `as` casts saturate (and NaN fails the test), so this is
    // round-half-up with saturation at 65535, without a libm call.
    if z_m > 0.0 { (z_m * DEPTH_U16_PER_METRE + 0.5) as u16 } else { 0 }
}

/// One mesh to draw with its pose (object → camera) and the label written to
/// the label map where it is visible (0 = background, e.g. table and room).
#[derive(Clone, Copy, Debug)]
pub struct RenderItem<'a> {
    pub mesh: &'a Mesh,
    pub pose: Pose,
    pub instance_label: u16,
    /// Drawn instead of `mesh` into shadow maps (a coarse copy,
    /// [`crate::shadow_mesh`]); `None`: `mesh` itself.
    pub shadow_mesh: Option<&'a Mesh>,
}

/// A directional light. `direction` is a unit vector pointing from the surface
/// towards the light, expressed in the frame the [`Lighting`] is given in.
#[derive(Clone, Debug, PartialEq)]
pub struct DirectionalLight {
    pub direction: Vector3<f64>,
    /// Linear RGB intensity (1.0 = full white).
    pub color: [f32; 3],
}

/// A point light: `position` in metres in the frame the [`Lighting`] is given
/// in; a surface facing it at distance d receives `color / d²` (linear RGB,
/// so `color` is the irradiance at 1 m).
#[derive(Clone, Debug, PartialEq)]
pub struct PointLight {
    pub position: Point3<f64>,
    pub color: [f32; 3],
}

/// Ambient + directional lights (linear RGB), plus point lights. Lambert: a
/// surface with unit normal n and albedo a gets
/// `a * (ambient + Σ color * max(0, n·direction))`. Point lights need the
/// per-pixel shading mode (any point light switches to it).
#[derive(Clone, Debug, PartialEq)]
pub struct Lighting {
    pub ambient: [f32; 3],
    pub lights: Vec<DirectionalLight>,
    pub points: Vec<PointLight>,
}

impl Default for Lighting {
    /// Camera-frame default: ambient 0.35 and one white light above and behind
    /// the camera (direction (0.3, -0.7, -0.65) normalised; y is down).
    fn default() -> Self {
        Lighting {
            ambient: [0.35; 3],
            lights: vec![DirectionalLight { direction: Vector3::new(0.3, -0.7, -0.65).normalize(), color: [0.75; 3] }],
            points: Vec::new(),
        }
    }
}

impl Lighting {
    /// The same lights with their directions (and point-light positions)
    /// rotated by `r` (e.g. table → camera).
    pub fn rotated(&self, r: &Rotation3<f64>) -> Lighting {
        Lighting {
            ambient: self.ambient,
            lights: self
                .lights
                .iter()
                .map(|l| DirectionalLight { direction: r * l.direction, color: l.color })
                .collect(),
            points: self.points.iter().map(|p| PointLight { position: r * p.position, color: p.color }).collect(),
        }
    }

    /// The same lights moved by a rigid transform (e.g. table → camera):
    /// directions rotated, point-light positions rotated and translated.
    pub fn transformed(&self, pose: &Pose) -> Lighting {
        let r = pose.rotation.to_rotation_matrix();
        let mut out = self.rotated(&r);
        for p in &mut out.points {
            p.position += pose.translation.vector;
        }
        out
    }

    /// Random indoor lighting in a z-up frame (e.g. the table frame): ambient
    /// 0.2–0.45 with a slight tint, one or two lights 25–90° above the horizon
    /// with intensity 0.35–0.8 (split between them) and a slight tint.
    pub fn random_z_up<R: Rng + ?Sized>(rng: &mut R) -> Lighting {
        fn tint<R: Rng + ?Sized>(rng: &mut R, base: f32, spread: f32) -> [f32; 3] {
            std::array::from_fn(|_| base * (1.0 + spread * (rng.random::<f32>() * 2.0 - 1.0)))
        }
        let ambient_level = rng.random_range(0.2..0.45);
        let ambient = tint(rng, ambient_level, 0.06);
        let n_lights = if rng.random_bool(0.5) { 1 } else { 2 };
        let total: f32 = rng.random_range(0.35..0.8);
        let mut lights = Vec::with_capacity(n_lights);
        for i in 0..n_lights {
            let share = if n_lights == 1 {
                1.0
            } else if i == 0 {
                0.65
            } else {
                0.35
            };
            let elev = rng.random_range(25f64..90.0).to_radians();
            let azim = rng.random_range(0.0..std::f64::consts::TAU);
            let direction = Vector3::new(elev.cos() * azim.cos(), elev.cos() * azim.sin(), elev.sin());
            lights.push(DirectionalLight { direction, color: tint(rng, total * share, 0.08) });
        }
        Lighting { ambient, lights, points: Vec::new() }
    }
}

/// Shadow mapping for every light (per-pixel mode). A map per light covers
/// the bounding sphere of the caster items (`items[first_caster..end_caster]`); the
/// items before them (e.g. table and room) only receive shadows. Directional
/// lights use a camera 50 m away (parallax below 1° for a 0.8 m scene).
#[derive(Clone, Debug, PartialEq)]
pub struct ShadowSettings {
    /// Off by default (no shadows, and no switch to per-pixel shading).
    pub enabled: bool,
    /// Map resolution in texels per side (1024).
    pub map_size: u32,
    /// Items `first_caster..end_caster` cast shadows (0 and `usize::MAX`:
    /// all do); the others only receive them.
    pub first_caster: usize,
    pub end_caster: usize,
    /// Depth bias in metres added to the texel-size bias (0.001).
    pub depth_bias_m: f32,
    /// Lookups are offset along the surface normal by this many texels (1.5),
    /// against self-shadowing acne.
    pub normal_offset_texels: f32,
}

impl Default for ShadowSettings {
    fn default() -> Self {
        ShadowSettings {
            enabled: false,
            map_size: 1024,
            first_caster: 0,
            end_caster: usize::MAX,
            depth_bias_m: 0.001,
            normal_offset_texels: 1.5,
        }
    }
}

/// Per-item surface appearance in per-pixel mode (index = item index).
#[derive(Clone, Debug, PartialEq)]
pub struct ItemShading {
    /// Blinn-Phong specular weight (0 = matte). The highlight of a light of
    /// colour c is `c · specular · (shininess + 8) / 8 · (n·h)^shininess · (n·l)`.
    pub specular: f32,
    /// Blinn-Phong exponent (glossiness; 8 = broad, 200 = sharp).
    pub shininess: f32,
    /// Linear-RGB albedo transform (row-major 3x3), e.g. a hue rotation with
    /// saturation and brightness gains; identity leaves colours unchanged.
    pub albedo_transform: [[f32; 3]; 3],
}

impl Default for ItemShading {
    fn default() -> Self {
        ItemShading { specular: 0.0, shininess: 32.0, albedo_transform: IDENTITY3 }
    }
}

const IDENTITY3: [[f32; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

impl ItemShading {
    /// Albedo jitter: hue rotated by `hue_deg` about the grey axis, saturation
    /// and value scaled by the given gains (linear RGB; 0, 1, 1 = identity).
    pub fn with_color_jitter(mut self, hue_deg: f32, saturation: f32, value: f32) -> ItemShading {
        // Rotation about (1,1,1)/√3 (Rodrigues), then saturation about grey.
        let (s, c) = hue_deg.to_radians().sin_cos();
        let k = (1.0 - c) / 3.0;
        let q = s / 3f32.sqrt();
        let rot = [[c + k, k - q, k + q], [k + q, c + k, k - q], [k - q, k + q, c + k]];
        let g = (1.0 - saturation) / 3.0;
        let sat = [[saturation + g, g, g], [g, saturation + g, g], [g, g, saturation + g]];
        let mut m = [[0.0f32; 3]; 3];
        for (i, row) in m.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = value * (0..3).map(|l| sat[i][l] * rot[l][j]).sum::<f32>();
            }
        }
        self.albedo_transform = m;
        self
    }
}

/// The camera's colour response, applied per pixel before encoding (per-pixel
/// mode): linear RGB × white-balance gains × exposure × vignetting, then
/// sRGB encoding, then a gamma tweak `v ↦ v^(1/gamma)` on the 0..1 encoded value.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraResponse {
    /// Per-channel white-balance gains (1, 1, 1).
    pub white_balance: [f32; 3],
    /// Exposure gain (1).
    pub exposure: f32,
    /// Light fall-off: gain `1 − vignetting · r²` with r the distance from the
    /// principal point over the half diagonal (0 = none).
    pub vignetting: f32,
    /// Gamma tweak on the encoded value (1 = plain sRGB).
    pub gamma: f32,
}

impl Default for CameraResponse {
    fn default() -> Self {
        CameraResponse { white_balance: [1.0; 3], exposure: 1.0, vignetting: 0.0, gamma: 1.0 }
    }
}

/// How textures are sampled. Bilinear is the default (smoother, slightly slower).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TextureFilter {
    Nearest,
    #[default]
    Bilinear,
}

/// Per-frame render settings.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSettings {
    /// Near clipping distance (metres, > 0).
    pub z_near: f64,
    /// Lights in the camera frame.
    pub lighting: Lighting,
    /// RGB of pixels no item covers (their depth is 0 and label 0).
    pub background_rgb: [u8; 3],
    pub texture_filter: TextureFilter,
    /// Cast shadows (off by default).
    pub shadows: ShadowSettings,
    /// Per-item specular and albedo transform, indexed like the items (empty:
    /// matte, unchanged albedo; missing entries take [`ItemShading::default`]).
    pub item_shading: Vec<ItemShading>,
    /// White balance, exposure, vignetting and gamma (identity by default).
    pub camera_response: CameraResponse,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            z_near: DEFAULT_Z_NEAR_M,
            lighting: Lighting::default(),
            background_rgb: [0, 0, 0],
            texture_filter: TextureFilter::default(),
            shadows: ShadowSettings::default(),
            item_shading: Vec::new(),
            camera_response: CameraResponse::default(),
        }
    }
}

impl RenderSettings {
    /// Whether these settings need the per-pixel shading mode.
    pub fn per_pixel(&self) -> bool {
        self.shadows.enabled
            || !self.item_shading.is_empty()
            || !self.lighting.points.is_empty()
            || self.camera_response != CameraResponse::default()
    }
}

/// Why a frame could not be rendered. Bad input never panics.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum RenderError {
    #[error("render target is {target_width}x{target_height} but the intrinsics are {width}x{height}")]
    SizeMismatch { target_width: u32, target_height: u32, width: u32, height: u32 },
    #[error("invalid intrinsics: {0}")]
    BadIntrinsics(&'static str),
    #[error("z_near must be finite and > 0, got {0}")]
    BadZNear(f64),
    #[error("too many items: {0} (at most 65534)")]
    TooManyItems(usize),
    #[error("item {item}: pose is not finite")]
    BadPose { item: usize },
    #[error("item {item}: invalid mesh: {reason}")]
    BadMesh { item: usize, reason: String },
    #[error("shadow map size {0} is out of range (use 16..=8192 texels)")]
    BadShadowMapSize(u32),
}

/// Renders `items` into `target` (which must match the intrinsics' size).
///
/// Writes RGB, depth (metres and u16), the label map and per-item coverage
/// (`target.coverage()[i]` belongs to `items[i]`). No allocation per pixel;
/// the target's buffers are reused across frames.
pub fn render_scene(
    items: &[RenderItem<'_>],
    k: &Intrinsics,
    settings: &RenderSettings,
    target: &mut RenderTarget,
) -> Result<(), RenderError> {
    if target.width() != k.width || target.height() != k.height {
        return Err(RenderError::SizeMismatch {
            target_width: target.width(),
            target_height: target.height(),
            width: k.width,
            height: k.height,
        });
    }
    if !(k.fx.is_finite() && k.fy.is_finite() && k.fx > 0.0 && k.fy > 0.0) {
        return Err(RenderError::BadIntrinsics("fx and fy must be finite and > 0"));
    }
    if !(k.cx.is_finite() && k.cy.is_finite()) {
        return Err(RenderError::BadIntrinsics("cx and cy must be finite"));
    }
    if !(settings.z_near.is_finite() && settings.z_near > 0.0) {
        return Err(RenderError::BadZNear(settings.z_near));
    }
    if items.len() >= u16::MAX as usize {
        return Err(RenderError::TooManyItems(items.len()));
    }
    for (i, item) in items.iter().enumerate() {
        let p = &item.pose;
        if !(p.translation.vector.iter().all(|v| v.is_finite()) && p.rotation.coords.iter().all(|v| v.is_finite())) {
            return Err(RenderError::BadPose { item: i });
        }
        validate_mesh(item.mesh).map_err(|reason| RenderError::BadMesh { item: i, reason })?;
        if let Some(m) = item.shadow_mesh {
            validate_mesh(m)
                .map_err(|reason| RenderError::BadMesh { item: i, reason: format!("shadow mesh: {reason}") })?;
        }
    }
    if settings.per_pixel() {
        if !(settings.shadows.map_size >= 16 && settings.shadows.map_size <= 8192) {
            return Err(RenderError::BadShadowMapSize(settings.shadows.map_size));
        }
        let textures = raster::rasterise_items(items, k, settings, true, target);
        let maps = shadow::build_maps(items, settings, target);
        lighting::resolve_lit(items, k, settings, &textures, &maps, target);
        shadow::recycle(maps, target);
    } else {
        let textures = raster::rasterise_items(items, k, settings, false, target);
        shading::resolve(items, settings, &textures, target);
    }
    target.intrinsics = Some(*k);
    Ok(())
}

/// Checks index ranges and per-vertex attribute lengths; O(triangles).
fn validate_mesh(m: &Mesh) -> Result<(), String> {
    let n = m.positions.len();
    if n > u32::MAX as usize {
        return Err("too many vertices".into());
    }
    for (name, len) in [("normals", m.normals.len()), ("uvs", m.uvs.len()), ("colors", m.colors.len())] {
        if len != 0 && len != n {
            return Err(format!("{name} has {len} entries for {n} positions"));
        }
    }
    if !m.triangle_materials.is_empty() && m.triangle_materials.len() != m.triangles.len() {
        return Err(format!(
            "triangle_materials has {} entries for {} triangles",
            m.triangle_materials.len(),
            m.triangles.len()
        ));
    }
    if let Some(t) = m.triangles.iter().position(|t| t.iter().any(|&i| i as usize >= n)) {
        return Err(format!("triangle {t} indexes past {n} vertices"));
    }
    let n_mat = m.materials.len().max(1);
    if let Some(t) = m.triangle_materials.iter().position(|&mi| mi as usize >= n_mat) {
        return Err(format!("triangle {t} uses material {} of {}", m.triangle_materials[t], n_mat));
    }
    for mat in &m.materials {
        if let Some(tex) = &mat.texture {
            let expect = tex.width as usize * tex.height as usize * 3;
            if tex.width == 0 || tex.height == 0 || tex.rgb.len() != expect {
                return Err(format!(
                    "material {:?}: texture {}x{} has {} bytes, expected {expect} (> 0)",
                    mat.name,
                    tex.width,
                    tex.height,
                    tex.rgb.len()
                ));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests;
