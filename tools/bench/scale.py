#!/usr/bin/env python3
"""vox scale benchmark: vox-render as the volume grows and the memory limit shrinks.

Usage (from the repository root; tools/bench/scale.sh wraps this):

  python3 tools/bench/scale.py [--build build] [--work DIR]
      [--grids 1024,2048,4096] [--shapes sphere,bumpy] [--modes default,exact]
      [--limits 1/2,1/4,1/8 | --limit-mib 512] [--runs 3] [--threads 2]
      [--size 1024x1024] [--store SHAPE:N=PATH ...] [--store-8192 PATH]
      [--vdb N=PATH ...] [--timeout SECONDS]
      [--render-args "--flag value ..."] [--no-cold] [--fresh]
      [--out docs/scale.md]
  python3 tools/bench/scale.py --compare A.exr B.exr   # pixel check of two tiled EXRs
  python3 tools/bench/scale.py --report-only ...       # rewrite docs from the CSV only

The scale law, in one command on existing stores:

  nice -n 19 tools/bench/scale.sh --grids 4096,8192,16384,32768 --shapes sphere,bumpy \
      --modes default,exact --limit-mib 512 --store sphere:4096=/data/sphere4096.store ...

For each grid size N and shape (--shapes: sphere, bumpy; 8192 and up are long
runs: stores of GBs and hours of generation) it makes the store `vox-gen SHAPE
WORK/SHAPEN.store --size N` (with its level-of-detail pyramid) unless it exists
or --store SHAPE:N=PATH names one (only read; a named store that is not there
yet is skipped with a note, and a rerun picks it up), then renders a full
view (camera at (0,0,3) looking at the origin, 40 degrees) and a close-up
(camera at (0,0,1.05) looking at (0,0,0.9), 20 degrees: a patch of the unit
sphere's surface) with one directional light without shadows and --threads,
in each --modes (default: no --lod flag, so level of detail when the store has
a pyramid; exact: --lod 0), unlimited and in memory cgroups of each --limits
fraction of the store's size on disk, or only in one cgroup of --limit-mib MiB. Each (camera, limit) gets a cold frame (`sync; echo 3 >
/proc/sys/vm/drop_caches` first; skipped, with a note, when not root) and a
warm frame (the same command again), --runs times; the report shows medians.
A run is killed after --timeout seconds (default: a limited run after 5 times
the slowest unlimited run of its grid, camera and tool, at least 60 s: under a
tight limit a process can thrash, re-reading its code and data for a long time
before the OOM killer acts; with --limit-mib, which runs no unlimited frame,
after 30 min) and recorded as timed out; the same tool, grid,
camera and phase are then not run again at that limit or tighter ones.

Every run is one vox-render process in its own memory cgroup (v1: NAME under
the memory mount, memory.limit_in_bytes, memory.max_usage_in_bytes,
memory.failcnt, memory.oom_control; v2: memory.max, memory.peak,
memory.events); an unlimited run gets a cgroup without a limit so its peak is
measured the same way. The child is moved into the cgroup before it execs.
Recorded per run: whole-process wall time, the cgroup's peak charge (anonymous
memory and the page cache it brought in), failcnt, the OOM kill (SIGKILL with
oom_kill or failcnt set), the child's ru_maxrss (which counts the forked
Python before exec, about 15 MB) and ru_inblock * 512 (bytes
it read from the block device, i.e. its /proc/PID/io read_bytes, from wait4),
vox-render's --stats JSON (render_seconds; bricks: lod.bricks_paged_total
when level of detail is on, else cache.bricks_paged_in; brick bytes:
lod.brick_bytes_read_total, else io.brick_bytes_read; io.read_bytes; the
"memory" object), whether its EXR's pixels are bit-identical to the first
finished run of the same shape, grid, mode and camera (the unlimited one when
there is one), and for close-ups whether they are bit-identical to the other
mode's (this script parses the tiled RLE or ZIP EXRs itself, see --compare).

The report has a section on the scale law: per shape, rows = grid, columns =
mode x camera (cold s, warm s, bricks, MiB read) at the --limit-mib limit (else
unlimited); the issue's ratios (default-mode full view cold time 16384/4096 <=
1.5 and 32768/4096 <= 2, bytes read 32768/4096 <= 2, exact/default at 16384 >=
8; from the smallest grid when 4096 is missing); whether the close-ups were
identical across modes; the load average; and a log-log plot (REPORT-law.svg).

Where --vdb N=PATH gives an OpenVDB file, vdb_render renders the same two
views in the same cgroups (only that: no pixel check against vox).

Results go to WORK/scale.csv, one row per run, written as each run ends;
a rerun skips the runs already there for the same vox-render binary (keyed
by its SHA-256; a rebuilt binary starts afresh), so an interrupted benchmark resumes, and a new build is
measured afresh. --fresh ignores earlier rows. The report (--out, default
docs/scale.md, and the SVG plots beside it) is rewritten after every grid.
Standard library only.
"""

import argparse
import csv
import hashlib
import itertools
import json
import math
import os
import platform
import re
import select
import shlex
import signal
import socket
import statistics
import struct
import subprocess
import sys
import time
import zlib

CAMERAS = {
    "full": {"position": [0, 0, 3], "look_at": [0, 0, 0], "fov_deg": 40},
    "close": {"position": [0, 0, 1.05], "look_at": [0, 0, 0.9], "fov_deg": 20},
}
CAMERA_LABEL = {"full": "full view", "close": "close-up"}
SCENE = {"lights": [{"type": "directional", "direction": [-0.3, -0.5, -1], "shadows": False}],
         "material": {"specular": 0}}
FIELDS = ["bin", "tool", "shape", "mode", "grid", "camera", "limit", "limit_bytes", "phase", "run", "store_bytes",
          "wall_s", "exit", "signal", "oom", "timeout", "peak_bytes", "failcnt", "maxrss_bytes",
          "inblock_bytes", "bricks_paged_in", "cache_misses", "stats_bytes_read",
          "stats_process_read_bytes", "render_s", "hit_pixels", "identical", "diff_pixels",
          "memory", "cgroup", "loadavg", "when",
          "bricks", "brick_bytes", "read_bytes", "lod_setting", "refined_pixels",
          "cross_mode", "cross_mode_pixels"]
SHAPES = ("sphere", "bumpy")
MODES = {"default": [], "exact": ["--lod", "0"]}  # vox-render flags of each mode
MiB = 1 << 20


def log(*a):
    print("scale:", *a, file=sys.stderr, flush=True)


# ---------------------------------------------------------------- EXR reading

def _read_exr(path):
    """Header fields and {(tx, ty): (stored_bytes, raw_size)} of a one-level tiled EXR."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:4] != b"\x76\x2f\x31\x01":
        raise ValueError(f"{path}: not an OpenEXR file")
    flags = struct.unpack_from("<I", data, 4)[0]
    if not flags & 0x200:
        raise ValueError(f"{path}: not a single-part tiled EXR")
    pos, attrs = 8, {}
    while data[pos] != 0:
        end = data.index(b"\0", pos)
        name = data[pos:end].decode()
        end2 = data.index(b"\0", end + 1)
        typ = data[end + 1:end2].decode()
        size = struct.unpack_from("<i", data, end2 + 1)[0]
        attrs[name] = (typ, data[end2 + 5:end2 + 5 + size])
        pos = end2 + 5 + size
    pos += 1
    chans, raw = [], attrs["channels"][1]
    p = 0
    while raw[p] != 0:
        end = raw.index(b"\0", p)
        ptype = struct.unpack_from("<i", raw, end + 1)[0]
        chans.append((raw[p:end].decode(), {0: 4, 1: 2, 2: 4}[ptype]))
        p = end + 17
    x0, y0, x1, y1 = struct.unpack("<4i", attrs["dataWindow"][1])
    w, h = x1 - x0 + 1, y1 - y0 + 1
    tw, th, mode = struct.unpack("<IIB", attrs["tiles"][1])
    if mode & 0xF != 0:
        raise ValueError(f"{path}: only ONE_LEVEL tiled EXRs are supported")
    comp = attrs["compression"][1][0]
    if comp not in (0, 1, 3):
        raise ValueError(f"{path}: compression {comp} (only none, RLE and ZIP are supported)")
    nx, ny = -(-w // tw), -(-h // th)
    offsets = struct.unpack_from(f"<{nx * ny}Q", data, pos)
    tiles = {}
    bpp = sum(s for _, s in chans)
    for off in offsets:
        tx, ty, lx, ly, size = struct.unpack_from("<5i", data, off)
        cw, ch = min(tw, w - tx * tw), min(th, h - ty * th)
        tiles[(tx, ty)] = (data[off + 20:off + 20 + size], cw * ch * bpp, cw, ch)
    if len(tiles) != nx * ny:
        raise ValueError(f"{path}: {len(tiles)} tiles, expected {nx * ny}")
    return {"w": w, "h": h, "chans": chans, "tiles": tiles, "comp": comp}


def _rle_decode(stored):
    """OpenEXR's RLE: a signed count byte c; c < 0: -c literal bytes follow; else the next byte c + 1 times."""
    out, i = bytearray(), 0
    while i < len(stored):
        c = stored[i] - 256 if stored[i] > 127 else stored[i]
        if c < 0:
            out += stored[i + 1:i + 1 - c]
            i += 1 - c
        else:
            out += bytes([stored[i + 1]]) * (c + 1)
            i += 2
    return bytes(out)


def _tile_transformed(stored, raw_size, comp=3):
    """RLE's or ZIP's predicted, interleaved bytes (a bijection of the raw pixels), or None for a raw tile."""
    if len(stored) == raw_size:
        return None
    return _rle_decode(stored) if comp == 1 else zlib.decompress(stored)


def _tile_raw(stored, raw_size, comp=3):
    if len(stored) == raw_size:
        return stored
    d = _tile_transformed(stored, raw_size, comp)
    t = bytes(v & 0xFF for v in itertools.accumulate(d[1:], lambda a, b: a + b - 128, initial=d[0]))
    half = (len(t) + 1) // 2
    out = bytearray(len(t))
    out[0::2] = t[:half]
    out[1::2] = t[half:]
    return bytes(out)


def _pixels_differing(raw_a, raw_b, chans, cw, ch):
    n = 0
    line = cw * sum(s for _, s in chans)
    for y in range(ch):
        la, lb = raw_a[y * line:(y + 1) * line], raw_b[y * line:(y + 1) * line]
        if la == lb:
            continue
        bad, o = set(), 0
        for _, s in chans:
            for x in range(cw):
                if la[o + x * s:o + (x + 1) * s] != lb[o + x * s:o + (x + 1) * s]:
                    bad.add(x)
            o += cw * s
        n += len(bad)
    return n


def compare_exr(a, b):
    """Number of pixels whose channel values differ bit for bit (0: identical)."""
    ea, eb = _read_exr(a), _read_exr(b)
    if (ea["w"], ea["h"], ea["chans"]) != (eb["w"], eb["h"], eb["chans"]):
        raise ValueError(f"{a} and {b} differ in size or channels")
    n = 0
    for key, (sa, size, cw, ch) in ea["tiles"].items():
        sb = eb["tiles"][key][0]
        if sa == sb:
            continue
        ta, tb = _tile_transformed(sa, size, ea["comp"]), _tile_transformed(sb, size, eb["comp"])
        if ta is not None and tb is not None and ta == tb:
            continue
        n += _pixels_differing(_tile_raw(sa, size, ea["comp"]), _tile_raw(sb, size, eb["comp"]),
                               ea["chans"], cw, ch)
    return n


def exr_covered_pixels(path):
    """Pixels with A > 0 (a self-check against the renderer's hit_pixels)."""
    e = _read_exr(path)
    names = [c for c, _ in e["chans"]]
    if "A" not in names:
        raise ValueError(f"{path}: no A channel")
    n = 0
    for stored, size, cw, ch in e["tiles"].values():
        raw = _tile_raw(stored, size, e["comp"])
        line = cw * sum(s for _, s in e["chans"])
        off = sum(s for c, s in e["chans"][:names.index("A")]) * cw
        fmt = {4: "f", 2: "e"}[e["chans"][names.index("A")][1]]  # float or half
        for y in range(ch):
            vals = struct.unpack_from(f"<{cw}{fmt}", raw, y * line + off)
            n += sum(1 for v in vals if v > 0)
    return n


# ---------------------------------------------------------------- cgroups

class Cgroups:
    def __init__(self):
        self.version, self.mount, self.why = 0, "", ""
        try:
            mountinfo = open("/proc/self/mountinfo").read().splitlines()
        except OSError as e:
            self.why = f"cannot read /proc/self/mountinfo: {e}"
            return
        v2 = ""
        for line in mountinfo:
            f = line.split()
            if "-" not in f:
                continue
            d = f.index("-")
            typ, opts = f[d + 1], "," + f[d + 3] + ","
            if typ == "cgroup" and ",memory," in opts:
                self.version, self.mount = 1, f[4]
                break
            if typ == "cgroup2" and not v2:
                v2 = f[4]
        if not self.version and v2:
            try:
                if "memory" not in open(v2 + "/cgroup.controllers").read():
                    self.why = f"the cgroup v2 hierarchy at {v2} has no memory controller"
                    return
                if "memory" not in open(v2 + "/cgroup.subtree_control").read():
                    with open(v2 + "/cgroup.subtree_control", "w") as fh:
                        fh.write("+memory")
                self.version, self.mount = 2, v2
            except OSError as e:
                self.why = f"cannot use the memory controller of {v2}: {e}"
                return
        if not self.version:
            self.why = self.why or "no memory cgroup hierarchy is mounted"
            return
        probe = f"{self.mount}/vox_scale_probe_{os.getpid()}"
        try:
            os.mkdir(probe)
            try:
                self._write(probe, "memory.limit_in_bytes" if self.version == 1 else "memory.max", str(1 << 30))
            finally:
                os.rmdir(probe)
        except OSError as e:
            self.why = f"cannot make a memory cgroup under {self.mount}: {e}"
            self.version = 0

    @staticmethod
    def _write(d, name, text):
        with open(f"{d}/{name}", "w") as fh:
            fh.write(text)

    @staticmethod
    def _read(d, name):
        try:
            return open(f"{d}/{name}").read()
        except OSError:
            return ""

    def _num(self, d, name):
        s = self._read(d, name).strip()
        return int(s) if s.isdigit() else 0

    def _key(self, d, name, key):
        for line in self._read(d, name).splitlines():
            p = line.split()
            if len(p) == 2 and p[0] == key and p[1].isdigit():
                return int(p[1])
        return 0

    def remove_stale(self):
        """Removes empty cgroups left by an earlier run of this script that was killed."""
        for name in os.listdir(self.mount) if self.version else []:
            m = re.fullmatch(r"vox_scale_(\d+)_\d+", name)
            if m and not os.path.exists(f"/proc/{m.group(1)}"):
                try:
                    os.rmdir(f"{self.mount}/{name}")
                except OSError:
                    pass

    def make(self, limit):
        d = f"{self.mount}/vox_scale_{os.getpid()}_{time.monotonic_ns()}"
        os.mkdir(d)
        if limit:
            if self.version == 1:
                self._write(d, "memory.limit_in_bytes", str(limit))
                swap = any(l.startswith("SwapTotal:") and l.split()[1] != "0"
                           for l in open("/proc/meminfo"))
                if swap and os.path.exists(f"{d}/memory.memsw.limit_in_bytes"):
                    self._write(d, "memory.memsw.limit_in_bytes", str(limit))
            else:
                self._write(d, "memory.max", str(limit))
                if os.path.exists(f"{d}/memory.swap.max"):
                    self._write(d, "memory.swap.max", "0")
        return d

    def finish(self, d):
        """(peak bytes, failcnt, oom kills) of cgroup d, which is then removed."""
        if self.version == 1:
            peak = self._num(d, "memory.max_usage_in_bytes")
            fail = max(self._num(d, "memory.failcnt"), self._num(d, "memory.memsw.failcnt"))
            oom = self._key(d, "memory.oom_control", "oom_kill")
        else:
            peak = self._num(d, "memory.peak")
            fail = self._key(d, "memory.events", "max")
            oom = self._key(d, "memory.events", "oom_kill")
        for _ in range(200):
            try:
                os.rmdir(d)
                break
            except OSError:
                time.sleep(0.02)
        return peak, fail, oom


def drop_page_cache():
    os.sync()
    try:
        with open("/proc/sys/vm/drop_caches", "w") as fh:
            fh.write("3")
        return True
    except OSError:
        return False


def run_process(argv, cg, limit, stdout, stderr, timeout):
    """Runs argv in a fresh cgroup (or none when cg is None). Returns a result dict."""
    d = cg.make(limit) if cg else None
    go_r, go_w = os.pipe()
    pid = os.fork()
    if pid == 0:
        try:
            os.close(go_w)
            if os.read(go_r, 1) != b"g":
                os._exit(126)
            o = os.open(stdout, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            e = os.open(stderr, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            os.dup2(o, 1)
            os.dup2(e, 2)
            os.execv(argv[0], argv)
        finally:
            os._exit(127)
    os.close(go_r)
    try:
        if d:
            with open(f"{d}/cgroup.procs", "w") as fh:
                fh.write(str(pid))
    except OSError:
        os.close(go_w)
        os.waitpid(pid, 0)
        cg.finish(d)
        raise
    pidfd = os.pidfd_open(pid)
    t0 = time.monotonic()
    os.write(go_w, b"g")
    os.close(go_w)
    poller = select.poll()
    poller.register(pidfd, select.POLLIN)
    timed_out = False
    try:
        if not poller.poll(int(timeout * 1000)):
            timed_out = True
            os.kill(pid, signal.SIGKILL)
    except BaseException:  # interrupted: leave no child or cgroup behind
        os.kill(pid, signal.SIGKILL)
        os.wait4(pid, 0)
        if d:
            cg.finish(d)
        raise
    _, status, ru = os.wait4(pid, 0)
    wall = time.monotonic() - t0
    os.close(pidfd)
    r = {"wall_s": f"{wall:.3f}", "exit": "", "signal": "", "timeout": int(timed_out),
         "maxrss_bytes": ru.ru_maxrss * 1024, "inblock_bytes": ru.ru_inblock * 512,
         "peak_bytes": "", "failcnt": "", "oom": 0}
    if os.WIFEXITED(status):
        r["exit"] = os.WEXITSTATUS(status)
    else:
        r["signal"] = os.WTERMSIG(status)
    if d:
        peak, fail, oom = cg.finish(d)
        r["peak_bytes"], r["failcnt"] = peak, fail
        r["oom"] = int(r["signal"] == signal.SIGKILL and not timed_out and (oom > 0 or fail > 0))
    return r


# ---------------------------------------------------------------- helpers

def sha256(path):
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()[:16]


def dir_bytes(path):
    if os.path.isfile(path):
        return os.path.getsize(path)
    total = 0
    for root, _, files in os.walk(path):
        for f in files:
            total += os.path.getsize(os.path.join(root, f))
    return total


def parse_fraction(s):
    m = re.fullmatch(r"\s*(\d+)\s*/\s*(\d+)\s*", s)
    if not m or int(m.group(1)) <= 0 or int(m.group(2)) <= 0 or int(m.group(1)) > int(m.group(2)):
        raise argparse.ArgumentTypeError(f"limit '{s}': expected a fraction like 1/4")
    return s.strip().replace(" ", "")


def frac_value(s):
    a, b = s.split("/")
    return int(a) / int(b)


def limit_bytes_of(limit, store_bytes):
    """Bytes of a limit label: 'none' (0), a fraction of the store ('1/4') or fixed ('512MiB')."""
    if limit == "none":
        return 0
    if limit.endswith("MiB"):
        return int(limit[:-3]) * MiB
    return int(store_bytes * frac_value(limit))


def wait_for(path, seconds=120):
    """The lead's build may replace a binary under us: wait until it is back."""
    t0 = time.monotonic()
    while not os.access(path, os.X_OK):
        if time.monotonic() - t0 > seconds:
            sys.exit(f"scale: {path} not found or not executable for {seconds} s")
        time.sleep(1)


def loadavg():
    try:
        return open("/proc/loadavg").read().split()[0]
    except OSError:
        return ""


def loadavg3():
    try:
        return ", ".join(open("/proc/loadavg").read().split()[:3])
    except OSError:
        return "?"


def machine_notes(cg, is_root):
    cpu = ""
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    mem = ""
    try:
        for line in open("/proc/meminfo"):
            if line.startswith("MemTotal:"):
                mem = f"{int(line.split()[1]) // 1024 // 1024} GiB"
    except OSError:
        pass
    return {"host": socket.gethostname(), "kernel": platform.release(), "cpu": cpu,
            "cores": os.cpu_count(), "memory": mem,
            "cgroup": f"v{cg.version} at {cg.mount}" if cg.version else f"none ({cg.why})",
            "root": is_root}


# ---------------------------------------------------------------- the benchmark

class Bench:
    def __init__(self, a):
        self.a = a
        self.render = os.path.join(a.build, "tools/render/vox-render")
        self.gen = os.path.join(a.build, "tools/gen/vox-gen")
        for p in (self.render, self.gen):
            if not os.access(p, os.X_OK):
                time.sleep(5)  # being relinked?
            if not os.access(p, os.X_OK):
                sys.exit(f"scale: {p} not found or not executable (build it: "
                         f"cmake --build {a.build} --target vox-render vox-gen)")
        os.makedirs(os.path.join(a.work, "out"), exist_ok=True)
        for attempt in range(30):
            try:
                self.bin = sha256(self.render)
                break
            except OSError:
                time.sleep(2)
        else:
            sys.exit(f"scale: cannot read {self.render}")
        self.csv = os.path.join(a.work, "scale.csv")
        self.rows = []
        if os.path.exists(self.csv) and not a.fresh:
            with open(self.csv, newline="") as f:
                rd = csv.DictReader(f)
                header = rd.fieldnames or []
                self.rows = list(rd)
            for r in self.rows:  # rows of earlier versions of this script: sphere, no --lod flag
                for k in FIELDS:
                    if r.get(k) is None:
                        r[k] = {"shape": "sphere", "mode": "default" if r.get("tool") == "vox"
                                else "-"}.get(k, "")
            if header != FIELDS:  # rewrite with this version's columns, so appends line up
                with open(self.csv, "w", newline="") as f:
                    w = csv.DictWriter(f, fieldnames=FIELDS, extrasaction="ignore")
                    w.writeheader()
                    w.writerows(self.rows)
        elif os.path.exists(self.csv):
            os.replace(self.csv, self.csv + f".{int(time.time())}.old")
        self.is_root = os.geteuid() == 0
        self.cg = Cgroups()
        self.cg.remove_stale()
        self.notes = []
        if not self.is_root:
            self.notes.append("not root: cold frames skipped (dropping the page cache needs root)")
        if not self.cg.version:
            self.notes.append(f"no writable memory cgroup ({self.cg.why}): limited runs skipped, "
                              "peaks are ru_maxrss")
        help_text = subprocess.run([self.render, "--help"], capture_output=True, text=True)
        self.has_memory_flag = "--memory-mb" in (help_text.stdout + help_text.stderr)
        if "exact" in a.modes and "--lod" not in help_text.stdout + help_text.stderr:
            sys.exit(f"scale: {self.render} has no --lod flag, so no exact mode (--modes default)")
        self.vdb_render = None
        if a.vdb:
            for d in os.environ.get("PATH", "").split(":"):
                if os.access(os.path.join(d, "vdb_render"), os.X_OK):
                    self.vdb_render = os.path.join(d, "vdb_render")
                    break
            if not self.vdb_render:
                self.notes.append("vdb_render not on PATH: its runs skipped")
        self.started = time.strftime("%Y-%m-%d %H:%M:%S %Z")
        self.load_start = loadavg3()
        scene = os.path.join(a.work, "scene.json")
        with open(scene, "w") as f:
            json.dump(SCENE, f)
        self.scene = scene
        w, h = a.size
        self.cams = {}
        for name, c in CAMERAS.items():
            path = os.path.join(a.work, f"cam_{name}_{w}x{h}.json")
            with open(path, "w") as f:
                json.dump(dict(c, up=[0, 1, 0], width=w, height=h, projection="perspective"), f)
            self.cams[name] = path

    def have(self, key):
        for r in self.rows:
            if all(str(r[k]) == str(v) for k, v in key.items()):
                return r
        return None

    def append(self, row):
        new = not os.path.exists(self.csv)
        with open(self.csv, "a", newline="") as f:
            w = csv.DictWriter(f, fieldnames=FIELDS)
            if new:
                w.writeheader()
            w.writerow({k: row.get(k, "") for k in FIELDS})
        self.rows.append({k: str(row.get(k, "")) for k in FIELDS})

    def store_for(self, shape, n):
        """The store of SHAPE at N^3: --store's, else WORK/SHAPEN.store (made by vox-gen, with
        its pyramid). None when a given store is not there (yet): that grid is skipped."""
        given = self.a.stores.get((shape, n))
        if given:
            if not os.path.isfile(os.path.join(given, "bricks.vxb")):
                log(f"--store {shape}:{n}={given}: not a vox store (yet? no bricks.vxb): skipped")
                self.notes.append(f"--store {shape}:{n}={given} was not a store when this ran: skipped")
                return None
            return given
        store = os.path.join(self.a.work, f"{shape}{n}.store")
        if os.path.isfile(os.path.join(store, "bricks.vxb")):
            return store  # vox-gen renames a finished store into place
        log(f"vox-gen {shape} {store} --size {n}")
        t0 = time.monotonic()
        wait_for(self.gen)
        r = subprocess.run([self.gen, shape, store, "--size", str(n), "--quiet", "--force"])
        if r.returncode != 0:
            sys.exit(f"scale: vox-gen {shape} failed for --size {n} (exit {r.returncode})")
        log(f"  made in {time.monotonic() - t0:.1f} s")
        return store

    def ref_path(self, shape, n, mode, cam):
        return os.path.join(self.a.work, "out", f"ref_{self.bin}_{shape}{n}_{mode}_{cam}.exr")

    def measure(self, tool, shape, mode, n, store, store_bytes, cam, limit, phase, run):
        key = {"bin": self.bin, "tool": tool, "shape": shape, "mode": mode, "grid": n,
               "camera": cam, "limit": limit, "phase": phase, "run": run}
        if self.have(key):
            return
        limit_bytes = limit_bytes_of(limit, store_bytes)
        if limit != "none" and any(
                r["bin"] == self.bin and r["tool"] == tool and r["shape"] == shape and
                r["mode"] == mode and r["grid"] == str(n) and
                r["camera"] == cam and r["phase"] == phase and
                (r["timeout"] == "1" or r["oom"] == "1") and
                r["limit"] != "none" and int(r["limit_bytes"]) >= limit_bytes for r in self.rows):
            return  # that limit or a looser one timed out or was OOM-killed: this would be too, slowly
        tag = f"{tool}_{shape}{n}_{mode}_{cam}_{limit.replace('/', 'of')}_{phase}_{run}"
        ref = self.ref_path(shape, n, mode, cam)
        out = os.path.join(self.a.work, "out")
        exr = os.path.join(out, tag + ".exr")
        stats = os.path.join(out, tag + ".json")
        for p in (exr, stats):
            if os.path.exists(p):
                os.remove(p)
        if tool == "vox":
            argv = [self.render, store, "--cam", self.cams[cam], "--scene", self.scene,
                    "--threads", str(self.a.threads), "--stats", stats, "-o", exr, "--quiet"]
            argv += MODES[mode] + shlex.split(self.a.render_args)
        else:
            c = CAMERAS[cam]
            argv = [self.vdb_render, store, exr, "-translate", ",".join(map(str, c["position"])),
                    "-lookat", ",".join(map(str, c["look_at"])), "-up", "0,1,0",
                    "-fov", str(c["fov_deg"]), "-res", "%dx%d" % self.a.size,
                    "-cpus", str(self.a.threads), "-shader", "diffuse"]
        wait_for(argv[0])
        if phase == "cold" and not drop_page_cache():
            log("cannot drop the page cache; cold run skipped")
            return
        timeout = self.a.timeout
        if not timeout:
            # A limited run that takes far longer than the unlimited one is
            # thrashing (re-reading its code and data from disk); give up.
            base = [float(r["wall_s"]) for r in self.rows
                    if r["bin"] == self.bin and r["tool"] == tool and r["shape"] == shape
                    and r["mode"] == mode and r["grid"] == str(n)
                    and r["camera"] == cam and r["limit"] == "none" and r["exit"] == "0"]
            # Without an unlimited run (--limit-mib) there is nothing to compare with: 30 min.
            timeout = (max(60.0, 5 * max(base)) if base and limit != "none" else
                       1800.0 if self.a.limit_mib else 7200.0)
        log(f"{tag}: limit {limit_bytes // MiB if limit_bytes else 'none'} MiB ...")
        r = run_process(argv, self.cg if self.cg.version else None, limit_bytes,
                        os.path.join(out, tag + ".out"), os.path.join(out, tag + ".err"),
                        timeout)
        row = dict(key, limit_bytes=limit_bytes, store_bytes=store_bytes, loadavg=loadavg(),
                   when=time.strftime("%Y-%m-%d %H:%M:%S"),
                   cgroup=f"v{self.cg.version}" if self.cg.version else "none", **r)
        if os.path.exists(stats):
            try:
                s = json.load(open(stats))
                cache, io, lod = s.get("cache", {}), s.get("io", {}), s.get("lod", {})
                row["bricks_paged_in"] = cache.get("bricks_paged_in", "")
                row["cache_misses"] = cache.get("misses", "")
                row["stats_bytes_read"] = cache.get("bytes_read", io.get("bytes_read", ""))
                row["stats_process_read_bytes"] = cache.get(
                    "process_read_bytes", io.get("process_read_bytes", ""))
                row["render_s"] = s.get("timings", {}).get("render_seconds", "")
                row["hit_pixels"] = s.get("image", {}).get("hit_pixels", "")
                # Level of detail pages bricks of the pyramid too: its totals count every level.
                row["bricks"] = lod.get("bricks_paged_total", cache.get("bricks_paged_in", ""))
                row["brick_bytes"] = lod.get("brick_bytes_read_total", io.get("brick_bytes_read", ""))
                row["read_bytes"] = io.get("read_bytes", "")
                row["lod_setting"] = lod.get("setting", "")
                row["refined_pixels"] = lod.get("refined_pixels", "")
                if "memory" in s:
                    row["memory"] = json.dumps(s["memory"], separators=(",", ":"))
            except (OSError, ValueError, AttributeError) as e:
                log(f"  {stats}: {e}")
        ok = row["exit"] == 0 and os.path.exists(exr)
        if ok and tool == "vox":
            # The first finished run of a configuration is its reference (the unlimited one when
            # there is one: limits run loosest first); the others are compared with it.
            if not os.path.exists(ref):
                os.replace(exr, ref)
                row["identical"] = "ref"
                exr = ref
            else:
                try:
                    d = compare_exr(ref, exr)
                    row["identical"] = "yes" if d == 0 else "no"
                    row["diff_pixels"] = d
                except (OSError, ValueError, KeyError, zlib.error) as e:
                    row["identical"] = f"error: {e}"
            # Close-ups: the default mode's frame against the exact one (the other mode's reference).
            other = [m for m in MODES if m != mode]
            oref = self.ref_path(shape, n, other[0], cam) if other else ""
            if cam == "close" and os.path.exists(oref):
                try:
                    d = compare_exr(oref, exr)
                    row["cross_mode"] = "yes" if d == 0 else "no"
                    row["cross_mode_pixels"] = d
                except (OSError, ValueError, KeyError, zlib.error) as e:
                    row["cross_mode"] = f"error: {e}"
        if os.path.exists(exr) and exr != ref:
            os.remove(exr)
        state = "ok" if ok else ("OOM-killed" if row["oom"] else
                                 "timeout" if row["timeout"] else f"exit {row['exit']} signal {row['signal']}")
        log(f"  {state}, {float(row['wall_s']):.2f} s, peak "
            f"{int(row['peak_bytes'] or row['maxrss_bytes']) // MiB} MiB, {row.get('identical', '')}"
            + (f", vs other mode {row['cross_mode']}" if row.get("cross_mode") else ""))
        self.append(row)

    def run(self):
        a = self.a
        phases = ["cold", "warm"] if self.is_root and not a.no_cold else ["warm"]
        if a.no_cold:
            self.notes.append("--no-cold: cold frames not run")
        if a.limit_mib:
            limits = [f"{a.limit_mib}MiB"] if self.cg.version else []
        else:
            limits = ["none"] + (a.limits if self.cg.version else [])
        for n in a.grids:
            if not a.report_only:
                for shape in a.shapes:
                    store = self.store_for(shape, n)
                    if not store:
                        continue
                    store_bytes = dir_bytes(store)
                    if "default" in a.modes and not os.path.isdir(os.path.join(store, "lod")):
                        self.notes.append(f"{store} has no pyramid (lod/): its default mode is the exact frame")
                    vdb = a.vdb.get(n) if shape == "sphere" else None
                    for cam in CAMERAS:
                        for limit in limits:
                            for mode in a.modes:
                                for run in range(a.runs):
                                    for phase in phases:
                                        self.measure("vox", shape, mode, n, store, store_bytes, cam,
                                                     limit, phase, run)
                            if vdb and self.vdb_render:
                                for run in range(a.runs):
                                    for phase in phases:
                                        self.measure("vdb_render", shape, "-", n, vdb, store_bytes,
                                                     cam, limit, phase, run)
                if n != a.grids[-1]:
                    self.report()
        self.report()

    # ------------------------------------------------------------ the scale law

    def law_rows(self, rows):
        lim = f"{self.a.limit_mib}MiB" if self.a.limit_mib else "none"
        return lim, [r for r in rows if r["tool"] == "vox" and r["limit"] == lim]

    @staticmethod
    def law_value(sel, what):
        """Median over the finished runs: wall s, render s, bricks or MiB read (None: none finished)."""
        done = [r for r in sel if r["exit"] == "0"]
        if what == "read":
            v = [float(r["read_bytes"] if r["read_bytes"] not in ("", None) else r["inblock_bytes"]) / MiB
                 for r in done if (r["read_bytes"] or r["inblock_bytes"]) not in ("", None)]
        elif what == "bricks":  # rows of earlier versions have only bricks_paged_in
            v = [float(r["bricks"] or r["bricks_paged_in"]) for r in done
                 if (r["bricks"] or r["bricks_paged_in"]) not in ("", None)]
        else:
            field = {"wall": "wall_s", "render": "render_s"}[what]
            v = [float(r[field]) for r in done if r[field] not in ("", None)]
        return statistics.median(v) if v else None

    @staticmethod
    def law_failure(sel):
        if not sel:
            return "–"
        bad = [r for r in sel if r["exit"] != "0"]
        what = sorted({"OOM" if r["oom"] == "1" else "timeout" if r["timeout"] == "1" else
                       f"exit {r['exit']}" if r["exit"] else f"signal {r['signal']}" for r in bad})
        return ", ".join(what) or "–"

    def law(self, rows, grids, svg):
        a = self.a
        lim, vox = self.law_rows(rows)
        L = ["## The scale law\n"]
        if not vox:
            L.append(f"No vox runs at limit `{lim}` yet.\n")
            return L
        shapes = [s for s in SHAPES if any(r["shape"] == s for r in vox)]
        modes = [m for m in MODES if any(r["mode"] == m for r in vox)]
        limtext = (f"in a memory cgroup of {a.limit_mib} MiB (`--limit-mib`), whatever the grid"
                   if a.limit_mib else "in a memory cgroup without a limit")
        L.append(f"Every frame {limtext}, {a.size[0]}x{a.size[1]} at the full view and at the close-up, in each "
                 "mode (**default**: no `--lod` flag; **exact**: `--lod 0`). **cold s**: the whole "
                 "process's wall time after `sync; echo 3 > /proc/sys/vm/drop_caches`; **warm s**: the "
                 "same command again; **bricks**: bricks paged in by the cold frame (every level of "
                 "the pyramid: `--stats` lod.bricks_paged_total, else cache.bricks_paged_in); "
                 "**MiB read**: what the cold process read from storage (`--stats` io.read_bytes). "
                 f"Medians of the finished runs ({a.runs} per cell asked); a failed cell says how it ended.\n")
        sel_of = {}
        for r in vox:
            sel_of.setdefault((r["shape"], int(r["grid"]), r["mode"], r["camera"], r["phase"]), []).append(r)

        def sel(shape, n, mode, cam, phase):
            return sel_of.get((shape, n, mode, cam, phase), [])

        def cell(shape, n, mode, cam, phase, what):
            s = sel(shape, n, mode, cam, phase)
            v = self.law_value(s, what)
            if v is None:
                return self.law_failure(s)
            return f"{v:.0f}" if what == "bricks" else f"{v:.1f}" if what == "read" else f"{v:.2f}"

        for shape in shapes:
            L.append(f"**{shape}**\n")
            hdr = ["grid", "store MiB"]
            for mode in modes:
                for cam in CAMERAS:
                    c = f"{mode}, {CAMERA_LABEL[cam]}"
                    hdr += [f"{c}: cold s", "warm s", "bricks", "MiB read"]
            L.append("| " + " | ".join(hdr) + " |")
            L.append("|" + "---|" * len(hdr))
            for n in grids:
                sr = [r for r in vox if r["shape"] == shape and int(r["grid"]) == n]
                if not sr:
                    continue
                line = [f"{n}³", f"{int(sr[0]['store_bytes']) / MiB:.0f}"]
                for mode in modes:
                    for cam in CAMERAS:
                        line += [cell(shape, n, mode, cam, "cold", "wall"),
                                 cell(shape, n, mode, cam, "warm", "wall"),
                                 cell(shape, n, mode, cam, "cold", "bricks"),
                                 cell(shape, n, mode, cam, "cold", "read")]
                L.append("| " + " | ".join(line) + " |")
            L.append("")
            missing = [n for n in a.grids if not any(r["shape"] == shape and int(r["grid"]) == n
                                                     for r in vox)]
            if missing:
                L.append(f"{shape}: not measured (yet): " + ", ".join(f"{n}³" for n in missing)
                         + " (no store, or not run).\n")

        # The goals, as ratios of cold full views.
        def ratio(shape, num, den, what, mode_n="default", mode_d="default"):
            v1 = self.law_value(sel(shape, num, mode_n, "full", "cold"), what)
            v0 = self.law_value(sel(shape, den, mode_d, "full", "cold"), what)
            return (v1 / v0, v1, v0) if v1 and v0 else None

        have = sorted({int(r["grid"]) for r in vox})
        base = 4096 if 4096 in have else (have[0] if have else 4096)
        unit = {"wall": "s", "render": "s", "read": "MiB", "bricks": ""}
        goals = [(f"full view cold time, default: {base * 4}³ / {base}³", "≤ 1.5", 1.5, "le",
                  lambda sh, w: ratio(sh, base * 4, base, w), ("wall", "render")),
                 (f"full view cold time, default: {base * 8}³ / {base}³", "≤ 2", 2, "le",
                  lambda sh, w: ratio(sh, base * 8, base, w), ("wall", "render")),
                 (f"full view bytes read, default: {base * 8}³ / {base}³", "≤ 2", 2, "le",
                  lambda sh, w: ratio(sh, base * 8, base, w), ("read",)),
                 (f"full view cold time at {base * 4}³: exact / default", "≥ 8", 8, "ge",
                  lambda sh, w: ratio(sh, base * 4, base * 4, w, "exact", "default"), ("wall", "render")),
                 (f"full view bytes read at {base * 4}³: exact / default", "–", None, "",
                  lambda sh, w: ratio(sh, base * 4, base * 4, w, "exact", "default"), ("read",)),
                 (f"full view bricks at {base * 4}³: exact / default", "–", None, "",
                  lambda sh, w: ratio(sh, base * 4, base * 4, w, "exact", "default"), ("bricks",))]
        L.append("The issue's goals (cold full views; time: the whole process's wall time, "
                 "render_seconds alone in brackets; the verdict is on wall time):\n")
        L.append("| ratio | goal | " + " | ".join(shapes) + " |")
        L.append("|---|---|" + "---|" * len(shapes))
        for label, goal, g, how, fn, whats in goals:
            cells = []
            for shape in shapes:
                r0 = fn(shape, whats[0])
                if not r0:
                    cells.append("not measured")
                    continue
                u = unit[whats[0]]
                fmt = "{:.0f}" if whats[0] == "bricks" else "{:.1f}" if whats[0] == "read" else "{:.2f}"
                c = f"**{r0[0]:.2f}** ({fmt.format(r0[1])} / {fmt.format(r0[2])}{(' ' + u) if u else ''})"
                if len(whats) > 1:
                    r1 = fn(shape, whats[1])
                    c += f" [render {r1[0]:.2f}]" if r1 else ""
                if g:
                    c += ": met" if (r0[0] <= g if how == "le" else r0[0] >= g) else ": **not met**"
                cells.append(c)
            L.append(f"| {label} | {goal} | " + " | ".join(cells) + " |")
        L.append("")
        if base != 4096:
            L.append(f"(4096³ not measured: the ratios are taken from {base}³, the smallest grid, "
                     "with the same factors 4 and 8; the issue's goals are for 4096³.)\n")
        # Close-ups: default mode against exact, bit for bit.
        if len(modes) > 1:
            L.append("Close-ups, default mode against exact, bit for bit (`scale.py --compare` of "
                     "each run's EXR with the other mode's first frame):\n")
            for shape in shapes:
                parts = []
                for n in grids:
                    c = [r for r in vox if r["shape"] == shape and int(r["grid"]) == n
                         and r["camera"] == "close" and r["cross_mode"]]
                    if not c:
                        continue
                    if all(r["cross_mode"] == "yes" for r in c):
                        parts.append(f"{n}³ identical ({len(c)}/{len(c)} runs)")
                    else:
                        worst = max((int(r["cross_mode_pixels"] or 0) for r in c), default=0)
                        parts.append(f"{n}³ **differ** ({sum(r['cross_mode'] != 'yes' for r in c)}/{len(c)} "
                                     f"runs, up to {worst} pixels)")
                L.append(f"- {shape}: " + ("; ".join(parts) if parts else "not compared yet") + ".")
            L.append("")
        L.append(f"![cold time, bytes read and bricks against grid size, both modes]({os.path.basename(svg)})\n")
        return L

    def law_plot(self, rows, grids):
        """2x3 log-log SVG: cold wall time, MiB read and bricks against grid size, per camera."""
        _, vox = self.law_rows(rows)
        W, H, pad = 330, 260, 52
        colors = {"default": "#1f77b4", "exact": "#d62728"}
        dashes = {"sphere": "", "bumpy": ' stroke-dasharray="6,3"'}
        parts = []
        whats = [("wall", "cold wall time (s)"), ("read", "cold MiB read"), ("bricks", "bricks paged (cold)")]
        gx = [math.log2(n) for n in grids] or [10]
        x0, x1 = min(gx) - 0.3, max(gx) + 0.3
        for ci, cam in enumerate(CAMERAS):
            for wi, (what, ylabel) in enumerate(whats):
                ox, oy = wi * (W + 16) + 10, ci * (H + 26) + 40
                series = {}
                for shape in SHAPES:
                    for mode in MODES:
                        pts = []
                        for n in grids:
                            s = [r for r in vox if r["shape"] == shape and r["mode"] == mode and
                                 int(r["grid"]) == n and r["camera"] == cam and r["phase"] == "cold"]
                            v = self.law_value(s, what)
                            if v and v > 0:
                                pts.append((n, v))
                        if pts:
                            series[(shape, mode)] = pts
                vals = [v for p in series.values() for _, v in p]
                lo, hi = (min(vals), max(vals)) if vals else (0.1, 10)
                lo, hi = 10 ** math.floor(math.log10(lo)), 10 ** math.ceil(math.log10(hi))
                if hi <= lo:
                    hi = lo * 10

                def X(n):
                    return ox + pad + (math.log2(n) - x0) / (x1 - x0) * (W - pad - 10)

                def Y(v):
                    return oy + H - 30 - (math.log10(v) - math.log10(lo)) / (math.log10(hi) - math.log10(lo)) * (H - 50)

                parts.append(f'<rect x="{ox + pad}" y="{oy + 20}" width="{W - pad - 10}" height="{H - 50}" '
                             'fill="none" stroke="#888"/>')
                parts.append(f'<text x="{ox + W / 2 + 20}" y="{oy + 14}" text-anchor="middle" font-size="13">'
                             f'{CAMERA_LABEL[cam]}: {ylabel}</text>')
                e = math.log10(lo)
                while e <= math.log10(hi) + 1e-9:
                    y = Y(10 ** e)
                    parts.append(f'<line x1="{ox + pad}" x2="{ox + W - 10}" y1="{y:.1f}" y2="{y:.1f}" stroke="#ddd"/>')
                    parts.append(f'<text x="{ox + pad - 4}" y="{y + 4:.1f}" text-anchor="end" '
                                 f'font-size="11">{10 ** e:g}</text>')
                    e += 1
                for n in grids:
                    parts.append(f'<text x="{X(n):.1f}" y="{oy + H - 14}" text-anchor="middle" '
                                 f'font-size="11">{n}³</text>')
                for (shape, mode), pts in series.items():
                    col = colors[mode]
                    xy = [(X(n), Y(v)) for n, v in pts]
                    if len(xy) > 1:
                        parts.append(f'<polyline fill="none" stroke="{col}" stroke-width="1.8"{dashes[shape]} '
                                     'points="' + " ".join(f"{x:.1f},{y:.1f}" for x, y in xy) + '"/>')
                    for x, y in xy:
                        if shape == "sphere":
                            parts.append(f'<circle cx="{x:.1f}" cy="{y:.1f}" r="3" fill="{col}"/>')
                        else:
                            parts.append(f'<rect x="{x - 3:.1f}" y="{y - 3:.1f}" width="6" height="6" fill="{col}"/>')
        ly = 2 * (H + 26) + 50
        x = 20
        for shape in SHAPES:
            for mode in MODES:
                label = f"{shape}, {mode}"
                parts.append(f'<line x1="{x}" x2="{x + 24}" y1="{ly}" y2="{ly}" stroke="{colors[mode]}" '
                             f'stroke-width="2"{dashes[shape]}/>')
                parts.append(f'<text x="{x + 28}" y="{ly + 4}" font-size="12">{label}</text>')
                x += 48 + 7 * len(label)
        parts.append(f'<text x="20" y="{ly + 22}" font-size="12">log-log; medians of the finished '
                     'cold runs; default: no --lod flag, exact: --lod 0</text>')
        total_w, total_h = 3 * (W + 16) + 20, ly + 36
        return (f'<svg xmlns="http://www.w3.org/2000/svg" width="{total_w}" height="{total_h}" '
                f'font-family="sans-serif">\n<rect width="100%" height="100%" fill="white"/>\n'
                f'<text x="20" y="24" font-size="15">vox-render scale law: cold frames against grid size</text>\n'
                + "\n".join(parts) + "\n</svg>\n")

    # ------------------------------------------------------------ the report

    def cells(self, rows):
        """Median cells of one configuration's runs."""
        if not rows:
            return None
        done = [r for r in rows if r["exit"] == "0"]
        killed = sum(1 for r in rows if r["oom"] == "1")
        other = len(rows) - len(done) - killed

        def med(field, scale=1.0, fmt="{:.2f}"):
            v = [float(r[field]) for r in done if r[field] not in ("", None)]
            return fmt.format(statistics.median(v) / scale) if v else "–"

        wall = med("wall_s")
        peaks = [float(r["peak_bytes"] or r["maxrss_bytes"]) for r in rows]
        peak = f"{statistics.median(peaks) / MiB:.0f}"
        fails = [int(r["failcnt"]) for r in rows if r["failcnt"] not in ("", None)]
        peak += f" ({statistics.median(fails):.0f})" if fails else ""
        paged = med("bricks" if any(r["bricks"] for r in done) else "bricks_paged_in", 1, "{:.0f}")
        reads = [float(r["inblock_bytes"]) for r in rows if r["inblock_bytes"] not in ("", None)]
        read = f"{statistics.median(reads) / MiB:.1f}" if reads else "–"
        ids = [r["identical"] for r in done]
        if killed or other:
            status = []
            bad = [float(r["wall_s"]) for r in rows if r["exit"] != "0"]
            if killed:
                status.append(f"OOM-killed {killed}/{len(rows)}")
            if other:
                what = sorted({f"timed out (thrashing)" if r["timeout"] == "1" else
                               f"exit {r['exit']}" if r["exit"] else f"signal {r['signal']}"
                               for r in rows if r["exit"] != "0" and r["oom"] != "1"})
                status.append(f"{', '.join(what)} {other}/{len(rows)}")
            result = ", ".join(status) + f" after {statistics.median(bad):.1f} s"
        elif all(i == "ref" for i in ids) or ("ref" in ids and all(i in ("ref", "yes") for i in ids)):
            result = "reference"
        elif ids and all(i == "yes" for i in ids):
            result = "identical"
        elif any(i == "no" for i in ids):
            diff = max(int(r["diff_pixels"] or 0) for r in done)
            result = f"differs ({diff} px)"
        else:
            result = "finished"
        return [wall, peak, paged, read, result]

    def report(self):
        a = self.a
        rows = [r for r in self.rows if r["bin"] == self.bin]
        grids = sorted({int(r["grid"]) for r in rows})
        out = a.out
        svg = os.path.splitext(out)[0] + ".svg"
        L = []
        cmd = "tools/bench/scale.sh " + " ".join(shlex.quote(x) for x in sys.argv[1:])
        L.append("# Scale benchmark: vox-render as the volume grows and the memory limit shrinks\n")
        whens = sorted(r["when"] for r in rows if r["when"])
        L.append(f"Produced by `{cmd}` (tools/bench/scale.py documents it; it resumes from the "
                 f"CSV in --work, so the runs may span several invocations): runs measured "
                 f"{whens[0] if whens else '?'} to {whens[-1] if whens else '?'}, report written "
                 f"{time.strftime('%Y-%m-%d %H:%M:%S %Z')}.\n")
        m = machine_notes(self.cg, self.is_root)
        loads = sorted(float(r["loadavg"]) for r in rows if r["loadavg"])
        load = (f"1-minute load average {loads[0]:.1f} to {loads[-1]:.1f}, median "
                f"{statistics.median(loads):.1f}, over the runs") if loads else f"load {loadavg()}"
        L.append(f"Machine: {m['cpu']}, {m['cores']} cores, {m['memory']}, Linux {m['kernel']}, "
                 f"memory cgroup {m['cgroup']}. **Shared and loaded**: other jobs build and test on "
                 f"the same cores ({load}; each run's is in the CSV; load average (1, 5, 15 min) "
                 f"{self.load_start} when this invocation started, {loadavg3()} when this report "
                 "was written), so wall times are noisy and only their order of magnitude and the "
                 "trends are meaningful.\n")
        try:
            commit = subprocess.run(["git", "-C", os.path.dirname(os.path.abspath(__file__)),
                                     "rev-parse", "--short", "HEAD"], capture_output=True,
                                    text=True).stdout.strip()
        except OSError:
            commit = ""
        L.append(f"vox-render: `{self.render}` (SHA-256 {self.bin}; repository at {commit or '?'} when the report was written), "
                 f"{'with' if self.has_memory_flag else 'without'} a `--memory-mb` flag; run with its "
                 f"defaults{(' plus `' + a.render_args + '`') if a.render_args else ''}, "
                 f"`--threads {a.threads}`, {a.size[0]}x{a.size[1]} pixels, one directional light "
                 f"without shadows. Medians of {a.runs} run(s) per cell.\n")
        law_svg = os.path.splitext(out)[0] + "-law.svg"
        L += self.law(rows, grids, law_svg)
        L.append("## All runs\n")
        counts = {}
        for r in rows:
            k = (r["grid"], r["shape"], r["mode"], r["tool"], r["camera"], r["limit"], r["phase"])
            counts[k] = counts.get(k, 0) + 1
        if counts and min(counts.values()) != max(counts.values()):
            L.append(f"Runs per cell: {min(counts.values())} to {max(counts.values())} (CSV).\n")
        tiny = sorted({int(r["limit_bytes"]) for r in rows if 0 < int(r["limit_bytes"]) < 32 * MiB})
        if tiny:
            L.append("Note: limits of "
                     + ", ".join(f"{b / MiB:.1f}" for b in tiny)
                     + " MiB are about the size of a render process's own code, libraries, thread "
                     "stacks and image tiles, so those rows test the process's floor more than "
                     "its paging; the bigger grids are the meaningful ones.\n")
        for note in self.notes:
            L.append(f"Note: {note}.\n")
        L.append("Stores: `vox-gen SHAPE --size N` (sphere: the unit sphere shell, 15/16 of the grid "
                 "across, band 3 voxels; bumpy: that sphere displaced by multi-octave noise), with "
                 "their level-of-detail pyramid unless `--store` named an existing store. Modes: "
                 "**default**: vox-render without a `--lod` flag (level of detail with factor 1 "
                 "when the store has a pyramid); **exact**: `--lod 0`. Cameras, side by side in each row: **full view** from "
                 "(0,0,3) at the origin, 40°; **close-up** from (0,0,1.05) at (0,0,0.9), 20° (a "
                 "patch of the surface: few bricks, so a frame should not need the whole store). "
                 "Limits are fractions of the store's size on disk (sum of its files' sizes) or a "
                 "fixed size (`--limit-mib`), "
                 "applied as a memory cgroup limit around the whole process; `none` runs in a "
                 "cgroup without a limit, so peaks are measured alike.\n")
        L.append("Columns per camera: **wall** s: the whole process (start, store open, render, "
                 "EXR write, exit; median of the runs that finished); **peak** MiB (failcnt): the cgroup's peak charge, anonymous "
                 "memory plus the page cache the process brought in (failcnt counts how often the "
                 "charge hit the limit, i.e. reclaim, not failure); **bricks**: bricks paged in "
                 "(`--stats` lod.bricks_paged_total with level of detail, every level counted, else cache.bricks_paged_in); **read** MiB: bytes the process read from the "
                 "disk, killed runs included (wait4 ru_inblock x 512, the same counter as /proc/PID/io read_bytes; near 0 "
                 "when warm); **pixels**: the EXR against the first finished run's of the same shape, grid, mode and camera (the unlimited one when there is one), bit for bit per "
                 "channel (`scale.py --compare`), or how the runs ended and when. Cold: `sync; echo 3 > "
                 "/proc/sys/vm/drop_caches` first. Warm: the same command again; page cache left by "
                 "an earlier run stays charged to that run's (removed) cgroup's parent, so a warm "
                 "limited run's peak is mostly anonymous memory.\n")
        order = ["none"] + ([f"{a.limit_mib}MiB"] if a.limit_mib else a.limits)
        order += sorted({r["limit"] for r in rows} - set(order))
        configs = [(sh, md) for sh in SHAPES for md in list(MODES) + ["-"]
                   if any(r["shape"] == sh and r["mode"] == md for r in rows)]

        def lim_label(limit, lb):
            if limit == "none":
                return "none"
            return f"{lb / MiB:.0f} MiB" if limit.endswith("MiB") else f"{limit} ({lb / MiB:.0f} MiB)"
        # Summary: the tightest limit under which every run, cold and warm, finished.
        summary = len({r["limit"] for r in rows}) > 1
        if summary:
            L.append("Summary: the tightest limit under which every run (cold and warm) finished; "
                     "`none` when only the unlimited runs did.\n")
            L.append("| shape | grid | tool | mode | full view | close-up |")
            L.append("|---|---|---|---|---|---|")
        for shape, mode in configs if summary else []:
            for n in grids:
                for tool in ("vox", "vdb_render"):
                    cr = [r for r in rows if int(r["grid"]) == n and r["tool"] == tool
                          and r["shape"] == shape and r["mode"] == mode]
                    if not cr:
                        continue
                    cells = []
                    for cam in CAMERAS:
                        best = "–"
                        for limit in order:
                            sel = [r for r in cr if r["camera"] == cam and r["limit"] == limit]
                            if sel and all(r["exit"] == "0" for r in sel):
                                best = lim_label(limit, int(sel[0]["limit_bytes"]))
                            elif limit != "none" or sel:
                                break
                        cells.append(best)
                    L.append(f"| {shape} | {n} | {tool} | {mode} | " + " | ".join(cells) + " |")
        L.append("")
        hdr = ["shape", "grid", "store MiB", "tool", "mode", "limit", "phase"]
        sub = ["wall s", "peak MiB (failcnt)", "bricks", "read MiB", "pixels"]
        L.append("| " + " | ".join(hdr + [f"full: {s}" for s in sub] + [f"close-up: {s}" for s in sub]) + " |")
        L.append("|" + "---|" * (len(hdr) + 2 * len(sub)))
        for shape, mode in configs:
            for n in grids:
                gr = [r for r in rows if int(r["grid"]) == n and r["shape"] == shape and r["mode"] == mode]
                if not gr:
                    continue
                sb = int(gr[0]["store_bytes"]) / MiB
                for tool in ("vox", "vdb_render"):
                    for limit in order:
                        for phase in ("cold", "warm"):
                            sel = [r for r in gr if r["tool"] == tool and r["limit"] == limit and r["phase"] == phase]
                            if not sel:
                                continue
                            lim = lim_label(limit, int(sel[0]["limit_bytes"]))
                            cells = []
                            for cam in CAMERAS:
                                c = self.cells([r for r in sel if r["camera"] == cam])
                                cells += c if c else ["–"] * len(sub)
                            L.append("| " + " | ".join([shape, str(n), f"{sb:.0f}", tool, mode, lim, phase]
                                                       + cells) + " |")
        if any(r["timeout"] == "1" for r in rows):
            L.append("Timed out: a run still going after 5 times the slowest unlimited run of its "
                     "grid, camera and tool (at least 60 s) was killed; after one, that tool, grid, "
                     "camera and phase were not run again at that limit or tighter ones, so those "
                     "cells hold fewer runs or none.\n")
        missing = [g for g in a.grids if g not in grids]
        L.append("")
        if missing:
            L.append(f"Not measured (yet): grids {', '.join(map(str, missing))}.\n")
        if not a.vdb:
            L.append("vdb_render: no `--vdb N=PATH` given, so no side-by-side OpenVDB runs.\n")
        else:
            for n in grids:
                if n not in a.vdb:
                    L.append(f"vdb_render: no .vdb for grid {n}: skipped.\n")
            L.append("vdb_render inputs: " + ", ".join(
                f"{n}: `{p}` ({os.path.getsize(p) / MiB:.0f} MiB)" if os.path.exists(p) else f"{n}: `{p}`"
                for n, p in sorted(a.vdb.items())) + " (given with `--vdb N=PATH`, not made by this "
                "script: each should hold the vox store's sphere at its voxel size, e.g. `vdb_tool "
                "-sphere r=1 v=32/(15N)`, whose band, `w=`, the user chose; its whole grid is "
                "read before rendering).\n")
            L.append("vdb_render rows: `-shader diffuse`, the same cameras and cgroups, whole-process wall time "
                     "(reading the .vdb included); limits are the same bytes as vox's (fractions of "
                     "the vox store), and its pixels are not compared with vox's.\n")
        L.append("Long runs: `--grids 8192` (a store of a few GB, about an hour to generate on this "
                 "machine) or `--store SHAPE:8192=PATH` for an existing one, and larger grids; raw "
                 f"rows: `{self.csv}`.\n")
        first = configs[0] if configs else ("sphere", "default")
        L.append(f"![wall time and peak memory against grid size]({os.path.basename(svg)})\n")
        L.append(f"(The plot above: {first[0]}, {first[1]} mode, every limit.)\n")
        with open(out, "w") as f:
            f.write("\n".join(L))
        with open(svg, "w") as f:
            f.write(self.plot([r for r in rows if r["tool"] != "vox" or
                               (r["shape"], r["mode"]) == first], grids, order))
        with open(law_svg, "w") as f:
            f.write(self.law_plot(rows, grids))
        log(f"wrote {out}, {svg} and {law_svg}")

    def plot(self, rows, grids, order):
        """A 2x2 SVG: wall time and peak memory against grid size, full view and close-up."""
        W, H, pad = 460, 300, 58
        colors = {"none": "#1f77b4", "1/2": "#2ca02c", "1/4": "#ff7f0e", "1/8": "#d62728",
                  "vdb_render": "#555555"}
        extra = ["#9467bd", "#8c564b", "#e377c2", "#7f7f7f"]
        for i, lim in enumerate(l for l in order if l not in colors):
            colors[lim] = extra[i % len(extra)]
        parts = []
        panels = [("wall_s", "wall time (s, log)", "full"), ("wall_s", "wall time (s, log)", "close"),
                  ("peak", "peak memory (MiB, log)", "full"), ("peak", "peak memory (MiB, log)", "close")]
        vox = [r for r in rows if r["tool"] == "vox"]
        for pi, (field, ylabel, cam) in enumerate(panels):
            ox, oy = (pi % 2) * (W + 20) + 10, (pi // 2) * (H + 30) + 40
            series = {}
            for lim in order + ["vdb_render"]:
                for phase in ("cold", "warm"):
                    pts = []
                    for n in grids:
                        if lim == "vdb_render":  # OpenVDB's renderer, unlimited, for scale
                            sel = [r for r in rows if r["tool"] == "vdb_render" and int(r["grid"]) == n
                                   and r["camera"] == cam and r["limit"] == "none" and r["phase"] == phase]
                        else:
                            sel = [r for r in vox if int(r["grid"]) == n and r["camera"] == cam
                                   and r["limit"] == lim and r["phase"] == phase]
                        if not sel:
                            continue
                        ok = [r for r in sel if r["exit"] == "0"]
                        if field == "wall_s":
                            v = [float(r["wall_s"]) for r in ok]
                        else:
                            v = [float(r["peak_bytes"] or r["maxrss_bytes"]) / MiB for r in sel]
                        killed = len(ok) < len(sel)
                        if v:
                            pts.append((n, statistics.median(v), killed))
                        elif killed:
                            pts.append((n, None, True))
                    if pts:
                        series[(lim, phase)] = pts
            vals = [p[1] for s in series.values() for p in s if p[1] and p[1] > 0]
            lo, hi = (min(vals), max(vals)) if vals else (0.1, 10)
            lo, hi = 10 ** math.floor(math.log10(lo)), 10 ** math.ceil(math.log10(hi))
            if hi <= lo:
                hi = lo * 10
            gx = [math.log2(n) for n in grids] or [10]
            x0, x1 = min(gx) - 0.3, max(gx) + 0.3

            def X(n):
                return ox + pad + (math.log2(n) - x0) / (x1 - x0) * (W - pad - 10)

            def Y(v):
                return oy + H - 30 - (math.log10(v) - math.log10(lo)) / (math.log10(hi) - math.log10(lo)) * (H - 50)

            parts.append(f'<rect x="{ox + pad}" y="{oy + 20}" width="{W - pad - 10}" height="{H - 50}" '
                         'fill="none" stroke="#888"/>')
            parts.append(f'<text x="{ox + W / 2 + 20}" y="{oy + 14}" text-anchor="middle" font-size="13">'
                         f'{CAMERA_LABEL[cam]}: {ylabel}</text>')
            e = math.log10(lo)
            while e <= math.log10(hi) + 1e-9:
                v = 10 ** e
                y = Y(v)
                parts.append(f'<line x1="{ox + pad}" x2="{ox + W - 10}" y1="{y:.1f}" y2="{y:.1f}" stroke="#ddd"/>')
                parts.append(f'<text x="{ox + pad - 4}" y="{y + 4:.1f}" text-anchor="end" font-size="11">{v:g}</text>')
                e += 1
            for n in grids:
                parts.append(f'<text x="{X(n):.1f}" y="{oy + H - 14}" text-anchor="middle" font-size="11">{n}³</text>')
            for (lim, phase), pts in series.items():
                col = colors[lim]
                dash = ' stroke-dasharray="5,3"' if phase == "cold" else ""
                # Side by side within a grid size: limits, then cold/warm.
                jit = ((order + ["vdb_render"]).index(lim) * 2 + (phase == "warm") - len(order) - 0.5) * 7
                live = [(X(n) + jit, Y(v)) for n, v, _ in pts if v]
                if len(live) > 1:
                    parts.append(f'<polyline fill="none" stroke="{col}" stroke-width="1.8"{dash} points="'
                                 + " ".join(f"{x:.1f},{y:.1f}" for x, y in live) + '"/>')
                for n, v, killed in pts:
                    x = X(n) + jit
                    if v and not killed:
                        parts.append(f'<circle cx="{x:.1f}" cy="{Y(v):.1f}" r="3" fill="{col}"/>')
                    else:
                        y = Y(v) if v else oy + 26
                        parts.append(f'<path d="M{x - 4:.1f},{y - 4:.1f}l8,8m0,-8l-8,8" stroke="{col}" '
                                     'stroke-width="2"/>')
        ly = 2 * (H + 30) + 48
        x = 20
        for lim in [l for l in order if any(r["limit"] == l for r in vox)] + (
                ["vdb_render"] if any(r["tool"] == "vdb_render" for r in rows) else []):
            label = ("vox unlimited" if lim == "none" else "vdb_render unlimited" if lim == "vdb_render"
                     else "vox, limit " + lim.replace("MiB", " MiB") if lim.endswith("MiB")
                     else "vox, limit " + lim + " of store")
            parts.append(f'<line x1="{x}" x2="{x + 24}" y1="{ly}" y2="{ly}" stroke="{colors[lim]}" stroke-width="2"/>')
            parts.append(f'<text x="{x + 28}" y="{ly + 4}" font-size="12">{label}</text>')
            x += 40 + 7 * len(label)
        parts.append(f'<text x="20" y="{ly + 22}" font-size="12">solid: warm, dashed: cold; '
                     'x: at least one run OOM-killed or failed (peak: median over all runs; '
                     'time: over the runs that finished; x at the top: none finished)</text>')
        total_w, total_h = 2 * (W + 20) + 20, ly + 36
        return (f'<svg xmlns="http://www.w3.org/2000/svg" width="{total_w}" height="{total_h}" '
                f'font-family="sans-serif">\n<rect width="100%" height="100%" fill="white"/>\n'
                f'<text x="20" y="24" font-size="15">vox-render scale benchmark (medians; table and notes in scale.md)</text>\n'
                + "\n".join(parts) + "\n</svg>\n")


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--build", default="build")
    p.add_argument("--work", default="/tmp/vox-scale")
    p.add_argument("--grids", default="1024,2048,4096")
    p.add_argument("--limits", default="1/2,1/4,1/8")
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--size", default="1024x1024")
    p.add_argument("--shapes", default="sphere", help="vox-gen shapes, comma-separated: sphere,bumpy")
    p.add_argument("--modes", default="default",
                   help="vox-render modes, comma-separated: default (no --lod flag: level of "
                        "detail when the store has a pyramid), exact (--lod 0)")
    p.add_argument("--store", action="append", default=[], metavar="SHAPE:N=PATH",
                   help="use this existing store for SHAPE at N^3 (repeatable); never written to")
    p.add_argument("--store-8192", dest="store_8192", help="same as --store sphere:8192=PATH")
    p.add_argument("--limit-mib", type=int, default=0,
                   help="one fixed memory cgroup limit in MiB for every run, instead of --limits "
                        "(and of the unlimited runs)")
    p.add_argument("--vdb", action="append", default=[], metavar="N=PATH")
    p.add_argument("--timeout", type=float, default=0,
                   help="seconds per run before SIGKILL (default: for a limited run 5x the slowest "
                        "unlimited run of the same grid, camera and tool, at least 60 s; with "
                        "--limit-mib 30 min; else 2 h)")
    p.add_argument("--render-args", default="", help="extra vox-render flags, one string")
    p.add_argument("--no-cold", action="store_true")
    p.add_argument("--fresh", action="store_true", help="ignore (and set aside) earlier results")
    p.add_argument("--report-only", action="store_true", help="rewrite the report from the CSV")
    p.add_argument("--out", default="docs/scale.md")
    p.add_argument("--compare", nargs=2, metavar=("A.exr", "B.exr"))
    p.add_argument("--covered", metavar="X.exr", help="print the pixels with A > 0")
    a = p.parse_args()
    if a.compare:
        try:
            d = compare_exr(*a.compare)
        except (OSError, ValueError, KeyError, zlib.error) as e:
            sys.exit(f"scale: {e}")
        print("identical" if d == 0 else f"{d} pixels differ")
        return 0 if d == 0 else 1
    if a.covered:
        print(exr_covered_pixels(a.covered))
        return 0
    try:
        grids = [int(g) for g in a.grids.split(",") if g.strip()]
        if not grids or any(g < 2 or g & (g - 1) for g in grids):
            raise ValueError
        a.grids = grids
    except ValueError:
        p.error(f"--grids {a.grids}: expected powers of two, comma-separated")
    try:
        a.limits = [parse_fraction(s) for s in a.limits.split(",") if s.strip()]
    except argparse.ArgumentTypeError as e:
        p.error(str(e))
    m = re.fullmatch(r"(\d+)x(\d+)", a.size)
    if not m or int(m.group(1)) <= 0 or int(m.group(2)) <= 0:
        p.error(f"--size {a.size}: expected WxH")
    a.size = (int(m.group(1)), int(m.group(2)))
    if a.runs < 1:
        p.error("--runs must be at least 1")
    vdb = {}
    for item in a.vdb:
        n, _, path = item.partition("=")
        if not n.isdigit() or not path:
            p.error(f"--vdb {item}: expected N=PATH")
        if not os.path.isfile(path):
            p.error(f"--vdb {item}: {path} is not a file")
        vdb[int(n)] = path
    a.vdb = vdb
    a.shapes = [x.strip() for x in a.shapes.split(",") if x.strip()]
    if not a.shapes or any(x not in SHAPES for x in a.shapes):
        p.error(f"--shapes: expected some of {','.join(SHAPES)}")
    a.modes = [x.strip() for x in a.modes.split(",") if x.strip()]
    if not a.modes or any(x not in MODES for x in a.modes) or len(set(a.modes)) != len(a.modes):
        p.error(f"--modes: expected some of {','.join(MODES)}")
    if a.limit_mib < 0:
        p.error("--limit-mib must be positive")
    stores = {}
    if a.store_8192:
        a.store.append(f"sphere:8192={a.store_8192}")
    for item in a.store:
        m = re.fullmatch(r"(\w+):(\d+)=(.+)", item)
        if not m or m.group(1) not in SHAPES:
            p.error(f"--store {item}: expected SHAPE:N=PATH with SHAPE one of {','.join(SHAPES)}")
        stores[(m.group(1), int(m.group(2)))] = m.group(3)
    for shape, n in stores:
        if n not in a.grids or shape not in a.shapes:
            p.error(f"--store {shape}:{n}=...: {n} is not in --grids or {shape} not in --shapes")
    a.stores = stores
    signal.signal(signal.SIGTERM, lambda *_: sys.exit("scale: terminated"))
    try:
        Bench(a).run()
    except KeyboardInterrupt:
        sys.exit("scale: interrupted (rerun the same command to resume)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
