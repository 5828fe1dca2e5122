"""A requeued sequence task (scripts/slurm/render-frames.sbatch, which passes
vox-render --skip-done) skips the frames already complete and verified as
that frame of that job, and renders again the missing, partial, damaged or
foreign ones, producing the same pixels."""
import os
import shutil
import subprocess
from pathlib import Path

import pytest

from conftest import tool

SBATCH = Path(__file__).resolve().parents[2] / "scripts" / "slurm" / "render-frames.sbatch"
FLAGS = ["--turntable", "4", "--size", "40x32", "--tile-size", "16"]


def task(store, out, *flags, task_id=1, chunk=4):
    """Array task `task_id` of render-frames.sbatch, run as Slurm would (without Slurm)."""
    env = dict(os.environ, VOX_RENDER=tool("render"), SLURM_ARRAY_TASK_ID=str(task_id),
               SLURM_ARRAY_TASK_MIN="1", SLURM_CPUS_PER_TASK="1")
    p = subprocess.run(["bash", str(SBATCH), store, "4", str(chunk), str(out / "f.%04d.exr"),
                        *FLAGS, "--stats", str(out / "f.%04d.json"), *flags],
                       env=env, capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    return p.stderr


def frames(out):
    return [out / ("f.%04d.exr" % n) for n in range(1, 5)]


def skipped(err):
    return sorted(int(l.split("f.")[1][:4]) for l in err.splitlines() if l.endswith("skipped"))


def test_a_requeued_task_renders_only_what_is_missing(store, workdir):
    out = workdir / "requeue"
    out.mkdir()
    first = task(store, out)
    assert skipped(first) == []
    reference = {p.name: p.read_bytes() for p in sorted(out.iterdir())}
    inode = {p: p.stat().st_ino for p in frames(out)}

    # Damage: frame 2 cut short, frame 3's stats gone, frame 4 replaced by
    # frame 1 (a complete EXR of another frame of the same job).
    f1, f2, f3, f4 = frames(out)
    data = f2.read_bytes()
    f2.write_bytes(data[: len(data) // 2])
    (out / "f.0003.json").unlink()
    shutil.copyfile(f1, f4)

    err = task(store, out)
    assert skipped(err) == [1], err
    assert "rendering %s: " % f2 in err and "rendering %s: no %s" % (f3, out / "f.0003.json") in err
    assert "rendering %s: %s has another vox:camera" % (f4, f4) in err, err
    assert f1.stat().st_ino == inode[f1]  # untouched
    for f in (f2, f3, f4):
        assert f.stat().st_ino != inode[f]
    # The frames rendered again are the same size as the first (pixels: below).
    for f in (f2, f3, f4):
        assert len(f.read_bytes()) == len(reference[f.name])

    # Everything is done now: a third run renders nothing.
    assert skipped(task(store, out)) == [1, 2, 3, 4]
    # Another job on the same paths (another image size: other cameras) renders everything.
    err = task(store, out, "--size", "48x32")
    assert skipped(err) == [] and err.count("has another vox:camera") == 4, err


def test_a_truncated_frame_is_rendered_again_with_the_same_pixels(store, workdir):
    """vox-render --skip-done itself: a frame whose EXR lost its last bytes is
    rendered again, the same pixels."""
    vox = pytest.importorskip("vox", reason="the vox module is not built (PYTHONPATH=build/python)")
    np = pytest.importorskip("numpy", reason="numpy (python3-numpy) is not installed")
    out = workdir / "skip"
    out.mkdir()
    cmd = [tool("render"), store, "-o", str(out / "a.exr"), "--size", "40x32", "--tile-size", "16",
           "--skip-done"]
    p = subprocess.run(cmd, capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    ref = (out / "a.exr").read_bytes()
    (out / "a.exr").write_bytes(ref[:-200])
    p = subprocess.run(cmd, capture_output=True, text=True)
    assert p.returncode == 0 and "rendering %s: " % (out / "a.exr") in p.stderr, p.stderr
    again = vox.read_exr(str(out / "a.exr"))
    (out / "ref.exr").write_bytes(ref)
    first = vox.read_exr(str(out / "ref.exr"))
    assert sorted(again["channels"]) == sorted(first["channels"])
    for name, pixels in first["channels"].items():
        assert np.array_equal(again["channels"][name], pixels, equal_nan=True), name
    p = subprocess.run(cmd, capture_output=True, text=True)
    assert "is done (this frame of this job, every tile read): skipped" in p.stderr, p.stderr
