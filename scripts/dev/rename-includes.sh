#!/usr/bin/env bash
# Rewrites our own #include lines to the installed layout (docs/library.md):
#   "core/x.h" -> "arbor_slam/core/x.h", and likewise bayestree/, io/, tools/, tests/;
#   lcm-gen's "io/lcm/arbor/x.hpp" -> "arbor/x.hpp" (the LCM convention: package/type.hpp).
# (An include of the older "arbor/core/x.h" form is scripts/dev/rename-package.sh's.)
# Only quoted includes at the start of a line are touched; a file already rewritten matches
# nothing, so running it twice changes nothing. The files it changes are then re-formatted
# with clang-format (include order within a block). Re-run it on files merged in later:
#   bash scripts/dev/rename-includes.sh            # every tracked C++ file
#   bash scripts/dev/rename-includes.sh FILE...    # only these
set -euo pipefail
cd "$(git rev-parse --show-toplevel)"
if (($#)); then
  files=("$@")
else
  mapfile -t files < <(git ls-files '*.cc' '*.h' '*.hpp' '*.cpp')
fi
lead='^[[:space:]]*#[[:space:]]*include[[:space:]]*"'
old="${lead}(io/lcm/arbor/|core/|bayestree/|io/|tools/|tests/)"
changed=()
for f in "${files[@]}"; do
  grep -Eq "$old" "$f" || continue
  sed -E -i \
    -e 's@^([[:space:]]*#[[:space:]]*include[[:space:]]*")io/lcm/arbor/@\1arbor/@' \
    -e 's@^([[:space:]]*#[[:space:]]*include[[:space:]]*")(core|bayestree|io|tools|tests)/@\1arbor_slam/\2/@' \
    "$f"
  changed+=("$f")
done
if ((${#changed[@]})); then
  clang-format -i "${changed[@]}"
fi
echo "rename-includes: ${#changed[@]} files rewritten"
