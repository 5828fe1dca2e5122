"""The memory budget as a promise: the matrix of frames that must render in a limit, and the
brick pool's cost in time."""

import json
import os

import harness as H

# Shadows and reflections: every secondary ray a frame can trace besides refraction.
SCENE = {"lights": [{"type": "directional", "direction": [-1, -1, -1], "intensity": 1.0, "shadows": True}],
         "material": {"reflect": 0.3}}


def store_arg(h, a):
    if a.store:
        if not os.path.isdir(a.store):
            H.fail(f"{a.store}: no such store")
        return os.path.abspath(a.store)
    return h.gen_store("sphere", a.grid)


class Matrix:
    """budget: the frames that must render inside a memory limit, or stop at the start.

Every combination of --sizes (square images), --modes (exact = --lod 0, default = the store's
level of detail) and --thread-list, each cold (page cache dropped) in a cgroup of --limit-mib:
the full view (camera (0,0,3) at the origin, fov 40), one shadow-casting light and a reflective
material. Per frame: exit, whether the cgroup's OOM killer ended it, the cgroup's peak and
failcnt, the process's peak resident set and the brick pool (from --stats), bricks read and
wall time. A frame may stop at the start (exit 1, naming the budget it needs) but never be
killed; the question fails if one was."""

    @staticmethod
    def add_arguments(p):
        p.add_argument("store", nargs="?", help="a store (default: vox-gen's sphere of --grid^3 in $SCRATCH)")
        p.add_argument("--grid", type=int, default=4096)
        p.add_argument("--limit-mib", type=int, default=256)
        p.add_argument("--sizes", default="1024,4096")
        p.add_argument("--modes", default="default,exact")
        p.add_argument("--thread-list", default="1,2,16")

    @staticmethod
    def main(h, a):
        store = store_arg(h, a)
        scene = H.write_json(h.path("budget.scene.json"), SCENE)
        rows, killed = [], []
        rep = H.Report(h, "budget", "Frames inside a memory limit")
        for size in [int(s) for s in a.sizes.split(",")]:
            cam = H.cam_json(h.path(f"budget.cam{size}.json"), (0, 0, 3), (0, 0, 0), 40, size)
            for mode in a.modes.split(","):
                for t in [int(x) for x in a.thread_list.split(",")]:
                    tag = h.path(f"budget-{size}-{mode}-{t}")
                    argv = [h.tool("vox-render"), store, "--cam", cam, "--scene", scene, "--threads", str(t),
                            "-o", tag + ".exr", "--stats", tag + ".json", "--quiet"]
                    argv += ["--lod", "0"] if mode == "exact" else []
                    for f in (tag + ".exr", tag + ".json"):
                        if os.path.exists(f):
                            os.remove(f)
                    r = H.run(argv, limit_mib=a.limit_mib, cold=True, stderr=tag + ".err")
                    s = json.load(open(tag + ".json")) if r["exit"] == 0 else {}
                    mem = s.get("memory", {})
                    pool = mem.get("brick_pool", {})
                    err = open(tag + ".err").read().strip().splitlines()
                    outcome = ("rendered" if r["exit"] == 0 else
                               "killed" if r["signal"] is not None else
                               f"refused: {err[-1] if err else ''}")
                    if r["signal"] is not None:
                        killed.append(tag)
                    rows.append((f"{size}^2", mode, t, outcome, f"{r['wall_s']:.1f}",
                                 f"{r['peak_bytes'] / H.MiB:.0f}", r["failcnt"],
                                 f"{mem['process']['peak_rss'] / H.MiB:.0f}" if mem else "-",
                                 f"{pool['capacity'] / H.MiB:.0f} / {pool['peak_in_use'] / H.MiB:.0f}"
                                 if pool else "-",
                                 pool.get("overflows", "-"), s.get("cache", {}).get("misses", "-")))
                    rep.raw[f"{size}.{mode}.{t}"] = {**{k: r[k] for k in ("wall_s", "exit", "signal",
                                                                          "peak_bytes", "failcnt")},
                                                     "peak_rss": mem.get("process", {}).get("peak_rss"),
                                                     "brick_pool": pool}
                    H.log(f"{size}^2 {mode} {t} threads: {outcome}, {r['wall_s']:.1f} s")
        rep.add(f"Store `{h.rel(store)}`, cold frames in a {a.limit_mib} MiB cgroup, full view, one "
                "shadow-casting light, reflective material.", "")
        rep.table(["image", "mode", "threads", "outcome", "wall s", "cgroup peak MiB", "failcnt",
                   "peak RSS MiB", "pool MiB mapped / peak", "pool overflows", "bricks read"], rows)
        rep.raw["killed"] = killed
        rep.write()
        if killed:
            H.fail(f"killed: {', '.join(h.rel(k) for k in killed)}")
        return rep.raw


class Pool:
    """pool: the brick pool's cost in time, against bricks on the heap (VOX_BRICK_POOL=0).

The same frame (--mode exact or default, --size, full view, one light without shadows) rendered
--runs times with the pool and without, alternately, warm (the store in the page cache, the
brick cache cold: every brick decoded once or more into pool blocks or heap blocks), with
--cache-mib of brick cache so that bricks churn. Medians of wall and CPU time, the ratio pool /
heap; the images must be identical."""

    @staticmethod
    def add_arguments(p):
        p.add_argument("store", nargs="?", help="a store (default: vox-gen's sphere of --grid^3 in $SCRATCH)")
        p.add_argument("--grid", type=int, default=4096)
        p.add_argument("--mode", default="exact")
        p.add_argument("--size", type=int, default=1024)
        p.add_argument("--cache-mib", type=int, default=32)
        p.add_argument("--runs", type=int, default=5)

    @staticmethod
    def main(h, a):
        store = store_arg(h, a)
        cam = H.cam_json(h.path("pool.cam.json"), (0, 0, 3), (0, 0, 0), 40, a.size)
        scene = H.write_json(h.path("pool.scene.json"), H.DIFFUSE)
        res = {"pool": [], "heap": []}

        def frame(how):
            tag = h.path(f"pool-{how}")
            argv = [h.tool("vox-render"), store, "--cam", cam, "--scene", scene, "--threads", str(h.threads),
                    "--cache-mb", str(a.cache_mib), "-o", tag + ".exr", "--stats", tag + ".json", "--quiet"]
            argv += ["--lod", "0"] if a.mode == "exact" else []
            env = dict(os.environ, VOX_BRICK_POOL="0" if how == "heap" else "1")
            r = H.run(argv, stderr=tag + ".err", env=env)
            if r["exit"] != 0:
                H.fail(f"{how}: vox-render exited {r['exit']}: see {h.rel(tag + '.err')}")
            s = json.load(open(tag + ".json"))
            res[how].append({**r, "frame_s": s["timings"]["render_seconds"], "misses": s["cache"]["misses"],
                             "pool": s["memory"]["brick_pool"]["capacity"], "exr": tag + ".exr"})

        frame("pool")  # warms the page cache
        res["pool"].clear()
        H.alternate({"pool": lambda: frame("pool"), "heap": lambda: frame("heap")}, a.runs)
        same = json.loads(H.check([h.tool("vox-lod-compare"), res["pool"][-1]["exr"], res["heap"][-1]["exr"]]))
        if same["rmse_rgb"] or same["rmse_alpha"]:
            H.fail("the images with and without the pool differ")
        if res["heap"][-1]["pool"] or not res["pool"][-1]["pool"]:
            H.fail("VOX_BRICK_POOL did not switch the pool")
        med = {how: {k: H.median([x[k] for x in v]) for k in ("frame_s", "cpu_s", "wall_s", "misses")}
               for how, v in res.items()}
        rep = H.Report(h, "pool", "The brick pool's cost in time")
        rep.add(f"Store `{h.rel(store)}`, {a.mode}, {a.size}^2, {h.threads} threads, --cache-mb "
                f"{a.cache_mib}, warm page cache, {a.runs} runs each alternately, medians.", "")
        rows = [(how, f"{m['frame_s']:.2f}", f"{m['cpu_s']:.2f}", f"{m['wall_s']:.2f}", int(m["misses"]))
                for how, m in med.items()]
        rep.table(["bricks in", "frame s", "CPU s", "wall s", "bricks decoded"], rows)
        ratio = {k: med["pool"][k] / med["heap"][k] for k in ("frame_s", "cpu_s")}
        rep.add(f"pool / heap: frame time **{ratio['frame_s']:.3f}**, CPU time **{ratio['cpu_s']:.3f}**.")
        rep.raw.update(med=med, ratio=ratio)
        rep.write()
        return rep.raw
