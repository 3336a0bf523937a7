"""wheel_venv's check, run by the venv's python: VENV is where `arbor_slam` must come from, the
module and our libraries both (the RUNPATH $ORIGIN/arbor_slam.libs, not the build tree's); a
4-pose square with a loop closure, started off, must be solved to the measurements' F = 0.
Usage: wheel_check.py VENV"""
import math
import os
import sys

import arbor_slam
import numpy as np

venv = os.path.realpath(sys.argv[1])
where = os.path.realpath(arbor_slam.__file__)
if not where.startswith(venv + os.sep):
    sys.exit(f"arbor_slam imported from {where}, not from the venv {venv}")
with open("/proc/self/maps", encoding="utf-8") as maps:
    ours = {line.split()[-1] for line in maps if "libarbor_" in line}
libs = os.path.join(os.path.dirname(where), "arbor_slam.libs")
if not ours or any(os.path.dirname(os.path.realpath(lib)) != libs for lib in ours):
    sys.exit(f"libarbor_* loaded from {sorted(ours)}, not from {libs}")

graph = arbor_slam.Graph2()
for i, start in enumerate([(0, 0, 0), (1.2, 0.1, 1.4), (0.9, 1.3, 3.0), (-0.2, 0.8, -1.4)]):
    graph.add_pose(i, arbor_slam.SE2(*start))
step = arbor_slam.SE2(1.0, 0.0, math.pi / 2)
for i in range(4):
    graph.add_edge(i, (i + 1) % 4, step, np.eye(3))
result = arbor_slam.solve(graph)
if not (result.F_initial > 1e-2 and result.F_final < 1e-12):
    sys.exit(f"F {result.F_initial} -> {result.F_final}: not solved")
# Relative to pose 0, pose 2 is (1, 1, pi) whatever the gauge.
relative = arbor_slam.SE2(*result.estimate[0]).between(arbor_slam.SE2(*result.estimate[2]))
if not relative.isclose(arbor_slam.SE2(1.0, 1.0, math.pi), atol=1e-6):
    sys.exit(f"pose 2 relative to pose 0 is {relative}, not (1, 1, pi)")
print(f"python {sys.version.split()[0]}: arbor_slam {arbor_slam.__version__} from {where}, "
      f"libraries from {libs}; F {result.F_initial:.3g} -> {result.F_final:.3g}")
