#!/usr/bin/env bash
# ctest wheel_venv (tests/CMakeLists.txt; docs/python.md, "The wheel"): builds the wheel
# arbor-slam offline with PYTHON (python3 -m build --no-isolation, its backend reusing BUILD, so
# nothing recompiles), checks what it holds, installs it with pip --no-index into a fresh venv
# (--system-site-packages: the module imports numpy, here Debian's python3-numpy) and runs
# wheel_check.py there, outside the build tree. Then the same wheel in a venv of each other
# CPython of its ABI found (e.g. pyenv's 3.11.7), which has no numpy of its own and none to get
# offline: Debian's numpy is given to it through a .pth file.
#   run_wheel_test.sh PYTHON BUILD WORK SOURCE
set -euo pipefail
python=$1 build=$2 work=$3 source=$4
unset PYTHONPATH PIP_INDEX_URL PIP_FIND_LINKS
export PIP_NO_INDEX=1 PIP_DISABLE_PIP_VERSION_CHECK=1
rm -rf "$work"
mkdir -p "$work"

start=$(date +%s%N)
"$python" -m build --no-isolation --wheel --outdir "$work/dist" -C build-dir="$build" "$source" \
  >"$work/build.log" 2>&1 || { cat "$work/build.log"; exit 1; }
wheel=$(ls "$work"/dist/arbor_slam-*.whl)
echo "wheel: $(basename "$wheel"), $(stat -c %s "$wheel") bytes," \
     "built in $((($(date +%s%N) - start) / 1000000)) ms"

# What it holds: the module at the root, our libraries in arbor_slam.libs/, the metadata.
read_wheel() {  # read_wheel WHEEL [MEMBER]: the names it holds, or one member's text
  "$python" -c 'import sys, zipfile
z = zipfile.ZipFile(sys.argv[1])
names = z.namelist()
print(z.read(sys.argv[2]).decode() if len(sys.argv) > 2 else "\n".join(names))' "$@"
}
listing=$(read_wheel "$wheel")
for expected in '^arbor_slam\.cpython-[0-9]+-.*\.so$' '^arbor_slam\.libs/libarbor_core\.so\.' \
                '^arbor_slam\.libs/libarbor_bayestree\.so\.' \
                '^arbor_slam\.libs/libarbor_io\.so\.' \
                '^arbor_slam-[0-9.]+\.dist-info/METADATA$' \
                '^arbor_slam-[0-9.]+\.dist-info/RECORD$'; do
  grep -Eq "$expected" <<<"$listing" ||
    { echo "no $expected in the wheel:"; echo "$listing"; exit 1; }
done
metadata=$(read_wheel "$wheel" "$(grep 'dist-info/METADATA$' <<<"$listing")")
grep -q '^Name: arbor-slam$' <<<"$metadata" && grep -q '^Requires-Dist: numpy$' <<<"$metadata" ||
  { echo "METADATA:"; echo "$metadata" | head -12; exit 1; }

# A fresh venv of INTERPRETER (venv options after it) with the wheel installed.
venv_with_wheel() {
  local interpreter=$1 venv=$2
  shift 2
  "$interpreter" -m venv "$@" "$venv"
  "$venv/bin/python" -m pip install --no-index --no-deps --quiet "$wheel"
}
# Run from WORK: nothing of the build tree or the source's python/ is on the path.
check() { (cd "$work" && "$1/bin/python" "$source/tests/wheel/wheel_check.py" "$1"); }

venv_with_wheel "$python" "$work/venv" --system-site-packages
check "$work/venv"

suffix() { "$1" -c 'import sysconfig; print(sysconfig.get_config_var("EXT_SUFFIX"))'; }
numpy_dir=$(dirname "$(dirname "$("$python" -c 'import numpy; print(numpy.__file__)')")")
for other in "$HOME"/.pyenv/versions/*/bin/python3; do
  [ -x "$other" ] && [ "$(suffix "$other")" = "$(suffix "$python")" ] || continue
  "$other" -c 'import venv, ensurepip' 2>/dev/null || continue
  venv=$work/venv-$("$other" -c 'import platform; print(platform.python_version())')
  venv_with_wheel "$other" "$venv"
  if ! "$venv/bin/python" -c 'import numpy' 2>/dev/null; then
    site=$("$venv/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
    echo "$numpy_dir" >"$site/debian_numpy.pth"
  fi
  check "$venv"
done
