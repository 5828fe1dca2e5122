"""The benchmark harness: builds, volumes and stores, memory cgroups, cold runs, medians, reports.

Every question of tools/bench/vbench.py runs on this. Paths it prints are relative to the
repository or start with $SCRATCH / $OUT (the scratch and report directories), never this
machine's. Standard library only.
"""

import json
import os
import platform
import re
import shlex
import shutil
import signal
import statistics
import subprocess
import sys
import threading
import time

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
MiB = 1 << 20
CGROUP_V1 = "/sys/fs/cgroup/memory"
# Where each program is built, relative to the build directory.
PROGRAMS = {
    "vox-render": "tools/render/vox-render", "vox-ingest": "tools/ingest/vox-ingest",
    "vox-gen": "tools/gen/vox-gen", "vox-render-bench": "tools/bench/vox-render-bench",
    "vox-study": "tools/bench/vox-study", "vox-lod-compare": "tools/bench/vox-lod-compare",
    "vox-lod-normals": "tools/bench/vox-lod-normals",
}
# The peers' level sets and the vox-gen shapes used by the questions.
SPHERE_2048 = ["-sphere", "d=2048", "r=1", "c=0,0,0", "v=0.001", "w=3"]
# One directional light without shadows and no specular: vdb_render's -shader diffuse.
DIFFUSE = {"lights": [{"type": "directional", "direction": [-0.3, -0.5, -1], "shadows": False}],
           "material": {"specular": 0}}


def log(*a):
    print("vbench:", *a, file=sys.stderr, flush=True)


def fail(msg):
    sys.exit("vbench: " + msg)


def median(v):
    v = [x for x in v if x is not None]
    return statistics.median(v) if v else float("nan")


def geomean(v):
    v = [x for x in v if x and x > 0]
    return statistics.geometric_mean(v) if v else float("nan")


def alternate(runners, rounds):
    """Runs each of runners {name: fn} once per round, in turn; {name: [results]}."""
    out = {k: [] for k in runners}
    for r in range(rounds):
        for name, fn in runners.items():
            out[name].append(fn())
    return out


def cam_json(path, position, look_at, fov, width, height=None):
    write_json(path, {"position": list(position), "look_at": list(look_at), "up": [0, 1, 0],
                      "fov_deg": fov, "width": width, "height": height or width,
                      "projection": "perspective"})
    return path


def write_json(path, obj):
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        json.dump(obj, f)
    os.replace(tmp, path)
    return path


def dir_bytes(path):
    if os.path.isfile(path):
        return os.path.getsize(path)
    return sum(os.path.getsize(os.path.join(r, f)) for r, _, fs in os.walk(path) for f in fs)


def loadavg():
    try:
        return open("/proc/loadavg").read().split()[0]
    except OSError:
        return "?"


def drop_page_cache():
    """sync and drop the page cache (root); False when it cannot."""
    os.sync()
    try:
        with open("/proc/sys/vm/drop_caches", "w") as fh:
            fh.write("3")
        return True
    except OSError:
        return False


class Cgroup:
    """A cgroup v1 memory group for one process: limit (0: none, only measured), peak, failcnt."""

    def __init__(self, limit_bytes=0):
        self.dir = f"{CGROUP_V1}/vbench_{os.getpid()}_{time.monotonic_ns()}"
        os.mkdir(self.dir)
        if limit_bytes:
            self._write("memory.limit_in_bytes", limit_bytes)
            if os.path.exists(self.dir + "/memory.memsw.limit_in_bytes"):
                try:
                    self._write("memory.memsw.limit_in_bytes", limit_bytes)
                except OSError:
                    pass

    @staticmethod
    def available():
        return os.geteuid() == 0 and os.access(CGROUP_V1, os.W_OK)

    def _write(self, name, value):
        with open(f"{self.dir}/{name}", "w") as f:
            f.write(str(value))

    def _num(self, name):
        try:
            return int(open(f"{self.dir}/{name}").read().split()[0])
        except (OSError, ValueError, IndexError):
            return 0

    def finish(self):
        """(peak bytes, failcnt, oom kills); removes the group."""
        oom = 0
        try:
            for line in open(self.dir + "/memory.oom_control"):
                if line.startswith("oom_kill "):
                    oom = int(line.split()[1])
        except OSError:
            pass
        r = self._num("memory.max_usage_in_bytes"), self._num("memory.failcnt"), oom
        for _ in range(200):
            try:
                os.rmdir(self.dir)
                break
            except OSError:
                time.sleep(0.02)
        return r


def sample_rss(pid, peaks, done):
    """Keeps the peaks of RssAnon and RssFile (bytes) of process pid, every 50 ms, until done."""
    while not done.wait(0.05):
        try:
            for line in open(f"/proc/{pid}/status"):
                k = line.split(":")[0]
                if k in ("RssAnon", "RssFile"):
                    peaks[k] = max(peaks.get(k, 0), int(line.split()[1]) * 1024)
        except (OSError, ValueError):
            pass


def run(argv, limit_mib=None, cold=False, stdout=None, stderr=None, timeout=None, cwd=None,
        groups=(), rss=False, env=None):
    """Runs one process: in its own cgroup when limit_mib is not None (0: unlimited, measured) and
    in the extra cgroup directories `groups`, after dropping the page cache when cold. Returns
    wall_s, exit, signal, peak/failcnt/oom (with a cgroup), maxrss and inblock bytes (wait4),
    cpu_s, and with rss the sampled peaks of RssAnon and RssFile. env: the child's environment."""
    if cold and not drop_page_cache():
        fail("a cold run drops the page cache: run as root")
    cg = Cgroup(int(limit_mib * MiB)) if limit_mib is not None else None
    out = open(stdout, "w") if stdout else subprocess.DEVNULL
    err = open(stderr, "w") if stderr else subprocess.DEVNULL
    dirs = ([cg.dir] if cg else []) + list(groups)

    def pre():
        for d in dirs:
            with open(d + "/cgroup.procs", "w") as f:
                f.write(str(os.getpid()))
    t0 = time.monotonic()
    try:
        p = subprocess.Popen(argv, stdout=out, stderr=err, preexec_fn=pre, cwd=cwd, env=env)
    except OSError as e:
        if cg:
            cg.finish()
        fail(f"cannot run {argv[0]}: {e}")
    timer = threading.Timer(timeout, p.kill) if timeout else None
    if timer:
        timer.start()
    peaks, done = {}, threading.Event()
    sampler = threading.Thread(target=sample_rss, args=(p.pid, peaks, done)) if rss else None
    if sampler:
        sampler.start()
    io = {}
    try:
        # The exited child's I/O counters (read syscalls, bytes), read before it is reaped.
        os.waitid(os.P_PID, p.pid, os.WEXITED | os.WNOWAIT)
        try:
            io = dict(l.split(": ") for l in open(f"/proc/{p.pid}/io").read().split("\n") if l)
        except (OSError, ValueError):
            pass
        _, status, ru = os.wait4(p.pid, 0)
    except BaseException:  # interrupted: leave no child or cgroup behind
        p.kill()
        os.wait4(p.pid, 0)
        if cg:
            cg.finish()
        raise
    wall = time.monotonic() - t0
    done.set()
    if sampler:
        sampler.join()
    p.returncode = 0  # reaped above
    timed_out = bool(timer) and not timer.is_alive() and os.WIFSIGNALED(status)
    if timer:
        timer.cancel()
    for f in (out, err):
        if f is not subprocess.DEVNULL:
            f.close()
    r = {"wall_s": wall, "exit": os.WEXITSTATUS(status) if os.WIFEXITED(status) else None,
         "signal": os.WTERMSIG(status) if os.WIFSIGNALED(status) else None, "timeout": timed_out,
         "maxrss_bytes": ru.ru_maxrss * 1024, "inblock_bytes": ru.ru_inblock * 512,
         "cpu_s": ru.ru_utime + ru.ru_stime, "rss_anon": peaks.get("RssAnon"),
         "rss_file": peaks.get("RssFile"), "syscr": int(io["syscr"]) if "syscr" in io else None}
    if cg:
        r["peak_bytes"], r["failcnt"], oom = cg.finish()
        r["oom"] = r["signal"] == signal.SIGKILL and not timed_out and (oom > 0 or r["failcnt"] > 0)
    return r


def check(argv, what=None, **kw):
    """Runs argv to completion; exits with its stderr's tail when it fails. Returns stdout."""
    p = subprocess.run(argv, capture_output=True, text=True, **kw)
    if p.returncode != 0:
        fail(f"{what or os.path.basename(argv[0])} exited {p.returncode}: "
             f"{shlex.join(argv)}\n{p.stderr[-2000:]}")
    return p.stdout


class Harness:
    """Build directory, scratch directory, output directory, and what is made there."""

    def __init__(self, args):
        self.build = os.path.abspath(args.build or os.environ.get("VOX_BUILD") or
                                     os.path.join(REPO, "build"))
        scratch = args.scratch or os.environ.get("SCRATCH")
        if not scratch:
            fail("give a scratch directory: --scratch DIR or SCRATCH=DIR (volumes and stores go there)")
        self.scratch = os.path.abspath(scratch)
        self.out = os.path.abspath(args.out or os.environ.get("OUT") or
                                   os.path.join(self.scratch, "reports"))
        self.threads = args.threads
        self.no_build = args.no_build
        self.built = set()  # the programs built by this run
        os.makedirs(self.scratch, exist_ok=True)
        os.makedirs(self.out, exist_ok=True)
        self.command = "tools/bench/vbench.py " + shlex.join(self.rel(a) for a in sys.argv[1:])

    def rel(self, path):
        """A path as reports print it: relative to the repo, or under $SCRATCH / $OUT."""
        s = str(path)
        for root, name in ((getattr(self, "out", None), "$OUT"), (getattr(self, "scratch", None), "$SCRATCH")):
            if root and (s == root or s.startswith(root + os.sep)):
                return name + s[len(root):]
        a = os.path.abspath(s) if os.path.exists(s) else s
        if a.startswith(REPO + os.sep):
            return os.path.relpath(a, REPO)
        return s

    def tool(self, name):
        """The built program `name`, built first (cmake --build) unless --no-build."""
        path = os.path.join(self.build, PROGRAMS[name])
        if not self.no_build and name not in self.built:
            self.built.add(name)
            if not os.path.exists(os.path.join(self.build, "build.ninja")):
                check(["cmake", "-S", REPO, "-B", self.build, "-G", "Ninja",
                       "-DCMAKE_BUILD_TYPE=Release"], "cmake")
            target = os.path.basename(PROGRAMS[name])
            log(f"building {target}")
            check(["cmake", "--build", self.build, "--target", target], "cmake --build")
        if not os.access(path, os.X_OK):
            fail(f"{self.rel(path)} is not built")
        return path

    def has_flag(self, name, flag):
        p = subprocess.run([self.tool(name), "--help"], capture_output=True, text=True)
        return re.search(re.escape(flag) + r"\b", p.stdout + p.stderr) is not None

    def path(self, *parts):
        return os.path.join(self.scratch, *parts)

    def vdb(self, name, vdb_tool_args):
        """SCRATCH/NAME.vdb, made by vdb_tool unless there."""
        out = self.path(name + ".vdb")
        if not os.path.exists(out):
            if not shutil.which("vdb_tool"):
                fail("vdb_tool is not installed (Debian: libopenvdb-tools)")
            log(f"making {self.rel(out)}: vdb_tool {shlex.join(vdb_tool_args)}")
            tmp = out + ".tmp.vdb"
            check(["vdb_tool", *vdb_tool_args, "-write", tmp], "vdb_tool")
            os.replace(tmp, out)
        return out

    def store(self, vdb, name=None, flags=()):
        """The vox store of a .vdb (vox-ingest), unless there."""
        out = self.path((name or os.path.splitext(os.path.basename(vdb))[0]) + ".store")
        if not os.path.isdir(out):
            log(f"ingesting {self.rel(out)}")
            check([self.tool("vox-ingest"), vdb, out, "--quiet", "--threads", str(self.threads),
                   *flags], "vox-ingest")
        return out

    def gen_store(self, shape, n):
        """SCRATCH/SHAPEN.store, made by vox-gen (with its pyramid) unless there."""
        out = self.path(f"{shape}{n}.store")
        if not os.path.isdir(out):
            log(f"making {self.rel(out)}: vox-gen {shape} --size {n}")
            check([self.tool("vox-gen"), shape, out, "--size", str(n), "--threads",
                   str(self.threads), "--quiet"], "vox-gen")
        return out


class Report:
    """A Markdown report: printed, and written to OUT/NAME.md (with NAME.json of the raw rows)."""

    def __init__(self, h, name, title):
        self.h, self.name, self.lines, self.raw = h, name, [f"# {title}", ""], {}
        cpu = next((l.split(":", 1)[1].strip() for l in open("/proc/cpuinfo")
                    if l.startswith("model name")), platform.machine())
        self.add(f"Produced by `{h.command}` on {os.cpu_count()} cores ({cpu}), "
                 f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, load average {loadavg()} "
                 f"at the start. $SCRATCH and $OUT are the scratch and report directories.", "")

    def add(self, *lines):
        self.lines.extend(lines)

    def table(self, header, rows):
        self.add("| " + " | ".join(header) + " |", "|" + " --- |" * len(header))
        for r in rows:
            self.add("| " + " | ".join(str(c).replace("|", "\\|") for c in r) + " |")
        self.add("")

    def write(self):
        text = "\n".join(self.lines) + "\n"
        path = os.path.join(self.h.out, self.name + ".md")
        with open(path + ".tmp", "w") as f:
            f.write(text)
        os.replace(path + ".tmp", path)
        if self.raw:
            write_json(os.path.join(self.h.out, self.name + ".json"), self.raw)
        print(text)
        log(f"report: {self.h.rel(path)}")
        return path
