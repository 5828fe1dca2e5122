"""Arrays ingested: vox-ingest streams a .npy into the store (no temporary
file) and records the file as its source; vox.ingest_array goes through a
temporary .vdb, which the store does not name. An interrupted vox-ingest of
an array leaves nothing behind and says what was kept."""
import os
import signal
import subprocess
import time

import pytest

from conftest import run, tool

np = pytest.importorskip("numpy", reason="numpy (python3-numpy) is not installed")
vox = pytest.importorskip("vox", reason="the vox module is not built (PYTHONPATH=build/python)")


def leftovers(d):
    return [e for e in os.listdir(d) if ".input-" in e or ".tmp-" in e]


def test_the_store_names_the_array_not_the_temporary_vdb(workdir):
    d = workdir / "source"
    d.mkdir()
    a = np.random.default_rng(3).random((8, 9, 10), dtype=np.float32)
    np.save(d / "a.npy", a)
    code, _, err = run([tool("ingest"), d / "a.npy", d / "npy.store", "--threshold", "0.5", "--quiet"])
    assert code == 0, err
    assert vox.Store(str(d / "npy.store")).info["source"] == str(d / "a.npy")
    code, _, err = run([tool("ingest"), d / "a.npy", d / "mine.store", "--threshold", "0.5",
                        "--source", "run 17 of the lab's model", "--quiet"])
    assert code == 0, err
    assert vox.Store(str(d / "mine.store")).info["source"] == "run 17 of the lab's model"
    vox.ingest_array(a, str(d / "array.store"), threshold=0.5, quiet=True)
    assert vox.Store(str(d / "array.store")).info["source"] == (
        "a numpy array of shape 8x9x10, float32 (through a temporary .vdb, removed)")
    assert leftovers(d) == []


def test_an_interrupted_array_ingest_leaves_nothing_behind(workdir):
    d = workdir / "convert"
    d.mkdir()
    npy = d / "big.npy"
    # 2^24 elements, half above the threshold: seconds of ingest.
    np.save(npy, np.random.default_rng(1).random((256, 256, 256), dtype=np.float32))
    out = d / "big.store"
    p = subprocess.Popen([tool("ingest"), str(npy), str(out), "--threshold", "0.5", "--quiet"],
                         stderr=subprocess.PIPE, text=True)
    # The bricks are being written once the store's temporary directory exists.
    deadline = time.monotonic() + 30
    while not any(e.startswith(".big.store.tmp-") for e in os.listdir(d)):
        assert time.monotonic() < deadline and p.poll() is None
        time.sleep(0.01)
    p.send_signal(signal.SIGINT)
    err = p.stderr.read()
    assert p.wait() == 128 + signal.SIGINT, err
    assert ("vox-ingest: interrupted (SIGINT); no store written at '%s', nothing left behind"
            % out) in err
    assert sorted(os.listdir(d)) == ["big.npy"]


def test_ingest_array_removes_the_temporary_vdb_a_killed_call_left(workdir):
    d = workdir / "stale"
    d.mkdir()
    gone = subprocess.Popen(["true"])
    gone.wait()  # a process that is gone: its temporary is stale
    stale = d / ("a.store.input-%d.vdb" % gone.pid)
    live = d / ("a.store.input-%d.vdb" % os.getppid())  # a live process's: kept
    other = d / ("b.store.input-%d.vdb" % gone.pid)     # another store's: kept
    for f in (stale, live, other):
        f.write_bytes(b"partial")
    vox.ingest_array(np.ones((4, 4, 4), np.float32), str(d / "a.store"), quiet=True)
    assert sorted(os.listdir(d)) == sorted(["a.store", live.name, other.name])
