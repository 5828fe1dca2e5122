#!/usr/bin/env python3
"""Tests of the benchmark driver's harness, without running a benchmark."""

import argparse
import os
import sys
import tempfile
import unittest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import harness as H  # noqa: E402
import peers  # noqa: E402
import vbench  # noqa: E402


class HarnessTest(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory()
        self.h = H.Harness(argparse.Namespace(build=None, scratch=self.tmp.name, out=None, threads=2,
                                              no_build=True))

    def tearDown(self):
        self.tmp.cleanup()

    def test_median_and_geomean(self):
        self.assertEqual(H.median([3, 1, 2]), 2)
        self.assertEqual(H.median([4, 1, 2, 3]), 2.5)
        self.assertAlmostEqual(H.geomean([1, 4]), 2.0)

    def test_alternate_runs_in_turn(self):
        order = []
        r = H.alternate({"a": lambda: order.append("a") or 1, "b": lambda: order.append("b") or 2}, 3)
        self.assertEqual(order, ["a", "b"] * 3)
        self.assertEqual(r, {"a": [1, 1, 1], "b": [2, 2, 2]})

    def test_reports_name_no_machine_paths(self):
        self.assertEqual(self.h.rel(os.path.join(self.tmp.name, "s.store")), "$SCRATCH/s.store")
        self.assertEqual(self.h.rel(os.path.join(self.tmp.name, "reports", "x.md")), "$OUT/x.md")
        self.assertEqual(self.h.rel(os.path.join(H.REPO, "tools", "bench")), "tools/bench")
        rep = H.Report(self.h, "t", "T")
        rep.add(self.h.rel(os.path.join(self.tmp.name, "a.vdb")))
        with open(rep.write()) as f:
            text = f.read()
        self.assertNotIn(self.tmp.name, text)
        self.assertIn("$SCRATCH/a.vdb", text)

    def test_run_measures_a_process(self):
        r = H.run(["sh", "-c", "exit 3"])
        self.assertEqual(r["exit"], 3)
        r = H.run(["sleep", "5"], timeout=0.2)
        self.assertTrue(r["timeout"])
        self.assertLess(r["wall_s"], 4)

    def test_pgm_coverage(self):
        p = os.path.join(self.tmp.name, "m.pgm")
        with open(p, "wb") as f:  # 4x3: one hit inside, one on the border
            f.write(b"P5\n4 3\n255\n" + bytes([255, 0, 0, 0, 0, 255, 0, 0, 0, 0, 0, 0]))
        self.assertEqual(peers.coverage(p), (2 / 12, 1))
        with open(p, "wb") as f:
            f.write(b"P6\n1 1\n255\n" + bytes(3))
        with self.assertRaises(SystemExit):
            peers.read_pgm(p)

    def test_figures_list_is_well_formed(self):
        rows = vbench.read_figures()
        self.assertTrue(rows)
        p = vbench.parser()
        for r in rows:
            self.assertTrue(os.path.exists(os.path.join(H.REPO, r["page"])), r["page"])
            q = p.parse_args(["--scratch", self.tmp.name] + r["command"].split())
            self.assertIn(q.question, vbench.QUESTIONS)

    def test_lookup(self):
        raw = {"a.b/c": 1, "x": {"y": 2}}
        self.assertEqual(vbench.lookup(raw, "a.b/c"), 1)
        self.assertEqual(vbench.lookup(raw, "x/y"), 2)
        self.assertIsNone(vbench.lookup(raw, "x/z"))


if __name__ == "__main__":
    unittest.main()
