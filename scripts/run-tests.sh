#!/usr/bin/env bash
# Installs dependencies, builds Arbor with warnings as errors, and runs the whole test suite.
# Tests that need ../shared/datasets say so and skip when it is absent.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
bash scripts/check-format.sh
build=${ARBOR_BUILD_DIR:-build-ci}
cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=Release -DARBOR_WERROR=ON >/dev/null
cmake --build "$build" -j "$(nproc)"
cd "$build"
ctest --output-on-failure -j "$(nproc)" --timeout 900
