"""An array ingested through a temporary .vdb: the store records the array
as its source (not the temporary), and an ingest interrupted while the array
is converted leaves no temporary .vdb and says what was kept."""
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
    assert vox.Store(str(d / "npy.store")).info["source"] == (
        "%s (an array, through a temporary .vdb, removed)" % (d / "a.npy"))
    code, _, err = run([tool("ingest"), d / "a.npy", d / "mine.store", "--threshold", "0.5",
                        "--source", "run 17 of the lab's model", "--quiet"])
    assert code == 0, err
    assert vox.Store(str(d / "mine.store")).info["source"] == "run 17 of the lab's model"
    vox.ingest_array(a, str(d / "array.store"), threshold=0.5, quiet=True)
    assert vox.Store(str(d / "array.store")).info["source"] == (
        "a numpy array of shape 8x9x10, float32 (through a temporary .vdb, removed)")
    assert leftovers(d) == []


def test_interrupted_while_converting_leaves_no_temporary_vdb(workdir):
    d = workdir / "convert"
    d.mkdir()
    npy = d / "big.npy"
    # 2^24 elements, half above the threshold: seconds of conversion.
    np.save(npy, np.random.default_rng(1).random((256, 256, 256), dtype=np.float32))
    out = d / "big.store"
    p = subprocess.Popen([tool("ingest"), str(npy), str(out), "--threshold", "0.5", "--quiet"],
                         stderr=subprocess.PIPE, text=True)
    # The conversion has begun once the .npy is mapped (it is unmapped before the ingest).
    deadline = time.monotonic() + 30
    while str(npy) not in open("/proc/%d/maps" % p.pid).read():
        assert time.monotonic() < deadline and p.poll() is None
        time.sleep(0.01)
    time.sleep(0.2)
    p.send_signal(signal.SIGINT)
    err = p.stderr.read()
    assert p.wait() == 128 + signal.SIGINT, err
    assert err == ("\nvox-ingest: interrupted while converting the array: no store written (the "
                   "output is as it was before), the temporary .vdb removed\n")
    assert sorted(os.listdir(d)) == ["big.npy"]
