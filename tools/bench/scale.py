"""scale: a frame's cost as the volume grows and the memory limit shrinks.

For each grid (--grids) and shape (--shapes: vox-gen's sphere, bumpy; --store SHAPE:N=PATH
names an existing store, only read), vox-render renders a full view (camera (0,0,3), 40 degrees)
and a close-up (camera (0,0,1.05) looking at (0,0,0.9), 20 degrees), in each mode (default: the
store's level of detail; exact: --lod 0), unlimited and in memory cgroups of each --limits
fraction of the store's size (or only in one of --limit-mib), a cold frame (page cache dropped)
and a warm one, --runs times. Each run is one process in its own cgroup: wall time, peak charge,
failcnt, OOM kill, bricks and bytes read (--stats); its image is compared with the first finished
run of its configuration, close-ups also with the other mode's (vox-lod-compare: identical or
not). A limited run is killed after --timeout s (default: 5 times the unlimited run, at least
60 s; 30 min with --limit-mib) and tighter limits are then skipped. Rows go to
$SCRATCH/scale.csv as they finish; a rerun skips the runs there for the same vox-render binary.
The report: per shape, the scale law's table at the --limit-mib limit (else unlimited), its
ratios against the goals, and the limits' table.
"""

import csv
import hashlib
import json
import os
import shlex
import time
from fractions import Fraction

import harness as H

CAMERAS = {"full": ((0, 0, 3), (0, 0, 0), 40), "close": ((0, 0, 1.05), (0, 0, 0.9), 20)}
MODES = {"default": [], "exact": ["--lod", "0"]}
FIELDS = ["bin", "shape", "mode", "grid", "camera", "limit", "limit_bytes", "phase", "run",
          "store_bytes", "wall_s", "exit", "signal", "oom", "timeout", "peak_bytes", "failcnt",
          "bricks", "read_bytes", "render_s", "identical", "cross_mode", "loadavg", "cpu_s", "syscr"]


def add_arguments(p):
    p.add_argument("--grids", default="1024,2048,4096")
    p.add_argument("--shapes", default="sphere,bumpy")
    p.add_argument("--modes", default="default,exact")
    p.add_argument("--limits", default="1/2,1/4,1/8", help="fractions of the store's size")
    p.add_argument("--limit-mib", type=int, help="only this one limit")
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--size", type=int, default=1024)
    p.add_argument("--store", action="append", default=[], help="SHAPE:N=PATH, an existing store")
    p.add_argument("--timeout", type=float)
    p.add_argument("--render-args", default="", help="more vox-render flags")
    p.add_argument("--no-cold", action="store_true")
    p.add_argument("--fresh", action="store_true", help="ignore the rows of earlier runs")
    p.add_argument("--report-only", action="store_true")


class Scale:
    def __init__(self, h, a):
        self.h, self.a = h, a
        self.render = h.tool("vox-render")
        self.compare = h.tool("vox-lod-compare")
        self.bin = hashlib.sha256(open(self.render, "rb").read()).hexdigest()[:16]
        self.csv = h.path("scale.csv")
        self.rows = [] if a.fresh or not os.path.exists(self.csv) else list(csv.DictReader(open(self.csv)))
        self.grids = [int(x) for x in a.grids.split(",")]
        self.stores = {}
        for s in a.store:
            k, _, path = s.partition("=")
            shape, _, n = k.partition(":")
            self.stores[(shape, int(n))] = os.path.abspath(path)
        self.cams = {c: H.cam_json(h.path(f"scale.{c}.cam.json"), *v, a.size) for c, v in CAMERAS.items()}
        self.scene = H.write_json(h.path("scale.scene.json"), H.DIFFUSE)
        os.makedirs(h.path("scale-out"), exist_ok=True)

    def mine(self, **key):
        return [r for r in self.rows if r["bin"] == self.bin and
                all(r[k] == str(v) for k, v in key.items())]

    def append(self, row):
        new = not os.path.exists(self.csv)
        with open(self.csv, "a", newline="") as f:
            w = csv.DictWriter(f, fieldnames=FIELDS, extrasaction="ignore")
            if new:
                w.writeheader()
            w.writerow(row)
        self.rows.append({k: str(row.get(k, "")) for k in FIELDS})

    def same(self, a, b):
        d = json.loads(H.check([self.compare, a, b], "vox-lod-compare"))
        return "yes" if d["rmse_rgb"] == 0 and d["rmse_alpha"] == 0 else "no"

    def measure(self, shape, n, store, sbytes, mode, cam, limit, phase, run):
        key = dict(shape=shape, mode=mode, grid=n, camera=cam, limit=limit, phase=phase, run=run)
        if self.mine(**key):
            return
        lb = 0 if limit == "none" else self.a.limit_mib * H.MiB if self.a.limit_mib else \
            int(sbytes * Fraction(limit))
        looser = [r for r in self.mine(shape=shape, mode=mode, grid=n, camera=cam, phase=phase)
                  if r["limit"] != "none" and (r["timeout"] == "True" or r["oom"] == "True")
                  and int(r["limit_bytes"]) >= lb]
        if limit != "none" and looser:
            return  # a looser limit already failed: this one would too, slowly
        base = [float(r["wall_s"]) for r in self.mine(shape=shape, mode=mode, grid=n, camera=cam,
                                                      limit="none") if r["exit"] == "0"]
        timeout = self.a.timeout or (max(60.0, 5 * max(base)) if base and limit != "none" else
                                     1800.0 if self.a.limit_mib else 7200.0)
        tag = self.h.path("scale-out", f"{shape}{n}_{mode}_{cam}_{limit.replace('/', 'of')}_{phase}_{run}")
        ref = self.h.path("scale-out", f"ref_{self.bin}_{shape}{n}_{mode}_{cam}.exr")
        argv = [self.render, store, "--cam", self.cams[cam], "--scene", self.scene, "--threads",
                str(self.h.threads), "--stats", tag + ".json", "-o", tag + ".exr", "--quiet",
                *MODES[mode], *shlex.split(self.a.render_args)]
        H.log(f"{os.path.basename(tag)}: limit {lb // H.MiB if lb else 'none'} MiB")
        r = H.run(argv, limit_mib=lb / H.MiB if H.Cgroup.available() else None,
                  cold=phase == "cold", stderr=tag + ".err", timeout=timeout)
        row = dict(key, bin=self.bin, limit_bytes=lb, store_bytes=sbytes, loadavg=H.loadavg(), **r)
        row["wall_s"] = f"{r['wall_s']:.3f}"
        if r["exit"] == 0:
            s = json.load(open(tag + ".json"))
            cache, io, lod = s.get("cache", {}), s.get("io", {}), s.get("lod") or {}
            row.update(bricks=lod.get("bricks_paged_total", cache.get("bricks_paged_in")),
                       read_bytes=io.get("read_bytes"), render_s=s["timings"]["render_seconds"])
            if not os.path.exists(ref):
                os.replace(tag + ".exr", ref)
                row["identical"] = "ref"
            else:
                row["identical"] = self.same(ref, tag + ".exr")
            other = self.h.path("scale-out", f"ref_{self.bin}_{shape}{n}_"
                                f"{'exact' if mode == 'default' else 'default'}_{cam}.exr")
            if cam == "close" and os.path.exists(other):
                row["cross_mode"] = self.same(other, ref if row["identical"] == "ref" else tag + ".exr")
        if os.path.exists(tag + ".exr"):
            os.remove(tag + ".exr")
        self.append(row)

    def run(self):
        a = self.a
        phases = ["cold", "warm"] if os.geteuid() == 0 and not a.no_cold else ["warm"]
        limits = [f"{a.limit_mib}MiB"] if a.limit_mib else ["none"] + a.limits.split(",")
        if not H.Cgroup.available():
            limits = ["none"]
            H.log("no writable cgroup v1 memory controller (root?): unlimited runs only")
        for n in self.grids:
            for shape in a.shapes.split(","):
                store = self.stores.get((shape, n)) or self.h.gen_store(shape, n)
                sbytes = H.dir_bytes(store)
                for cam in CAMERAS:
                    for limit in limits:
                        for run in range(a.runs):
                            for mode in a.modes.split(","):
                                for phase in phases:
                                    self.measure(shape, n, store, sbytes, mode, cam, limit, phase, run)

    def value(self, sel, what):
        done = [r for r in sel if r["exit"] == "0" and r[what] not in ("", "None")]
        return H.median([float(r[what]) for r in done]) if done else None

    def cell(self, sel, what, fmt):
        v = self.value(sel, what)
        if v is not None:
            return fmt.format(v)
        bad = sorted({"OOM" if r["oom"] == "True" else "timeout" if r["timeout"] == "True" else
                      f"exit {r['exit'] or r['signal']}" for r in sel})
        return ", ".join(bad) or "–"

    def report(self):
        a = self.a
        rep = H.Report(self.h, "scale", "Scale: a frame's cost as the volume grows")
        lim = f"{a.limit_mib}MiB" if a.limit_mib else "none"
        rep.add(f"{a.size}^2, {self.h.threads} threads, one directional light without shadows; memory "
                f"limit {lim}; cold: page cache dropped; bricks and MiB read: the cold frame's "
                f"(`--stats`); medians of the finished runs of {a.runs}. vox-render's SHA-256 {self.bin}.", "")
        modes = a.modes.split(",")
        for shape in a.shapes.split(","):
            hdr, rows = ["grid", "store MiB"], []
            for m in modes:
                for c in CAMERAS:
                    hdr += [f"{m}, {c}: cold s", "warm s", "bricks", "MiB read"]
            for n in self.grids:
                sel = lambda m, c, p: self.mine(shape=shape, grid=n, mode=m, camera=c, limit=lim, phase=p)
                if not self.mine(shape=shape, grid=n):
                    continue
                row = [f"{n}^3", f"{int(self.mine(shape=shape, grid=n)[0]['store_bytes']) / H.MiB:.0f}"]
                for m in modes:
                    for c in CAMERAS:
                        row += [self.cell(sel(m, c, "cold"), "wall_s", "{:.2f}"),
                                self.cell(sel(m, c, "warm"), "wall_s", "{:.2f}"),
                                self.cell(sel(m, c, "cold"), "bricks", "{:.0f}"),
                                f"{(self.value(sel(m, c, 'cold'), 'read_bytes') or 0) / H.MiB:.1f}"]
                rows.append(row)
                for m in modes:
                    rep.raw[f"{shape}.{n}.{m}.full.cold_s"] = self.value(sel(m, "full", "cold"), "wall_s")
                    rep.raw[f"{shape}.{n}.{m}.full.read_mib"] = \
                        (self.value(sel(m, "full", "cold"), "read_bytes") or 0) / H.MiB
                cross = [r["cross_mode"] for r in self.mine(shape=shape, grid=n, camera="close")
                         if r["cross_mode"]]
                rep.raw[f"{shape}.{n}.close_identical"] = bool(cross) and all(x == "yes" for x in cross)
            rep.add(f"**{shape}**", "")
            rep.table(hdr, rows)
            self.law(rep, shape, lim)
            self.goals(rep, shape)
            self.limits(rep, shape)
        rep.write()
        return rep.raw

    def law(self, rep, shape, lim):
        """The default full view, cold, per grid: bytes read, read syscalls, CPU and wall time (medians)."""
        rows, prev = [], None
        for n in self.grids:
            sel = self.mine(shape=shape, grid=n, mode="default", camera="full", limit=lim, phase="cold")
            if not sel:
                continue
            v = {k: self.value(sel, k) for k in ("read_bytes", "syscr", "cpu_s", "wall_s")}
            ratio = lambda k: f"{v[k] / prev[k]:.2f}" if prev and v[k] and prev[k] else "–"
            rows.append((f"{n}^3", f"{(v['read_bytes'] or 0) / H.MiB:.1f}", ratio("read_bytes"),
                         f"{v['syscr'] or 0:.0f}", ratio("syscr"), f"{v['cpu_s'] or 0:.2f}", ratio("cpu_s"),
                         f"{v['wall_s'] or 0:.2f}", ratio("wall_s")))
            prev = v
        if rows:
            rep.add("Default full view, cold, medians (ratios: against the grid before):", "")
            rep.table(["grid", "MiB read", "x", "read syscalls", "x", "CPU s", "x", "wall s", "x"], rows)

    def goals(self, rep, shape):
        g = [n for n in self.grids if rep.raw.get(f"{shape}.{n}.default.full.cold_s")]
        if len(g) < 2:
            return
        base, rows = g[0], []
        for n in g[1:]:
            for what, unit in (("cold_s", "time"), ("read_mib", "bytes read")):
                v = rep.raw[f"{shape}.{n}.default.full.{what}"] / rep.raw[f"{shape}.{base}.default.full.{what}"]
                rep.raw[f"{shape}.{n}/{base}.{what}"] = v
                rows.append((f"default full view cold {unit}: {n}^3 / {base}^3", f"{v:.2f}"))
            e = rep.raw.get(f"{shape}.{n}.exact.full.cold_s")
            if e:
                v = rep.raw[f"{shape}.{n}.exact.full.cold_s"] / rep.raw[f"{shape}.{n}.default.full.cold_s"]
                rep.raw[f"{shape}.{n}.exact/default"] = v
                rows.append((f"cold full view at {n}^3: exact / default", f"{v:.2f}"))
        rep.table(["ratio", shape], rows)

    def limits(self, rep, shape):
        if self.a.limit_mib:
            return
        rows = []
        for n in self.grids:
            for m in self.a.modes.split(","):
                for lim in ["none"] + self.a.limits.split(","):
                    sel = self.mine(shape=shape, grid=n, mode=m, camera="full", limit=lim, phase="cold")
                    if sel:
                        rows.append((f"{n}^3", m, lim, f"{int(sel[0]['limit_bytes']) / H.MiB:.1f}"
                                     if lim != "none" else "-",
                                     self.cell(sel, "wall_s", "{:.2f}"),
                                     f"{(self.value(sel, 'peak_bytes') or 0) / H.MiB:.0f}",
                                     max(int(r["failcnt"] or 0) for r in sel),
                                     ", ".join(sorted({r["identical"] for r in sel}))))
        if rows:
            rep.add("Cold full views as the memory limit shrinks (limit: a fraction of the store's size):", "")
            rep.table(["grid", "mode", "limit", "MiB", "cold s", "peak MiB", "failcnt",
                       "pixels as the first run"], rows)


def main(h, a):
    s = Scale(h, a)
    if not a.report_only:
        t0 = time.monotonic()
        s.run()
        H.log(f"measured in {time.monotonic() - t0:.0f} s")
    return s.report()
