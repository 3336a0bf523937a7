#!/usr/bin/env bash
# Installs dependencies, builds Arbor with warnings as errors, and runs the whole test suite.
# Tests that need ../shared/datasets say so and skip when it is absent.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
bash scripts/check-format.sh
build=${ARBOR_BUILD_DIR:-build-ci}
# ccache (installed by install-deps.sh) makes a rebuild of unchanged files a cache hit.
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache
                                         -DCMAKE_C_COMPILER_LAUNCHER=ccache)
cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=Release -DARBOR_WERROR=ON "${launcher[@]}" >/dev/null
cmake --build "$build" -j "$(nproc)"
cd "$build"
# A test that fails is run once more (--repeat until-pass:2): a second failure is red. Only a
# nondeterministic failure passes on the retry; ctest prints both attempts, so it stays visible.
ctest --output-on-failure -j "$(nproc)" --timeout 900 --repeat until-pass:2

# The sanitizer build (ARBOR_SANITIZE: AddressSanitizer and UBSan; docs/lcm.md, "Fuzzing"): only
# what reads untrusted bytes, the LCM and journal tests and the fuzz targets (ctest label
# "sanitize"). With Clang's libFuzzer each fuzz target runs coverage-guided for
# ARBOR_FUZZ_SECONDS (10 s); without it, GCC, and each runs the seeded-mutation driver.
cd ..
san=${ARBOR_SANITIZE_BUILD_DIR:-$build-sanitize}
probe=$(mktemp -d)
echo 'extern "C" int LLVMFuzzerTestOneInput(const unsigned char*, unsigned long) { return 0; }' \
  > "$probe/p.cc"
if command -v clang++ >/dev/null && clang++ -fsanitize=fuzzer "$probe/p.cc" -o "$probe/p" 2>/dev/null
then
  CC=clang CXX=clang++ cmake -S . -B "$san" -DCMAKE_BUILD_TYPE=Release -DARBOR_WERROR=ON \
    -DARBOR_FUZZ=ON -DARBOR_BUILD_BENCHMARKS=OFF "${launcher[@]}" >/dev/null
else
  echo "run-tests.sh: no libFuzzer (clang++ -fsanitize=fuzzer fails): GCC's sanitizer build" >&2
  cmake -S . -B "$san" -DCMAKE_BUILD_TYPE=Release -DARBOR_WERROR=ON -DARBOR_SANITIZE=ON \
    -DARBOR_BUILD_BENCHMARKS=OFF "${launcher[@]}" >/dev/null
fi
rm -rf "$probe"
cmake --build "$san" -j "$(nproc)" --target arbor_fuzz test_lcm_messages test_lcm_journal
cd "$san"
UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1 \
  ctest -L sanitize --output-on-failure -j "$(nproc)" --timeout 900
