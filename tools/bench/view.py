"""view: vox-view's latency in headless Chromium, against vox-render's default frame.

Starts vox-view on STORE (default: vox-gen's SHAPE of --grid voxels in $SCRATCH) with --threads
threads, in a memory cgroup of --limit-mib (0: none, only measured), and Debian's chromium (outside
the cgroup) on its page with a --width x --height canvas. Then, driving the page over the DevTools
protocol as a person's mouse would:
  1. --moves drags of 10 pixels, each as soon as the previous move's coarse frame is painted:
     from the input event to the page's next paint after the coarse frame is drawn, median, p95
     and fastest, with the coarse frames' sizes (the page picks them from its time budget);
  2. --interrupts moves after the view rested 0.6 s, each stopping the full-size frame in
     flight: the same latency, and the server's wait for the old frame to stop;
  3. the view left still: the refined frame (the default level of detail), from its request to the
     paint, median over --refines views; each view saved ("Save scene") and rendered by
     vox-render with the saved command line, warm (the second of two runs): the ratio;
  4. --orbit-seconds of continuous orbit: the server still running, the cgroup's peak (its page
     cache included) and its failures (failcnt, OOM kills); all along, the peaks of the server's
     anonymous and file-backed resident memory and of the cgroup's rss and page cache, against
     the budget's lines and its heap watch's target (/stats).
The load average (1 min) is given at the start and at the end. --view-tool measures another
vox-view binary (an older build) with the same page driving."""

import base64  # noqa: F401  (kept for screenshots when debugging)
import collections
import json
import os
import shlex
import shutil
import subprocess
import tempfile
import threading
import time
import urllib.request

import harness as H
from memory import add_store_arguments, store_arg


def add_arguments(p):
    add_store_arguments(p, grid=4096)
    p.add_argument("--width", type=int, default=1024)
    p.add_argument("--height", type=int, default=768)
    p.add_argument("--moves", type=int, default=50)
    p.add_argument("--refines", type=int, default=5)
    p.add_argument("--interrupts", type=int, default=10)
    p.add_argument("--orbit-seconds", type=float, default=60)
    p.add_argument("--limit-mib", type=int, default=512)
    p.add_argument("--view-tool", help="the vox-view to measure (default: the build's)")
    p.add_argument("--callgrind", type=int, default=0, metavar="N",
                   help="instead: instructions per warm coarse frame over N views, by callgrind")


class Page:
    """Chromium on vox-view's page, driven over the DevTools protocol."""

    def __init__(self, url, tmp):
        try:
            import websocket  # python3-websocket
        except ImportError:
            H.fail("the view question needs python3-websocket (Debian's, for /usr/bin/python3)")
        chromium = shutil.which("chromium") or H.fail("chromium is not installed")
        profile = os.path.join(tmp, "profile")
        self.proc = subprocess.Popen([chromium, "--headless=new", "--no-sandbox", "--disable-gpu",
                                      "--remote-debugging-port=0", f"--user-data-dir={profile}",
                                      "--window-size=1500,1000", url],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        port_file = os.path.join(profile, "DevToolsActivePort")
        for _ in range(300):
            if os.path.exists(port_file) and open(port_file).read().count("\n") >= 1:
                break
            time.sleep(0.1)
        port = open(port_file).read().split()[0]
        targets = json.loads(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list").read())
        page = next(t for t in targets if t["type"] == "page")
        self.ws = websocket.create_connection(page["webSocketDebuggerUrl"], timeout=120)
        self.id = 0

    def cdp(self, method, **params):
        self.id += 1
        self.ws.send(json.dumps({"id": self.id, "method": method, "params": params}))
        while True:
            m = json.loads(self.ws.recv())
            if m.get("id") == self.id:
                if "error" in m:
                    H.fail(f"{method}: {m['error']}")
                return m["result"]

    def js(self, expr):
        r = self.cdp("Runtime.evaluate", expression=expr, awaitPromise=True, returnByValue=True)
        return r["result"].get("value")

    def frames(self):
        return self.js("window.voxTimes.length")

    def wait(self, cond, what, timeout=120):
        t = time.monotonic()
        while time.monotonic() - t < timeout:
            v = self.js(cond)
            if v:
                return v
            time.sleep(0.005)
        H.fail(f"no {what} within {timeout} s")

    def close(self):
        self.proc.terminate()
        self.proc.wait()


def sample_cgroup(cg_dir, peaks, done):
    """Keeps the peaks of a cgroup v1 memory group's rss and page cache, every 50 ms, until done."""
    while not done.wait(0.05):
        try:
            for line in open(cg_dir + "/memory.stat"):
                k, v = line.split()
                if k in ("rss", "cache"):
                    peaks["cg_" + k] = max(peaks.get("cg_" + k, 0), int(v))
        except (OSError, ValueError):
            pass


def pct(v, p):
    v = sorted(v)
    return v[min(len(v) - 1, int(round(p / 100 * (len(v) - 1))))]


def instructions(h, a, store, view_tool):
    """Instructions (callgrind, all of the server's threads) per warm coarse frame of a quarter of
    --width x --height: N views 0.6 degrees apart rendered once to warm the caches, then again
    with the instruments on; as the page asks for a coarse frame (fmt=rgba8, aa=0) and as a
    float frame with silhouette antialiasing (the /frame defaults)."""
    shutil.which("valgrind") or H.fail("--callgrind needs valgrind")
    w, hh = round(a.width / 4), round(a.height / 4)
    rows = []
    for name, extra in (("coarse, as the page asks (fmt=rgba8&aa=0)", "&fmt=rgba8&aa=0"),
                        ("float, silhouettes antialiased (no fmt, aa)", "")):
        tmp = tempfile.mkdtemp(prefix="vbench-view-cg-", dir=h.scratch)
        out = os.path.join(tmp, "callgrind.out")
        server = subprocess.Popen(["valgrind", "--tool=callgrind", "--instr-atstart=no",
                                   f"--callgrind-out-file={out}", view_tool, store, "--threads",
                                   str(h.threads)], stdout=subprocess.PIPE,
                                  stderr=subprocess.DEVNULL, text=True)
        url = server.stdout.readline().split()[-1]
        qs = [f"{url}frame?w={w}&h={hh}&az={30 + 0.6 * i:.1f}&el=20{extra}"
              for i in range(a.callgrind)]
        ctl = lambda *args: H.check(["callgrind_control", *args, str(server.pid)])  # noqa: E731
        try:
            for q in qs:
                urllib.request.urlopen(q, timeout=3600).read()
            ctl("-i", "on")
            for q in qs:
                urllib.request.urlopen(q, timeout=3600).read()
            ctl("-i", "off")
            ctl("-d")
        finally:
            server.terminate()
            server.wait()
        total = 0
        for f in os.listdir(tmp):
            for line in open(os.path.join(tmp, f)):
                if line.startswith("totals:"):
                    total += int(line.split()[1])
        shutil.rmtree(tmp, ignore_errors=True)
        rows.append([f"{name}, {w}x{hh}", f"{total / a.callgrind / 1e6:.1f} M"])
    return rows


def main(h, a):
    store = store_arg(h, a)
    view_tool = a.view_tool or os.path.join(h.build, "tools/view/vox-view")
    if not os.access(view_tool, os.X_OK):
        H.fail(f"{h.rel(view_tool)} is not built")
    if a.callgrind:
        rep = H.Report(h, "view", "vox-view's instructions per coarse frame")
        rep.add(f"Store: {h.rel(store)}; {h.rel(view_tool)}, {h.threads} threads, "
                f"{a.callgrind} warm views each.", "")
        rep.table(["frame", "instructions per frame"], instructions(h, a, store, view_tool))
        return rep.write()
    tmp = tempfile.mkdtemp(prefix="vbench-view-", dir=h.scratch)
    out_dir = os.path.join(tmp, "saved")
    os.mkdir(out_dir)
    cg = H.Cgroup(a.limit_mib * H.MiB) if a.limit_mib and H.Cgroup.available() else None
    pre = (lambda: open(cg.dir + "/cgroup.procs", "w").write(str(os.getpid()))) if cg else None
    server = subprocess.Popen([view_tool, store, "--threads", str(h.threads), "--out", out_dir],
                              stdout=subprocess.PIPE, text=True, preexec_fn=pre)
    url = server.stdout.readline().split()[-1]
    # The server's resident set (anonymous: what its budget governs; file: the store's mapped
    # pages) and the cgroup's charge (rss and page cache), their peaks every 50 ms.
    peaks, done = {}, threading.Event()
    samplers = [threading.Thread(target=H.sample_rss, args=(server.pid, peaks, done))]
    if cg:
        samplers.append(threading.Thread(target=sample_cgroup, args=(cg.dir, peaks, done)))
    for t in samplers:
        t.start()
    page = None
    rep = H.Report(h, "view", "vox-view's latency")
    try:
        page = Page(url + f"?w={a.width}&h={a.height}", tmp)
        page.wait("cv.dataset.refined === '1'", "first frame")
        x, y = 300, 300

        def drag_steps(n, until=None):
            """n moves of 10 px (or until time `until`); each waits for its coarse frame."""
            page.cdp("Input.dispatchMouseEvent", type="mousePressed", x=x, y=y, button="left",
                     clickCount=1)
            px, i = x, 0
            while (until is None and i < n) or (until is not None and time.monotonic() < until):
                before = page.frames()
                px += 10 if (i // 40) % 2 == 0 else -10
                page.cdp("Input.dispatchMouseEvent", type="mouseMoved", x=px, y=y, button="left")
                page.wait(f"window.voxTimes.length > {before} && "
                          f"window.voxTimes[window.voxTimes.length - 1].scale !== 1", "coarse frame")
                i += 1
            page.cdp("Input.dispatchMouseEvent", type="mouseReleased", x=px, y=y, button="left",
                     clickCount=1)
            return i

        drag_steps(5)  # warm-up
        start = page.frames()
        drag_steps(a.moves)
        coarse_frames = [t for t in page.js("window.voxTimes")[start:] if t["scale"] != 1]
        coarse = [t["event_to_paint"] for t in coarse_frames]
        # Moves that stop a refined frame: the view rests 0.6 s (the full-size frame starts at
        # 0.3 s and takes longer), then moves; the coarse frame waits for the full-size one to
        # stop (the server's wait_ms).
        stopped = []
        for k in range(a.interrupts):
            drag_steps(1)
            time.sleep(0.6)
            drag_steps(1)
            stopped.append(page.js("window.voxTimes[window.voxTimes.length - 1]"))
        rows = []
        for k in range(a.refines):
            drag_steps(3)
            page.wait("cv.dataset.refined === '1'", "refined frame")
            time.sleep(0.5)
            page.wait("cv.dataset.refined === '1'", "refined frame")
            t = page.js("window.voxTimes[window.voxTimes.length - 1]")
            saved = page.js("save(true)")
            argv = shlex.split(saved["command"])
            argv[0] = h.tool("vox-render")
            stats = os.path.join(tmp, f"r{k}.json")
            argv += ["--threads", str(h.threads), "--quiet", "--stats", stats]
            runs = [H.run(argv) for _ in range(2)]
            if any(r["exit"] != 0 for r in runs):
                H.fail(f"vox-render failed: {saved['command']}")
            rs = json.load(open(stats))["timings"]["render_seconds"]
            rows.append({"page_ms": t["request_to_paint"], "page_render_ms": t["render_ms"],
                         "page_data_ms": t["request_to_data"],
                         "vox_render_wall_ms": runs[1]["wall_s"] * 1e3,
                         "vox_render_render_ms": rs * 1e3})
        orbit_moves = drag_steps(0, until=time.monotonic() + a.orbit_seconds)
        alive = server.poll() is None
        budget = page.js("st.last.panel.budget")
        memory = json.loads(urllib.request.urlopen(url + "stats").read())["memory"]
    finally:
        done.set()
        for t in samplers:
            t.join()
        if page:
            page.close()
        server.terminate()
        server.wait()
        peak, failcnt, oom = cg.finish() if cg else (None, None, None)
    med = H.median
    stop_ms = [t["event_to_paint"] for t in stopped]
    waits = [t["wait_ms"] for t in stopped if "wait_ms" in t]
    page_ms = med([r["page_ms"] for r in rows])
    vr_ms = med([r["vox_render_wall_ms"] for r in rows])
    rep.add(f"Store: {h.rel(store)}; page {a.width}x{a.height}, {h.threads} threads, server in "
            f"{'a ' + str(a.limit_mib) + ' MiB cgroup' if cg else 'no cgroup'}.", "")
    rep.table(["measure", "value"], [
        [f"input event -> painted coarse frame, median of {len(coarse)} moves", f"{med(coarse):.0f} ms"],
        ["input event -> painted coarse frame, p95", f"{pct(coarse, 95):.0f} ms"],
        ["input event -> painted coarse frame, fastest", f"{min(coarse):.0f} ms"],
        ["coarse frames' sizes (count)",
         ", ".join(f"{w}x{h} ({n})" for (w, h), n in sorted(collections.Counter(
             (t.get("w", round(a.width / t["scale"])), t.get("h", round(a.height / t["scale"])))
             for t in coarse_frames).items(), reverse=True))],
        [f"a move stopping the full-size frame: input event -> painted coarse frame, median of "
         f"{len(stopped)}", f"{med(stop_ms):.0f} ms" if stopped else "-"],
        ["the same: the server's wait for the full-size frame to stop, median, max",
         f"{med(waits):.0f} ms, {max(waits):.0f} ms" if waits else "-"],
        [f"refined frame, request -> paint, median of {len(rows)} views", f"{page_ms:.0f} ms"],
        ["vox-render, the saved command, warm, wall", f"{vr_ms:.0f} ms"],
        ["refined / vox-render", f"{page_ms / vr_ms:.2f}"],
        ["refined render only / vox-render render only",
         f"{med([r['page_render_ms'] for r in rows]) / med([r['vox_render_render_ms'] for r in rows]):.2f}"],
        [f"orbit of {a.orbit_seconds:.0f} s: coarse frames, server alive", f"{orbit_moves}, {alive}"],
        ["load average (1 min) at the end", f"{os.getloadavg()[0]:.2f}"],
        ["server cgroup peak MiB, failcnt, OOM kills",
         f"{peak / H.MiB:.0f}, {failcnt}, {oom}" if cg else "n/a"],
        ["cgroup peak MiB: rss, page cache",
         f"{peaks.get('cg_rss', 0) / H.MiB:.0f}, {peaks.get('cg_cache', 0) / H.MiB:.0f}"
         if cg else "n/a"],
        ["server peak resident MiB: anonymous, file; its memory budget",
         f"{peaks.get('RssAnon', 0) / H.MiB:.0f}, {peaks.get('RssFile', 0) / H.MiB:.0f}; "
         f"{budget / H.MiB:.0f}"],
        ["the budget's lines (MiB): brick caches, headroom; the heap watch's target",
         f"{memory['brick_cache'] / H.MiB:.0f}, {memory['headroom'] / H.MiB:.0f}; "
         f"{memory['heap_watch']['target'] / H.MiB:.0f}"],
    ])
    rep.raw = {"coarse_ms": coarse, "coarse_frames": coarse_frames, "stopping_moves": stopped,
               "peaks": peaks, "budget": budget, "memory": memory, "refined": rows,
               "orbit_moves": orbit_moves, "alive": alive, "peak_bytes": peak, "failcnt": failcnt,
               "oom_kills": oom}
    rep.write()
    shutil.rmtree(tmp, ignore_errors=True)
    if not alive:
        H.fail("vox-view did not survive the orbit")
