"""Fixtures of the vox module's tests: the command-line tools (their paths
come from ctest's environment), a generated store, cameras and scenes."""
import json
import os
import shutil
import subprocess

import pytest


def pytest_sessionfinish(session, exitstatus):
    """A run where tests were skipped (importorskip: no numpy, module not
    built; a tool not given) and none failed exits 77, the test's
    SKIP_RETURN_CODE, so ctest reports it as skipped rather than passed and
    .ci/run can refuse it. A module skipped whole collects no test (exit 5)."""
    reporter = session.config.pluginmanager.get_plugin("terminalreporter")
    skipped = reporter.stats.get("skipped") if reporter is not None else None
    if skipped and exitstatus in (pytest.ExitCode.OK, pytest.ExitCode.NO_TESTS_COLLECTED):
        session.exitstatus = 77


def tool(name):
    path = os.environ.get("VOX_%s_BIN" % name.upper())
    if not path or not os.path.exists(path):
        pytest.skip("vox-%s not given (run through ctest)" % name)
    return path


def run(args, stdin=None):
    """Runs a tool; returns (exit code, stdout, stderr)."""
    p = subprocess.run([str(a) for a in args], input=stdin, capture_output=True, text=True)
    return p.returncode, p.stdout, p.stderr


def cli_message(stderr, program):
    """The first line a tool printed, without its "vox-NAME: " prefix."""
    first = stderr.splitlines()[0]
    prefix = program + ": "
    assert first.startswith(prefix), stderr
    return first[len(prefix):]


CAMERA = {"position": [2.2, 1.4, 3.1], "look_at": [0.05, -0.1, 0.0], "up": [0, 1, 0],
          "fov_deg": 38, "width": 96, "height": 72, "projection": "perspective"}
ORTHO = {"position": [-2.5, 1.0, 2.0], "look_at": [0.0, 0.1, 0.0], "up": [0, 1, 0],
         "ortho_width": 2.6, "width": 80, "height": 64, "projection": "orthographic"}


@pytest.fixture(scope="session")
def workdir(tmp_path_factory):
    return tmp_path_factory.mktemp("vox_python")


@pytest.fixture(scope="session")
def store(workdir):
    """A 64^3 level-set sphere (world [-1, 1]^3, index [-32, 32)^3)."""
    path = workdir / "sphere.store"
    code, _, err = run([tool("gen"), "sphere", path, "--size", "64", "--levels", "3+3", "--quiet"])
    assert code == 0, err
    return str(path)


@pytest.fixture(scope="session")
def files(workdir):
    """cam.json, ortho.json and the demo's scene.json, as files and dicts."""
    demo = os.environ.get("VOX_DEMO_DIR")
    if not demo:
        pytest.skip("VOX_DEMO_DIR not given (run through ctest)")
    with open(os.path.join(demo, "scene.json")) as f:
        scene = json.load(f)
    out = {"scene": scene, "camera": CAMERA, "ortho": ORTHO}
    for name, obj in list(out.items()):
        path = workdir / (name + ".json")
        path.write_text(json.dumps(obj))
        out[name + "_path"] = str(path)
    return out


@pytest.fixture(scope="session")
def vdb(workdir):
    """A small OpenVDB level-set sphere made with vdb_tool."""
    vdb_tool = shutil.which("vdb_tool")
    if not vdb_tool:
        pytest.skip("vdb_tool (libopenvdb-tools) not found")
    path = workdir / "ball.vdb"
    code, _, err = run([vdb_tool, "-sphere", "r=0.5", "c=0.1,0,0", "v=0.02", "w=3", "-write", path])
    assert code == 0, err
    return str(path)
