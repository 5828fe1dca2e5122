"""The vox module against the command-line tools: the same pixels bit for
bit, the same first hits, the same refusals with the same messages, and
long calls that let other Python threads run."""
import faulthandler
import json
import math
import os
import re
import shutil
import signal
import threading

import pytest

from conftest import cli_message, run, tool

np = pytest.importorskip("numpy", reason="numpy (python3-numpy) is not installed")
vox = pytest.importorskip("vox", reason="the vox module is not built (PYTHONPATH=build/python)")

LAYERS = {"rgba": ["R", "G", "B", "A"], "z": ["Z"], "normal": ["N.X", "N.Y", "N.Z"],
          "voxel": ["voxel.i", "voxel.j", "voxel.k"], "position": ["P.X", "P.Y", "P.Z"],
          "distance": ["distance"]}


def assert_same_bits(result, exr):
    """Every channel of the module's result equals the EXR's, bit for bit."""
    h, w = exr["height"], exr["width"]
    for key, names in LAYERS.items():
        arr = result[key].reshape(h, w, len(names))
        for c, name in enumerate(names):
            ours = np.ascontiguousarray(arr[:, :, c]).view(np.uint32)
            theirs = exr["channels"][name].view(np.uint32)
            assert np.array_equal(ours, theirs), "channel %s differs" % name


@pytest.mark.parametrize("camera", ["camera", "ortho"])
def test_render_equals_vox_render(store, files, workdir, camera):
    exr_path = workdir / ("cli_%s.exr" % camera)
    code, _, err = run([tool("render"), store, "--cam", files[camera + "_path"], "--scene",
                        files["scene_path"], "-o", exr_path, "--layers", "normal,voxel,position,distance",
                        "--threads", "2", "--tile-size", "16", "--float", "--quiet"])
    assert code == 0, err
    exr = vox.read_exr(exr_path)
    # Paths, and the same camera and scene as dicts.
    by_path = vox.render(store, files[camera + "_path"], files["scene_path"],
                         layers="normal,voxel,position,distance", threads=2, tile_size=16)
    by_dict = vox.render(vox.Store(store), files[camera], files["scene"],
                         layers=["normal", "voxel", "position", "distance"], threads=1)
    assert by_path["rgba"].shape == (exr["height"], exr["width"], 4)
    assert by_path["rgba"].dtype == np.float32
    assert_same_bits(by_path, exr)
    assert_same_bits(by_dict, exr)
    hit = by_path["rgba"][:, :, 3] > 0
    assert 0.05 < hit.mean() < 0.95  # the sphere is in the picture, not all of it
    assert np.all(np.isinf(by_path["z"][~hit]))


def test_render_stats_and_options(store, files, workdir):
    r = vox.render(store, files["camera"], threads=2, memory_mb=256, split="2+4",
                   o=str(workdir / "py.exr"))
    s = r["stats"]
    assert s["threads"] == 2
    assert s["split"] == {"n1": 2, "n2": 4}
    assert s["image"]["width"] == 96 and s["image"]["height"] == 72
    assert s["memory"]["total"] == 256 << 20
    assert s["rays"]["primary"] == 96 * 72
    assert s["image"]["hit_pixels"] == int((r["rgba"][:, :, 3] > 0).sum())
    assert "normal" not in r and "voxel" not in r
    # o= also writes the EXR, with the same pixels.
    exr = vox.read_exr(workdir / "py.exr")
    assert np.array_equal(exr["channels"]["Z"].view(np.uint32), r["z"].view(np.uint32))
    # Without a camera, the default camera at --size.
    d = vox.render(store, size=(40, 30))
    assert d["rgba"].shape == (30, 40, 4)
    # size= overrides the camera's, as --size does, and the stats say so.
    e = vox.render(store, files["camera"], size=(40, 30), view=(30, 20))
    assert e["rgba"].shape == (30, 40, 4)
    assert e["stats"]["camera"]["width"] == 40
    assert e["stats"]["camera"]["source"]["size"] == "--size"
    assert e["stats"]["camera"]["source"]["view"] == [30.0, 20.0]


def test_render_one_frame_of_a_sequence(store, files, workdir):
    """A list of cameras or turntable=N is a frame sequence; frames=K renders
    its frame K, the pixels vox-render writes for that frame."""
    def same(a, b):
        for key in ("rgba", "z"):
            assert np.array_equal(np.ascontiguousarray(a[key]).view(np.uint32),
                                  np.ascontiguousarray(b[key]).view(np.uint32)), key
    cams = [files["camera"], files["ortho"]]
    second = vox.render(store, cams, frames=2, threads=2)
    same(second, vox.render(store, files["ortho"], threads=2))
    assert second["stats"]["frame"] == {"number": 2, "count": 2, "first": 2, "last": 2}
    with pytest.raises(ValueError, match="one frame"):
        vox.render(store, cams, threads=2)
    code, _, err = run([tool("render"), store, "--cam", files["camera_path"], "--turntable", "4",
                        "--frames", "3", "-o", workdir / "tt.%d.exr", "--threads", "2", "--float",
                        "--quiet"])
    assert code == 0, err
    exr = vox.read_exr(workdir / "tt.3.exr")
    third = vox.render(store, files["camera_path"], turntable=4, frames=3, threads=2)
    for c, name in enumerate("RGBA"):
        assert np.array_equal(np.ascontiguousarray(third["rgba"][:, :, c]).view(np.uint32),
                              exr["channels"][name].view(np.uint32)), name
    assert third["stats"]["camera"]["source"]["turntable"] == {"frames": 4, "turn_deg": 180.0}


def test_store_info_is_vox_info(store):
    code, out, err = run([tool("info"), store])
    assert code == 0, err
    s = vox.Store(store)
    assert str(s) == out
    info = s.info
    assert info["levels"] == 6 and info["brick_level"] == 3
    assert info["grid_class"] == "level set"
    assert "voxels:          %d occupied" % info["voxels"] in out
    assert "bricks:          %d " % info["bricks"] in out
    assert info["origin"] == [-32, -32, -32]
    assert sum(info["stored_size_histogram"].values()) == info["bricks"]


def probe_cli(args, rays):
    text = "".join(" ".join(float(x).hex() for x in row) + "\n" for row in rays)
    code, out, err = run([tool("probe")] + args, stdin=text)
    assert code == 0, err
    voxels, ts, hits = [], [], []
    for line in out.splitlines():
        f = line.split()
        hits.append(f[0] == "hit")
        voxels.append([int(v) for v in f[1:4]] if f[0] == "hit" else [0, 0, 0])
        ts.append(float(f[4]) if f[0] == "hit" else math.inf)
    return np.array(voxels, dtype=np.int64), np.array(ts), np.array(hits)


def random_rays(n, seed):
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    origin = 70 * d / np.linalg.norm(d, axis=1, keepdims=True)
    target = rng.uniform(-40, 40, size=(n, 3))
    return np.hstack([origin, target - origin])


@pytest.mark.parametrize("options,args", [({}, []),
                                          ({"split": "2+4", "fixed": 128}, ["--split", "2+4", "--fixed", "128"]),
                                          ({"tracer": "long-double"}, ["--tracer", "long-double"]),
                                          ({"tracer": "render", "fixed": 64}, ["--tracer", "render", "--fixed", "64"]),
                                          ({"single_step": True}, ["--single-step"])])
def test_probe_equals_vox_probe(store, options, args):
    rays = random_rays(2000, 7)
    voxels, t, hit = vox.probe(store, rays, **options)
    cv, ct, ch = probe_cli([store] + args, rays)
    assert hit.dtype == np.bool_ and voxels.shape == (2000, 3)
    assert 200 < hit.sum() < 1900
    assert np.array_equal(hit, ch)
    assert np.array_equal(voxels[hit], cv[ch])
    assert np.array_equal(t[hit], ct[ch])  # 17 significant digits round-trip a double
    assert np.all(np.isinf(t[~hit]))


def test_probe_generated_shape_equals_vox_probe():
    rays = random_rays(500, 3)
    voxels, t, hit = vox.probe(None, rays.tolist(), generate="sphere:64")
    cv, ct, ch = probe_cli(["--generate", "sphere:64"], rays)
    assert np.array_equal(hit, ch) and np.array_equal(voxels[hit], cv[ch])
    assert np.array_equal(t[hit], ct[ch])


# (tool, command-line arguments, call, exception, exit code): every one of
# these the tool refuses with its documented exit code (2: a bad command
# line, a --generate shape included; 1: the run failed, a store that does not
# open included); the module raises with the line the tool printed.
def bad_inputs(store, files, workdir):
    bad_cam = workdir / "bad_cam.json"
    bad_cam.write_text(json.dumps(dict(files["camera"], width=-4)))
    far_cam = dict(files["camera"], position=[1e9, 0, 0])
    far_path = workdir / "far_cam.json"
    far_path.write_text(json.dumps(far_cam))
    missing = str(workdir / "no_such.store")
    cam = files["camera_path"]
    R, P = "render", "probe"
    return [
        (R, [store, "--threads", "-1"], lambda: vox.render(store, threads=-1), ValueError, 2),
        (R, [store, "--tiles", "3/2"], lambda: vox.render(store, tiles="3/2"), ValueError, 2),
        (R, [store, "--layers", "normal,depth"], lambda: vox.render(store, layers="normal,depth"), ValueError, 2),
        (R, [store, "--size", "64"], lambda: vox.render(store, size="64"), ValueError, 2),
        (R, [store, "--cache-mb", "0"], lambda: vox.render(store, cache_mb=0), ValueError, 2),
        (R, [store, "--memory-mb", "lots"], lambda: vox.render(store, memory_mb="lots"), ValueError, 2),
        (R, [store, "--no-prefetch"], lambda: vox.render(store, no_prefetch=True), ValueError, 2),
        (R, [store, "--cam", cam, "--split", "9+9", "-o", workdir / "x.exr"],
         lambda: vox.render(store, cam, split="9+9"), ValueError, 1),
        (R, [store, "--cam", cam, "--tile-size", "3", "-o", workdir / "x.exr"],
         lambda: vox.render(store, cam, tile_size=3), ValueError, 2),
        (R, [store, "--cam", bad_cam, "-o", workdir / "x.exr"], lambda: vox.render(store, bad_cam), ValueError, 1),
        (R, [store, "--cam", far_path, "-o", workdir / "x.exr"], lambda: vox.render(store, far_path), ValueError, 1),
        (R, [store, "--cam", cam, "--memory-mb", "1", "-o", workdir / "x.exr"],
         lambda: vox.render(store, cam, memory_mb=1), RuntimeError, 1),
        (R, [missing, "--cam", cam, "-o", workdir / "x.exr"], lambda: vox.render(missing, cam), OSError, 1),
        (P, [store, "--fixed", "32"], lambda: vox.probe(store, np.zeros((1, 6)), fixed=32), ValueError, 2),
        (P, [store, "--tracer", "exact"], lambda: vox.probe(store, np.zeros((1, 6)), tracer="exact"),
         ValueError, 2),
        (P, [store, "--split", "x"], lambda: vox.probe(store, np.zeros((1, 6)), split="x"), ValueError, 2),
        (P, [store, "--cache-mb", "-1"], lambda: vox.probe(store, np.zeros((1, 6)), cache_mb=-1), ValueError, 2),
        (P, [missing], lambda: vox.probe(missing, np.zeros((1, 6))), OSError, 1),
        (P, ["--generate", "cube:7"], lambda: vox.probe(None, np.zeros((1, 6)), generate="cube:7"), ValueError, 2),
        (P, [store, "--single-step", "--split", "3"],
         lambda: vox.probe(store, np.zeros((1, 6)), single_step=True, split="3"), ValueError, 2),
    ]


def test_bad_inputs_raise_the_cli_message(store, files, workdir):
    for name, args, call, exc, want in bad_inputs(store, files, workdir):
        if name == "render":
            args = args + ["--quiet"]  # no memory report before the error
        code, _, err = run([tool(name)] + args, stdin="")
        # The exact code: a sanitizer's report (86) or a signal (128 + N) on
        # the error path must not pass for the refusal.
        assert code == want, (name, args, code, err)
        expected = cli_message(err, "vox-" + name)
        with pytest.raises(exc) as info:
            call()
        if "--memory-mb" in args and exc is RuntimeError:
            # The module holds the image, which the budget charges to the
            # process: the same message, with that much more needed.
            number = r"[0-9]+(\.[0-9]+)?"
            assert re.sub(number, "N", str(info.value)) == re.sub(number, "N", expected)
            image_mib = 96 * 72 * 5 * 4 / 2**20
            ours = float(re.search(r"process (" + number + ")", str(info.value)).group(1))
            theirs = float(re.search(r"process (" + number + ")", expected).group(1))
            assert abs(ours - theirs - image_mib) < 0.06, (ours, theirs)
            continue
        assert str(info.value) == expected, (name, args)


def test_bad_ray_raises_the_cli_message(store):
    rays = random_rays(3, 1)
    rays[1, 3:] = 0  # no direction
    code, out, err = run([tool("probe"), store], stdin="".join(
        " ".join(repr(float(x)) for x in r) + "\n" for r in rays))
    assert code == 1 and out.splitlines()[1] == "error"
    line = cli_message(err, "vox-probe")  # "stdin line 2: MESSAGE: ox oy ..."
    message = line[len("stdin line 2: "):].rsplit(": ", 1)[0]
    with pytest.raises(ValueError) as info:
        vox.probe(store, rays)
    assert str(info.value) == "rays[1]: " + message
    with pytest.raises(ValueError, match=r"\(N, 6\)"):
        vox.probe(store, np.zeros((4, 5)))


def test_unknown_option_is_a_type_error(store):
    with pytest.raises(TypeError, match="colour"):
        vox.render(store, colour="red")
    with pytest.raises(TypeError, match="takes a value"):
        vox.render(store, threads=True)


def test_quiet_takes_a_bool(store, vdb, workdir):
    # The message a switch's keyword gets, not a cast error.
    with pytest.raises(TypeError, match=r"^render\(\): quiet takes True or False$"):
        vox.render(store, quiet="no")
    with pytest.raises(TypeError, match=r"^ingest\(\): quiet takes True or False$"):
        vox.ingest(vdb, workdir / "quiet.store", quiet="no")
    assert not (workdir / "quiet.store").exists()


# The keywords are the tools' flags. Each tool's command line and
# its Python function read one option table (tools/common/options.h); every
# flag its --help lists is a keyword of the function (None: not given).
def help_flags(name):
    code, out, err = run([tool(name), "--help"])
    assert code == 0, err
    flags = set(re.findall(r"^  (-{1,2}[a-z][a-z0-9-]*)", out, re.M))
    return flags - {"-h", "--help", "--version"}


def test_every_flag_is_a_keyword(store, vdb, workdir):
    calls = {
        "ingest": lambda kw: vox.ingest(vdb, workdir / "kw.store", **kw, force=True),
        "render": lambda kw: vox.render(store, **kw, size=(8, 6)),
        "probe": lambda kw: vox.probe(store, np.zeros((0, 6)), **kw),
    }
    for name, call in calls.items():
        flags = help_flags(name)
        assert {"--threads", "--memory-mb"} & flags, (name, flags)  # the help was read
        keywords = {f.lstrip("-").replace("-", "_"): None for f in flags}
        keywords.pop("size" if name == "render" else "force", None)
        call(keywords)
    with pytest.raises(TypeError, match="no flag --no-such-flag"):
        vox.probe(store, np.zeros((0, 6)), no_such_flag=None)


def test_ingest_equals_vox_ingest(vdb, workdir):
    cli_store = workdir / "cli.store"
    code, _, err = run([tool("ingest"), vdb, cli_store, "--zstd-level", "5", "--normal-bits", "12",
                        "--threads", "2", "--quiet"])
    assert code == 0, err
    calls = []
    stats = vox.ingest(vdb, workdir / "py.store", progress=lambda *a: calls.append(a),
                       zstd_level=5, normal_bits=12, threads=2)
    assert stats["threads"] == 2 and stats["bricks"] > 0
    assert calls and calls[-1][0] == calls[-1][1] and calls[-1][2] == stats["occupied_voxels"]
    ours, theirs = vox.Store(workdir / "py.store").info, vox.Store(cli_store).info
    # The index records the command line: vox.ingest's differs from vox-ingest's.
    assert (ours["index_file_bytes"] - theirs["index_file_bytes"] ==
            len(ours["build_options"]) - len(theirs["build_options"]))
    assert ours["build_options"].startswith("vox.ingest ")
    for key in ("dir", "build_options", "index_file_bytes"):
        ours.pop(key), theirs.pop(key)
    assert ours == theirs
    assert stats["occupied_voxels"] == ours["voxels"]
    # Refusals, as the tool prints them, with the tool's exit code (2: a bad
    # command line, 1: the run failed).
    for args, kwargs, exc, want in [(["--zstd-level", "30"], {"zstd_level": 30}, ValueError, 2),
                                    (["--normal-bits", "20"], {"normal_bits": 20}, ValueError, 2),
                                    (["--levels", "7+"], {"levels": "7+"}, ValueError, 2),
                                    (["--threads", "-2"], {"threads": -2}, ValueError, 2),
                                    (["--isovalue", "abc"], {"isovalue": "abc"}, ValueError, 2),
                                    (["--grid", "nope"], {"grid": "nope"}, None, 1),
                                    ([], {}, "missing", 1)]:
        src = vdb if exc != "missing" else str(workdir / "none.vdb")
        code, _, err = run([tool("ingest"), src, workdir / "bad.store", "--force"] + args)
        assert code == want, (args, code, err)
        expected = cli_message(err, "vox-ingest")
        with pytest.raises((ValueError, OSError)) as info:
            vox.ingest(src, workdir / "bad.store", force=True, **kwargs)
        assert str(info.value) == expected, args


def test_ingest_progress_exception_is_raised(vdb, workdir):
    def progress(done, total, voxels):
        raise KeyError("stop")
    with pytest.raises(KeyError):
        vox.ingest(vdb, workdir / "p.store", progress=progress, force=True)


def test_render_in_a_thread_does_not_block_python(store, files, workdir):
    # The render reads its camera from a FIFO that this thread writes only
    # once the render has opened it: the render can finish only if Python
    # runs while vox.render is inside C++, that is, if the call released the
    # GIL. No clock decides it. Were the GIL held, both threads would wait
    # for ever; faulthandler's watchdog (a C thread that needs no GIL) then
    # ends the process with the stacks instead of waiting for ctest's timeout.
    fifo = os.path.join(str(workdir), "camera.fifo")
    os.mkfifo(fifo)
    result, failure = {}, []

    def render():
        try:
            result.update(vox.render(store, fifo, files["scene"], threads=1))
        except BaseException as e:  # unblock the writer below, then report
            failure.append(e)
            os.close(os.open(fifo, os.O_RDONLY | os.O_NONBLOCK))

    worker = threading.Thread(target=render)
    faulthandler.dump_traceback_later(120, exit=True)
    try:
        worker.start()
        try:
            with open(fifo, "w") as f:  # returns once the render opened the FIFO
                json.dump(files["camera"], f)
        except BrokenPipeError:  # the render failed: reported below
            pass
        worker.join()
    finally:
        faulthandler.cancel_dump_traceback_later()
        os.unlink(fifo)
    assert not failure, failure
    camera = files["camera"]
    assert result["rgba"].shape == (camera["height"], camera["width"], 4)


# Every keyword does what its flag does; Ctrl-C and a raising
# progress callback stop a long call, keep the old outputs and raise.

@pytest.fixture(scope="session")
def fog_vdb(workdir):
    """A fog volume whose interior is active tiles (vdb_tool -ls2fog)."""
    vdb_tool = shutil.which("vdb_tool")
    if not vdb_tool:
        pytest.skip("vdb_tool (libopenvdb-tools) not found")
    path = workdir / "fog.vdb"
    code, _, err = run([vdb_tool, "-sphere", "r=0.5", "v=0.01", "w=3", "-ls2fog", "-write", path])
    assert code == 0, err
    return str(path)


def test_ingest_max_voxels_is_the_cli_flag(fog_vdb, workdir):
    for limit in ("1000", None):
        args = ["--max-voxels", limit] if limit else []
        code, _, err = run([tool("ingest"), fog_vdb, workdir / "mv-cli.store", "--force",
                            "--quiet"] + args)
        kwargs = {"max_voxels": int(limit)} if limit else {}
        if code == 0:
            vox.ingest(fog_vdb, workdir / "mv-py.store", force=True, **kwargs)
            continue
        assert limit, err
        with pytest.raises((ValueError, OSError, RuntimeError)) as info:
            vox.ingest(fog_vdb, workdir / "mv-py.store", force=True, **kwargs)
        assert str(info.value) == cli_message(err, "vox-ingest")
        assert "--max-voxels" in str(info.value)


def store_bytes(path):
    out = {}
    for root, _, names in os.walk(path):
        for n in names:
            with open(os.path.join(root, n), "rb") as f:
                out[os.path.relpath(os.path.join(root, n), path)] = f.read()
    return out


def temporaries(path):
    return [n for n in os.listdir(path) if ".tmp-" in n]


def test_a_raising_progress_callback_keeps_the_old_store(vdb, workdir):
    target = workdir / "kept.store"
    vox.ingest(vdb, target, force=True)
    before = store_bytes(target)
    calls = []

    def progress(done, total, voxels):
        calls.append(done)
        raise KeyError("stop")
    with pytest.raises(KeyError):
        vox.ingest(vdb, target, progress=progress, force=True)
    assert len(calls) == 1  # stopped at the first progress point
    assert store_bytes(target) == before
    assert temporaries(workdir) == []


@pytest.mark.parametrize("hook,value,words", [
    ("VOX_INGEST_TEST_CRASH", str(int(signal.SIGSEGV)), "crashed with SIGSEGV"),
    ("VOX_INGEST_TEST_EXIT", "1", "exited with code 1 before finishing"),
])
def test_a_crashing_ingest_raises_and_keeps_the_old_store(hook, value, words, vdb, workdir,
                                                          monkeypatch):
    # The ingest runs in a child process, as vox-ingest's does: a crash while
    # reading (the tool's test hook raises the signal, or exits as a
    # sanitizer report does, at the first progress point) raises here, Python
    # goes on, the old store stays and the child's temporaries are removed.
    target = workdir / "crash.store"
    vox.ingest(vdb, target, force=True)
    before = store_bytes(target)
    monkeypatch.setenv(hook, value)
    with pytest.raises(RuntimeError) as info:
        vox.ingest(vdb, target, force=True)
    message = str(info.value)
    assert str(vdb) + ": the ingest child process (pid " in message, message
    assert words in message and "its unfinished store is removed" in message, message
    assert store_bytes(target) == before
    assert temporaries(workdir) == []
    monkeypatch.delenv(hook)
    assert vox.ingest(vdb, target, force=True)["bricks"] > 0  # and the next call works


INTERRUPT = r"""
import os, signal, sys, threading, time
import vox
what, store, target = sys.argv[1:4]
t0 = time.monotonic()
threading.Timer(0.4, lambda: os.kill(os.getpid(), signal.SIGINT)).start()
try:
    if what == "ingest":
        vox.ingest(store, target, force=True, threads=1,
                   progress=lambda *a: time.sleep(0.25))
    else:
        vox.render(store, size=(2000, 2000), threads=1, o=target, lod=0)
    print("finished")
except KeyboardInterrupt:
    print("interrupted %.3f" % (time.monotonic() - t0))
"""


@pytest.mark.parametrize("what", ["ingest", "render"])
def test_ctrl_c_stops_long_calls_and_keeps_old_outputs(what, vdb, store, workdir):
    target = workdir / ("ctrl-c.store" if what == "ingest" else "ctrl-c.exr")
    if what == "ingest":
        vox.ingest(vdb, target, force=True)
    else:
        vox.render(store, size=(32, 32), o=target)
    before = store_bytes(target) if what == "ingest" else target.read_bytes()
    source = vdb if what == "ingest" else store
    import subprocess
    import sys
    p = subprocess.run([sys.executable, "-c", INTERRUPT, what, source, str(target)],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    words = p.stdout.split()
    assert words and words[0] == "interrupted", p.stdout + p.stderr
    assert float(words[1]) < 0.4 + 1.5  # stopped within about a second
    after = store_bytes(target) if what == "ingest" else target.read_bytes()
    assert after == before
    assert temporaries(workdir) == []


PROBE_INTERRUPT = r"""
import os, signal, sys, threading, time
import numpy as np
import vox
store, n = sys.argv[1], int(sys.argv[2])
rng = np.random.default_rng(3)
d = rng.normal(size=(n, 3))
origin = 70 * d / np.linalg.norm(d, axis=1, keepdims=True)
rays = np.hstack([origin, rng.uniform(-40, 40, size=(n, 3)) - origin])
t0 = time.monotonic()
if len(sys.argv) > 3:
    threading.Timer(0.4, lambda: os.kill(os.getpid(), signal.SIGINT)).start()
try:
    vox.probe(store, rays, tracer="long-double")
    print("finished %.3f" % (time.monotonic() - t0))
except KeyboardInterrupt:
    print("interrupted %.3f" % (time.monotonic() - t0))
"""


def test_ctrl_c_stops_probe_within_a_second(store):
    import subprocess
    import sys

    def probe(n, interrupt):
        p = subprocess.run([sys.executable, "-c", PROBE_INTERRUPT, store, str(n)] +
                           (["interrupt"] if interrupt else []),
                           capture_output=True, text=True, timeout=300)
        assert p.returncode == 0, p.stderr
        return p.stdout.split()
    # Enough rays that the whole call takes several seconds.
    n = 20000
    while True:
        words = probe(n, False)
        assert words[0] == "finished", words
        if float(words[1]) > 3.0 or n >= 20000000:
            break
        n = int(n * max(2.0, 4.0 / max(float(words[1]), 0.05)))
    words = probe(n, True)
    assert words and words[0] == "interrupted", words
    assert float(words[1]) < 0.4 + 1.0  # stopped within a second


def test_bytes_paths_are_file_system_names(store, workdir):
    name = bytes(workdir) + b"/bytes-\xff.exr"  # not UTF-8: os.fsencode's bytes
    out = vox.render(os.fsencode(store), size=(16, 16), o=name)
    assert os.path.exists(name)
    assert vox.read_exr(name)["width"] == 16
    assert vox.Store(os.fsencode(store)).path == store
    assert out["rgba"].shape == (16, 16, 4)
    assert not any(f.startswith("b'") for f in os.listdir(workdir))
    os.remove(name)


def test_version_is_the_tools_version(store):
    """vox.__version__ and vox.__git_describe__ are what `vox-render --version` prints."""
    assert re.fullmatch(r"\d+\.\d+\.\d+", vox.__version__), vox.__version__
    code, out, err = run([tool("render"), "--version"])
    assert code == 0, err
    assert out == "vox-render %s (git %s)\n" % (vox.__version__, vox.__git_describe__)


FAKED_INTERPRETER = r"""
import sys
sys.version_info = (3, 99, 1, "final", 0)   # as a Python the module was not built for
sys.executable = "/opt/other/bin/python3.99"
try:
    import vox
except ImportError as e:
    print("loaded" if "vox._vox" in sys.modules else "not loaded")
    print(e)
else:
    print("imported")
"""


def test_other_interpreter_is_told_which_one_vox_was_built_for():
    """An interpreter other than the one the extension was built for gets an
    ImportError naming both, before the extension is loaded."""
    import subprocess
    import sys
    p = subprocess.run([sys.executable, "-c", FAKED_INTERPRETER], capture_output=True, text=True,
                       timeout=60)
    assert p.returncode == 0, p.stderr
    loaded, message = p.stdout.splitlines()[:2]
    built = vox._BUILT_FOR
    assert loaded == "not loaded"
    assert message.startswith("vox: built for %s %d.%d; this is /opt/other/bin/python3.99 3.99."
                              % (built["executable"], *built["version"])), message
    assert "-DPython_EXECUTABLE=/opt/other/bin/python3.99" in message


def test_interpreter_check():
    """The check itself: this interpreter passes; another version or
    implementation does not."""
    import sys
    assert vox._interpreter_mismatch(sys.version_info, sys.implementation.name,
                                     sys.executable) is None
    major, minor = vox._BUILT_FOR["version"]
    assert "3.%d" % (minor + 1) in vox._interpreter_mismatch((major, minor + 1, 0), "cpython", "py")
    assert "(pypy)" in vox._interpreter_mismatch((major, minor, 0), "pypy", "/usr/bin/pypy3")
