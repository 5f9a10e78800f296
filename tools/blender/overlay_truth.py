"""Draws the ground-truth poses of a BOP split onto its RGB frames, with nothing
but the files `fusepose eval` reads: scene_camera.json (cam_K), scene_gt.json
(cam_R_m2c, cam_t_m2c) and the exported meshes. Each object's model is
projected with its pose and K (pixel centres at integer coordinates) and its
silhouette outline drawn in a class colour, with its axes (x red, y green, z
blue, 4 cm). If the ground truth lines up, every outline hugs its object.

Plain Python 3 (no packages), independent of Blender and of fusepose:

    python3 tools/blender/overlay_truth.py --dataset scratch/pathtraced/test \
        --objects scratch/objects --frames 0/0,3/1 --out docs/pathtraced_overlay.png

Frames are SCENE/IMAGE pairs; they are placed side by side, two per row.
"""

import argparse
import json
import math
import os
import struct
import zlib

COLORS = [(255, 64, 64), (64, 255, 64), (80, 160, 255), (255, 255, 0), (255, 0, 255), (0, 255, 255),
          (255, 160, 0), (255, 255, 255)]


def read_png(path):
    """(width, height, bytes per sample, channels, rows of raw samples) of a non-interlaced PNG."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise SystemExit(f"{path}: not a PNG")
    pos, idat = 8, b""
    while pos < len(data):
        (n,) = struct.unpack(">I", data[pos:pos + 4])
        tag, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + n]
        if tag == b"IHDR":
            w, h, depth, ctype, _, _, interlace = struct.unpack(">IIBBBBB", body)
        elif tag == b"IDAT":
            idat += body
        pos += n + 12
    if depth not in (8, 16) or ctype not in (0, 2, 6) or interlace:
        raise SystemExit(f"{path}: only 8/16-bit grey/RGB/RGBA non-interlaced PNGs are read")
    channels = {0: 1, 2: 3, 6: 4}[ctype]
    bpp = channels * depth // 8
    raw, stride = zlib.decompress(idat), w * bpp
    rows, prev = [], bytearray(stride)
    for y in range(h):
        ft, line = raw[y * (stride + 1)], bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - bpp] if i >= bpp else 0
            b, c = prev[i], prev[i - bpp] if i >= bpp else 0
            if ft == 1:
                line[i] = (line[i] + a) & 255
            elif ft == 2:
                line[i] = (line[i] + b) & 255
            elif ft == 3:
                line[i] = (line[i] + (a + b) // 2) & 255
            elif ft == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append(line)
        prev = line
    return w, h, depth // 8, channels, rows


def read_png_rgb(path):
    w, h, size, bpp, rows = read_png(path)
    if size != 1:
        raise SystemExit(f"{path}: expected an 8-bit image")
    img = bytearray()
    for line in rows:
        for x in range(w):
            px = line[x * bpp:(x + 1) * bpp]
            img += bytes(px[:3]) if bpp >= 3 else bytes([px[0]] * 3)
    return w, h, img


def write_png_rgb(path, w, h, img):
    """RGB8 PNG; each row takes the filter (none/sub/up/Paeth) with the
    smallest sum of absolute residuals, which keeps photos compact."""
    stride, prev, rows = w * 3, bytes(w * 3), []
    for y in range(h):
        line = bytes(img[y * stride:(y + 1) * stride])
        left = bytes(3) + line[:-3]
        upleft = bytes(3) + prev[:-3]
        sub = bytes((x - a) & 255 for x, a in zip(line, left))
        up = bytes((x - b) & 255 for x, b in zip(line, prev))

        def paeth(a, b, c):
            p = a + b - c
            pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
            return a if pa <= pb and pa <= pc else b if pb <= pc else c

        pae = bytes((x - paeth(a, b, c)) & 255 for x, a, b, c in zip(line, left, prev, upleft))
        cost = lambda r: sum(v if v < 128 else 256 - v for v in r)
        ft, best = min(enumerate((line, sub, up, None, pae)), key=lambda f: cost(f[1]) if f[1] is not None else 1e18)
        rows.append(bytes([ft]) + best)
        prev = line

    def chunk(tag, body):
        return struct.pack(">I", len(body)) + tag + body + struct.pack(">I", zlib.crc32(tag + body) & 0xFFFFFFFF)

    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
                + chunk(b"IDAT", zlib.compress(b"".join(rows), 9)) + chunk(b"IEND", b""))


def read_mesh(path):
    v, tris = [], []
    with open(path) as f:
        for line in f:
            p = line.split()
            if not p:
                continue
            if p[0] == "v":
                v.append(tuple(float(x) for x in p[1:4]))
            elif p[0] == "f":
                ids = [int(c.split("/")[0]) for c in p[1:]]
                ids = [i - 1 if i > 0 else len(v) + i for i in ids]
                tris += [(ids[0], ids[k], ids[k + 1]) for k in range(1, len(ids) - 1)]
    return v, tris


def silhouette(verts, tris, rot, t, k, w, h):
    """Pixel centres covered by the projected triangles, and the nearest
    camera-frame z there (a z-buffer; 0 where uncovered)."""
    fx, cx, fy, cy = k[0], k[2], k[4], k[5]
    proj = []
    for p in verts:
        q = [sum(rot[3 * i + j] * p[j] for j in range(3)) + t[i] for i in range(3)]
        proj.append((fx * q[0] / q[2] + cx, fy * q[1] / q[2] + cy, 1.0 / q[2]) if q[2] > 1e-6 else None)
    mask = bytearray(w * h)
    zbuf = [0.0] * (w * h)
    for a, b, c in tris:
        pa, pb, pc = proj[a], proj[b], proj[c]
        if pa is None or pb is None or pc is None:
            continue
        area = (pb[0] - pa[0]) * (pc[1] - pa[1]) - (pb[1] - pa[1]) * (pc[0] - pa[0])
        if area == 0:
            continue
        x0, x1 = max(0, math.ceil(min(pa[0], pb[0], pc[0]))), min(w - 1, math.floor(max(pa[0], pb[0], pc[0])))
        y0, y1 = max(0, math.ceil(min(pa[1], pb[1], pc[1]))), min(h - 1, math.floor(max(pa[1], pb[1], pc[1])))
        for y in range(y0, y1 + 1):
            for x in range(x0, x1 + 1):
                w0 = ((pb[0] - x) * (pc[1] - y) - (pb[1] - y) * (pc[0] - x)) / area
                w1 = ((pc[0] - x) * (pa[1] - y) - (pc[1] - y) * (pa[0] - x)) / area
                w2 = 1.0 - w0 - w1
                if w0 >= 0 and w1 >= 0 and w2 >= 0:
                    # 1/z is linear in the image plane.
                    z = 1.0 / (w0 * pa[2] + w1 * pb[2] + w2 * pc[2])
                    i = y * w + x
                    if not mask[i] or z < zbuf[i]:
                        mask[i], zbuf[i] = 1, z
    return mask, zbuf


def depth_residuals(split, scene_id, im_id, meshes):
    """Per GT instance: observed depth minus the z-buffer of its posed model,
    in mm, over the pixels of its visible mask."""
    scene = os.path.join(split, f"{scene_id:06d}")
    cam = json.load(open(os.path.join(scene, "scene_camera.json")))[str(im_id)]
    gts = json.load(open(os.path.join(scene, "scene_gt.json")))[str(im_id)]
    w, h, size, _, rows = read_png(os.path.join(scene, "depth", f"{im_id:06d}.png"))
    depth = [struct.unpack(f">{w}H", bytes(r)) for r in rows]
    out = []
    for n, gt in enumerate(gts):
        verts, tris = meshes[gt["obj_id"]]
        rot, t = gt["cam_R_m2c"], [x / 1000.0 for x in gt["cam_t_m2c"]]
        model, zbuf = silhouette(verts, tris, rot, t, cam["cam_K"], w, h)
        _, _, _, _, mrows = read_png(os.path.join(scene, "mask_visib", f"{im_id:06d}_{n:06d}.png"))
        res, outside = [], 0
        for y in range(h):
            for x in range(w):
                if mrows[y][x] and depth[y][x]:
                    if model[y * w + x]:
                        res.append(depth[y][x] * cam["depth_scale"] - zbuf[y * w + x] * 1000.0)
                    else:
                        outside += 1
        out.append((gt["obj_id"], res, outside))
    return out


def draw_line(img, w, h, p, q, color):
    n = int(max(abs(q[0] - p[0]), abs(q[1] - p[1]))) + 1
    for s in range(n + 1):
        x = round(p[0] + (q[0] - p[0]) * s / n)
        y = round(p[1] + (q[1] - p[1]) * s / n)
        for dx, dy in ((0, 0), (1, 0), (0, 1)):
            if 0 <= x + dx < w and 0 <= y + dy < h:
                i = ((y + dy) * w + x + dx) * 3
                img[i:i + 3] = bytes(color)


def overlay(split, objects, scene_id, im_id, meshes):
    scene = os.path.join(split, f"{scene_id:06d}")
    cam = json.load(open(os.path.join(scene, "scene_camera.json")))[str(im_id)]
    gts = json.load(open(os.path.join(scene, "scene_gt.json")))[str(im_id)]
    w, h, img = read_png_rgb(os.path.join(scene, "rgb", f"{im_id:06d}.png"))
    k = cam["cam_K"]
    for gt in gts:
        verts, tris = meshes[gt["obj_id"]]
        rot, t = gt["cam_R_m2c"], [x / 1000.0 for x in gt["cam_t_m2c"]]
        mask, _ = silhouette(verts, tris, rot, t, k, w, h)
        color = COLORS[(gt["obj_id"] - 1) % len(COLORS)]
        for y in range(h):
            for x in range(w):
                if mask[y * w + x] and (x == 0 or y == 0 or x == w - 1 or y == h - 1 or not mask[y * w + x - 1]
                                        or not mask[y * w + x + 1] or not mask[(y - 1) * w + x]
                                        or not mask[(y + 1) * w + x]):
                    i = (y * w + x) * 3
                    img[i:i + 3] = bytes(color)

        def px(p):
            q = [sum(rot[3 * i + j] * p[j] for j in range(3)) + t[i] for i in range(3)]
            return (k[0] * q[0] / q[2] + k[2], k[4] * q[1] / q[2] + k[5])

        o = px((0, 0, 0))
        for axis, color in ((0, (255, 0, 0)), (1, (0, 220, 0)), (2, (0, 0, 255))):
            end = [0.0, 0.0, 0.0]
            end[axis] = 0.04
            draw_line(img, w, h, o, px(end), color)
    return w, h, img


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dataset", required=True, help="the split folder (holding NNNNNN/ scenes)")
    ap.add_argument("--objects", required=True, help="the folder `fusepose objects export` wrote")
    ap.add_argument("--frames", default="0/0", help="comma list of SCENE/IMAGE")
    ap.add_argument("--out", help="write the overlay PNG here")
    ap.add_argument("--depth-check", action="store_true",
                    help="print observed depth minus the posed model's z-buffer over each visible mask")
    args = ap.parse_args()
    info = json.load(open(os.path.join(args.objects, "models_info.json")))
    meshes = {o["class_id"]: read_mesh(os.path.join(args.objects, o["mesh"])) for o in info["objects"]}
    frames = [tuple(int(x) for x in item.split("/")) for item in args.frames.split(",")]
    if args.depth_check:
        names = {o["class_id"]: o["name"] for o in info["objects"]}
        every = []
        for s, i in frames:
            for obj_id, res, outside in depth_residuals(args.dataset, s, i, meshes):
                every += res
                r = sorted(abs(v) for v in res) or [float("nan")]
                print(f"scene {s} image {i} {names[obj_id]:16s} {len(res):6d} px: |depth - model z| median "
                      f"{r[len(r) // 2]:.3f} mm, p95 {r[int(0.95 * (len(r) - 1))]:.3f} mm; "
                      f"{outside} mask px outside the model's silhouette")
        r = sorted(abs(v) for v in every)
        print(f"all {len(r)} px: median {r[len(r) // 2]:.3f} mm, p95 {r[int(0.95 * (len(r) - 1))]:.3f} mm, "
              f"p99 {r[int(0.99 * (len(r) - 1))]:.3f} mm, mean signed {sum(every) / len(every):+.4f} mm")
    if not args.out:
        return
    tiles = [overlay(args.dataset, args.objects, s, i, meshes) for s, i in frames]
    w, h = tiles[0][0], tiles[0][1]
    cols = min(2, len(tiles))
    nrows = (len(tiles) + cols - 1) // cols
    out = bytearray(w * cols * h * nrows * 3)
    for n, (_, _, img) in enumerate(tiles):
        ox, oy = (n % cols) * w, (n // cols) * h
        for y in range(h):
            d = ((oy + y) * w * cols + ox) * 3
            out[d:d + w * 3] = img[y * w * 3:(y + 1) * w * 3]
    write_png_rgb(args.out, w * cols, h * nrows, out)
    print(f"wrote {args.out}: {len(tiles)} frames")


if __name__ == "__main__":
    main()
