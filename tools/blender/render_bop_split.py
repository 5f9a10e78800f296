"""Path-traced BOP test split of fusepose's objects, rendered by Blender Cycles.

A second renderer that shares no code with fusepose's own (`scene::render`):
Blender's Cycles path tracer on the CPU (physically based: soft and hard
shadows, inter-reflections, glossy highlights), tabletop scenes with procedural
table materials, rooms or open backgrounds and 1-3 lights of random kinds and
colours. It writes one BOP split exactly as `fusepose eval --dataset` reads it.

Install (Debian 12 / Ubuntu 23.04+; Blender 3.4 from the distribution, no
add-ons or Python packages needed):

    apt-get install blender

Objects to render (the built-in set as OBJ + MTL + PNG and models_info.json):

    fusepose objects export scratch/objects

or a folder of your own meshes, as fusepose loads them (metres, textures
resolved; name the mesh folder with --source so that `fusepose eval` loads it):

    fusepose objects export scratch/mine --objects meshes/ --scale 0.001 --symmetry suggested

Render (run `blender` from any folder; everything after `--` goes to this script):

    nice -n 15 blender -b -t 1 --factory-startup --python tools/blender/render_bop_split.py -- \
        --objects scratch/objects --out scratch/pathtraced --scenes 20 --views 3 --seed 190004 \
        --log scratch/pathtraced/render.log

    fusepose eval --dataset scratch/pathtraced --estimator icp

Touching copies of one object (issue 24's pairs on images fusepose did not
render): `--pairs 1` gives every scene a second copy of one of its objects
beside the first, as `fusepose render --pairs` does.

Check the camera model and the depth convention (prints measured numbers, no files kept):

    blender -b -t 1 --factory-startup --python tools/blender/render_bop_split.py -- --self-test

Output (BOP layout, see scene/src/bop/mod.rs): OUT/fusepose_dataset.json
(object source + class names, obj_id = class id = position in models_info.json),
OUT/camera.json, OUT/models/models_info.json (mm), OUT/SPLIT/NNNNNN/{rgb,depth,
mask_visib}/..., scene_camera.json (cam_K, depth_scale 0.1: u16 depth in 0.1 mm),
scene_gt.json (cam_R_m2c, cam_t_m2c in mm, object -> OpenCV camera frame),
scene_gt_info.json (bbox_obj from the projected mesh, bbox_visib, px_count_all
from a render of the object alone, px_count_visib, px_count_valid, visib_fract).

Conventions, all checked by --self-test: pixel centres at integer coordinates
(u = fx x / z + cx); depth is the camera-frame z (planar), not the ray length;
masks and depth come from a 1-sample render with a 0.01-pixel filter, so they
hold the surface seen through each pixel centre (no anti-aliased mixtures).

Materials follow the MTL spec: the diffuse colour is map_Kd (sRGB texture)
multiplied by Kd, or Kd alone (linear) without a texture; vertex colours, when
the OBJ has them, multiply too.

Determinism: every random choice of scene S comes from --seed and S, of view V
from --seed, S and V; Cycles' sampling seed too. --resume skips frames already
written, so an interrupted run can continue with the same command.

Colour pipeline: Cycles renders scene-linear radiance to EXR; this script then
applies a white balance for the mean light colour (a camera with the right
preset: mixed lights and coloured walls still tint), an auto exposure (frame
mean luminance to a random target), clips and encodes sRGB 8-bit. Debian's
Blender is built without OpenImageDenoise, so frames are not denoised: the
sample count and adaptive sampling keep the noise near a real sensor's.
"""

import argparse
import array
import json
import math
import os
import random
import shutil
import struct
import sys
import tempfile
import time
import zlib

import bpy
from mathutils import Matrix, Vector

WIDTH, HEIGHT = 640, 480
# YCB-Video's first camera, as fusepose's Intrinsics::YCB_VIDEO.
FX, FY, CX, CY = 1066.778, 1067.487, 312.9869, 241.3109
# BOP depth_scale: depth PNG value * 0.1 = millimetres (fusepose's 0.1 mm units).
DEPTH_SCALE = 0.1
DEPTH_UNITS_PER_M = 1000.0 / DEPTH_SCALE
# Blender camera (x right, y up, z backwards) <-> OpenCV camera (x right, y down, z forward).
CV_TO_BLENDER_CAM = Matrix(((1, 0, 0, 0), (0, -1, 0, 0), (0, 0, -1, 0), (0, 0, 0, 1)))
TABLE_TOP_Z = 0.0
# Objects float this far above the table so Cycles never sees coincident faces.
REST_GAP = 0.0003


# ---------------------------------------------------------------- arguments


def parse_args(argv):
    p = argparse.ArgumentParser(
        prog="blender -b -t 1 --factory-startup --python tools/blender/render_bop_split.py --",
        description="Render a BOP split of exported fusepose objects with Blender Cycles.",
    )
    p.add_argument("--objects", help="folder written by `fusepose objects export` (models_info.json + NAME/NAME.obj)")
    p.add_argument("--out", help="BOP dataset root to write (the split goes to OUT/SPLIT)")
    p.add_argument("--split", default="test")
    p.add_argument("--scenes", type=int, default=20)
    p.add_argument("--views", type=int, default=3, help="camera views per scene")
    p.add_argument("--first-scene", type=int, default=0, help="scene id of the first scene")
    p.add_argument("--seed", type=int, default=190004)
    p.add_argument("--min-objects", type=int, default=5)
    p.add_argument("--max-objects", type=int, default=7)
    p.add_argument("--pairs", type=float, default=0.0,
                   help="probability that a scene holds a second copy of one of its objects, side by side with the "
                        "first (same rest, yaw within 8 degrees, 0.5-3 mm apart), as `fusepose render --pairs`")
    p.add_argument("--samples", type=int, default=48, help="Cycles samples per pixel (adaptive, at most)")
    p.add_argument("--noise-threshold", type=float, default=0.03, help="Cycles adaptive-sampling threshold")
    p.add_argument("--source", default="builtin",
                   help="object set named in fusepose_dataset.json: `builtin` (what `objects export` wrote) "
                        "or the mesh folder fusepose should load")
    p.add_argument("--log", help="append one line per frame here")
    p.add_argument("--resume", action="store_true", help="keep frames already written, render the rest")
    p.add_argument("--keep-exr", action="store_true", help="keep the linear EXR of each frame (debugging)")
    p.add_argument("--self-test", action="store_true", help="measure the camera model and depth convention")
    args = p.parse_args(argv)
    if not args.self_test and not (args.objects and args.out):
        p.error("--objects and --out are required (or --self-test)")
    if not 1 <= args.min_objects <= args.max_objects:
        p.error("need 1 <= --min-objects <= --max-objects")
    if not 0.0 <= args.pairs <= 1.0:
        p.error("--pairs is a probability: 0..1")
    return args


def script_argv():
    return sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []


class Log:
    def __init__(self, path):
        self.path = path

    def __call__(self, msg):
        line = time.strftime("%Y-%m-%d %H:%M:%S ") + msg
        print(line, flush=True)
        if self.path:
            with open(self.path, "a") as f:
                f.write(line + "\n")


# ---------------------------------------------------------------- files


def write_png(path, width, height, rows, channels, bit_depth):
    """Writes a PNG from `rows` (bytes per row, top row first; 16-bit big-endian)."""
    color_type = {1: 0, 3: 2, 4: 6}[channels]
    raw = b"".join(b"\x00" + r for r in rows)

    def chunk(tag, data):
        c = struct.pack(">I", len(data)) + tag + data
        return c + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", width, height, bit_depth, color_type, 0, 0, 0)
    data = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b"")
    write_atomic(path, data)


def write_atomic(path, data):
    tmp = path + ".tmp"
    with open(tmp, "wb" if isinstance(data, bytes) else "w") as f:
        f.write(data)
    os.replace(tmp, path)


def write_json(path, value):
    write_atomic(path, json.dumps(value, indent=2, sort_keys=True) + "\n")


def read_json(path):
    with open(path) as f:
        return json.load(f)


def read_obj(path):
    """Minimal Wavefront OBJ reader: positions (+ optional vertex colours),
    UVs, normals, polygon corners as (v, vt, vn) index triples, usemtl, mtllib."""
    v, vc, vt, vn, faces, libs = [], [], [], [], [], []
    material = None
    with open(path) as f:
        for line in f:
            parts = line.split()
            if not parts or parts[0].startswith("#"):
                continue
            tag = parts[0]
            if tag == "v":
                v.append(tuple(float(x) for x in parts[1:4]))
                if len(parts) >= 7:
                    vc.append(tuple(float(x) for x in parts[4:7]))
            elif tag == "vt":
                vt.append((float(parts[1]), float(parts[2]) if len(parts) > 2 else 0.0))
            elif tag == "vn":
                vn.append(tuple(float(x) for x in parts[1:4]))
            elif tag == "f":
                corners = []
                for c in parts[1:]:
                    ids = c.split("/")

                    def index(k, n):
                        if len(ids) <= k or ids[k] == "":
                            return None
                        i = int(ids[k])
                        return i - 1 if i > 0 else n + i

                    corners.append((index(0, len(v)), index(1, len(vt)), index(2, len(vn))))
                faces.append((corners, material))
            elif tag == "usemtl":
                material = " ".join(parts[1:])
            elif tag == "mtllib":
                libs.append(" ".join(parts[1:]))
    if len(vc) != len(v):
        vc = []
    return {"v": v, "vc": vc, "vt": vt, "vn": vn, "faces": faces, "mtllibs": libs}


def read_mtl(path):
    """Kd and map_Kd of each material (MTL spec: diffuse = map_Kd * Kd)."""
    out, cur = {}, None
    with open(path) as f:
        for line in f:
            parts = line.split()
            if not parts or parts[0].startswith("#"):
                continue
            if parts[0] == "newmtl":
                cur = " ".join(parts[1:])
                out[cur] = {"Kd": (1.0, 1.0, 1.0), "map_Kd": None}
            elif cur is None:
                continue
            elif parts[0] == "Kd" and len(parts) >= 4:
                out[cur]["Kd"] = tuple(float(x) for x in parts[1:4])
            elif parts[0] == "map_Kd" and len(parts) >= 2:
                # Options (-s 1 1 1 ...) come first; the file name is last.
                out[cur]["map_Kd"] = os.path.join(os.path.dirname(path), parts[-1])
    return out


# ---------------------------------------------------------------- objects


def load_object_set(folder):
    """Reads models_info.json and every OBJ of an exported object set."""
    info = read_json(os.path.join(folder, "models_info.json"))
    if info.get("units", "metres") != "metres":
        raise SystemExit(f"{folder}/models_info.json: units {info.get('units')!r}, expected metres")
    classes = []
    for entry in sorted(info["objects"], key=lambda e: e["class_id"]):
        path = os.path.join(folder, entry["mesh"])
        obj = read_obj(path)
        mtl = {}
        for lib in obj["mtllibs"]:
            lib_path = os.path.join(os.path.dirname(path), lib)
            if os.path.isfile(lib_path):
                mtl.update(read_mtl(lib_path))
        classes.append({"class_id": entry["class_id"], "name": entry["name"], "info": entry, "obj": obj,
                        "mtl": mtl, "path": path})
    ids = [c["class_id"] for c in classes]
    if ids != list(range(1, len(ids) + 1)):
        raise SystemExit(f"{folder}/models_info.json: class ids {ids} are not 1..{len(ids)}")
    return classes


def object_material(name, spec, has_vertex_colors):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    bsdf = nt.nodes["Principled BSDF"]
    kd = tuple(spec["Kd"]) if spec else (0.6, 0.6, 0.6)
    color = None
    if spec and spec["map_Kd"] and os.path.isfile(spec["map_Kd"]):
        tex = nt.nodes.new("ShaderNodeTexImage")
        tex.image = bpy.data.images.load(spec["map_Kd"], check_existing=True)
        tex.image.colorspace_settings.name = "sRGB"
        tex.interpolation = "Linear"
        color = tex.outputs["Color"]
    if has_vertex_colors:
        attr = nt.nodes.new("ShaderNodeVertexColor")
        attr.layer_name = "Col"
        color = attr.outputs["Color"] if color is None else multiply(nt, color, attr.outputs["Color"])
    if color is None:
        bsdf.inputs["Base Color"].default_value = kd + (1.0,)
    else:
        if kd != (1.0, 1.0, 1.0):
            color = multiply(nt, color, kd + (1.0,))
        nt.links.new(color, bsdf.inputs["Base Color"])
    return mat


def multiply(nt, a, b):
    node = nt.nodes.new("ShaderNodeMixRGB")
    node.blend_type = "MULTIPLY"
    node.inputs["Fac"].default_value = 1.0
    nt.links.new(a, node.inputs["Color1"])
    if isinstance(b, tuple):
        node.inputs["Color2"].default_value = b
    else:
        nt.links.new(b, node.inputs["Color2"])
    return node.outputs["Color"]


def build_mesh(cls):
    """A Blender mesh with the OBJ's exact vertex positions (metres, object
    frame; no axis conversion), UVs, custom normals and materials."""
    obj = cls["obj"]
    verts = obj["v"]
    faces = [f for f, _ in obj["faces"] if len(f) >= 3]
    mats = [m for f, m in obj["faces"] if len(f) >= 3]
    mesh = bpy.data.meshes.new(cls["name"])
    mesh.from_pydata(verts, [], [[c[0] for c in f] for f in faces])
    corners = [c for f in faces for c in f]
    if obj["vt"] and all(c[1] is not None for c in corners):
        uv = mesh.uv_layers.new(name="UVMap")
        uv.data.foreach_set("uv", [x for c in corners for x in obj["vt"][c[1]]])
    names = sorted({m for m in mats if m is not None}) or [None]
    for n in names:
        mesh.materials.append(object_material(f"{cls['name']}:{n}", cls["mtl"].get(n), bool(obj["vc"])))
    mesh.polygons.foreach_set("material_index", [names.index(m) if m in names else 0 for m in mats])
    if obj["vc"]:
        col = mesh.color_attributes.new("Col", "FLOAT_COLOR", "POINT")
        col.data.foreach_set("color", [x for c in obj["vc"] for x in (c + (1.0,))])
    mesh.update()
    if obj["vn"] and all(c[2] is not None for c in corners):
        mesh.polygons.foreach_set("use_smooth", [True] * len(faces))
        mesh.use_auto_smooth = True
        mesh.normals_split_custom_set([obj["vn"][c[2]] for c in corners])
    return mesh


def rest_poses(verts):
    """The six bounding-box-face rests: rotation (object -> table, before yaw)
    putting that face down; `upright` for the object's own -z face."""
    lo = [min(p[i] for p in verts) for i in range(3)]
    hi = [max(p[i] for p in verts) for i in range(3)]
    up_height = hi[2] - lo[2]
    rests = []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            n = Vector([sign if i == axis else 0.0 for i in range(3)])
            rot = n.rotation_difference(Vector((0.0, 0.0, -1.0))).to_matrix()
            if axis == 2 and sign > 0:
                rot = Matrix.Rotation(math.pi, 3, "X")  # upside down (rotation_difference is ill-posed for -n)
            height = max((rot @ Vector(p)).z for p in verts) - min((rot @ Vector(p)).z for p in verts)
            dims = [hi[i] - lo[i] for i in range(3) if i != axis]
            rests.append({"rot": rot, "upright": axis == 2 and sign < 0, "area": dims[0] * dims[1],
                          "height": height, "plausible": height <= 2.0 * up_height + 1e-9})
    return rests


def convex_hull(points):
    pts = sorted(set((round(x, 5), round(y, 5)) for x, y in points))
    if len(pts) <= 2:
        return pts

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower, upper = [], []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return lower[:-1] + upper[:-1]


def hulls_apart(a, b, gap):
    """Separating-axis test: True when convex polygons a and b are at least
    `gap` apart along some edge normal (then their prisms cannot intersect)."""
    for poly in (a, b):
        for i in range(len(poly)):
            x0, y0 = poly[i]
            x1, y1 = poly[(i + 1) % len(poly)]
            nx, ny = y1 - y0, x0 - x1
            norm = math.hypot(nx, ny)
            if norm == 0:
                continue
            nx, ny = nx / norm, ny / norm
            pa = [x * nx + y * ny for x, y in a]
            pb = [x * nx + y * ny for x, y in b]
            if min(pb) - max(pa) >= gap or min(pa) - max(pb) >= gap:
                return True
    return False


def place_twin(rng, cls, first, placed, limit):
    """A second copy of `first` touching it: same rest, yaw within 8 degrees,
    slid along a random direction until its footprint is 0.5-3 mm from the
    first's (bisection on the separating-axis test; footprints are convex, so
    the offsets at which they overlap form one interval). None when no
    direction leaves it on the table and clear of the other objects."""
    for _ in range(60):
        gap = rng.uniform(0.0005, 0.003)
        rot = Matrix.Rotation(first["yaw"] + rng.uniform(-0.14, 0.14), 3, "Z") @ first["rest"]["rot"]
        pts = [rot @ Vector(p) for p in cls["obj"]["v"]]
        cr = max(math.hypot(p.x, p.y) for p in pts)
        a = rng.uniform(0, math.tau)
        ux, uy = math.cos(a), math.sin(a)

        def hull_at(t):
            return convex_hull([(p.x + first["x"] + t * ux, p.y + first["y"] + t * uy) for p in pts])

        lo, hi = 0.0, first["r"] + cr + gap + 0.01
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            if hulls_apart(first["hull"], hull_at(mid), gap):
                hi = mid
            else:
                lo = mid
        x, y = first["x"] + hi * ux, first["y"] + hi * uy
        hull = hull_at(hi)
        if any(abs(hx) > limit[0] or abs(hy) > limit[1] for hx, hy in hull):
            continue
        if any(not hulls_apart(hull, o["hull"], 0.003) for o in placed if o is not first):
            continue
        z = TABLE_TOP_Z + REST_GAP - min(p.z for p in pts)
        return {"class": first["class"], "rot": rot, "x": x, "y": y, "z": z, "r": cr, "hull": hull,
                "upright": first["upright"], "yaw": first["yaw"], "rest": first["rest"]}
    return None


# ---------------------------------------------------------------- scene


def clear_scene():
    for o in list(bpy.data.objects):
        bpy.data.objects.remove(o, do_unlink=True)


def hsv(h, s, v):
    import colorsys

    return colorsys.hsv_to_rgb(h % 1.0, s, v)


def srgb_to_linear(c):
    return c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4


def random_color(rng, saturated=None):
    """A linear RGB colour from an sRGB HSV draw (saturated or muted)."""
    if saturated is None:
        saturated = rng.random() < 0.35
    s = rng.uniform(0.45, 0.9) if saturated else rng.uniform(0.0, 0.35)
    v = rng.uniform(0.25, 0.95)
    return tuple(srgb_to_linear(c) for c in hsv(rng.random(), s, v))


def procedural_material(rng, name, bump=True):
    """Random procedural surface: noise / wood rings / voronoi / brick /
    checker / plain, coloured through a random colour ramp."""
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    bsdf = nt.nodes["Principled BSDF"]
    bsdf.inputs["Roughness"].default_value = rng.uniform(0.3, 0.95)
    bsdf.inputs["Specular"].default_value = rng.uniform(0.2, 0.6)
    kind = rng.choice(["noise", "wood", "voronoi", "brick", "checker", "plain", "noise", "wood"])
    c1 = random_color(rng)
    if kind == "plain":
        bsdf.inputs["Base Color"].default_value = c1 + (1.0,)
        return mat, kind
    coord = nt.nodes.new("ShaderNodeTexCoord")
    mapping = nt.nodes.new("ShaderNodeMapping")
    mapping.inputs["Rotation"].default_value = (rng.uniform(0, 0.3), rng.uniform(0, 0.3), rng.uniform(0, math.tau))
    nt.links.new(coord.outputs["Object"], mapping.inputs["Vector"])
    if kind == "noise":
        tex = nt.nodes.new("ShaderNodeTexNoise")
        tex.inputs["Scale"].default_value = rng.uniform(2.0, 25.0)
        tex.inputs["Detail"].default_value = rng.uniform(1.0, 8.0)
        tex.inputs["Roughness"].default_value = rng.uniform(0.4, 0.7)
        tex.inputs["Distortion"].default_value = rng.uniform(0.0, 2.0)
        fac = tex.outputs["Fac"]
    elif kind == "wood":
        tex = nt.nodes.new("ShaderNodeTexWave")
        tex.wave_type = rng.choice(["RINGS", "BANDS"])
        tex.inputs["Scale"].default_value = rng.uniform(1.0, 8.0)
        tex.inputs["Distortion"].default_value = rng.uniform(2.0, 12.0)
        tex.inputs["Detail"].default_value = rng.uniform(1.0, 6.0)
        mapping.inputs["Scale"].default_value = (1.0, rng.uniform(4.0, 12.0), 1.0)
        fac = tex.outputs["Fac"]
    elif kind == "voronoi":
        tex = nt.nodes.new("ShaderNodeTexVoronoi")
        tex.feature = rng.choice(["F1", "DISTANCE_TO_EDGE", "F2"])
        tex.inputs["Scale"].default_value = rng.uniform(3.0, 40.0)
        fac = tex.outputs["Distance"]
    elif kind == "brick":
        tex = nt.nodes.new("ShaderNodeTexBrick")
        tex.inputs["Scale"].default_value = rng.uniform(2.0, 12.0)
        tex.inputs["Mortar Size"].default_value = rng.uniform(0.005, 0.03)
        fac = tex.outputs["Fac"]
    else:
        tex = nt.nodes.new("ShaderNodeTexChecker")
        tex.inputs["Scale"].default_value = rng.uniform(2.0, 15.0)
        fac = tex.outputs["Fac"]
    nt.links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
    ramp = nt.nodes.new("ShaderNodeValToRGB")
    stops = ramp.color_ramp.elements
    c2 = c1 if rng.random() < 0.5 else random_color(rng)
    c2 = tuple(min(1.0, x * rng.uniform(0.3, 1.6)) for x in c2)
    stops[0].color = c1 + (1.0,)
    stops[1].color = c2 + (1.0,)
    stops[0].position, stops[1].position = rng.uniform(0.0, 0.4), rng.uniform(0.6, 1.0)
    nt.links.new(fac, ramp.inputs["Fac"])
    nt.links.new(ramp.outputs["Color"], bsdf.inputs["Base Color"])
    if bump and rng.random() < 0.6:
        b = nt.nodes.new("ShaderNodeBump")
        b.inputs["Strength"].default_value = rng.uniform(0.02, 0.25)
        b.inputs["Distance"].default_value = 0.002
        nt.links.new(fac, b.inputs["Height"])
        nt.links.new(b.outputs["Normal"], bsdf.inputs["Normal"])
    return mat, kind


def add_box(name, size, location, material):
    sx, sy, sz = (s / 2 for s in size)
    verts = [(x, y, z) for x in (-sx, sx) for y in (-sy, sy) for z in (-sz, sz)]
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts, [], faces)
    mesh.update()
    mesh.materials.append(material)
    o = bpy.data.objects.new(name, mesh)
    o.location = location
    bpy.context.scene.collection.objects.link(o)
    return o


def add_plane(name, size, matrix, material):
    sx, sy = size[0] / 2, size[1] / 2
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([(-sx, -sy, 0), (sx, -sy, 0), (sx, sy, 0), (-sx, sy, 0)], [], [(0, 1, 2, 3)])
    mesh.update()
    mesh.materials.append(material)
    o = bpy.data.objects.new(name, mesh)
    o.matrix_world = matrix
    bpy.context.scene.collection.objects.link(o)
    return o


def blackbody_rgb(kelvin):
    """Approximate linear RGB of a black body, normalised to max 1 (a fit to
    the CIE 1931 Planckian locus in sRGB primaries, 1500-15000 K)."""
    t = kelvin / 100.0
    r = 1.0 if t <= 66 else min(1.0, 1.292936186 * (t - 60) ** -0.1332047592)
    g = (0.390081579 * math.log(t) - 0.631841444) if t <= 66 else 1.129890861 * (t - 60) ** -0.0755148492
    b = 1.0 if t >= 66 else (0.0 if t <= 19 else 0.543206789 * math.log(t - 10) - 1.196254089)
    srgb = [max(0.0, min(1.0, c)) for c in (r, g, b)]
    lin = [srgb_to_linear(c) for c in srgb]
    m = max(lin)
    return tuple(c / m for c in lin)


def add_lights(rng, centre, room):
    """1-3 lights aimed at the table; powers set for a random share of the
    irradiance at the table centre (the auto exposure fixes the overall level)."""
    lights, colors = [], []
    for i in range(rng.randint(1, 3)):
        kind = rng.choice(["AREA", "AREA", "POINT", "SUN", "SPOT"])
        data = bpy.data.lights.new(f"light{i}", kind)
        if rng.random() < 0.8:
            color = blackbody_rgb(rng.uniform(3200.0, 7500.0))
        else:
            color = tuple(0.6 + 0.4 * c for c in hsv(rng.random(), 1.0, 1.0))
        data.color = color
        elev = math.radians(rng.uniform(50.0, 85.0) if (kind == "SUN" and room) else rng.uniform(25.0, 85.0))
        azim = rng.uniform(0.0, math.tau)
        dist = rng.uniform(0.9, 2.6)
        d = Vector((math.cos(elev) * math.cos(azim), math.cos(elev) * math.sin(azim), math.sin(elev)))
        pos = centre + d * dist
        share = rng.uniform(0.3, 1.0)  # irradiance (W/m^2, rough conventions) at the centre
        if kind == "AREA":
            data.shape = rng.choice(["SQUARE", "DISK", "RECTANGLE"])
            data.size = rng.uniform(0.2, 1.5)
            data.size_y = rng.uniform(0.2, 1.5)
            data.energy = share * math.pi * dist * dist * 4.0
        elif kind == "POINT":
            data.shadow_soft_size = rng.uniform(0.01, 0.3)
            data.energy = share * 4.0 * math.pi * dist * dist * 3.0
        elif kind == "SPOT":
            data.shadow_soft_size = rng.uniform(0.01, 0.2)
            data.spot_size = math.radians(rng.uniform(50.0, 110.0))
            data.spot_blend = rng.uniform(0.1, 0.6)
            data.energy = share * 4.0 * math.pi * dist * dist * 3.0
        else:
            data.angle = math.radians(rng.uniform(0.5, 12.0))
            data.energy = share * 3.0
        o = bpy.data.objects.new(f"light{i}", data)
        # Lights shine along their local -z: aim it at the centre.
        o.matrix_world = Matrix.Translation(pos) @ (-d).to_track_quat("-Z", "Y").to_matrix().to_4x4()
        bpy.context.scene.collection.objects.link(o)
        lights.append(o)
        colors.append((share, color))
    return lights, colors


def build_scene(rng, classes, meshes, scene_index, args, log):
    """Table, room or open background, lights and 5-7 objects resting on the table."""
    made = []
    table_size = (rng.uniform(1.0, 1.8), rng.uniform(0.7, 1.2), 0.03)
    table_mat, table_kind = procedural_material(rng, f"table{scene_index}")
    made.append(add_box("table", table_size, (0, 0, TABLE_TOP_Z - table_size[2] / 2), table_mat))
    leg_h = 0.72
    for sx in (-1, 1):
        for sy in (-1, 1):
            loc = (sx * (table_size[0] / 2 - 0.05), sy * (table_size[1] / 2 - 0.05), -table_size[2] - leg_h / 2)
            made.append(add_box("leg", (0.05, 0.05, leg_h), loc, table_mat))
    room = rng.random() < 0.6
    world = bpy.context.scene.world
    bg = world.node_tree.nodes["Background"]
    bg_color = random_color(rng, saturated=rng.random() < 0.2)
    bg.inputs["Color"].default_value = bg_color + (1.0,)
    bg.inputs["Strength"].default_value = rng.uniform(0.15, 0.8)
    floor_z = -table_size[2] - leg_h
    if room:
        floor_mat, _ = procedural_material(rng, f"floor{scene_index}")
        made.append(add_plane("floor", (12, 12), Matrix.Translation((0, 0, floor_z)), floor_mat))
        wall_mat, _ = procedural_material(rng, f"wall{scene_index}", bump=False)
        yaw = rng.uniform(0, math.tau)
        for k in range(4):
            if k == 3 and rng.random() < 0.5:
                continue  # sometimes an open side: world light comes in
            a = yaw + k * math.pi / 2
            dist = rng.uniform(2.0, 3.5)
            centre = Vector((math.cos(a) * dist, math.sin(a) * dist, floor_z + 1.5))
            rot = Matrix.Rotation(a, 4, "Z") @ Matrix.Rotation(math.pi / 2, 4, "Y")
            made.append(add_plane("wall", (3.0, 12), Matrix.Translation(centre) @ rot, wall_mat))
    lights, light_colors = add_lights(rng, Vector((0, 0, 0.1)), room)
    made += lights

    # Objects: distinct classes, mostly upright, rejection-sampled footprints.
    n = min(len(classes), rng.randint(args.min_objects, args.max_objects))
    chosen = rng.sample(range(len(classes)), n)
    # Drawn only with --pairs, so that splits rendered without it stay as they were.
    twin_of = rng.choice(chosen) if args.pairs > 0 and rng.random() < args.pairs else None
    paired = None
    radius = rng.uniform(0.06, 0.15)
    centre = (rng.uniform(-0.1, 0.1), rng.uniform(-0.08, 0.08))
    limit = (table_size[0] / 2 - 0.03, table_size[1] / 2 - 0.03)
    placed = []
    for ci in sorted(chosen, key=lambda c: -classes[c]["footprint_area"]):
        cls = classes[ci]
        rests = [r for r in cls["rests"] if r["plausible"]]
        if rng.random() < 0.72:
            rest = next(r for r in rests if r["upright"])
        else:
            others = [r for r in rests if not r["upright"]]
            rest = rng.choices(others, weights=[r["area"] for r in others])[0]
        ok = False
        for attempt in range(400):
            yaw = rng.uniform(0, math.tau)
            rot = Matrix.Rotation(yaw, 3, "Z") @ rest["rot"]
            pts = [rot @ Vector(p) for p in cls["obj"]["v"]]
            r = radius * (1.0 + attempt / 100.0)
            a, d = rng.uniform(0, math.tau), r * math.sqrt(rng.random())
            x, y = centre[0] + d * math.cos(a), centre[1] + d * math.sin(a)
            hull = convex_hull([(p.x + x, p.y + y) for p in pts])
            if any(abs(hx) > limit[0] or abs(hy) > limit[1] for hx, hy in hull):
                continue
            # Footprint circles first (cheap), then the exact convex footprints.
            cr = max(math.hypot(p.x, p.y) for p in pts)
            gap = 0.001 if rng.random() < 0.5 else rng.uniform(0.003, 0.025)
            clash = False
            for o in placed:
                if math.hypot(o["x"] - x, o["y"] - y) >= o["r"] + cr + gap:
                    continue
                if not hulls_apart(hull, o["hull"], gap):
                    clash = True
                    break
            if clash:
                continue
            z = TABLE_TOP_Z + REST_GAP - min(p.z for p in pts)
            placed.append({"class": ci, "rot": rot, "x": x, "y": y, "z": z, "r": cr, "hull": hull,
                           "upright": rest["upright"], "yaw": yaw, "rest": rest})
            ok = True
            break
        if not ok:
            log(f"scene {scene_index}: no room for {cls['name']}, left out")
        elif ci == twin_of:
            twin = place_twin(rng, cls, placed[-1], placed, limit)
            if twin is None:
                log(f"scene {scene_index}: no room for a second {cls['name']}, left out")
            else:
                placed.append(twin)
                paired = cls["name"]
    instances = []
    for k, p in enumerate(sorted(placed, key=lambda p: p["class"])):
        cls = classes[p["class"]]
        o = bpy.data.objects.new(cls["name"], meshes[p["class"]])
        o.matrix_world = Matrix.Translation((p["x"], p["y"], p["z"])) @ p["rot"].to_4x4()
        o.pass_index = k + 1
        bpy.context.scene.collection.objects.link(o)
        for slot in o.material_slots:
            bsdf = slot.material.node_tree.nodes["Principled BSDF"]
            bsdf.inputs["Roughness"].default_value = rng.uniform(0.2, 0.65)
            bsdf.inputs["Specular"].default_value = rng.uniform(0.3, 0.6)
        made.append(o)
        instances.append({"object": o, "class_id": cls["class_id"], "class": p["class"], "upright": p["upright"]})
    total = sum(s for s, _ in light_colors)
    mean_light = tuple(sum(s * c[i] for s, c in light_colors) / total for i in range(3))
    desc = {"table": table_kind, "room": room, "lights": [l.data.type for l in lights], "objects": len(instances),
            "lying": sum(not i["upright"] for i in instances),
            "pair": paired}
    return made, instances, mean_light, desc


# ---------------------------------------------------------------- camera


def setup_camera():
    """A Blender camera whose projection is fusepose's pinhole K (pixel centres
    at integer coordinates: Blender's continuous pixel coordinate is u + 0.5)."""
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = WIDTH, HEIGHT
    scene.render.resolution_percentage = 100
    # Blender needs pixel aspects >= 1; fy/fx = aspect_x/aspect_y.
    if FY >= FX:
        scene.render.pixel_aspect_x, scene.render.pixel_aspect_y = FY / FX, 1.0
    else:
        scene.render.pixel_aspect_x, scene.render.pixel_aspect_y = 1.0, FX / FY
    ycor = scene.render.pixel_aspect_y / scene.render.pixel_aspect_x
    data = bpy.data.cameras.new("camera")
    data.type = "PERSP"
    data.sensor_fit = "HORIZONTAL"
    data.sensor_width = 36.0
    data.lens = FX * data.sensor_width / WIDTH
    data.shift_x = (WIDTH / 2 - (CX + 0.5)) / WIDTH
    data.shift_y = (CY + 0.5 - HEIGHT / 2) * ycor / WIDTH
    data.clip_start, data.clip_end = 0.01, 100.0
    cam = bpy.data.objects.new("camera", data)
    scene.collection.objects.link(cam)
    scene.camera = cam
    return cam


def set_camera_pose(cam, world_from_cv):
    cam.matrix_world = world_from_cv @ CV_TO_BLENDER_CAM


def look_at(eye, target, roll):
    """World <- OpenCV camera transform: z towards the target, x right, y down, then `roll` about z."""
    z = (target - eye).normalized()
    x = z.cross(Vector((0, 0, 1)))
    if x.length < 1e-6:
        x = Vector((1, 0, 0))
    x.normalize()
    y = z.cross(x)
    r = Matrix((x, y, z)).transposed() @ Matrix.Rotation(roll, 3, "Z")
    m = r.to_4x4()
    m.translation = eye
    return m


def project(p_cam):
    if p_cam.z <= 1e-6:
        return None
    return FX * p_cam.x / p_cam.z + CX, FY * p_cam.y / p_cam.z + CY


def sample_view(rng, instances):
    """A camera 0.5-1.3 m from the objects on a hemisphere, some roll; at least
    two thirds of the object centres inside the image."""
    centres = [i["object"].matrix_world.translation for i in instances]
    mean = sum(centres, Vector()) / max(1, len(centres))
    best = None
    for _ in range(200):
        target = mean + Vector((rng.gauss(0, 0.03), rng.gauss(0, 0.03), rng.gauss(0, 0.02)))
        dist = rng.uniform(0.5, 1.3)
        elev = math.radians(rng.uniform(12.0, 65.0))
        azim = rng.uniform(0, math.tau)
        eye = target + dist * Vector((math.cos(elev) * math.cos(azim), math.cos(elev) * math.sin(azim), math.sin(elev)))
        roll = math.radians(max(-30.0, min(30.0, rng.gauss(0.0, 10.0))))
        world_from_cv = look_at(eye, target, roll)
        cv_from_world = world_from_cv.inverted()
        inside = 0
        for c in centres:
            uv = project(cv_from_world @ c)
            if uv and 20 <= uv[0] < WIDTH - 20 and 20 <= uv[1] < HEIGHT - 20:
                inside += 1
        if best is None or inside > best[0]:
            best = (inside, world_from_cv, dist)
        if inside * 3 >= 2 * len(centres) + 2 or inside == len(centres):
            break
    return best[1], best[2]


# ---------------------------------------------------------------- rendering


def configure_cycles(seed):
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    c = scene.cycles
    c.device = "CPU"
    c.seed = seed
    c.use_animated_seed = False
    c.caustics_reflective = False
    c.caustics_refractive = False
    scene.render.film_transparent = False
    vs = scene.view_settings
    vs.view_transform, vs.look, vs.exposure, vs.gamma = "Standard", "None", 0.0, 1.0
    scene.display_settings.display_device = "sRGB"


def beauty_settings(args):
    scene = bpy.context.scene
    c = scene.cycles
    c.samples = args.samples
    c.use_adaptive_sampling = True
    c.adaptive_threshold = args.noise_threshold
    c.adaptive_min_samples = min(args.samples, 12)
    c.use_denoising = False
    c.max_bounces, c.diffuse_bounces, c.glossy_bounces = 6, 3, 3
    c.transmission_bounces, c.transparent_max_bounces, c.volume_bounces = 2, 2, 0
    c.sample_clamp_direct, c.sample_clamp_indirect = 0.0, 4.0
    c.blur_glossy = 1.0
    c.pixel_filter_type, c.filter_width = "BLACKMAN_HARRIS", 1.5
    scene.use_nodes = False
    vl = scene.view_layers[0]
    vl.use_pass_z = vl.use_pass_object_index = False
    img = scene.render.image_settings
    img.file_format, img.color_mode, img.color_depth, img.exr_codec = "OPEN_EXR", "RGB", "32", "ZIP"


def geometry_settings(out_dir):
    """1 sample through each pixel centre: exact depth and object index."""
    scene = bpy.context.scene
    c = scene.cycles
    c.samples = 1
    c.use_adaptive_sampling = False
    c.use_denoising = False
    c.max_bounces = 0
    c.pixel_filter_type, c.filter_width = "BOX", 0.01
    vl = scene.view_layers[0]
    vl.use_pass_z = vl.use_pass_object_index = True
    scene.use_nodes = True
    nt = scene.node_tree
    nt.nodes.clear()
    rl = nt.nodes.new("CompositorNodeRLayers")
    comp = nt.nodes.new("CompositorNodeComposite")
    nt.links.new(rl.outputs["Image"], comp.inputs["Image"])
    fo = nt.nodes.new("CompositorNodeOutputFile")
    fo.base_path = out_dir
    fo.format.file_format, fo.format.color_mode, fo.format.color_depth = "OPEN_EXR", "RGB", "32"
    fo.format.exr_codec = "ZIP"
    fo.file_slots.clear()
    fo.file_slots.new("depth")
    fo.file_slots.new("index")
    nt.links.new(rl.outputs["Depth"], fo.inputs["depth"])
    nt.links.new(rl.outputs["IndexOB"], fo.inputs["index"])


def read_exr(path, channels):
    """Float pixels of an EXR as one array per wanted channel (0=R..), top row first."""
    img = bpy.data.images.load(path, check_existing=False)
    img.colorspace_settings.name = "Non-Color"
    w, h = img.size
    buf = array.array("f", bytes(4 * w * h * 4))
    img.pixels.foreach_get(buf)
    bpy.data.images.remove(img)
    out = []
    for ch in channels:
        plane = buf[ch::4]
        rows = [plane[r * w:(r + 1) * w] for r in range(h - 1, -1, -1)]  # Blender's row 0 is the bottom
        flat = array.array("f")
        for r in rows:
            flat.extend(r)
        out.append(flat)
    return w, h, out


def render_geometry(tmp):
    """Depth (camera z, metres) and object index per pixel centre."""
    for f in os.listdir(tmp):
        os.remove(os.path.join(tmp, f))
    bpy.ops.render.render(write_still=False)
    files = sorted(os.listdir(tmp))
    depth_file = next(f for f in files if f.startswith("depth"))
    index_file = next(f for f in files if f.startswith("index"))
    _, _, (depth,) = read_exr(os.path.join(tmp, depth_file), [0])
    _, _, (index,) = read_exr(os.path.join(tmp, index_file), [0])
    return depth, bytes(int(v) if 0 <= v < 256 else 0 for v in index)


def render_beauty(path):
    bpy.context.scene.render.filepath = path
    bpy.ops.render.render(write_still=True)
    _, _, planes = read_exr(path, [0, 1, 2])
    return planes


def encode_rgb(planes, wb, target, log_prefix=""):
    """White balance, auto exposure (mean luminance -> target, after clipping
    the brightest 1 %), sRGB 8-bit rows."""
    r, g, b = planes
    step = 7
    lum = sorted(0.2126 * r[i] * wb[0] + 0.7152 * g[i] * wb[1] + 0.0722 * b[i] * wb[2]
                 for i in range(0, len(r), step))
    cap = lum[int(0.99 * (len(lum) - 1))]
    mean = sum(min(v, cap) for v in lum) / len(lum)
    gain = target / max(mean, 1e-6)
    n = 4096
    lut = bytes(int(round(255 * (12.92 * x if x <= 0.0031308 else 1.055 * x ** (1 / 2.4) - 0.055)))
                for x in (i / n for i in range(n + 1)))
    scale = [gain * wb[c] * n for c in range(3)]
    out = bytearray(3 * len(r))
    for c, plane in enumerate(planes):
        s = scale[c]
        out[c::3] = bytes(lut[min(n, int(v * s + 0.5))] if v > 0 else 0 for v in plane)
    rows = [bytes(out[y * WIDTH * 3:(y + 1) * WIDTH * 3]) for y in range(HEIGHT)]
    return rows, gain


# ---------------------------------------------------------------- ground truth


def pose_m2c(obj, cv_from_world):
    m = cv_from_world @ obj.matrix_world
    # mathutils is single precision: 8 decimals hold all it has.
    rot = [round(m[i][j], 8) for i in range(3) for j in range(3)]
    t = [round(m[i][3] * 1000.0, 5) for i in range(3)]
    return rot, t


def bbox_of(mask_rows, width):
    """[x, y, w, h] of the 255-bytes in rows, or [-1]*4."""
    ys = [y for y, r in enumerate(mask_rows) if 255 in r]
    if not ys:
        return [-1, -1, -1, -1]
    x0 = min(r.find(255) for r in mask_rows if 255 in r)
    x1 = max(r.rfind(255) for r in mask_rows if 255 in r)
    return [x0, ys[0], x1 - x0 + 1, ys[-1] - ys[0] + 1]


def bbox_obj(verts, m):
    """Box of the projected mesh vertices (pixel centres covered), unclipped."""
    us, vs = [], []
    for p in verts:
        q = m @ Vector(p)
        uv = project(q)
        if uv is None:
            return [-1, -1, -1, -1]
        us.append(uv[0])
        vs.append(uv[1])
    x0, y0, x1, y1 = math.ceil(min(us)), math.ceil(min(vs)), math.floor(max(us)), math.floor(max(vs))
    if x1 < x0 or y1 < y0:
        return [-1, -1, -1, -1]
    return [x0, y0, x1 - x0 + 1, y1 - y0 + 1]


# ---------------------------------------------------------------- dataset


def models_info_bop(classes):
    out = {}
    for cls in classes:
        i = cls["info"]
        lo, hi = i["bbox_min"], i["bbox_max"]
        e = {"diameter": i["diameter"] * 1000.0, "min_x": lo[0] * 1000.0, "min_y": lo[1] * 1000.0,
             "min_z": lo[2] * 1000.0, "size_x": (hi[0] - lo[0]) * 1000.0, "size_y": (hi[1] - lo[1]) * 1000.0,
             "size_z": (hi[2] - lo[2]) * 1000.0}
        s = i.get("symmetry", {"kind": "none"})
        if s["kind"] == "discrete":
            e["symmetries_discrete"] = [
                [v * 1000.0 if k in (3, 7, 11) else v for k, v in enumerate(t)] for t in s["transforms"]]
        elif s["kind"] == "continuous":
            e["symmetries_continuous"] = [{"axis": s["axis"], "offset": [v * 1000.0 for v in s["origin"]]}]
        out[str(cls["class_id"])] = e
    return out


def prepare_dataset(args, classes):
    root = args.out
    split_dir = os.path.join(root, args.split)
    if os.path.isdir(split_dir) and os.listdir(split_dir) and not args.resume:
        raise SystemExit(f"{split_dir} is not empty: pass --resume to continue it, or choose another --out/--split")
    os.makedirs(split_dir, exist_ok=True)
    os.makedirs(os.path.join(root, "models"), exist_ok=True)
    manifest_path = os.path.join(root, "fusepose_dataset.json")
    class_list = [{"obj_id": c["class_id"], "name": c["name"]} for c in classes]
    manifest = {"format": "fusepose-bop", "version": 1, "objects": args.source, "classes": class_list, "splits": {}}
    if os.path.isfile(manifest_path):
        old = read_json(manifest_path)
        if old.get("classes") != class_list or old.get("objects") != args.source:
            raise SystemExit(f"{manifest_path} names another object set ({old.get('objects')}); use another --out")
        manifest["splits"] = old.get("splits", {})
    manifest["splits"][args.split] = {
        "generator": "tools/blender/render_bop_split.py (Blender Cycles, CPU)",
        "blender": bpy.app.version_string, "seed": args.seed, "scenes": args.scenes, "first_scene": args.first_scene,
        "views_per_scene": args.views, "objects_per_frame": [args.min_objects, args.max_objects],
        "samples": args.samples, "noise_threshold": args.noise_threshold, "pairs": args.pairs,
    }
    write_json(manifest_path, manifest)
    write_json(os.path.join(root, "models", "models_info.json"), models_info_bop(classes))
    write_json(os.path.join(root, "camera.json"), {"cx": CX, "cy": CY, "depth_scale": DEPTH_SCALE, "fx": FX,
                                                    "fy": FY, "height": HEIGHT, "width": WIDTH})
    return split_dir


def load_scene_json(scene_dir):
    def load(name):
        p = os.path.join(scene_dir, name)
        return read_json(p) if os.path.isfile(p) else {}

    return load("scene_camera.json"), load("scene_gt.json"), load("scene_gt_info.json")


def render_split(args):
    log = Log(args.log)
    classes = load_object_set(args.objects)
    split_dir = prepare_dataset(args, classes)
    clear_scene()
    scene = bpy.context.scene
    if scene.world is None:
        scene.world = bpy.data.worlds.new("world")
    scene.world.use_nodes = True
    cam = setup_camera()
    meshes = [build_mesh(c) for c in classes]
    for c in classes:
        c["rests"] = rest_poses(c["obj"]["v"])
        up = next(r for r in c["rests"] if r["upright"])
        c["footprint_area"] = up["area"]
    tmp = tempfile.mkdtemp(prefix="fusepose_blender_")
    log(f"Blender {bpy.app.version_string}: {len(classes)} classes from {args.objects}; "
        f"{args.scenes} scenes x {args.views} views, seed {args.seed}, {args.samples} samples -> {split_dir}")
    t_all, cpu_all = time.time(), time.process_time()
    done = 0
    try:
        for scene_id in range(args.first_scene, args.first_scene + args.scenes):
            scene_dir = os.path.join(split_dir, f"{scene_id:06d}")
            for sub in ("rgb", "depth", "mask_visib"):
                os.makedirs(os.path.join(scene_dir, sub), exist_ok=True)
            cams, gts, infos = load_scene_json(scene_dir)
            if args.resume and all(str(v) in gts for v in range(args.views)):
                continue
            rng = random.Random(f"{args.seed}/scene/{scene_id}")
            made, instances, mean_light, desc = build_scene(rng, classes, meshes, scene_id, args, log)
            wb = tuple(mean_light[1] / max(c, 1e-3) for c in mean_light)
            for view in range(args.views):
                if args.resume and str(view) in gts:
                    continue
                t0, cpu0 = time.time(), time.process_time()
                vrng = random.Random(f"{args.seed}/view/{scene_id}/{view}")
                world_from_cv, dist = sample_view(vrng, instances)
                set_camera_pose(cam, world_from_cv)
                cv_from_world = world_from_cv.inverted()
                configure_cycles(vrng.randrange(1 << 30))
                beauty_settings(args)
                exr = os.path.join(tmp, "beauty.exr")
                planes = render_beauty(exr)
                if args.keep_exr:
                    shutil.copy(exr, os.path.join(scene_dir, "rgb", f"{view:06d}.exr"))
                t1 = time.time()
                geometry_settings(tmp)
                depth, index = render_geometry(tmp)
                # Each object alone: its full in-image silhouette for visib_fract.
                others = [o for o in made]
                alone = []
                for inst in instances:
                    for o in others:
                        o.hide_render = o is not inst["object"]
                    _, alone_index = render_geometry(tmp)
                    alone.append(alone_index.count(inst["object"].pass_index))
                for o in others:
                    o.hide_render = False
                t2 = time.time()
                rows, gain = encode_rgb(planes, wb, vrng.uniform(0.14, 0.26))
                write_png(os.path.join(scene_dir, "rgb", f"{view:06d}.png"), WIDTH, HEIGHT, rows, 3, 8)
                dvals = array.array("H", (int(z * DEPTH_UNITS_PER_M + 0.5) if 0.0 < z < 6.5 else 0 for z in depth))
                dvals.byteswap()
                draw = dvals.tobytes()
                write_png(os.path.join(scene_dir, "depth", f"{view:06d}.png"), WIDTH, HEIGHT,
                          [draw[y * WIDTH * 2:(y + 1) * WIDTH * 2] for y in range(HEIGHT)], 1, 16)
                gt_list, info_list, k = [], [], 0
                for inst, all_px in zip(instances, alone):
                    label = inst["object"].pass_index
                    table = bytes(255 if i == label else 0 for i in range(256))
                    mask = index.translate(table)
                    visib = mask.count(255)
                    if visib == 0:
                        continue  # out of view or hidden: not part of this frame's ground truth
                    mask_rows = [mask[y * WIDTH:(y + 1) * WIDTH] for y in range(HEIGHT)]
                    valid = sum(1 for i, m in enumerate(mask) if m and 0.0 < depth[i] < 6.5)
                    write_png(os.path.join(scene_dir, "mask_visib", f"{view:06d}_{k:06d}.png"), WIDTH, HEIGHT,
                              mask_rows, 1, 8)
                    rot, t = pose_m2c(inst["object"], cv_from_world)
                    gt_list.append({"cam_R_m2c": rot, "cam_t_m2c": t, "obj_id": inst["class_id"]})
                    all_px = max(all_px, visib)
                    m = cv_from_world @ inst["object"].matrix_world
                    info_list.append({"bbox_obj": bbox_obj(classes[inst["class"]]["obj"]["v"], m),
                                      "bbox_visib": bbox_of(mask_rows, WIDTH), "px_count_all": all_px,
                                      "px_count_valid": valid, "px_count_visib": visib,
                                      "visib_fract": visib / all_px})
                    k += 1
                cams[str(view)] = {"cam_K": [FX, 0.0, CX, 0.0, FY, CY, 0.0, 0.0, 1.0], "depth_scale": DEPTH_SCALE}
                gts[str(view)] = gt_list
                infos[str(view)] = info_list
                order = lambda d: {str(key): d[str(key)] for key in sorted(int(x) for x in d)}
                write_json(os.path.join(scene_dir, "scene_camera.json"), order(cams))
                write_json(os.path.join(scene_dir, "scene_gt_info.json"), order(infos))
                write_json(os.path.join(scene_dir, "scene_gt.json"), order(gts))
                t3 = time.time()
                done += 1
                vis = ", ".join(f"{i['visib_fract']:.2f}" for i in info_list)
                log(f"scene {scene_id} view {view}: {len(gt_list)} objects (visible {vis}), camera {dist:.2f} m, "
                    f"{desc}, gain {gain:.2f}; beauty {t1 - t0:.1f} s, masks/depth {t2 - t1:.1f} s, "
                    f"write {t3 - t2:.1f} s, total {t3 - t0:.1f} s (CPU {time.process_time() - cpu0:.1f} s)")
            for o in made:
                if o.type == "LIGHT":
                    data = o.data
                    bpy.data.objects.remove(o, do_unlink=True)
                    bpy.data.lights.remove(data)
                elif o.data is not None and o.data not in meshes:
                    data = o.data
                    bpy.data.objects.remove(o, do_unlink=True)
                    bpy.data.meshes.remove(data)
                else:
                    bpy.data.objects.remove(o, do_unlink=True)
            for m in list(bpy.data.materials):
                if m.users == 0:
                    bpy.data.materials.remove(m)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    elapsed = time.time() - t_all
    cpu = time.process_time() - cpu_all
    log(f"done: {done} frames in {elapsed:.0f} s ({elapsed / max(done, 1):.1f} s per frame; "
        f"CPU {cpu / max(done, 1):.1f} s per frame)")


# ---------------------------------------------------------------- self-test


def self_test():
    """Renders known geometry and measures: the projection against K (pixel
    centroids of small spheres), the depth convention (planar z vs ray length)
    and the depth and mask at a posed object."""
    clear_scene()
    scene = bpy.context.scene
    if scene.world is None:
        scene.world = bpy.data.worlds.new("world")
    cam = setup_camera()
    set_camera_pose(cam, Matrix.Identity(4))  # world frame = OpenCV camera frame
    configure_cycles(1)
    tmp = tempfile.mkdtemp(prefix="fusepose_selftest_")
    geometry_settings(tmp)
    white = bpy.data.materials.new("white")
    # 1. Sphere centroids vs K.
    r = 0.006
    points = []
    for u in (30.0, 160.0, 312.0, 470.0, 610.0):
        for v in (25.0, 130.0, 241.0, 350.0, 455.0):
            z = 0.7 + 0.3 * ((u + v) % 3)
            points.append(Vector(((u - CX) * z / FX, (v - CY) * z / FY, z)))
    for i, p in enumerate(points):
        mesh = bpy.data.meshes.new(f"s{i}")
        import bmesh

        bm = bmesh.new()
        bmesh.ops.create_uvsphere(bm, u_segments=48, v_segments=24, radius=r)
        bm.to_mesh(mesh)
        bm.free()
        mesh.materials.append(white)
        o = bpy.data.objects.new(f"s{i}", mesh)
        o.location = p
        o.pass_index = i + 1
        scene.collection.objects.link(o)
    # A plane at z = 1.5 behind everything, perpendicular to the optical axis.
    plane = add_plane("plane", (4.0, 4.0), Matrix.Translation((0, 0, 1.5)), white)
    depth, index = render_geometry(tmp)
    errs, rows = [], []
    for i, p in enumerate(points):
        sx = sy = n = 0
        for k, lab in enumerate(index):
            if lab == i + 1:
                sx += k % WIDTH
                sy += k // WIDTH
                n += 1
        cu, cv = sx / n, sy / n
        eu, ev = project(p)
        errs.append((cu - eu, cv - ev))
        rows.append((eu, ev, cu, cv, n, p))
    # Least-squares fit of fx, cx (u = fx * x/z + cx) and fy, cy from the centroids.
    def fit(xs, ys):
        n = len(xs)
        mx, my = sum(xs) / n, sum(ys) / n
        sxx = sum((x - mx) ** 2 for x in xs)
        a = sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sxx
        return a, my - a * mx

    fx, cx = fit([p.x / p.z for *_, p in rows], [c[2] for c in rows])
    fy, cy = fit([p.y / p.z for *_, p in rows], [c[3] for c in rows])
    print(f"SELFTEST projection: {len(points)} spheres (r {r * 1000:.0f} mm, 0.7-1.3 m), centroid - K projection: "
          f"max |du| {max(abs(e[0]) for e in errs):.3f} px, max |dv| {max(abs(e[1]) for e in errs):.3f} px, "
          f"mean du {sum(e[0] for e in errs) / len(errs):+.3f}, mean dv {sum(e[1] for e in errs) / len(errs):+.3f}")
    print(f"SELFTEST fitted K: fx {fx:.3f} (want {FX}), fy {fy:.3f} (want {FY}), "
          f"cx {cx:.3f} (want {CX}), cy {cy:.3f} (want {CY})")
    # 2. Depth convention on the plane: corners vs centre.
    def at(u, v):
        return depth[v * WIDTH + u]

    for u, v in ((0, 0), (639, 479), (320, 5), (5, 240)):
        ray = math.sqrt(1 + ((u - CX) / FX) ** 2 + ((v - CY) / FY) ** 2)
        print(f"SELFTEST depth pass at plane z=1.5 m, pixel ({u},{v}): {at(u, v):.6f} m "
              f"(planar z 1.500000, ray length {1.5 * ray:.6f})")
    # 3. Sphere front: depth at the pixel nearest the centre vs the surface along that pixel's ray.
    worst = 0.0
    for (eu, ev, cu, cv, n, p) in rows:
        u, v = int(round(eu)), int(round(ev))
        d = Vector(((u - CX) / FX, (v - CY) / FY, 1.0))
        # Ray-sphere: smallest t with |t d - p| = r, planar z = t (d.z = 1).
        a, b, c = d.dot(d), -2 * d.dot(p), p.dot(p) - r * r
        t = (-b - math.sqrt(b * b - 4 * a * c)) / (2 * a)
        worst = max(worst, abs(at(u, v) - t))
    print(f"SELFTEST depth at sphere pixels vs ray-sphere planar z: max error {worst * 1000:.4f} mm")
    # 4. A posed box: pose through the same path as the dataset writer, depth at its centre pixel.
    for o in list(scene.objects):
        if o.name.startswith("s"):
            o.hide_render = True
    plane.hide_render = True
    box = add_box("box", (0.1, 0.06, 0.2), (0, 0, 0), white)
    box.pass_index = 99
    world_from_cv = look_at(Vector((0.5, -0.6, 0.45)), Vector((0.0, 0.0, 0.0)), math.radians(12.0))
    set_camera_pose(cam, world_from_cv)
    box.matrix_world = Matrix.Rotation(0.4, 4, "Z") @ Matrix.Rotation(0.3, 4, "X")
    depth, index = render_geometry(tmp)
    rot, t = pose_m2c(box, world_from_cv.inverted())
    m = world_from_cv.inverted() @ box.matrix_world
    # The box face nearest the camera along the centre ray: intersect the ray through the projected centre.
    u0, v0 = project(Vector(t) / 1000.0)
    u, v = int(round(u0)), int(round(v0))
    d = Vector(((u - CX) / FX, (v - CY) / FY, 1.0))
    inv = m.inverted()
    o_obj, d_obj = inv @ Vector((0, 0, 0)), inv.to_3x3() @ d
    tmin, tmax = -1e9, 1e9
    for k, half in enumerate((0.05, 0.03, 0.1)):
        t1, t2 = (-half - o_obj[k]) / d_obj[k], (half - o_obj[k]) / d_obj[k]
        tmin, tmax = max(tmin, min(t1, t2)), min(tmax, max(t1, t2))
    print(f"SELFTEST posed box: t_m2c {', '.join(f'{x:.1f}' for x in t)} mm, centre pixel ({u},{v}) label "
          f"{index[v * WIDTH + u]}, depth {at(u, v) * 1000:.3f} mm, ray-box planar z {tmin * 1000:.3f} mm, "
          f"mask {index.count(99)} px")
    shutil.rmtree(tmp, ignore_errors=True)


def main():
    args = parse_args(script_argv())
    if args.self_test:
        self_test()
    else:
        render_split(args)


if __name__ == "__main__":
    main()
