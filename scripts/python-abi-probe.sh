#!/usr/bin/env bash
# Which Pythons can load the module (docs/python.md, "Which Pythons"): compiles the module's
# sources (python/*.cc) for the CPython PYTHON against Debian's pybind11 and the libraries of an
# existing build tree BUILD (unoptimised, no LTO: a probe, not the wheel), then imports it in
# that Python without numpy and, if the Python has numpy, solves a four-pose square.
#   scripts/python-abi-probe.sh PYTHON BUILD [OUT]
# A script, not a test: it needs a Python other than Debian's (pyenv's on this machine).
set -euo pipefail
python=$1
build=$(cd "$2" && pwd)
out=${3:-/tmp/arbor-abi-probe-$("$python" -c 'import sys; print("cp%d%d" % sys.version_info[:2])')}
source=$(readlink -f "$build/include/arbor_slam")  # the tree BUILD was configured from
mkdir -p "$out"
include=$("$python" -c "import sysconfig; print(sysconfig.get_paths()['include'])")
suffix=$("$python" -c "import sysconfig; print(sysconfig.get_config_var('EXT_SUFFIX'))")
echo "python: $("$python" -c 'import sys; print(sys.version.split()[0])') ($include)"
echo "pybind11: $(grep -E 'define PYBIND11_VERSION_(MAJOR|MINOR|PATCH)' /usr/include/pybind11/detail/common.h | awk '{printf "%s.", $3}' | sed 's/\.$//')"
objects=()
start=$(date +%s)
for cc in "$source"/python/*.cc; do
  o="$out/$(basename "$cc" .cc).o"
  c++ -O0 -fPIC -fvisibility=hidden -std=c++17 -DARBOR_VERSION=\"probe\" \
    -I"$build/include" -isystem "$include" -isystem /usr/include/eigen3 -c "$cc" -o "$o" \
    2> "$o.log" || { echo "compile FAILED: $(basename "$cc") (log: $o.log)"; head -20 "$o.log"; exit 1; }
  objects+=("$o")
done
c++ -shared -o "$out/arbor_slam$suffix" "${objects[@]}" \
  -Wl,-rpath,"$build/io:$build/bayestree:$build/core" "$build/io/libarbor_io.so" \
  "$build/tools/libarbor_refine.a" "$build/tools/libarbor_option_tables.a" \
  "$build/bayestree/libarbor_bayestree.so" "$build/core/libarbor_core.so" -fopenmp -lpthread
echo "compiled and linked in $(( $(date +%s) - start )) s: $out/arbor_slam$suffix"
cd "$out"
"$python" -c "import numpy" 2>/dev/null && has_numpy=1 || has_numpy=0
echo "numpy in this Python: $([ $has_numpy = 1 ] && echo yes || echo no)"
"$python" - <<'PY' || true
import sys
sys.path.insert(0, ".")
try:
    import arbor_slam
except Exception as e:  # noqa: BLE001
    print(f"import: {type(e).__name__}: {e}")
    raise SystemExit(0)
print("import: ok", arbor_slam.__version__)
g = arbor_slam.Graph2()
for k, (x, y) in enumerate([(0, 0), (1, 0), (1, 1), (0, 1)]):
    g.add_pose(k, arbor_slam.SE2(x, y, 0))
try:
    import numpy as np
    for k in range(4):
        g.add_edge(k, (k + 1) % 4, arbor_slam.SE2(1, 0, 1.5707963267948966), np.eye(3))
    print("solve: F =", arbor_slam.solve(g).F_final)
except Exception as e:  # noqa: BLE001
    print(f"solve: {type(e).__name__}: {e}")
PY
