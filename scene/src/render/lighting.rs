//! The per-pixel shading pass (see the `render` module doc): Lambert +
//! Blinn-Phong per light with shadow-map visibility, per-item albedo
//! transform, then the camera response (white balance, exposure, vignetting,
//! gamma) and sRGB encoding.
//!
//! Organised per image row for speed: a scalar pass gathers each visible
//! pixel's albedo, normal and depth into row arrays; each light then runs
//! branch-free loops over those arrays (which the compiler vectorises), with
//! only the shadow-map texel fetches scalar; a last pass encodes.

use super::shading::{
    ENCODE_STEPS, luminance, sample, srgb_decode_table, srgb_encode_table, unit_to_u8, write_geometry,
};
use super::shadow::ShadowMap;
use super::target::RenderTarget;
use super::{IDENTITY3, ItemShading, RenderItem, RenderSettings, raster::NO_TEXTURE};
use crate::{Intrinsics, Texture};

/// A light as the row loops use it (camera frame, f32).
#[derive(Clone, Copy, Debug)]
struct RowLight {
    /// Unit direction towards the light (directional) or its position (point).
    v: [f32; 3],
    point: bool,
    color: [f32; 3],
    map: Option<usize>,
}

/// Per-item shading resolved for the loops.
#[derive(Clone, Copy, Debug)]
struct ItemLook {
    m: [[f32; 3]; 3],
    identity: bool,
    shininess: f32,
    /// `specular · (shininess + 8) / 8`.
    spec_scale: f32,
    /// `n·h` below this contributes under 1/1000 of the peak.
    ndh_min: f32,
}

impl ItemLook {
    fn new(s: &ItemShading) -> ItemLook {
        let sh = s.shininess.max(1.0);
        let ks = s.specular.max(0.0);
        ItemLook {
            m: s.albedo_transform,
            identity: s.albedo_transform == IDENTITY3,
            shininess: sh,
            spec_scale: ks * (sh + 8.0) / 8.0,
            ndh_min: (1e-3f32.ln() / sh).exp(),
        }
    }
}

/// `x^y` for x in (0, 1], y > 0 (least-squares quintics for log2 and exp2 on
/// the mantissa; relative error about 3e-5 · y). Only float and bit
/// operations, no float → int conversion, so loops over it vectorise on
/// baseline x86-64; libm's powf is too slow per pixel and light.
#[inline(always)]
fn fast_pow(x: f32, y: f32) -> f32 {
    // 1.5 · 2^23: adding it rounds to an integer held in the low mantissa bits.
    const MAGIC: f32 = 12_582_912.0;
    let bits = x.to_bits();
    let e = f32::from_bits((bits >> 23) | 0x4b00_0000) - 8_388_608.0 - 127.0;
    let m = f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000) - 1.0;
    let l = e + m * (1.441_825_5 + m * (-0.708_679 + m * (0.415_411_2 + m * (-0.194_408_3 + m * 0.045_879))));
    let p = (y * l).max(-126.0);
    // floor(p) (exact integers may land one lower, leaving f = 1, still on the fit).
    let pi = (p - 0.5 + MAGIC) - MAGIC;
    let f = p - pi;
    let two_f = 1.0 + f * (0.693_152_7 + f * (0.240_153_2 + f * (0.055_828_3 + f * (0.008_988_8 + f * 0.001_876_7))));
    // 2^pi from the integer pi + 127 placed in the exponent field.
    let biased = (pi + 127.0 + MAGIC).to_bits() & 0x00ff;
    f32::from_bits(biased << 23) * two_f
}

/// Encode table with a gamma tweak on the encoded value (see [`super::CameraResponse`]).
fn encode_table_with_gamma(gamma: f32) -> Vec<u8> {
    (0..ENCODE_STEPS)
        .map(|i| {
            let l = i as f32 / (ENCODE_STEPS - 1) as f32;
            let c = if l <= 0.003_130_8 { l * 12.92 } else { 1.055 * l.powf(1.0 / 2.4) - 0.055 };
            (c.clamp(0.0, 1.0).powf(1.0 / gamma) * 255.0).round().clamp(0.0, 255.0) as u8
        })
        .collect()
}

/// Structure-of-arrays buffers for the visible pixels of one row (sized to
/// the image width once; the first `m` entries are live).
#[derive(Default)]
struct Row {
    m: usize,
    any_spec: bool,
    /// Pixel index in the image.
    index: Vec<u32>,
    /// Ray slope (x − cx) / fx of the pixel.
    rx: Vec<f32>,
    z: Vec<f32>,
    albedo: [Vec<f32>; 3],
    n: [Vec<f32>; 3],
    view: [Vec<f32>; 3],
    spec_scale: Vec<f32>,
    shininess: Vec<f32>,
    ndh_min: Vec<f32>,
    diffuse: [Vec<f32>; 3],
    spec: [Vec<f32>; 3],
    // Per-light scratch.
    dir: [Vec<f32>; 3],
    weight: Vec<f32>,
    su: Vec<f32>,
    sv: Vec<f32>,
    sz: Vec<f32>,
}

impl Row {
    fn new(width: usize) -> Row {
        let v = || vec![0.0f32; width];
        Row {
            m: 0,
            any_spec: false,
            index: vec![0; width],
            rx: v(),
            z: v(),
            albedo: [v(), v(), v()],
            n: [v(), v(), v()],
            view: [v(), v(), v()],
            spec_scale: v(),
            shininess: v(),
            ndh_min: v(),
            diffuse: [v(), v(), v()],
            spec: [v(), v(), v()],
            dir: [v(), v(), v()],
            weight: v(),
            su: v(),
            sv: v(),
            sz: v(),
        }
    }

    /// Resets the accumulators of the live entries.
    fn ready(&mut self, ambient: [f32; 3]) {
        let m = self.m;
        for ((d, s), a) in self.diffuse.iter_mut().zip(&mut self.spec).zip(ambient) {
            d[..m].fill(a);
            s[..m].fill(0.0);
        }
    }

    /// Adds one light's diffuse and specular contribution.
    fn add_light(&mut self, light: &RowLight, ry: f32, map: Option<&ShadowMap>) {
        let m = self.m;
        let [nx, ny, nz] = [&self.n[0][..m], &self.n[1][..m], &self.n[2][..m]];
        let [dx, dy, dz] = &mut self.dir;
        let (dx, dy, dz) = (&mut dx[..m], &mut dy[..m], &mut dz[..m]);
        let weight = &mut self.weight[..m];
        if light.point {
            point_light(&self.rx[..m], &self.z[..m], ry, light.v, nx, ny, nz, dx, dy, dz, weight);
        } else {
            directional_light(light.v, nx, ny, nz, weight);
            dx.fill(light.v[0]);
            dy.fill(light.v[1]);
            dz.fill(light.v[2]);
        }
        if let Some(map) = map {
            let (su, sv, sz) = (&mut self.su[..m], &mut self.sv[..m], &mut self.sz[..m]);
            map.project_row(&self.rx[..m], ry, &self.z[..m], [nx, ny, nz], su, sv, sz);
            for i in 0..m {
                if weight[i] > 0.0 {
                    weight[i] *= map.lookup(su[i], sv[i], sz[i]);
                }
            }
        }
        let [fr, fg, fb] = &mut self.diffuse;
        accumulate(weight, light.color, &mut fr[..m], &mut fg[..m], &mut fb[..m]);
        if !self.any_spec {
            return;
        }
        let [sr, sg, sb] = &mut self.spec;
        specular(
            nx,
            ny,
            nz,
            dx,
            dy,
            dz,
            &self.view[0][..m],
            &self.view[1][..m],
            &self.view[2][..m],
            &self.spec_scale[..m],
            &self.shininess[..m],
            &self.ndh_min[..m],
            weight,
            light.color,
            &mut sr[..m],
            &mut sg[..m],
            &mut sb[..m],
        );
    }
}

// The loops below take every array as its own slice argument: Rust marks
// them non-aliasing, which lets the compiler vectorise without runtime
// overlap checks.

/// Direction to a point light at `l`, and `max(0, n·dir) / d²`.
#[allow(clippy::too_many_arguments)]
#[inline(never)]
fn point_light(
    rx: &[f32],
    z: &[f32],
    ry: f32,
    l: [f32; 3],
    nx: &[f32],
    ny: &[f32],
    nz: &[f32],
    dx: &mut [f32],
    dy: &mut [f32],
    dz: &mut [f32],
    weight: &mut [f32],
) {
    let m = z.len();
    let (rx, nx, ny, nz) = (&rx[..m], &nx[..m], &ny[..m], &nz[..m]);
    let (dx, dy, dz, weight) = (&mut dx[..m], &mut dy[..m], &mut dz[..m], &mut weight[..m]);
    for i in 0..m {
        let (ax, ay, az) = (l[0] - rx[i] * z[i], l[1] - ry * z[i], l[2] - z[i]);
        let d2 = (ax * ax + ay * ay + az * az).max(1e-6);
        let inv = 1.0 / d2.sqrt();
        let (ux, uy, uz) = (ax * inv, ay * inv, az * inv);
        dx[i] = ux;
        dy[i] = uy;
        dz[i] = uz;
        weight[i] = (nx[i] * ux + ny[i] * uy + nz[i] * uz).max(0.0) * (inv * inv);
    }
}

/// `max(0, n·u)` for a directional light towards `u`.
#[inline(never)]
fn directional_light(u: [f32; 3], nx: &[f32], ny: &[f32], nz: &[f32], weight: &mut [f32]) {
    let m = weight.len();
    let (nx, ny, nz) = (&nx[..m], &ny[..m], &nz[..m]);
    for i in 0..m {
        weight[i] = (nx[i] * u[0] + ny[i] * u[1] + nz[i] * u[2]).max(0.0);
    }
}

/// Normalises the normals and writes the unit vectors towards the camera.
#[allow(clippy::too_many_arguments)]
#[inline(never)]
fn normalise_and_view(
    rx: &[f32],
    ry: f32,
    nx: &mut [f32],
    ny: &mut [f32],
    nz: &mut [f32],
    vx: &mut [f32],
    vy: &mut [f32],
    vz: &mut [f32],
) {
    let m = rx.len();
    let (nx, ny, nz, vx, vy, vz) = (&mut nx[..m], &mut ny[..m], &mut nz[..m], &mut vx[..m], &mut vy[..m], &mut vz[..m]);
    for i in 0..m {
        let inv = 1.0 / (nx[i] * nx[i] + ny[i] * ny[i] + nz[i] * nz[i]).max(1e-24).sqrt();
        nx[i] *= inv;
        ny[i] *= inv;
        nz[i] *= inv;
        let inv_len = 1.0 / (rx[i] * rx[i] + ry * ry + 1.0).sqrt();
        vx[i] = -rx[i] * inv_len;
        vy[i] = -ry * inv_len;
        vz[i] = -inv_len;
    }
}

/// `out += color · weight`.
#[inline(never)]
fn accumulate(weight: &[f32], color: [f32; 3], r: &mut [f32], g: &mut [f32], b: &mut [f32]) {
    let m = weight.len();
    let (r, g, b) = (&mut r[..m], &mut g[..m], &mut b[..m]);
    for i in 0..m {
        r[i] += color[0] * weight[i];
        g[i] += color[1] * weight[i];
        b[i] += color[2] * weight[i];
    }
}

/// Blinn-Phong: `out += color · scale · (n·h)^shininess · weight`.
#[allow(clippy::too_many_arguments)]
#[inline(never)]
fn specular(
    nx: &[f32],
    ny: &[f32],
    nz: &[f32],
    dx: &[f32],
    dy: &[f32],
    dz: &[f32],
    vx: &[f32],
    vy: &[f32],
    vz: &[f32],
    scale: &[f32],
    shin: &[f32],
    ndh_min: &[f32],
    weight: &[f32],
    color: [f32; 3],
    r: &mut [f32],
    g: &mut [f32],
    b: &mut [f32],
) {
    let m = weight.len();
    let (nx, ny, nz, dx, dy, dz) = (&nx[..m], &ny[..m], &nz[..m], &dx[..m], &dy[..m], &dz[..m]);
    let (vx, vy, vz, scale, shin, ndh_min) = (&vx[..m], &vy[..m], &vz[..m], &scale[..m], &shin[..m], &ndh_min[..m]);
    let (r, g, b) = (&mut r[..m], &mut g[..m], &mut b[..m]);
    for i in 0..m {
        let (hx, hy, hz) = (dx[i] + vx[i], dy[i] + vy[i], dz[i] + vz[i]);
        let hl = (hx * hx + hy * hy + hz * hz).max(1e-12);
        let ndh = (nx[i] * hx + ny[i] * hy + nz[i] * hz) / hl.sqrt();
        let p = fast_pow(ndh.clamp(1e-6, 1.0), shin[i]);
        let keep = if ndh > ndh_min[i] { 1.0 } else { 0.0 };
        let s = scale[i] * p * weight[i] * keep;
        r[i] += color[0] * s;
        g[i] += color[1] * s;
        b[i] += color[2] * s;
    }
}

/// Shades every pixel once (per-pixel mode) and fills the output planes and
/// per-item coverage.
pub(super) fn resolve_lit(
    items: &[RenderItem<'_>],
    k: &Intrinsics,
    settings: &RenderSettings,
    textures: &[&Texture],
    maps: &[Option<ShadowMap>],
    target: &mut RenderTarget,
) {
    let dec = srgb_decode_table();
    let resp = &settings.camera_response;
    let custom_enc;
    let enc: &[u8] = if resp.gamma == 1.0 {
        srgb_encode_table()
    } else {
        custom_enc = encode_table_with_gamma(resp.gamma.clamp(0.05, 20.0));
        &custom_enc
    };
    let (width, height) = (target.width() as usize, target.height() as usize);
    let bg = settings.background_rgb;
    let filter = settings.texture_filter;
    let l = &settings.lighting;
    let map_of = |i: usize| maps.get(i).and_then(|m| m.as_ref()).map(|_| i);
    let mut lights: Vec<RowLight> = Vec::with_capacity(l.lights.len() + l.points.len());
    for (i, d) in l.lights.iter().enumerate() {
        let n = d.direction.try_normalize(1e-12).unwrap_or(d.direction);
        let v = [n.x as f32, n.y as f32, n.z as f32];
        lights.push(RowLight { v, point: false, color: d.color, map: map_of(i) });
    }
    for (j, pl) in l.points.iter().enumerate() {
        let v = [pl.position.x as f32, pl.position.y as f32, pl.position.z as f32];
        lights.push(RowLight { v, point: true, color: pl.color, map: map_of(l.lights.len() + j) });
    }
    let looks: Vec<ItemLook> = (0..items.len())
        .map(|i| ItemLook::new(settings.item_shading.get(i).unwrap_or(&ItemShading::default())))
        .collect();
    let gain = [
        resp.white_balance[0] * resp.exposure,
        resp.white_balance[1] * resp.exposure,
        resp.white_balance[2] * resp.exposure,
    ];
    let half_diag2 = ((width * width + height * height) as f32 / 4.0).max(1.0);
    let (fx, fy, cx, cy) = (k.fx as f32, k.fy as f32, k.cx as f32, k.cy as f32);
    let mut row = Row::new(width);
    let t = target;
    for y in 0..height {
        let ry = (y as f32 - cy) / fy;
        row.m = 0;
        row.any_spec = false;
        for x in 0..width {
            let p = y * width + x;
            let Some(id) = write_geometry(t, items, bg, x, y) else { continue };
            let s = &t.tris[id];
            let item = s.item as usize;

            let a = s.attributes(x as f32, y as f32);
            let look = &looks[item];
            let mut albedo = if s.texture != NO_TEXTURE {
                sample(dec, textures[s.texture as usize], a[0], a[1], filter)
            } else {
                [a[2], a[3], a[4]]
            };
            if !look.identity {
                let m = &look.m;
                albedo = [
                    (m[0][0] * albedo[0] + m[0][1] * albedo[1] + m[0][2] * albedo[2]).max(0.0),
                    (m[1][0] * albedo[0] + m[1][1] * albedo[1] + m[1][2] * albedo[2]).max(0.0),
                    (m[2][0] * albedo[0] + m[2][1] * albedo[1] + m[2][2] * albedo[2]).max(0.0),
                ];
            }
            // Normalised (with the view vector) in a vectorised pass below.
            let mut n = [a[5], a[6], a[7]];
            if n[0] * n[0] + n[1] * n[1] + n[2] * n[2] <= 1e-12 {
                n = s.normal_facing();
            }
            let rx = (x as f32 - cx) / fx;
            let i = row.m;
            row.m += 1;
            row.index[i] = p as u32;
            row.rx[i] = rx;
            row.z[i] = t.depth_m[p];
            for c in 0..3 {
                row.albedo[c][i] = albedo[c];
                row.n[c][i] = n[c];
            }
            row.spec_scale[i] = look.spec_scale;
            row.shininess[i] = look.shininess;
            row.ndh_min[i] = look.ndh_min;
            row.any_spec |= look.spec_scale > 0.0;
        }
        if row.m == 0 {
            continue;
        }
        row.ready(l.ambient);
        let m = row.m;
        let [nx, ny, nz] = &mut row.n;
        let [vx, vy, vz] = &mut row.view;
        normalise_and_view(
            &row.rx[..m],
            ry,
            &mut nx[..m],
            &mut ny[..m],
            &mut nz[..m],
            &mut vx[..m],
            &mut vy[..m],
            &mut vz[..m],
        );
        for light in &lights {
            let map = light.map.and_then(|i| maps[i].as_ref());
            row.add_light(light, ry, map);
        }
        let dy2 = (y as f32 - cy) * (y as f32 - cy);
        for i in 0..row.m {
            let p = row.index[i] as usize;
            let spec = [row.spec[0][i], row.spec[1][i], row.spec[2][i]];
            t.specular[p] = unit_to_u8(luminance(spec));
            t.reflectance[p] = unit_to_u8(luminance([row.albedo[0][i], row.albedo[1][i], row.albedo[2][i]]));
            let vig = if resp.vignetting != 0.0 {
                let dx = row.rx[i] * fx;
                (1.0 - resp.vignetting * (dx * dx + dy2) / half_diag2).max(0.0)
            } else {
                1.0
            };
            let o = &mut t.rgb[p * 3..p * 3 + 3];
            for c in 0..3 {
                let lin = (row.albedo[c][i] * row.diffuse[c][i] + spec[c]) * gain[c] * vig;
                let q = (lin.clamp(0.0, 1.0) * (ENCODE_STEPS - 1) as f32 + 0.5) as usize;
                o[c] = enc[q.min(ENCODE_STEPS - 1)];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::fast_pow;

    #[test]
    fn fast_pow_matches_powf() {
        for &y in &[1.0f32, 2.5, 8.0, 32.0, 100.0, 200.0] {
            for i in 1..=1000 {
                let x = i as f32 / 1000.0;
                let (a, b) = (fast_pow(x, y), x.powf(y));
                if b > 1e-30 {
                    assert!((a / b - 1.0).abs() < 1e-4 * y.max(1.0) + 1e-5, "{x}^{y}: {a} vs {b}");
                }
            }
        }
    }
}
