"""peers: vox against NanoVDB's CPU ray caster (nanocast) and OpenVDB's vdb_render.

Frames: the 2048^3 sphere, the Stanford bunny and a dodecahedron, each seen far (the whole
object in the frame: no hit on the border) and close (the object covers >= 95% of the pixels,
the camera within half the object's radius of its surface: both checked, the run fails
otherwise). vox: `vox-render-bench STORE --lod 0 --cam CAM --scene flat.json` (no light; with
--bare when it has it: first hits only); NanoVDB: nanocast, the bare loop of NanoVDB's own
examples (HDDA + ZeroCrossing), built out of tree from $NANOCAST_SRC. Each round runs one
process of each, alternately; a process keeps its best of --repeat frames. Reported per frame:
the median over rounds of vox's speed / NanoVDB's (each round's pair side by side), the best
frame against the best frame, and the geometric means over frames. Then whole processes of
vox-render (--lod 0) against `vdb_render -shader diffuse` on the sphere, warm page cache.
"""

import json
import math
import os

import harness as H

# name: (vdb_tool arguments, [(view, position, look_at, fov)], centre, radius). The bunny's scan
# has holes at its base: its level set is made from its points.
SCENES = {
    "sphere": (H.SPHERE_2048, [("far", (0, 0, 3), (0, 0, 0), 40),
                               ("close", (0.35, 0.25, 1.35), (0.05, 0.03, 0), 40)], (0, 0, 0), 1.0),
    "bunny": (["-read", "{bunny}", "-points2ls", "d=300", "r=1.5", "w=3", "-dilate", "r=1",
               "-erode", "r=1"],
              [("far", (-0.017, 0.11, 0.35), (-0.017, 0.11, 0), 44.8),
               ("close", (-0.03, 0.1, 0.085), (-0.03, 0.1, 0), 44.8)], (-0.017, 0.11, 0), 0.08),
    "dodecahedron": (["-platonic", "d=1024", "f=12", "s=1", "w=3"],
                     [("far", (0, 0, 3), (0, 0, 0), 40),
                      ("close", (0.15, 0.2, 1.2), (0, 0, 0), 40)], (0, 0, 0), 1.0),
}


def add_arguments(p):
    p.add_argument("--scenes", default="sphere,bunny,dodecahedron")
    p.add_argument("--rounds", type=int, default=int(os.environ.get("ROUNDS", 5)))
    p.add_argument("--repeat", type=int, default=3, help="frames per process (its best counts)")
    p.add_argument("--size", type=int, default=1024)
    p.add_argument("--compare", action="store_true",
                   help="only compare vox's hit mask with nanocast's, per frame")
    p.add_argument("--no-whole", action="store_true", help="skip the vdb_render whole-process rows")
    p.add_argument("--split", default="", help="vox's first-step levels (vox-render --split N1)")


def nanocast(h):
    """The nanocast binary, built out of tree into $SCRATCH/build-nanocast."""
    src = os.environ.get("NANOCAST_SRC") or os.path.join(H.REPO, "..", "shared", "tools", "nanocast")
    if not os.path.exists(os.path.join(src, "nanocast.cpp")):
        H.fail(f"no nanocast sources at {src}: set NANOCAST_SRC")
    b = h.path("build-nanocast")
    exe = os.path.join(b, "nanocast")
    if not os.path.exists(exe) or not h.no_build:
        H.check(["cmake", "-S", src, "-B", b, "-DCMAKE_BUILD_TYPE=Release"], "cmake (nanocast)")
        H.check(["cmake", "--build", b], "cmake --build (nanocast)")
    return exe


def frames(h, a):
    bunny = os.environ.get("BUNNY") or os.path.join(H.REPO, "..", "shared", "data", "stanford-bunny",
                                                    "bunny.ply")
    out = []
    for s in a.scenes.split(","):
        if s not in SCENES:
            H.fail(f"unknown scene '{s}' (sphere, bunny, dodecahedron)")
        args, views, centre, radius = SCENES[s]
        if s == "bunny" and not os.path.exists(bunny):
            H.fail(f"{bunny}: no bunny PLY (set BUNNY)")
        vdb = h.vdb(s, [x.replace("{bunny}", bunny) for x in args])
        store = h.store(vdb)
        for view, pos, at, fov in views:
            if view == "close":
                d = math.dist(pos, centre) - radius
                if d > radius / 2:
                    H.fail(f"{s} close: the camera is {d:.3f} from the surface, more than half the radius")
            cam = H.cam_json(h.path(f"{s}.{view}.cam.json"), pos, at, fov, a.size)
            nano = ["--eye", ",".join(map(str, pos)), "--lookat", ",".join(map(str, at)),
                    "--fov", str(fov), "--res", f"{a.size}x{a.size}", "--threads", str(h.threads)]
            out.append({"scene": s, "view": view, "vdb": vdb, "store": store, "cam": cam, "nano": nano})
    return out


def read_pgm(path):
    data = open(path, "rb").read()
    parts = data.split(maxsplit=4)
    if parts[0] not in (b"P5",) or parts[3] != b"255":
        H.fail(f"{path}: not an 8-bit binary PGM")
    w, hgt = int(parts[1]), int(parts[2])
    return w, hgt, parts[4][:w * hgt]


def coverage(path):
    """(fraction of pixels hit, hits on the border) of a PGM hit mask."""
    w, hgt, px = read_pgm(path)
    hits = sum(1 for b in px if b)
    border = sum(1 for i, b in enumerate(px) if b and (i < w or i >= w * (hgt - 1) or i % w in (0, w - 1)))
    return hits / (w * hgt), border


def mask_flag(h):
    """vox-render-bench's hit-mask flag, when it has --bare and one."""
    if not h.has_flag("vox-render-bench", "--bare"):
        return None
    for flag in ("--mask", "--hit-mask"):
        if h.has_flag("vox-render-bench", flag):
            return flag
    return None


def round_pair(h, f, a, nc, flat, bare):
    """One vox process and one nanocast process on frame f: their best frames (seconds)."""
    tag = h.path(f"{f['scene']}.{f['view']}")
    vox = [h.tool("vox-render-bench"), f["store"], "--lod", "0", "--cam", f["cam"], "--scene", flat,
           "--threads", str(h.threads), "--runs", str(a.repeat + 1)] + (["--bare"] if bare else []) + \
        (["--split", a.split] if a.split else [])
    r = H.run(vox, stdout=tag + ".vox.json", stderr=tag + ".vox.err")
    if r["exit"] != 0:
        H.fail(f"vox-render-bench failed: see {h.rel(tag + '.vox.err')}")
    v = json.load(open(tag + ".vox.json"))
    r = H.run([nc, f["vdb"], *f["nano"], "--repeat", str(a.repeat), "--mask", tag + ".nano.pgm"],
              stdout=tag + ".nano.json", stderr=tag + ".nano.err")
    if r["exit"] != 0:
        H.fail(f"nanocast failed: see {h.rel(tag + '.nano.err')}")
    n = json.load(open(tag + ".nano.json"))
    return min(v["warm_seconds"]), n["seconds"], v.get("hits"), n["hits"]


def compare(h, a, fs, nc):
    flag = mask_flag(h)
    if not flag:
        H.fail("--compare needs vox-render-bench --bare with a hit-mask flag (--mask)")
    rep = H.Report(h, "peers-compare", "vox's hit mask against NanoVDB's (nanocast --mask)")
    rows = []
    for f in fs:
        tag = h.path(f"{f['scene']}.{f['view']}")
        H.check([h.tool("vox-render-bench"), f["store"], "--lod", "0", "--cam", f["cam"], "--threads",
                 str(h.threads), "--runs", "2", "--bare", flag, tag + ".vox.pgm"], "vox-render-bench")
        H.check([nc, f["vdb"], *f["nano"], "--repeat", "1", "--mask", tag + ".nano.pgm"], "nanocast")
        w, hgt, va = read_pgm(tag + ".vox.pgm")
        w2, h2, na = read_pgm(tag + ".nano.pgm")
        if (w, hgt) != (w2, h2):
            H.fail(f"{f['scene']} {f['view']}: masks of {w}x{hgt} and {w2}x{h2} pixels")
        diff = sum(1 for x, y in zip(va, na) if bool(x) != bool(y))
        rows.append((f["scene"], f["view"], sum(1 for x in va if x), sum(1 for x in na if x), diff,
                     f"{100 * diff / (w * hgt):.3f}%"))
    rep.table(["scene", "view", "vox hits", "NanoVDB hits", "pixels differing", "of the frame"], rows)
    rep.write()


def whole(h, a, rep):
    """Whole processes of vox-render --lod 0 and vdb_render -shader diffuse, alternately."""
    vdb = h.vdb("sphere", H.SPHERE_2048)
    store = h.store(vdb)
    cam = H.cam_json(h.path("whole.cam.json"), (0, 0, 3), (0, 0, 0), 40, a.size)
    scene = H.write_json(h.path("whole.scene.json"), H.DIFFUSE)
    vox = [h.tool("vox-render"), store, "--lod", "0", "--cam", cam, "--scene", scene, "--threads",
           str(h.threads), "-o", h.path("whole-vox.exr"), "--quiet"]
    vdbr = ["vdb_render", vdb, h.path("whole-vdb.exr"), "-translate", "0,0,3", "-lookat", "0,0,0",
            "-up", "0,1,0", "-fov", "40", "-res", f"{a.size}x{a.size}", "-cpus", str(h.threads),
            "-shader", "diffuse"]
    if not H.shutil.which("vdb_render"):
        H.fail("vdb_render is not installed (Debian: libopenvdb-tools)")

    def timed(argv):
        r = H.run(argv)
        if r["exit"] != 0:
            H.fail(f"{os.path.basename(argv[0])} exited {r['exit']}")
        return r["wall_s"]
    timed(vox), timed(vdbr)  # warm the page cache
    t = H.alternate({"vox": lambda: timed(vox), "vdb": lambda: timed(vdbr)}, a.rounds)
    ratios = [d / v for v, d in zip(t["vox"], t["vdb"])]
    rep.raw["whole"] = t
    rep.add("## Whole process against vdb_render", "",
            f"The 2048^3 sphere (`vdb_tool {' '.join(H.SPHERE_2048)}`), camera (0,0,3) fov 40, "
            f"{a.size}^2, {h.threads} threads, one directional light without shadows; "
            f"`vox-render --lod 0` against `vdb_render -shader diffuse`, open to exit, {a.rounds} "
            "rounds alternately, warm page cache.", "")
    rep.table(["vox-render s (median)", "vdb_render s (median)", "vox speed / vdb_render (median)"],
              [(f"{H.median(t['vox']):.3f}", f"{H.median(t['vdb']):.3f}", f"{H.median(ratios):.2f}x")])
    return H.median(ratios)


def main(h, a):
    nc = nanocast(h)
    fs = frames(h, a)
    if a.compare:
        return compare(h, a, fs, nc)
    bare = h.has_flag("vox-render-bench", "--bare")
    flat = H.write_json(h.path("flat.json"), {"lights": []})
    rep = H.Report(h, "peers", "vox against NanoVDB and vdb_render")
    rep.add(f"{a.size}^2 pixels, {h.threads} threads, vox `--lod 0`" +
            (f" `--split {a.split}`" if a.split else "") +
            (" `--bare` (first hits only)" if bare else " with no light") +
            f", NanoVDB: nanocast (the bare loop). {a.rounds} rounds alternately, best of "
            f"{a.repeat} frames per process. Ratios are vox's speed over NanoVDB's (above 1: vox "
            "faster).", "")
    rows, med_ratios, best_ratios = [], [], []
    for f in fs:
        H.log(f"{f['scene']} {f['view']}: {a.rounds} rounds")
        res = H.alternate({"pair": lambda: round_pair(h, f, a, nc, flat, bare)}, a.rounds)["pair"]
        hit, border = coverage(h.path(f"{f['scene']}.{f['view']}.nano.pgm"))
        if f["view"] == "close" and hit < 0.95:
            H.fail(f"{f['scene']} close: the object covers {100 * hit:.1f}% of the pixels, not 95%")
        if f["view"] == "far" and border:
            H.fail(f"{f['scene']} far: {border} border pixels hit: the object is not whole")
        px = a.size * a.size
        ratios = [n / v for v, n, _, _ in res]
        vbest, nbest = min(r[0] for r in res), min(r[1] for r in res)
        med_ratios.append(H.median(ratios))
        best_ratios.append(nbest / vbest)
        rep.raw[f"{f['scene']}.{f['view']}"] = res
        rows.append((f["scene"], f["view"], f"{100 * hit:.1f}%",
                     f"{px / H.median([r[0] for r in res]) / 1e6:.1f}",
                     f"{px / H.median([r[1] for r in res]) / 1e6:.1f}",
                     f"{med_ratios[-1]:.2f}x", f"{best_ratios[-1]:.2f}x"))
    rows.append(("geometric mean", "", "", "", "", f"{H.geomean(med_ratios):.2f}x",
                 f"{H.geomean(best_ratios):.2f}x"))
    rep.table(["scene", "view", "hit pixels", "vox M rays/s", "NanoVDB M rays/s",
               "vox / NanoVDB (median)", "vox / NanoVDB (best)"], rows)
    rep.raw["geomean_median"], rep.raw["geomean_best"] = H.geomean(med_ratios), H.geomean(best_ratios)
    if not a.no_whole:
        rep.raw["whole_ratio"] = whole(h, a, rep)
    rep.write()
    return rep.raw
