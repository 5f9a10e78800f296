//! Visibility pass: transforms and lights vertices, clips triangles against the
//! near plane (and a wide guard band), and rasterises them with exact integer
//! edge functions (8 sub-pixel bits, top-left fill rule) into the inverse-depth
//! and triangle-id buffers. Also counts each item's coverage when alone.

use super::shading::{self, TriShade};
use super::target::{ItemCoverage, NO_TRIANGLE, RenderTarget};
use super::{RenderItem, RenderSettings};
use crate::{Intrinsics, Texture};

/// Sub-pixel precision of snapped vertex positions: 1/256 pixel.
const SUBPIXEL_BITS: u32 = 8;
const SUBPIXEL: f64 = (1 << SUBPIXEL_BITS) as f64;
/// Screen-space guard band (pixels) beyond the image: triangles are clipped to
/// it so fixed-point coordinates stay far from i64 overflow.
const GUARD_PX: f64 = 8192.0;
/// Outcode bit for a vertex with a non-finite position.
const INVALID: u8 = 0x80;
/// Marks "no texture" in [`TriShade::texture`].
pub(super) const NO_TEXTURE: u32 = u32::MAX;
/// Attributes interpolated per vertex, all linear. Gouraud mode: u, v, three
/// colour channels (shade for textured triangles, albedo × shade otherwise),
/// the albedo's luminance (untextured), two unused. Per-pixel-lighting mode:
/// u, v, albedo (untextured), then the unit normal facing the camera.
pub(super) const N_ATTR: usize = 8;

/// A projected vertex: pixel coordinates, inverse depth (1/m) and attributes.
#[derive(Clone, Copy, Debug)]
pub(super) struct ScreenVert {
    pub x: f64,
    pub y: f64,
    pub w: f64,
    pub a: [f32; N_ATTR],
}

/// A camera-frame vertex with attributes, as used by the clipper.
#[derive(Clone, Copy, Debug, Default)]
struct ClipVert {
    p: [f64; 3],
    a: [f32; N_ATTR],
}

/// A transformed mesh vertex (camera frame) with its lighting.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct CamVertex {
    p: [f64; 3],
    n: [f64; 3],
    outcode: u8,
    shade_front: [f32; 3],
    shade_back: [f32; 3],
}

/// The five clip planes as `n·p + d >= 0` (inside): near, then the guard band
/// left, right, top, bottom.
fn clip_planes(k: &Intrinsics, z_near: f64) -> [[f64; 4]; 5] {
    let (w, h) = (k.width as f64, k.height as f64);
    [
        [0.0, 0.0, 1.0, -z_near],
        [k.fx, 0.0, k.cx + GUARD_PX, 0.0],
        [-k.fx, 0.0, w - 1.0 + GUARD_PX - k.cx, 0.0],
        [0.0, k.fy, k.cy + GUARD_PX, 0.0],
        [0.0, -k.fy, h - 1.0 + GUARD_PX - k.cy, 0.0],
    ]
}

#[inline]
fn plane_dist(pl: &[f64; 4], p: &[f64; 3]) -> f64 {
    pl[0] * p[0] + pl[1] * p[1] + pl[2] * p[2] + pl[3]
}

#[inline]
fn sub(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

#[inline]
fn cross(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

#[inline]
fn dot(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Mesh vertex `q` (object frame) in the camera frame `r q + t`, with its
/// clip outcode ([`INVALID`] alone for a non-finite position); no lighting.
#[inline]
fn cam_vertex(
    r: &nalgebra::Matrix3<f64>,
    t: &nalgebra::Vector3<f64>,
    q: &[f32; 3],
    planes: &[[f64; 4]; 5],
) -> CamVertex {
    let q = [q[0] as f64, q[1] as f64, q[2] as f64];
    let p = [
        r[(0, 0)] * q[0] + r[(0, 1)] * q[1] + r[(0, 2)] * q[2] + t[0],
        r[(1, 0)] * q[0] + r[(1, 1)] * q[1] + r[(1, 2)] * q[2] + t[1],
        r[(2, 0)] * q[0] + r[(2, 1)] * q[1] + r[(2, 2)] * q[2] + t[2],
    ];
    let mut v = CamVertex { p, ..Default::default() };
    if !p.iter().all(|c| c.is_finite()) {
        v.outcode = INVALID;
        return v;
    }
    for (b, pl) in planes.iter().enumerate() {
        if plane_dist(pl, &p) < 0.0 {
            v.outcode |= 1 << b;
        }
    }
    v
}

/// Per-frame context shared by all triangles.
struct Frame<'t> {
    k: Intrinsics,
    width: i64,
    height: i64,
    inv_depth: &'t mut [f32],
    tri_id: &'t mut [u32],
    stamp: &'t mut [u16],
    tris: &'t mut Vec<TriShade>,
}

/// Per-triangle data that does not depend on clipping.
#[derive(Clone, Copy)]
struct TriContext {
    /// Exact inverse depth as an affine function of pixel coordinates:
    /// `1/z = a·x + b·y + c`, from the triangle's 3D plane.
    w_plane: [f64; 3],
    item: u32,
    tag: u16,
    texture: u32,
    normal: [f32; 3],
}

/// Clears the visibility buffers and rasterises every item. Returns the
/// textures referenced by [`TriShade::texture`].
pub(super) fn rasterise_items<'a>(
    items: &[RenderItem<'a>],
    k: &Intrinsics,
    settings: &RenderSettings,
    lit: bool,
    target: &mut RenderTarget,
) -> Vec<&'a Texture> {
    target.inv_depth.fill(0.0);
    target.tri_id.fill(NO_TRIANGLE);
    target.stamp.fill(0);
    target.tris.clear();
    target.coverage.clear();
    let planes = clip_planes(k, settings.z_near);
    let mut textures: Vec<&'a Texture> = Vec::new();
    let mut verts: Vec<CamVertex> = Vec::new();
    let mut coverage = std::mem::take(&mut target.coverage);
    let mut frame = Frame {
        k: *k,
        width: k.width as i64,
        height: k.height as i64,
        inv_depth: &mut target.inv_depth,
        tri_id: &mut target.tri_id,
        stamp: &mut target.stamp,
        tris: &mut target.tris,
    };
    for (idx, item) in items.iter().enumerate() {
        let alone = rasterise_item(idx, item, &planes, settings, lit, &mut frame, &mut verts, &mut textures);
        coverage.push(ItemCoverage {
            instance_label: item.instance_label,
            visible_pixels: 0,
            alone_pixels: alone,
            bbox: None,
        });
    }
    target.coverage = coverage;
    textures
}

#[allow(clippy::too_many_arguments)]
fn rasterise_item<'a>(
    idx: usize,
    item: &RenderItem<'a>,
    planes: &[[f64; 4]; 5],
    settings: &RenderSettings,
    lit: bool,
    frame: &mut Frame<'_>,
    verts: &mut Vec<CamVertex>,
    textures: &mut Vec<&'a Texture>,
) -> u32 {
    let mesh = item.mesh;
    let rot = item.pose.rotation.to_rotation_matrix();
    let r = rot.matrix();
    let t = item.pose.translation.vector;
    let has_normals = !mesh.normals.is_empty();
    let lighting = &settings.lighting;

    // Vertex pass: transform, outcode, light (front and back side).
    verts.clear();
    verts.extend(mesh.positions.iter().enumerate().map(|(i, q)| {
        let mut v = cam_vertex(r, &t, q, planes);
        if v.outcode == INVALID {
            return v;
        }
        if has_normals {
            let m = mesh.normals[i];
            let m = [m[0] as f64, m[1] as f64, m[2] as f64];
            let n = [
                r[(0, 0)] * m[0] + r[(0, 1)] * m[1] + r[(0, 2)] * m[2],
                r[(1, 0)] * m[0] + r[(1, 1)] * m[1] + r[(1, 2)] * m[2],
                r[(2, 0)] * m[0] + r[(2, 1)] * m[1] + r[(2, 2)] * m[2],
            ];
            let len = dot(&n, &n).sqrt();
            if len > 0.0 && len.is_finite() {
                v.n = [n[0] / len, n[1] / len, n[2] / len];
            }
            if !lit {
                v.shade_front = shading::lambert(lighting, &v.n, 1.0);
                v.shade_back = shading::lambert(lighting, &v.n, -1.0);
            }
        }
        v
    }));

    // Texture of each material (only used when the mesh has uvs).
    let material_texture: Vec<u32> = if mesh.uvs.is_empty() {
        Vec::new()
    } else {
        mesh.materials
            .iter()
            .map(|m| match &m.texture {
                Some(tex) => {
                    textures.push(tex);
                    textures.len() as u32 - 1
                }
                None => NO_TEXTURE,
            })
            .collect()
    };
    let texture_of = |mi: usize| material_texture.get(mi).copied().unwrap_or(NO_TEXTURE);

    let tag = idx as u16 + 1;
    let mut alone = 0u32;
    let default_albedo = [0.6f32; 3];
    for (ti, tri) in mesh.triangles.iter().enumerate() {
        let [i0, i1, i2] = [tri[0] as usize, tri[1] as usize, tri[2] as usize];
        let (v0, v1, v2) = (&verts[i0], &verts[i1], &verts[i2]);
        let or = v0.outcode | v1.outcode | v2.outcode;
        if or & INVALID != 0 || v0.outcode & v1.outcode & v2.outcode != 0 {
            continue;
        }
        let nf = cross(&sub(&v1.p, &v0.p), &sub(&v2.p, &v0.p));
        let nf_len = dot(&nf, &nf).sqrt();
        if nf_len == 0.0 || !nf_len.is_finite() {
            continue;
        }
        let nf = [nf[0] / nf_len, nf[1] / nf_len, nf[2] / nf_len];
        // Which side do we see? Judge by the vertex normals when present
        // (robust to inconsistent winding), else by the winding.
        let centroid = [
            (v0.p[0] + v1.p[0] + v2.p[0]) / 3.0,
            (v0.p[1] + v1.p[1] + v2.p[1]) / 3.0,
            (v0.p[2] + v1.p[2] + v2.p[2]) / 3.0,
        ];
        let n_ref = if has_normals {
            [v0.n[0] + v1.n[0] + v2.n[0], v0.n[1] + v1.n[1] + v2.n[1], v0.n[2] + v1.n[2] + v2.n[2]]
        } else {
            nf
        };
        let back = dot(&n_ref, &centroid) > 0.0;

        let mi = mesh.triangle_materials.get(ti).copied().unwrap_or(0) as usize;
        let material = mesh.materials.get(mi);
        let texture = texture_of(mi);
        let flat_shade = if has_normals || lit {
            [0.0; 3]
        } else {
            shading::lambert(&settings.lighting, &nf, if back { -1.0 } else { 1.0 })
        };
        let side = if back { -1.0f32 } else { 1.0 };
        let mut clip = [ClipVert::default(); 3];
        for (c, (&vi, v)) in clip.iter_mut().zip([(&i0, v0), (&i1, v1), (&i2, v2)]) {
            c.p = v.p;
            if lit {
                // Albedo and the normal of the side we see; lighting per pixel.
                let n = if has_normals { v.n } else { nf };
                let n = [n[0] as f32 * side, n[1] as f32 * side, n[2] as f32 * side];
                let (uv, albedo) = if texture != NO_TEXTURE {
                    (mesh.uvs[vi], [1.0; 3])
                } else {
                    ([0.0; 2], vertex_albedo(mesh, vi, material, default_albedo))
                };
                c.a = [uv[0], uv[1], albedo[0], albedo[1], albedo[2], n[0], n[1], n[2]];
                continue;
            }
            let shade = if !has_normals {
                flat_shade
            } else if back {
                v.shade_back
            } else {
                v.shade_front
            };
            if texture != NO_TEXTURE {
                let uv = mesh.uvs[vi];
                c.a = [uv[0], uv[1], shade[0], shade[1], shade[2], 0.0, 0.0, 0.0];
            } else {
                let albedo = vertex_albedo(mesh, vi, material, default_albedo);
                c.a = [
                    0.0,
                    0.0,
                    albedo[0] * shade[0],
                    albedo[1] * shade[1],
                    albedo[2] * shade[2],
                    shading::luminance(albedo),
                    0.0,
                    0.0,
                ];
            }
        }
        // Plane n·X = d: along the ray X = z·((x − cx)/fx, (y − cy)/fy, 1),
        // 1/z = n·ray / d, which is affine in the pixel coordinates.
        let d = dot(&nf, &v0.p);
        let k = &frame.k;
        let w_plane = if d.abs() > 1e-12 {
            let (a, b) = (nf[0] / (k.fx * d), nf[1] / (k.fy * d));
            [a, b, nf[2] / d - a * k.cx - b * k.cy]
        } else {
            [0.0, 0.0, 1.0 / v0.p[2].max(settings.z_near)]
        };
        let ctx =
            TriContext { w_plane, item: idx as u32, tag, texture, normal: [nf[0] as f32, nf[1] as f32, nf[2] as f32] };
        if or == 0 {
            let sv = clip.map(|c| project(&frame.k, &c));
            alone += rasterise_triangle(frame, sv, &ctx);
        } else {
            alone += clip_and_rasterise(frame, planes, or, clip, &ctx);
        }
    }
    alone
}

/// Linear albedo of an untextured vertex: its colour, else its material's.
#[inline]
fn vertex_albedo(mesh: &crate::Mesh, vi: usize, material: Option<&crate::Material>, default: [f32; 3]) -> [f32; 3] {
    if let Some(col) = mesh.colors.get(vi) {
        [shading::srgb_to_linear(col[0]), shading::srgb_to_linear(col[1]), shading::srgb_to_linear(col[2])]
    } else if let Some(m) = material {
        m.diffuse
    } else {
        default
    }
}

#[inline]
fn project(k: &Intrinsics, c: &ClipVert) -> ScreenVert {
    let w = 1.0 / c.p[2];
    ScreenVert { x: k.fx * c.p[0] * w + k.cx, y: k.fy * c.p[1] * w + k.cy, w, a: c.a }
}

/// Sutherland–Hodgman against the planes flagged in `outcodes`, then a fan.
fn clip_and_rasterise(
    frame: &mut Frame<'_>,
    planes: &[[f64; 4]; 5],
    outcodes: u8,
    tri: [ClipVert; 3],
    ctx: &TriContext,
) -> u32 {
    let mut poly = [ClipVert::default(); CLIP_MAX];
    let n = clip_polygon(planes, outcodes, tri, &mut poly);
    let mut alone = 0;
    for i in 1..n.saturating_sub(1) {
        if poly[0].p[2] <= 0.0 || poly[i].p[2] <= 0.0 || poly[i + 1].p[2] <= 0.0 {
            continue;
        }
        let sv = [project(&frame.k, &poly[0]), project(&frame.k, &poly[i]), project(&frame.k, &poly[i + 1])];
        alone += rasterise_triangle(frame, sv, ctx);
    }
    alone
}

/// One edge function `E(P) = (b.x - a.x)(P.y - a.y) - (b.y - a.y)(P.x - a.x)`
/// in fixed point, positive inside.
struct Edge {
    /// Value at the bounding box's first pixel, minus 1 if not a top-left edge.
    row_start: i64,
    step_x: i64,
    step_y: i64,
}

impl Edge {
    #[inline]
    fn new(a: (i64, i64), b: (i64, i64), px: i64, py: i64) -> Edge {
        let dedx = -(b.1 - a.1);
        let dedy = b.0 - a.0;
        let top_left = dedx > 0 || (dedx == 0 && dedy > 0);
        let bias = if top_left { 0 } else { -1 };
        let raw = dedy * ((py << SUBPIXEL_BITS) - a.1) + dedx * ((px << SUBPIXEL_BITS) - a.0);
        Edge { row_start: raw + bias, step_x: dedx << SUBPIXEL_BITS, step_y: dedy << SUBPIXEL_BITS }
    }
}

/// Rasterises one front-clipped triangle; returns the pixels it covers that
/// its item had not covered yet (for the item's "alone" coverage).
fn rasterise_triangle(frame: &mut Frame<'_>, mut sv: [ScreenVert; 3], ctx: &TriContext) -> u32 {
    let snap = |v: &ScreenVert| ((v.x * SUBPIXEL).round() as i64, (v.y * SUBPIXEL).round() as i64);
    let mut p = [snap(&sv[0]), snap(&sv[1]), snap(&sv[2])];
    let area = (p[1].0 - p[0].0) * (p[2].1 - p[0].1) - (p[2].0 - p[0].0) * (p[1].1 - p[0].1);
    if area == 0 {
        return 0;
    }
    if area < 0 {
        p.swap(1, 2);
        sv.swap(1, 2);
    }
    let one = 1i64 << SUBPIXEL_BITS;
    let min_x = p[0].0.min(p[1].0).min(p[2].0);
    let max_x = p[0].0.max(p[1].0).max(p[2].0);
    let min_y = p[0].1.min(p[1].1).min(p[2].1);
    let max_y = p[0].1.max(p[1].1).max(p[2].1);
    // Pixel centres sit at integer pixel coordinates.
    let x0 = ((min_x + one - 1) >> SUBPIXEL_BITS).max(0);
    let x1 = (max_x >> SUBPIXEL_BITS).min(frame.width - 1);
    let y0 = ((min_y + one - 1) >> SUBPIXEL_BITS).max(0);
    let y1 = (max_y >> SUBPIXEL_BITS).min(frame.height - 1);
    if x0 > x1 || y0 > y1 {
        return 0;
    }
    // Edge opposite vertex i weighs vertex i.
    let mut e0 = Edge::new(p[1], p[2], x0, y0);
    let mut e1 = Edge::new(p[2], p[0], x0, y0);
    let mut e2 = Edge::new(p[0], p[1], x0, y0);
    // Inverse depth from the exact plane, clamped to the triangle's range
    // (pixels the snapped edges admit just outside the true triangle).
    let w_min = sv[0].w.min(sv[1].w).min(sv[2].w);
    let w_max = sv[0].w.max(sv[1].w).max(sv[2].w);
    let [wa, wb, wc] = ctx.w_plane;

    let id = frame.tris.len() as u32;
    frame.tris.push(TriShade::new(&sv, ctx.item, ctx.texture, ctx.normal));
    let width = frame.width as usize;
    let tag = ctx.tag;
    let mut alone = 0u32;
    for y in y0..=y1 {
        let (mut a, mut b, mut c) = (e0.row_start, e1.row_start, e2.row_start);
        let w_row = wb * y as f64 + wc;
        let row = y as usize * width;
        let inv_row = &mut frame.inv_depth[row..row + width];
        let tri_row = &mut frame.tri_id[row..row + width];
        let stamp_row = &mut frame.stamp[row..row + width];
        for x in x0 as usize..=x1 as usize {
            if (a | b | c) >= 0 {
                if stamp_row[x] != tag {
                    stamp_row[x] = tag;
                    alone += 1;
                }
                let w = (wa * x as f64 + w_row).clamp(w_min, w_max) as f32;
                if w > inv_row[x] {
                    inv_row[x] = w;
                    tri_row[x] = id;
                }
            }
            a += e0.step_x;
            b += e1.step_x;
            c += e2.step_x;
        }
        e0.row_start += e0.step_y;
        e1.row_start += e1.step_y;
        e2.row_start += e2.step_y;
    }
    alone
}

/// Depth-only rasterisation (shadow maps): writes the nearest inverse depth
/// (1/m) per pixel of `items` (each item's `shadow_mesh` where it has one), each posed by `view_from_cam * item.pose`, into
/// `inv_depth` (`k.width * k.height`, cleared by the caller). Same coverage
/// rules and clipping as the colour pass.
pub(super) fn rasterise_depth(
    items: &[RenderItem<'_>],
    view_from_cam: &crate::Pose,
    k: &Intrinsics,
    z_near: f64,
    inv_depth: &mut [f32],
    scratch: &mut Vec<CamVertex>,
) {
    let planes = clip_planes(k, z_near);
    let (width, height) = (k.width as i64, k.height as i64);
    for item in items {
        let pose = view_from_cam * item.pose;
        let rot = pose.rotation.to_rotation_matrix();
        let r = rot.matrix();
        let t = pose.translation.vector;
        let mesh = item.shadow_mesh.unwrap_or(item.mesh);
        scratch.clear();
        scratch.extend(mesh.positions.iter().map(|q| cam_vertex(r, &t, q, &planes)));
        for tri in &mesh.triangles {
            let (v0, v1, v2) = (&scratch[tri[0] as usize], &scratch[tri[1] as usize], &scratch[tri[2] as usize]);
            let or = v0.outcode | v1.outcode | v2.outcode;
            if or & INVALID != 0 || v0.outcode & v1.outcode & v2.outcode != 0 {
                continue;
            }
            let nf = cross(&sub(&v1.p, &v0.p), &sub(&v2.p, &v0.p));
            let len = dot(&nf, &nf).sqrt();
            if len == 0.0 || !len.is_finite() {
                continue;
            }
            let nf = [nf[0] / len, nf[1] / len, nf[2] / len];
            let d = dot(&nf, &v0.p);
            let w_plane = if d.abs() > 1e-12 {
                let (a, b) = (nf[0] / (k.fx * d), nf[1] / (k.fy * d));
                [a, b, nf[2] / d - a * k.cx - b * k.cy]
            } else {
                [0.0, 0.0, 1.0 / v0.p[2].max(z_near)]
            };
            let clip = [v0, v1, v2].map(|v| ClipVert { p: v.p, a: [0.0; N_ATTR] });
            if or == 0 {
                let sv = clip.map(|c| project(k, &c));
                depth_triangle(width, height, inv_depth, sv, w_plane);
            } else {
                let mut poly = [ClipVert::default(); CLIP_MAX];
                let n = clip_polygon(&planes, or, clip, &mut poly);
                for i in 1..n.saturating_sub(1) {
                    if poly[0].p[2] <= 0.0 || poly[i].p[2] <= 0.0 || poly[i + 1].p[2] <= 0.0 {
                        continue;
                    }
                    let sv = [project(k, &poly[0]), project(k, &poly[i]), project(k, &poly[i + 1])];
                    depth_triangle(width, height, inv_depth, sv, w_plane);
                }
            }
        }
    }
}

/// Most vertices a triangle clipped by the five planes can have.
const CLIP_MAX: usize = 3 + 5 + 1;

/// Sutherland–Hodgman of one triangle against the planes flagged in
/// `outcodes`; returns the polygon's vertex count (< 3: nothing left).
fn clip_polygon(planes: &[[f64; 4]; 5], outcodes: u8, tri: [ClipVert; 3], poly: &mut [ClipVert; CLIP_MAX]) -> usize {
    let mut next = [ClipVert::default(); CLIP_MAX];
    poly[..3].copy_from_slice(&tri);
    let mut n = 3;
    for (b, pl) in planes.iter().enumerate() {
        if outcodes & (1 << b) == 0 {
            continue;
        }
        let mut m = 0;
        for i in 0..n {
            let cur = poly[i];
            let nxt = poly[(i + 1) % n];
            let dc = plane_dist(pl, &cur.p);
            let dn = plane_dist(pl, &nxt.p);
            if dc >= 0.0 && m < CLIP_MAX {
                next[m] = cur;
                m += 1;
            }
            if (dc >= 0.0) != (dn >= 0.0) && m < CLIP_MAX {
                let s = dc / (dc - dn);
                let mut v = ClipVert::default();
                for j in 0..3 {
                    v.p[j] = cur.p[j] + s * (nxt.p[j] - cur.p[j]);
                }
                let sf = s as f32;
                for j in 0..N_ATTR {
                    v.a[j] = cur.a[j] + sf * (nxt.a[j] - cur.a[j]);
                }
                next[m] = v;
                m += 1;
            }
        }
        std::mem::swap(poly, &mut next);
        n = m;
        if n < 3 {
            return 0;
        }
    }
    n
}

/// [`rasterise_triangle`] without shading data: nearest inverse depth only.
fn depth_triangle(width: i64, height: i64, inv_depth: &mut [f32], mut sv: [ScreenVert; 3], w_plane: [f64; 3]) {
    let snap = |v: &ScreenVert| ((v.x * SUBPIXEL).round() as i64, (v.y * SUBPIXEL).round() as i64);
    let mut p = [snap(&sv[0]), snap(&sv[1]), snap(&sv[2])];
    let area = (p[1].0 - p[0].0) * (p[2].1 - p[0].1) - (p[2].0 - p[0].0) * (p[1].1 - p[0].1);
    if area == 0 {
        return;
    }
    if area < 0 {
        p.swap(1, 2);
        sv.swap(1, 2);
    }
    let one = 1i64 << SUBPIXEL_BITS;
    let x0 = ((p[0].0.min(p[1].0).min(p[2].0) + one - 1) >> SUBPIXEL_BITS).max(0);
    let x1 = (p[0].0.max(p[1].0).max(p[2].0) >> SUBPIXEL_BITS).min(width - 1);
    let y0 = ((p[0].1.min(p[1].1).min(p[2].1) + one - 1) >> SUBPIXEL_BITS).max(0);
    let y1 = (p[0].1.max(p[1].1).max(p[2].1) >> SUBPIXEL_BITS).min(height - 1);
    if x0 > x1 || y0 > y1 {
        return;
    }
    let mut e0 = Edge::new(p[1], p[2], x0, y0);
    let mut e1 = Edge::new(p[2], p[0], x0, y0);
    let mut e2 = Edge::new(p[0], p[1], x0, y0);
    let w_min = sv[0].w.min(sv[1].w).min(sv[2].w);
    let w_max = sv[0].w.max(sv[1].w).max(sv[2].w);
    let [wa, wb, wc] = w_plane;
    let w_usize = width as usize;
    for y in y0..=y1 {
        let (mut a, mut b, mut c) = (e0.row_start, e1.row_start, e2.row_start);
        let w_row = wb * y as f64 + wc;
        let row = &mut inv_depth[y as usize * w_usize..(y as usize + 1) * w_usize];
        for (x, px) in row.iter_mut().enumerate().take(x1 as usize + 1).skip(x0 as usize) {
            if (a | b | c) >= 0 {
                let w = (wa * x as f64 + w_row).clamp(w_min, w_max) as f32;
                if w > *px {
                    *px = w;
                }
            }
            a += e0.step_x;
            b += e1.step_x;
            c += e2.step_x;
        }
        e0.row_start += e0.step_y;
        e1.row_start += e1.step_y;
        e2.row_start += e2.step_y;
    }
}
