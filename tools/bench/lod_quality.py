#!/usr/bin/env python3
"""Level of detail: what the default costs and how close it is to the truth.

    python3 tools/bench/lod_quality.py STORE [STORE ...] [--build build] [--size 512]
        [--runs 3] [--threads 2] [--work DIR] [--view full|close]

For each store (a vox-gen sphere or bumpy store with its pyramid) renders the
full view (camera at (0,0,3) looking at the origin, 40 degrees; --view close:
at (0,0,1.05) looking at (0,0,0.9), 20 degrees) at SIZE^2 over a black
background, with the default light, in four modes:

  reference  --lod 0 with 16 samples a pixel (the exact frame, supersampled)
  exact      --lod 0, one sample a pixel (the paper's frame)
  default    no --lod flag (level of detail, silhouettes from 4x4 sub-pixel rays)
  aa2        --silhouette-aa 2 (silhouettes from 2x2 sub-pixel rays)
  whole      --silhouette-aa 0 (level of detail, coarse silhouettes whole cells)

and compares each with the reference (build/tools/bench/vox-lod-compare): RMSE
of RGB and of alpha, and silhouette pixels wrong (alpha off by more than 1/2).
Time is the median of --runs warm frames (`timings.render_seconds` of
--stats, after one frame that warms the page cache), alternating the modes
round by round; bricks and bytes are the frame's (`lod.bricks_paged_total`
and `lod.brick_bytes_read_total`, or `cache.misses` and `io.brick_bytes_read`
for exact frames). Prints a Markdown table; standard library only.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys

CAMERAS = {
    "full": {"position": [0, 0, 3], "look_at": [0, 0, 0], "fov_deg": 40},
    "close": {"position": [0, 0, 1.05], "look_at": [0, 0, 0.9], "fov_deg": 20},
}
MODES = {
    "exact": ["--lod", "0"],
    "default": [],
    "aa2": ["--silhouette-aa", "2"],
    "whole": ["--silhouette-aa", "0"],
}


def render(args, store, mode_args, scene, out, stats):
    cmd = [os.path.join(args.build, "tools/render/vox-render"), store, "--cam", args.cam_path,
           "--scene", scene, "-o", out, "--stats", stats, "--quiet", "--threads",
           str(args.threads)] + mode_args
    subprocess.run(cmd, check=True)
    with open(stats) as f:
        return json.load(f)


def frame_io(stats):
    lod = stats.get("lod", {})
    if "bricks_paged_total" in lod:
        return lod["bricks_paged_total"], lod["brick_bytes_read_total"]
    return stats["cache"]["misses"], stats["io"]["brick_bytes_read"]


def compare(args, ref, test):
    out = subprocess.run([os.path.join(args.build, "tools/bench/vox-lod-compare"), ref, test],
                         check=True, capture_output=True, text=True).stdout
    return json.loads(out)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("stores", nargs="+")
    p.add_argument("--build", default="build")
    p.add_argument("--size", type=int, default=512)
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--view", choices=sorted(CAMERAS), default="full")
    p.add_argument("--work", default="/tmp/vox-lod-quality")
    args = p.parse_args()
    os.makedirs(args.work, exist_ok=True)
    cam = dict(CAMERAS[args.view], width=args.size, height=args.size)
    args.cam_path = os.path.join(args.work, "cam.json")
    with open(args.cam_path, "w") as f:
        json.dump(cam, f)
    black = os.path.join(args.work, "black.json")
    with open(black, "w") as f:
        json.dump({"background": [0, 0, 0]}, f)
    black16 = os.path.join(args.work, "black16.json")
    with open(black16, "w") as f:
        json.dump({"background": [0, 0, 0], "samples_per_pixel": 16}, f)

    print(f"{args.view} view, {args.size}^2, {args.threads} threads, black background; "
          f"medians of {args.runs} warm frames; load average {os.getloadavg()[0]:.1f} at the start\n")
    print("| store | mode | RGB RMSE | alpha RMSE | silhouette pixels wrong | warm s | bricks | "
          "brick MB |")
    print("| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    for store in args.stores:
        name = os.path.basename(os.path.normpath(store))
        ref = os.path.join(args.work, f"{name}.reference.exr")
        render(args, store, ["--lod", "0"], black16, ref, ref + ".json")
        times = {m: [] for m in MODES}
        last = {}
        for m, margs in MODES.items():  # warms the page cache
            render(args, store, margs, black, os.path.join(args.work, f"{name}.{m}.exr"),
                   os.path.join(args.work, f"{name}.{m}.json"))
        for _ in range(args.runs):
            for m, margs in MODES.items():
                exr = os.path.join(args.work, f"{name}.{m}.exr")
                last[m] = render(args, store, margs, black, exr, exr + ".json")
                times[m].append(last[m]["timings"]["render_seconds"])
        for m in MODES:
            q = compare(args, ref, os.path.join(args.work, f"{name}.{m}.exr"))
            bricks, nbytes = frame_io(last[m])
            print(f"| {name} | {m} | {q['rmse_rgb']:.5f} | {q['rmse_alpha']:.5f} | "
                  f"{q['silhouette_wrong']} | {statistics.median(times[m]):.3f} | {bricks} | "
                  f"{nbytes / 1e6:.1f} |")
        sys.stdout.flush()


if __name__ == "__main__":
    main()
