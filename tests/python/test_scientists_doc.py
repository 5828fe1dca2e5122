"""docs/scientists.md's examples, run as written and in order in one
directory: every ```python block in this interpreter, every ```sh block by
the shell with the tools' directories first on PATH."""
import os
import re
import subprocess

import pytest

from conftest import tool

np = pytest.importorskip("numpy", reason="numpy (python3-numpy) is not installed")
vox = pytest.importorskip("vox", reason="the vox module is not built (PYTHONPATH=build/python)")

DOC = os.path.join(os.path.dirname(__file__), "..", "..", "docs", "scientists.md")


def test_examples_run_as_written(tmp_path, monkeypatch):
    text = open(DOC).read()
    blocks = re.findall(r"```(python|sh)\n(.*?)```", text, re.S)
    assert len(blocks) >= 8
    dirs = {os.path.dirname(tool(n)) for n in ("ingest", "probe", "render", "gen")}
    env = dict(os.environ, PATH=os.pathsep.join(sorted(dirs) + [os.environ.get("PATH", "")]))
    monkeypatch.chdir(tmp_path)
    for lang, code in blocks:
        if lang == "python":
            exec(compile(code, DOC, "exec"), {})
        else:
            p = subprocess.run(["bash", "-euo", "pipefail", "-c", code], env=env, capture_output=True, text=True)
            assert p.returncode == 0, code + p.stderr
    assert os.path.exists("blob-z32.exr") and os.path.exists("blob.exr")
