#!/usr/bin/env python3
"""lod_normal_error.py: per-pixel error of a render's shading normals on a sphere (docs/lod.md).

    PYTHONPATH=build/python python3 tools/bench/lod_normal_error.py OUT.exr CAM.json \
        [--sphere cx,cy,cz,r] [--crop x,y,w,h]

OUT.exr: a perspective vox-render frame with `--layers normal --float` of a sphere (default: the
unit sphere at the origin, world units); CAM.json: its camera. For every pixel whose ray meets the
sphere and whose frame has coverage and a normal, the angle between the frame's N layer and the
sphere's exact normal where the pixel's centre ray meets it; prints mean, median, p95 and max in
degrees, and mean and standard deviation inside the crop (the moire's strength). Needs numpy and
the vox Python module (vox.read_exr).
"""
import argparse
import json
import math
import sys

import numpy as np
import vox


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("exr")
    ap.add_argument("cam")
    ap.add_argument("--sphere", default="0,0,0,1")
    ap.add_argument("--crop", default=None)
    a = ap.parse_args()
    img = vox.read_exr(a.exr)
    ch, w, h = img["channels"], img["width"], img["height"]
    if not all(k in ch for k in ("N.X", "N.Y", "N.Z", "A")):
        sys.exit(f"{a.exr}: needs channels A and N.X, N.Y, N.Z (vox-render --layers normal --float)")
    cam = json.load(open(a.cam))
    if cam.get("projection", "perspective") != "perspective":
        sys.exit(f"{a.cam}: only perspective cameras")
    cx, cy, cz, r = (float(v) for v in a.sphere.split(","))
    centre = np.array([cx, cy, cz])
    pos = np.array(cam["position"], float)
    f = np.array(cam["look_at"], float) - pos
    f /= np.linalg.norm(f)
    up = np.array(cam.get("up", [0, 1, 0]), float)
    right = np.cross(f, up / np.linalg.norm(up))
    right /= np.linalg.norm(right)
    true_up = np.cross(right, f)
    sx = math.tan(math.radians(cam["fov_deg"]) / 2)  # as render/camera.cpp
    sy = sx * h / w
    ys, xs = np.mgrid[0:h, 0:w]
    u = (2 * (xs + 0.5) / w - 1) * sx
    v = (1 - 2 * (ys + 0.5) / h) * sy
    d = f + u[..., None] * right + v[..., None] * true_up
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    oc = pos - centre
    b = d @ oc
    disc = b * b - (oc @ oc - r * r)
    t = -b - np.sqrt(np.maximum(disc, 0))
    exact = (pos + t[..., None] * d - centre) / r
    n = np.stack([np.asarray(ch[k]).reshape(h, w) for k in ("N.X", "N.Y", "N.Z")], -1)
    alpha = np.asarray(ch["A"]).reshape(h, w)
    mask = (disc > 0) & (alpha > 0) & (np.linalg.norm(n, axis=-1) > 0.5)
    ang = np.degrees(np.arccos(np.clip((n * exact).sum(-1), -1, 1)))
    sel = ang[mask]
    print(f"pixels {sel.size}: normal error mean {sel.mean():.3f} median {np.median(sel):.3f} "
          f"p95 {np.percentile(sel, 95):.3f} max {sel.max():.3f} deg")
    if a.crop:
        x0, y0, cw, chh = (int(k) for k in a.crop.split(","))
        c = ang[y0:y0 + chh, x0:x0 + cw][mask[y0:y0 + chh, x0:x0 + cw]]
        print(f"crop {a.crop}: mean {c.mean():.3f} std {c.std():.3f} deg over {c.size} pixels")


if __name__ == "__main__":
    main()
