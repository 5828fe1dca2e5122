"""vox-gen's scalar fields (fog, noise) against the fields evaluated here,
independently, in numpy: every voxel of a small grid, random voxels of a
larger one; its progress lines; and what an interrupted run says it kept."""
import math
import os
import signal
import subprocess
import time

import pytest

from conftest import run, tool

np = pytest.importorskip("numpy", reason="numpy (python3-numpy) is not installed")
vox = pytest.importorskip("vox", reason="the vox module is not built (PYTHONPATH=build/python)")

MASK = (1 << 64) - 1


def voxel_size(n):
    return 32.0 / (15.0 * n)


def fog_density(n, i, j, k):
    """The fog ball: 1 - |p|^2 / r^2 at voxel centre p = (i, j, k), r = 15 n / 32."""
    r = n * 15.0 / 32.0
    return 1.0 - (i * i + j * j + k * k) / (r * r)


def noise_waves(n):
    """The noise field's plane waves (k per voxel, amplitude, phase), from
    splitmix64 seeded with "vox-fog1", as docs/scientists.md describes them."""
    state = int.from_bytes(b"vox-fog1", "big")

    def uniform():
        nonlocal state
        state = (state + 0x9E3779B97F4A7C15) & MASK
        z = state
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK
        z ^= z >> 31
        return (z >> 11) * 2.0**-53

    octaves, per_octave = 6, 3
    a0 = 0.5 / (per_octave * sum(1.0 / (1 << o) for o in range(octaves)))
    waves = []
    for o in range(octaves):
        for _ in range(per_octave):
            z = 2 * uniform() - 1
            t = 2 * math.pi * uniform()
            s = math.sqrt(max(0.0, 1 - z * z))
            kw = 2 * math.pi / (0.5 / (1 << o)) * voxel_size(n)
            k = (s * math.cos(t) * kw, s * math.sin(t) * kw, z * kw)
            waves.append((k, a0 / (1 << o), 2 * math.pi * uniform()))
    return waves


def noise_value(n, i, j, k):
    v = 0.5
    for (kx, ky, kz), a, phase in noise_waves(n):
        v = v + a * np.sin(kx * i + ky * j + kz * k + phase)
    return v


def gen(workdir, shape, n, *extra):
    path = workdir / ("%s%d.store" % (shape, n))
    if not path.exists():
        code, _, err = run([tool("gen"), shape, path, "--size", n, "--quiet", *extra])
        assert code == 0, err
    return str(path)


def grid(n):
    i, j, k = np.meshgrid(*([np.arange(-n // 2, n // 2, dtype=np.float64)] * 3), indexing="ij")
    return i, j, k


def test_fog_ball_equals_the_formula_at_every_voxel(workdir):
    n = 64
    store = gen(workdir, "fog", n)
    info = vox.Store(store).info
    assert info["grid_class"] == "fog volume"
    d = fog_density(n, *grid(n))
    want = np.where(d > 0, d, 0).astype(np.float32)
    got = vox.read(store, ((-n // 2,) * 3, (n // 2,) * 3), attr="density")
    assert got.shape == (n, n, n)
    assert np.array_equal(got, want)  # the same arithmetic in double, then float: bit for bit
    assert info["voxels"] == int((d > 0).sum()) > 0.4 * n**3


def test_noise_equals_the_waves_at_every_voxel(workdir):
    n = 64
    store = gen(workdir, "noise", n)
    v = noise_value(n, *grid(n))
    got = vox.read(store, ((-n // 2,) * 3, (n // 2,) * 3), attr="density")
    occupied = v > 0.6
    # Occupancy agrees wherever the value is not within rounding of the threshold.
    clear = np.abs(v - 0.6) > 1e-12
    assert np.array_equal((got > 0)[clear], occupied[clear])
    assert 0.1 < occupied.mean() < 0.35, occupied.mean()
    want = np.where(occupied, (v - 0.6) / (1 - 0.6), 0)
    assert np.abs(got - want).max() < 1e-6  # sin's last bit may differ between libraries


@pytest.mark.parametrize("shape,n", [("fog", 256), ("noise", 128)])
def test_fields_at_random_voxels_of_a_larger_grid(workdir, shape, n):
    store = gen(workdir, shape, n, "--levels", "%d+5" % (n.bit_length() - 6))
    rng = np.random.default_rng(7)
    ijk = rng.integers(-n // 2, n // 2, size=(20000, 3)).astype(np.float64)
    s = vox.sample(store, ijk + 0.5)  # vox's index space: voxel centres at ijk + 0.5
    i, j, k = ijk.T
    if shape == "fog":
        d = fog_density(n, i, j, k)
        want = np.where(d > 0, d, 0).astype(np.float32)
        assert np.array_equal(np.nan_to_num(s["density"]) * (s["occupancy"] > 0), want)
    else:
        v = noise_value(n, i, j, k)
        want = np.where(v > 0.6, (v - 0.6) / 0.4, 0)
        clear = np.abs(v - 0.6) > 1e-12
        got = np.nan_to_num(s["density"]) * (s["occupancy"] > 0)
        assert np.array_equal((got > 0)[clear], (want > 0)[clear])
        assert np.abs(got - want).max() < 1e-6
    assert (want > 0).sum() > 1000


def test_progress_reaches_100_percent_with_the_time_left(workdir):
    """Plain lines (stderr is not a terminal) at each 10% of the grid, the time
    left on those drawn after the first second, then the finishing step."""
    out = workdir / "progress.store"
    start = time.monotonic()
    p = subprocess.Popen([tool("gen"), "fog", str(out), "--size", "512", "--threads", "1",
                          "--no-lod"], stderr=subprocess.PIPE, text=True)
    lines = [(time.monotonic() - start, line.rstrip("\n")) for line in p.stderr]
    assert p.wait() == 0, lines
    grid = [(t, l) for t, l in lines if "% of the grid" in l]
    percents = [int(l.split("%")[0].split()[-1]) for _, l in grid]
    assert percents == sorted(percents) and percents[-1] == 100 and len(percents) >= 10, lines
    # The display starts after this clock: a line seen 1.5 s after the start
    # was drawn at least a second into the run, and before 100% it says the time left.
    late = [l for t, l in grid[:-1] if t > 1.5]
    assert late, "the run was too fast to show the time left: %s" % lines
    assert all(l.endswith(" left") for l in late), lines
    assert lines[len(grid)][1] == "vox-gen: writing the index", lines


def interrupt(args, wait_for):
    """Starts vox-gen, sends SIGINT once `wait_for` is on its stderr, returns (code, stderr)."""
    p = subprocess.Popen([str(a) for a in args], stderr=subprocess.PIPE, text=True)
    seen = ""
    for line in p.stderr:
        seen += line
        if wait_for in line:
            p.send_signal(signal.SIGINT)
            break
    rest = p.stderr.read()
    return p.wait(), seen + rest


@pytest.mark.parametrize("force", [False, True])
def test_interrupted_run_says_what_was_kept(workdir, force):
    d = workdir / ("interrupted-%d" % force)
    d.mkdir()
    out = d / "noise.store"
    if force:
        code, _, err = run([tool("gen"), "sphere", out, "--size", "32", "--quiet"])
        assert code == 0, err
        before = {f: (out / f).read_bytes() for f in os.listdir(out) if (out / f).is_file()}
    code, err = interrupt([tool("gen"), "noise", out, "--size", "1024", "--threads", "1"]
                          + (["--force"] if force else []), "% of the grid")
    assert code == 1, err
    last = err.strip().splitlines()[-1]
    if force:
        assert last == "vox-gen: interrupted; no store written: '%s' is as it was before" % out
        assert {f: (out / f).read_bytes() for f in os.listdir(out) if (out / f).is_file()} == before
    else:
        assert last == "vox-gen: interrupted; no store written at '%s', nothing left behind" % out
        assert not out.exists()
    assert sorted(os.listdir(d)) == (["noise.store"] if force else [])
