# The examples of docs/examples run: replay_and_plot.py writes a PNG; range_2d.py (the 30-line
# script of docs/python.md) solves a graph with a range factor in batch and online, writes TUM
# and a PNG, and pickles its result.
import os
import subprocess
import sys

import pytest

EXAMPLES = os.path.join(os.path.dirname(__file__), "..", "..", "docs", "examples")


def test_range_2d(tmp_path):
    example = os.path.join(EXAMPLES, "range_2d.py")
    out = subprocess.run([sys.executable, example], cwd=tmp_path, check=True,
                         capture_output=True, text=True)
    assert out.stdout.startswith("F batch ")
    rows = [line.split() for line in (tmp_path / "range_2d.tum").read_text().splitlines()]
    assert [len(r) for r in rows] == [8] * 5  # time x y z qx qy qz qw per pose
    # The solution is the truth: poses 1 m apart on the x axis (pose 2 is 3 m from the beacon).
    assert [float(r[1]) for r in rows] == pytest.approx([0, 1, 2, 3, 4], abs=1e-6)
    assert (tmp_path / "range_2d.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_replay_and_plot(tmp_path, data_dir):
    example = os.path.join(EXAMPLES, "replay_and_plot.py")
    for name in ["manhattan_2d.g2o", "sphere_3d.g2o"]:
        png = tmp_path / (name + ".png")
        out = subprocess.run([sys.executable, example, os.path.join(data_dir, name), str(png)],
                             check=True, capture_output=True, text=True)
        assert out.stdout.startswith("F ")
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
