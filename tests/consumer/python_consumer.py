"""install_consumer's Python step: `import arbor_slam` from an installed prefix (PYTHONPATH) and
replay FILE through the online smoother to EXPECTED_F (`arbor replay`'s F_final, within 1e-9
relative); its type stub is installed beside it. Usage: python_consumer.py PREFIX FILE EXPECTED_F"""
import os
import sys

sys.path.append(os.path.join(os.path.dirname(__file__), "..", "python"))

import arbor_slam  # noqa: E402
from replay import replay  # noqa: E402

prefix, path, expected = sys.argv[1], sys.argv[2], float(sys.argv[3])
where = os.path.realpath(arbor_slam.__file__)
if not where.startswith(os.path.realpath(prefix) + os.sep):
    sys.exit(f"arbor imported from {where}, not from the prefix {prefix}")
stub = os.path.join(os.path.dirname(where), arbor_slam.__name__ + ".pyi")
if not os.path.isfile(stub):
    sys.exit(f"no type stub {stub} beside the installed module")
_, F = replay(arbor_slam.read(path))
print(f"python arbor {arbor_slam.__version__} from {where}: F {F!r}")
if abs(F - expected) > 1e-9 * abs(expected):
    sys.exit(f"F {F!r} differs from arbor replay's {expected!r}")
