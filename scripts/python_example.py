#!/usr/bin/env python3
"""vox from Python, end to end: make a level set with OpenVDB's vdb_tool,
ingest it, render it with the demo's camera and scene, show the picture and
its depth with matplotlib, and probe a few rays.

    scripts/build.sh && scripts/python_example.py [--out out/python] [--show]

Imports vox from build/python unless it is already importable (after
`cmake --install build --prefix P`, put P/lib/python3.X/site-packages on
PYTHONPATH). Writes OUT/example.png; --show also opens a window.
"""
import argparse
import json
import os
import shutil
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "python"))
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--show", action="store_true", help="open a matplotlib window")
    args = ap.parse_args()
    sys.path.insert(0, os.path.join(args.build, "python"))
    import numpy as np
    import vox
    import matplotlib
    if not args.show:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    os.makedirs(args.out, exist_ok=True)
    vdb = os.path.join(args.out, "shapes.vdb")
    if not os.path.exists(vdb):
        if not shutil.which("vdb_tool"):
            sys.exit("python_example: needs vdb_tool (Debian: libopenvdb-tools)")
        subprocess.run(["vdb_tool", "-platonic", "f=12", "s=0.45", "c=-0.45,0.0,0.0", "v=0.004",
                        "w=3", "-sphere", "r=0.3", "c=0.45,-0.1,0.1", "v=0.004", "w=3",
                        "-union", "-write", vdb], check=True, stdout=subprocess.DEVNULL)

    # Ingest: vox-ingest's flags as keyword arguments, progress as a callback.
    store = os.path.join(args.out, "shapes.store")
    def progress(done, total, voxels):
        print("\ringest: %d/%d bricks, %d voxels" % (done, total, voxels), end="", flush=True)
    stats = vox.ingest(vdb, store, progress=progress, force=True, threads=2)
    print("\ningest: %d occupied voxels in %d bricks, %.2f s"
          % (stats["occupied_voxels"], stats["bricks"], stats["seconds"]["total"]))
    info = vox.Store(store).info  # what vox-info prints, as a dict
    print("store: levels %d, %d voxels, %d bytes on disk"
          % (info["levels"], info["voxels"], info["index_file_bytes"] + info["brick_file_bytes"]))

    # Render: camera and scene as dicts (or paths to cam.json / scene.json).
    with open(os.path.join(ROOT, "scripts", "demo", "cam.json")) as f:
        camera = json.load(f)
    camera.update(width=640, height=480)
    with open(os.path.join(ROOT, "scripts", "demo", "scene.json")) as f:
        scene = json.load(f)
    image = vox.render(store, camera, scene, layers="normal", threads=2, memory_mb=512)
    rgba, z = image["rgba"], image["z"]
    print("render: %dx%d, %d rays in %.2f s" % (rgba.shape[1], rgba.shape[0],
          image["stats"]["rays"]["total"], image["stats"]["timings"]["render_seconds"]))

    # Probe: the first voxel hit by rays in index space (ox oy oz dx dy dz).
    lo, hi = np.array(info["bbox_min"]), np.array(info["bbox_max"])
    centre = (lo + hi) / 2
    rays = np.array([[*(centre + [0, 0, 2 * (hi - lo)[2]]), 0, 0, -1],
                     [*(centre + [0, 2 * (hi - lo)[1], 0]), 0, -1, 0]], dtype=np.float64)
    voxels, t, hit = vox.probe(store, rays)
    for v, tt, h in zip(voxels, t, hit):
        print("probe:", "hit voxel %s at t=%.3f" % (tuple(v), tt) if h else "miss")

    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    srgb = np.where(rgba[..., :3] <= 0.0031308, 12.92 * rgba[..., :3],
                    1.055 * np.clip(rgba[..., :3], 0, None) ** (1 / 2.4) - 0.055)
    ax[0].imshow(np.clip(srgb, 0, 1))
    ax[0].set_title("vox.render: RGB (premultiplied, over black)")
    depth = np.where(np.isfinite(z), z, np.nan)
    im = ax[1].imshow(depth, cmap="viridis")
    ax[1].set_title("Z (planar camera depth)")
    fig.colorbar(im, ax=ax[1])
    for a in ax:
        a.axis("off")
    png = os.path.join(args.out, "example.png")
    fig.savefig(png, dpi=100, bbox_inches="tight")
    print("python_example: wrote", png)
    if args.show:
        plt.show()


if __name__ == "__main__":
    main()
