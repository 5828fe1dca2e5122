"""Questions of memory and disk: cold frames, turntables, ingest."""

import json
import os
import re
import subprocess

import harness as H

COLD_SCENE = {"lights": [{"type": "directional", "direction": [-1, -1, -1], "intensity": 1.0,
                          "shadows": False}]}


def store_arg(h, a):
    """The store a question renders: STORE, or vox-gen's SHAPE of --grid voxels in $SCRATCH."""
    if a.store:
        if not os.path.isdir(a.store):
            H.fail(f"{a.store}: no such store")
        return os.path.abspath(a.store)
    return h.gen_store(a.shape, a.grid)


def add_store_arguments(p, grid=2048):
    p.add_argument("store", nargs="?", help=f"a store (default: vox-gen's SHAPE of {grid}^3 in $SCRATCH)")
    p.add_argument("--shape", default="sphere")
    p.add_argument("--grid", type=int, default=grid)


def throttle_group(h, path, mbps, iops):
    """A cgroup v1 blkio group reading the disk of `path` at mbps MB/s and iops reads/s."""
    root = "/sys/fs/cgroup/blkio"
    if not os.access(root, os.W_OK):
        H.fail(f"--disk-mbps/--disk-iops need root and a writable {root}")
    src = H.check(["df", "--output=source", path]).split()[-1]
    disk = subprocess.run(["lsblk", "-ndo", "PKNAME", src], capture_output=True, text=True).stdout.strip()
    dev = open(f"/sys/block/{disk or os.path.basename(src)}/dev").read().strip()
    g = f"{root}/vbench_{os.getpid()}"
    os.makedirs(g, exist_ok=True)
    if mbps:
        open(g + "/blkio.throttle.read_bps_device", "w").write(f"{dev} {mbps * 1000000}")
    if iops:
        open(g + "/blkio.throttle.read_iops_device", "w").write(f"{dev} {iops}")
    return g


class Cold:
    """cold: a cold frame (page cache dropped) in a memory limit, against the warm one right after.

Per mode (exact = --lod 0, default = the store's level of detail) and reading strategy (wait, or
--prefetch), --runs times alternately: a cold frame in a cgroup of --limit-mib (0: unlimited, only
measured), then a warm one (page cache warm, brick cache cold). Reports the medians, the bytes
read, the cgroup's peak, and cold / max(warm, bytes read / the disk's sequential bandwidth) (1 means
the cold frame waits only for the disk). Camera (0,0,3) fov 40, one light without shadows."""

    @staticmethod
    def add_arguments(p):
        add_store_arguments(p)
        p.add_argument("--limit-mib", type=int, default=0)
        p.add_argument("--runs", type=int, default=3)
        p.add_argument("--modes", default="exact,default")
        p.add_argument("--reads", default="wait,prefetch")
        p.add_argument("--size", type=int, default=1024)
        p.add_argument("--disk-mbps", type=int, help="emulate a disk of this many MB/s (blkio)")
        p.add_argument("--disk-iops", type=int, help="... and this many reads/s")

    @staticmethod
    def main(h, a):
        store = store_arg(h, a)
        blk = [throttle_group(h, store, a.disk_mbps, a.disk_iops)] if a.disk_mbps or a.disk_iops else []
        try:
            return Cold.measure(h, a, store, blk)
        finally:
            for g in blk:
                os.rmdir(g)

    @staticmethod
    def measure(h, a, store, blk):
        bricks = os.path.join(store, "bricks.vxb")
        mib = min(os.path.getsize(bricks) >> 20, 1024)
        H.drop_page_cache() or H.fail("cold frames drop the page cache: run as root")
        err = h.path("cold.dd.err")
        H.run(["dd", "if=" + bricks, "of=/dev/null", "bs=1M", f"count={mib}"], groups=blk, stderr=err)
        m = re.search(r"^(\d+) bytes .* copied, ([0-9.e+-]+) s", open(err).read(), re.M)
        if not m:
            H.fail(f"cannot read dd's rate in {h.rel(err)}")
        mbps = int(m.group(1)) / 1e6 / float(m.group(2))  # dd's own rate, as read by the frames
        cam = H.cam_json(h.path("cold.cam.json"), (0, 0, 3), (0, 0, 0), 40, a.size)
        scene = H.write_json(h.path("cold.scene.json"), COLD_SCENE)

        def frame(mode, how, temp):
            tag = h.path(f"cold-{mode}-{how}-{temp}")
            argv = [h.tool("vox-render"), store, "--cam", cam, "--scene", scene, "--threads",
                    str(h.threads), "-o", tag + ".exr", "--stats", tag + ".json", "--quiet"]
            argv += (["--lod", "0"] if mode == "exact" else []) + (["--prefetch"] if how == "prefetch" else [])
            r = H.run(argv, limit_mib=a.limit_mib, cold=temp == "cold", stderr=tag + ".err", groups=blk)
            s = json.load(open(tag + ".json")) if r["exit"] == 0 else {}
            return {**r, "read_bytes": s.get("io", {}).get("read_bytes"), "exr": tag + ".exr"}

        runs = {}
        for _ in range(a.runs):
            for mode in a.modes.split(","):
                for how in a.reads.split(","):
                    c, w = frame(mode, how, "cold"), frame(mode, how, "warm")
                    if c["exit"] != 0 or w["exit"] != 0:
                        H.fail(f"{mode} {how}: vox-render failed (exit {c['exit']}, {w['exit']}; "
                               f"oom {c.get('oom')}): see {h.rel(h.path('cold-' + mode + '-' + how + '-cold.err'))}")
                    same = json.loads(H.check([h.tool("vox-lod-compare"), c["exr"], w["exr"]]))
                    if same["rmse_rgb"] or same["rmse_alpha"]:
                        H.fail(f"{mode} {how}: the cold and warm images differ")
                    runs.setdefault((mode, how), []).append((c, w))
        rep = H.Report(h, "cold", "Cold frames against warm ones")
        rep.add(f"Store `{h.rel(store)}`, {a.size}^2, {h.threads} threads, "
                f"{f'a memory limit of {a.limit_mib} MiB' if a.limit_mib else 'no memory limit'}, the disk read sequentially at {mbps:.0f} MB/s"
                + (f" (throttled: {a.disk_mbps} MB/s, {a.disk_iops} reads/s)" if blk else "")
                + f"; medians of {a.runs} runs.", "")
        rows = []
        for (mode, how), v in runs.items():
            ratio = [c["wall_s"] / max(w["wall_s"], c["read_bytes"] / 1e6 / mbps) for c, w in v]
            mb = H.median([c["read_bytes"] for c, _ in v]) / 1e6
            rows.append((mode, how, f"{H.median([c['wall_s'] for c, _ in v]):.2f}",
                         f"{H.median([w['wall_s'] for _, w in v]):.2f}", f"{mb:.0f}", f"{mb / mbps:.2f}",
                         f"{H.median([c['peak_bytes'] for c, _ in v]) / H.MiB:.0f}",
                         max(c["failcnt"] for c, _ in v), f"{H.median(ratio):.2f}"))
            rep.raw[f"{mode}.{how}"] = {"cold_s": H.median([c["wall_s"] for c, _ in v]),
                                        "warm_s": H.median([w["wall_s"] for _, w in v]),
                                        "read_mb": mb, "ratio": H.median(ratio)}
        rep.table(["mode", "reads", "cold s", "warm s", "MB read", "disk s", "peak MiB", "failcnt",
                   "cold / max(warm, disk)"], rows)
        rep.raw["disk_mbps"] = mbps
        rep.write()
        return rep.raw


class Turntable:
    """turntable: the frames of a turntable in one vox-render process, in a memory limit.

--frames frames around the volume from --view 0,20, the first cold (page cache dropped) in a
cgroup of --limit-mib; per frame its render time, whole time and bricks read; then the mean of
frames 2..N over frame 1 (later frames find the bricks earlier ones read in the cache)."""

    @staticmethod
    def add_arguments(p):
        add_store_arguments(p)
        p.add_argument("--frames", type=int, default=36)
        p.add_argument("--limit-mib", type=int, default=512)
        p.add_argument("--size", default="1024x1024")
        p.add_argument("--warm", action="store_true", help="keep the page cache")
        p.add_argument("--render-args", default="", help="more vox-render flags, e.g. '--lod 0'")

    @staticmethod
    def main(h, a):
        store = store_arg(h, a)
        d = h.path("turntable")
        os.makedirs(d, exist_ok=True)
        for f in os.listdir(d):
            os.remove(os.path.join(d, f))
        argv = [h.tool("vox-render"), store, "--view", "0,20", "--turntable", str(a.frames), "--size",
                a.size, "--threads", str(h.threads), "-o", d + "/tt.%04d.exr", "--stats",
                d + "/tt.%04d.json", *a.render_args.split()]
        r = H.run(argv, limit_mib=a.limit_mib, cold=not a.warm, stderr=d + "/tt.log")
        if r["exit"] != 0:
            H.fail(f"vox-render exited {r['exit']} (signal {r['signal']}): see {h.rel(d + '/tt.log')}")
        rep = H.Report(h, "turntable", "A turntable in one process")
        rep.add(f"Store `{h.rel(store)}`, {a.frames} frames, {a.size}, {h.threads} threads, "
                f"limit {a.limit_mib} MiB (peak {r['peak_bytes'] / H.MiB:.0f} MiB, failcnt "
                f"{r['failcnt']}), {'warm' if a.warm else 'cold'} start, {r['wall_s']:.1f} s in all.", "")
        rows = []
        for f in range(1, a.frames + 1):
            s = json.load(open(f"{d}/tt.{f:04d}.json"))
            t = s["timings"]
            rows.append((f, f"{t['frame_seconds']:.3f}", f"{t['total_seconds']:.3f}", s["cache"]["misses"],
                         f"{s['io']['read_bytes'] / H.MiB:.1f}"))
        rep.table(["frame", "render s", "total s", "bricks read", "MiB read"], rows)
        first = float(rows[0][1])
        later = [float(x[1]) for x in rows[1:]]
        if later:
            rep.raw["ratio"] = sum(later) / len(later) / first
            rep.add(f"Frame 1: {first:.3f} s; frames 2-{a.frames}: mean {sum(later) / len(later):.3f} s: "
                    f"ratio **{rep.raw['ratio']:.3f}**.")
        rep.raw.update(first_s=first, peak_mib=r["peak_bytes"] / H.MiB)
        rep.write()
        return rep.raw


class Ingest:
    """ingest: vox-ingest's throughput, its store's size against the .vdb, and its peak memory.

The 2048^3 sphere (vdb_tool) unless --vdb; --runs runs, medians: wall and CPU time, M active
voxels/s, store bytes against the .vdb's, bytes per occupied voxel, the sampled peaks of RssAnon
(the process's own memory) and RssFile (the mapped .vdb, reclaimable page cache)."""

    @staticmethod
    def add_arguments(p):
        p.add_argument("--vdb", help="an OpenVDB level set (default: the 2048^3 sphere)")
        p.add_argument("--runs", type=int, default=3)

    @staticmethod
    def main(h, a):
        vdb = os.path.abspath(a.vdb) if a.vdb else h.vdb("sphere", H.SPHERE_2048)
        out = h.path("ingest.store")
        rows = []
        for i in range(a.runs):
            r = H.run([h.tool("vox-ingest"), vdb, out, "--force", "--threads", str(h.threads)],
                      stderr=h.path("ingest.log"), rss=True)
            log = open(h.path("ingest.log")).read()
            m = re.search(r"(\d+) occupied voxels in .* (\d+) active voxels read", log)
            if r["exit"] != 0 or not m:
                H.fail(f"vox-ingest failed: see {h.rel(h.path('ingest.log'))}")
            rows.append({**r, "occupied": int(m.group(1)), "active": int(m.group(2)),
                         "store_bytes": H.dir_bytes(out)})
        med = {k: H.median([x[k] for x in rows]) for k in ("wall_s", "cpu_s", "rss_anon", "rss_file")}
        x = rows[0]
        vdb_bytes = os.path.getsize(vdb)
        res = {"wall_s": med["wall_s"], "cpu_s": med["cpu_s"], "mvox_s": x["active"] / med["wall_s"] / 1e6,
               "store_pct": 100 * x["store_bytes"] / vdb_bytes,
               "bytes_per_voxel": x["store_bytes"] / x["occupied"],
               "rss_anon_mib": med["rss_anon"] / H.MiB, "rss_file_mib": med["rss_file"] / H.MiB}
        rep = H.Report(h, "ingest", "Ingest")
        rep.add(f"`vox-ingest {h.rel(vdb)} --threads {h.threads}`, medians of {a.runs} runs.", "")
        rep.table(["wall s", "CPU s", "M active voxels/s (wall)", "store MB", ".vdb MB", "store / .vdb",
                   "bytes / occupied voxel", "peak RssAnon MiB", "peak RssFile MiB"],
                  [(f"{res['wall_s']:.2f}", f"{res['cpu_s']:.2f}", f"{res['mvox_s']:.2f}",
                    f"{x['store_bytes'] / 1e6:.1f}", f"{vdb_bytes / 1e6:.1f}", f"{res['store_pct']:.1f}%",
                    f"{res['bytes_per_voxel']:.2f}", f"{res['rss_anon_mib']:.1f}", f"{res['rss_file_mib']:.1f}")])
        rep.raw.update(res)
        rep.write()
        return rep.raw
