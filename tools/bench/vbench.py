#!/usr/bin/env python3
"""vbench: vox's benchmarks, one subcommand per question.

    tools/bench/vbench.py [--build DIR] [--scratch DIR] [--out DIR] [--threads N] [--no-build]
                          QUESTION [options]

  peers      vox against NanoVDB's CPU ray caster and vdb_render (--compare: hit masks)
  scale      a frame's cost as the volume grows and the memory limit shrinks
  cold       a cold frame in a memory limit, against the warm one right after
  turntable  the frames of a turntable in one process, in a memory limit
  budget     the frames that must render in a memory limit (sizes, modes, threads), never killed
  pool       the brick pool's cost in time, against bricks on the heap
  ingest     vox-ingest's throughput, store size and peak memory
  precision  the accuracy study: every traversal variant against the exact reference
  paper      the paper's split: two steps against one, per grid and image size
  lod        level of detail against the exact frame: time, bytes and error
  view       vox-view in headless Chromium: coarse and refined frames, an orbit in a memory limit
  figures    re-measures every figure the docs quote (tools/bench/figures.tsv)

Volumes and stores are made in the scratch directory (--scratch, or $SCRATCH) and kept for
later runs; reports go to --out (or $OUT, default $SCRATCH/reports) as NAME.md and NAME.json.
Programs are built first in --build (or $VOX_BUILD, default build/) unless --no-build.
Runs that drop the page cache or use memory cgroups (cgroup v1) need root.
"""

import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import budget  # noqa: E402
import harness as H  # noqa: E402
import memory  # noqa: E402
import peers  # noqa: E402
import scale  # noqa: E402
import study  # noqa: E402
import view  # noqa: E402

QUESTIONS = {
    "peers": peers, "scale": scale, "cold": memory.Cold, "turntable": memory.Turntable,
    "ingest": memory.Ingest, "budget": budget.Matrix, "pool": budget.Pool, "precision": study.Precision,
    "paper": study.Paper, "lod": study.Lod, "view": view,
}
FIGURES = os.path.join(os.path.dirname(os.path.abspath(__file__)), "figures.tsv")


def parser():
    p = argparse.ArgumentParser(prog="vbench.py", description=__doc__.split("\n")[1],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--build", help="build directory (default $VOX_BUILD or build)")
    p.add_argument("--scratch", help="scratch directory for volumes and stores (default $SCRATCH)")
    p.add_argument("--out", help="report directory (default $OUT or $SCRATCH/reports)")
    p.add_argument("--threads", type=int, default=int(os.environ.get("THREADS", 2)))
    p.add_argument("--no-build", action="store_true", help="use the programs as built")
    sub = p.add_subparsers(dest="question", required=True)
    for name, mod in QUESTIONS.items():
        q = sub.add_parser(name, help=(mod.__doc__ or "").split("\n")[0],
                           description=mod.__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
        mod.add_arguments(q)
    f = sub.add_parser("figures", help="re-measure the figures the docs quote")
    f.add_argument("--page", help="only the figures of this page")
    f.add_argument("--list", action="store_true", help="list them, measure nothing")
    return p


def read_figures(path=FIGURES):
    """Rows of figures.tsv: page, quoted value, key into the subcommand's results, subcommand."""
    rows = []
    for n, line in enumerate(open(path), 1):
        if not line.strip() or line.startswith("#"):
            continue
        f = line.rstrip("\n").split("\t")
        if len(f) != 4:
            H.fail(f"{path}:{n}: want 4 tab-separated fields (page, quoted, key, command)")
        rows.append(dict(zip(("page", "quoted", "key", "command"), f)))
    return rows


def lookup(raw, key):
    """raw[key], or raw[A][B..] for key A/B.. (a key may itself hold a /)."""
    if isinstance(raw, dict) and key in raw:
        return raw[key]
    head, _, rest = key.partition("/")
    if isinstance(raw, dict) and head in raw and rest:
        return lookup(raw[head], rest)
    return None


def figures(h, a, p):
    rows = [r for r in read_figures() if not a.page or r["page"] == a.page]
    results = {}
    if not a.list:
        for cmd in dict.fromkeys(r["command"] for r in rows):
            H.log(f"measuring: {cmd}")
            q = p.parse_args(sys.argv[1:sys.argv.index("figures")] + cmd.split())
            results[cmd] = QUESTIONS[q.question].main(h, q)
    rep = H.Report(h, "figures", "The figures the docs quote, re-measured")
    out = []
    for r in rows:
        page = os.path.join(H.REPO, r["page"])
        stated = os.path.exists(page) and r["quoted"] in open(page).read()
        v = lookup(results.get(r["command"]), r["key"])
        measured = "-" if a.list else ("?" if v is None else
                                       f"{v:.3g}" if isinstance(v, float) else str(v))
        out.append((r["page"], r["quoted"] + ("" if stated else " (not on the page)"), measured,
                    f"`vbench.py {r['command']}` {r['key']}"))
    rep.table(["page", "the page says", "measured now", "command, result"], out)
    rep.write()


def main():
    p = parser()
    a = p.parse_args()
    h = H.Harness(a)
    if a.question == "figures":
        return figures(h, a, p)
    QUESTIONS[a.question].main(h, a)


if __name__ == "__main__":
    main()
