#!/usr/bin/env bash
# Renames Arbor's package names so that none can collide with arbor-sim's (the neuron simulator
# that owns the PyPI name `arbor`, include/arbor/ and find_package(Arbor); docs/library.md,
# "Names"):
#   #include "arbor/core/x.h" (and bayestree/, io/, tools/, tests/) -> "arbor_slam/core/x.h"
#   Arbor::core, find_package(Arbor)                      -> ArborSLAM::core, find_package(ArborSLAM)
#   arbor.pc (pkg-config arbor)                            -> arbor-slam.pc (pkg-config arbor-slam)
#   Python: import arbor, arbor.solve(...)                 -> import arbor_slam, arbor_slam.solve(...)
#     (only in *.py, *.md and python/; prose naming the module is edited by hand)
# Unchanged: the C++ namespace arbor::, the `arbor` tool, the LCM message package arbor
# ("arbor/edge_t.hpp", arbor::edge_t), the library files libarbor_*.so, share/arbor/.
# Lines between the markers "rename-package: off" and "rename-package: on" (docs/library.md's
# table of old names) are left alone. Every rule matches only the old form, so running it twice
# changes nothing. Re-run it on a tree that merged files still written the old way:
#   bash scripts/dev/rename-package.sh            # every tracked text file
#   bash scripts/dev/rename-package.sh FILE...    # only these
set -euo pipefail
cd "$(git rev-parse --show-toplevel)"
self=scripts/dev/rename-package.sh
[ -e cmake/ArborConfig.cmake.in ] && git mv cmake/ArborConfig.cmake.in cmake/ArborSLAMConfig.cmake.in
[ -e cmake/arbor.pc.in ] && git mv cmake/arbor.pc.in cmake/arbor-slam.pc.in
if (($#)); then
  files=("$@")
else
  mapfile -t files < <(git ls-files -- ':!data/' ':!docs/plots/' ':!'"$self" \
                         ':!scripts/dev/rename-includes.sh' |
                       xargs -d '\n' grep -Il '' --)
fi
changed=()
for f in "${files[@]}"; do
  python_text=0
  case "$f" in *.py | *.md | python/*) python_text=1 ;; esac
  before=$(sha1sum <"$f")
  PY=$python_text perl -pi -e '
    $off = /rename-package: off/ ? 1 : /rename-package: on/ ? 0 : $off;
    $off = 0 if eof;
    next if $off;
    s{\barbor/(core|bayestree|io|tools|tests)/}{arbor_slam/$1/}g;
    s{\bArbor::}{ArborSLAM::}g;
    s{find_package\(Arbor\b}{find_package(ArborSLAM}g;
    s{\barbor\.pc\b}{arbor-slam.pc}g;
    s{((?:pkg-config|--cflags|--libs|--modversion|--exists)(?: --[a-z-]+)* )arbor\b(?![-_.])}
     {$1arbor-slam}g;
    if ($ENV{PY}) {
      s{(?<![\w.])import arbor\b(?![\w.-])}{import arbor_slam}g;
      s{(?<![\w.])from arbor import\b}{from arbor_slam import}g;
      s{(?<![\w/.-])arbor\.(?=[A-Za-z_])}{arbor_slam.}g;
      s{"<arbor\."}{"<arbor_slam."}g;  # reprs built as "<arbor." + name
    }' "$f"
  [ "$before" = "$(sha1sum <"$f")" ] || changed+=("$f")
done
cxx=()
for f in "${changed[@]}"; do
  case "$f" in *.cc | *.h | *.hpp | *.cpp) cxx+=("$f") ;; esac
done
if ((${#cxx[@]})); then
  clang-format -i "${cxx[@]}"  # include order within a block
fi
echo "rename-package: ${#changed[@]} files rewritten"
