# docs/examples/replay_and_plot.py runs and writes a PNG.
import os
import subprocess
import sys


def test_replay_and_plot(tmp_path, data_dir):
    example = os.path.join(os.path.dirname(__file__), "..", "..", "docs", "examples",
                           "replay_and_plot.py")
    for name in ["manhattan_2d.g2o", "sphere_3d.g2o"]:
        png = tmp_path / (name + ".png")
        out = subprocess.run([sys.executable, example, os.path.join(data_dir, name), str(png)],
                             check=True, capture_output=True, text=True)
        assert out.stdout.startswith("F ")
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
