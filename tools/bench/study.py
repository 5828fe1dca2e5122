"""The accuracy study (vox-study) and level of detail's quality."""

import json
import os

import harness as H


def study_sphere(h, voxels, band=3.0):
    """A level-set sphere of radius 1, `voxels` across, and its store (vox-ingest)."""
    vdb = h.vdb(f"study-sphere{voxels}", ["-sphere", f"voxel={2.0 / voxels:.17g}", "radius=1",
                                          "center=0,0,0", f"width={band:g}"])
    return h.store(vdb)


def run_study(h, part, args, name):
    out = H.check([h.tool("vox-study"), part, *map(str, args)], "vox-study")
    with open(h.path(f"study-{name}.json"), "w") as f:
        f.write(out)
    return json.loads(out)


def pct(bad, n):
    return f"{100 * bad / n:.3g}% ({bad})" if n else "n/a"


class Precision:
    """precision: every traversal variant against the exact GMP reference, and its time per ray.

Scenarios A (2^8 grid), B (the same shell deep in a 2^24 grid) and C (at the far corner of a 2^40
grid), each with random rays and the hard-case families, and the primary rays of an image of a
sphere 240 voxels across. Refused: first hits the exact reference does not accept. ns / ray: one
thread, median of passes over scenario A's random rays, all variants in turn each round."""

    @staticmethod
    def add_arguments(p):
        p.add_argument("--quick", action="store_true", help="2000 rays a family, a 192^2 image")
        p.add_argument("--rounds", type=int, default=5)

    @staticmethod
    def main(h, a):
        store = study_sphere(h, 240)
        image, per = (192, 2000) if a.quick else (384, 10000)
        j = run_study(h, "precision", [store, "--image", image, "--per-family", per, "--rounds", a.rounds],
                      "precision")
        rep = H.Report(h, "precision", "Precision against time")
        base = j["variants"][0]["scenarios"][0]["pass_seconds"]
        rows, raw = [], {}
        for v in j["variants"]:
            sc = v["scenarios"]
            ns = [1e9 * H.median(s["pass_seconds"]) if s["pass_seconds"] else None for s in sc]
            ratio = H.median([x / b for x, b in zip(sc[0]["pass_seconds"], base)])
            bad = sum(s["refused"] for s in sc if s["fits"])
            n = sum(s["rays"] for s in sc if s["fits"])
            im = v.get("image")
            raw[v["name"]] = {"ns_A": ns[0], "time_over_default": ratio, "refused": bad, "rays": n}
            rows.append((v["name"], v["family"], v["word"] or "-", v["word"] and v["frac"] or "-", v["real"],
                         f"{ns[0]:.0f}" if ns[0] else "n/a", f"{ratio:.2f}" if ns[0] else "n/a",
                         f"{ns[2]:.0f}" if ns[2] else "n/a",
                         *[pct(s["refused"], s["rays"]) if s["fits"] else "n/a (step too deep)" for s in sc],
                         pct(bad, n), pct(im["refused"], j["image"]["pixels"]) if im else "n/a",
                         pct(im["other_voxel"], j["image"]["pixels"]) if im else "n/a"))
        rep.table(["variant", "family", "word", "frac", "real", "ns / ray (A)", "time / default (A)",
                   "ns / ray (C)", "refused A", "refused B", "refused C", "refused, all",
                   "image pixels refused", "image pixels with another voxel"], rows)
        for s in j["scenarios"]:
            rep.add(f"- **{s['name']}**: {s['description']}; rays per family: " +
                    ", ".join(f"{f['name']} {f['rays']}" for f in s["families"]) + ".")
        im = j["image"]
        rep.add(f"- **image**: the {im['size']}x{im['size']} primary rays of the study camera on the "
                f"level-set sphere 240 voxels across ({im['voxels']} voxels, split {im['split']}).", "")
        with open(os.path.join(h.out, "precision_refused.txt"), "w") as f:
            f.write(j["refused_log"])
        rep.raw = raw
        rep.write()
        return raw


class Paper:
    """paper: the paper's figures 7 and 8, single step against two steps (4..7 first-step levels).

A level-set sphere 15/16 of each grid across, ingested once; whole frames at each image size
(camera (0,0,3), 40 degrees, one light), without beam start distances (the paper's walk), warm,
the splits alternating round by round; ratios are medians of per-round ratios. First hits only:
the same primary rays traced for their first hit, nothing else."""

    @staticmethod
    def add_arguments(p):
        p.add_argument("--grids", default="1024,2048,4096")
        p.add_argument("--images", default="256,512,1024,2048")
        p.add_argument("--rounds", type=int, default=5)

    @staticmethod
    def main(h, a):
        stores = [study_sphere(h, int(g) * 15 // 16, 1.5 if int(g) >= 8192 else 3.0) for g in a.grids.split(",")]
        j = run_study(h, "paper", [*stores, "--images", a.images, "--threads", h.threads,
                                   "--rounds", a.rounds], "paper")
        rep = H.Report(h, "paper", "Single step against two steps (the paper's figures 7 and 8)")
        rows = []
        for c, grid in zip([x for x in j], [g for g in a.grids.split(",") for _ in a.images.split(",")]):
            sp = c["splits"]
            med = [H.median(s["frame_s"]) for s in sp]
            best = 1 + min(range(len(sp) - 1), key=lambda i: med[i + 1])

            def speedup(i, key="frame_s"):
                return H.median([x / y for x, y in zip(sp[0][key], sp[i][key])])
            by_n1 = {s["n1"]: i for i, s in enumerate(sp) if i}
            rows.append([f"{c['image']}^2", f"{grid}^3", c["levels"], f"{med[0]:.3f}"] +
                        [(f"**{med[by_n1[n]]:.3f}**" if by_n1[n] == best else f"{med[by_n1[n]]:.3f}")
                         if n in by_n1 else "n/a" for n in (4, 5, 6, 7)] +
                        [f"{sp[best]['n1']}+{sp[best]['n2']}", f"{speedup(best):.2f}x",
                         f"{speedup(by_n1[6]):.2f}x" if 6 in by_n1 else "n/a",
                         f"{speedup(best, 'first_hits_s'):.2f}x"])
            rep.raw[f"{grid}.{c['image']}"] = {"best": f"{sp[best]['n1']}+{sp[best]['n2']}",
                                               "single_over_best": speedup(best)}
        rep.table(["image", "grid", "levels", "single step (s)", "4+ (s)", "5+ (s)", "6+ (s)", "7+ (s)",
                   "best split", "single / best", "single / 6+", "first hits only: single / best"], rows)
        rep.write()
        return rep.raw


class Lod:
    """lod: level of detail against the exact frame: time, bricks, bytes and error.

For each store (vox-gen's sphere and bumpy of --grid unless given), at --size^2 over a black
background: the reference (--lod 0, 16 samples a pixel), exact (--lod 0), default (level of
detail), aa2 (--silhouette-aa 2), whole (--silhouette-aa 0). Each against the reference
(vox-lod-compare): RMSE of RGB and alpha, silhouette pixels wrong; the median of --runs warm
frames (modes alternating) and a cold one (page cache dropped, as root), bricks and bytes read."""
    MODES = {"exact": ["--lod", "0"], "default": [], "aa2": ["--silhouette-aa", "2"],
             "whole": ["--silhouette-aa", "0"]}
    CAMERAS = {"full": ((0, 0, 3), (0, 0, 0), 40), "close": ((0, 0, 1.05), (0, 0, 0.9), 20)}

    @staticmethod
    def add_arguments(p):
        p.add_argument("stores", nargs="*")
        p.add_argument("--grid", type=int, default=2048)
        p.add_argument("--size", type=int, default=512)
        p.add_argument("--runs", type=int, default=3)
        p.add_argument("--view", choices=("full", "close"), default="full")
        p.add_argument("--no-cold", action="store_true")

    @staticmethod
    def frame(h, store, mode, scene, cam, out, cold=False):
        r = H.run([h.tool("vox-render"), store, "--cam", cam, "--scene", scene, "-o", out + ".exr",
                   "--stats", out + ".json", "--quiet", "--threads", str(h.threads), *Lod.MODES.get(mode, [])],
                  cold=cold)
        if r["exit"] != 0:
            H.fail(f"vox-render failed on {h.rel(store)} ({mode})")
        s = json.load(open(out + ".json"))
        lod = s.get("lod") or {}
        return {"render_s": s["timings"]["render_seconds"], "wall_s": r["wall_s"],
                "bricks": lod.get("bricks_paged_total", s["cache"]["misses"]),
                "bytes": lod.get("brick_bytes_read_total", s["io"]["brick_bytes_read"])}

    @staticmethod
    def main(h, a):
        stores = [os.path.abspath(s) for s in a.stores] or [h.gen_store(s, a.grid) for s in ("sphere", "bumpy")]
        cam = H.cam_json(h.path(f"lod.{a.view}.cam.json"), *Lod.CAMERAS[a.view], a.size)
        black = H.write_json(h.path("lod.black.json"), {"background": [0, 0, 0]})
        black16 = H.write_json(h.path("lod.black16.json"), {"background": [0, 0, 0], "samples_per_pixel": 16})
        rep = H.Report(h, "lod", "Level of detail against the exact frame")
        rep.add(f"{a.view} view, {a.size}^2, {h.threads} threads, black background; warm: medians of "
                f"{a.runs} frames (render seconds); cold: one whole process after dropping the page cache.", "")
        rows = []
        for store in stores:
            name = os.path.basename(os.path.normpath(store))
            out = lambda m: h.path(f"lod-{name}.{m}")
            Lod.frame(h, store, "reference", black16, cam, out("reference"))
            cold = {m: None if a.no_cold else Lod.frame(h, store, m, black, cam, out(m), cold=True)
                    for m in Lod.MODES}
            warm = H.alternate({m: (lambda m=m: Lod.frame(h, store, m, black, cam, out(m))) for m in Lod.MODES},
                               a.runs)
            for m in Lod.MODES:
                q = json.loads(H.check([h.tool("vox-lod-compare"), out("reference") + ".exr", out(m) + ".exr"]))
                w = H.median([x["render_s"] for x in warm[m]])
                rep.raw[f"{name}.{m}"] = {"warm_s": w, "cold_s": cold[m] and cold[m]["wall_s"], **q,
                                          "bricks": warm[m][-1]["bricks"], "bytes": warm[m][-1]["bytes"]}
                rows.append((name, m, f"{q['rmse_rgb']:.5f}", f"{q['rmse_alpha']:.5f}", q["silhouette_wrong"],
                             f"{w:.3f}", f"{cold[m]['wall_s']:.2f}" if cold[m] else "-",
                             warm[m][-1]["bricks"], f"{warm[m][-1]['bytes'] / 1e6:.1f}"))
        rep.table(["store", "mode", "RGB RMSE", "alpha RMSE", "silhouette pixels wrong", "warm s",
                   "cold s (process)", "bricks", "brick MB"], rows)
        rep.write()
        return rep.raw
