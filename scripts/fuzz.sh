#!/usr/bin/env bash
# Runs a fuzz target (tests/fuzz; docs/lcm.md, "Fuzzing") for longer than the test suite does:
#   scripts/fuzz.sh TARGET SECONDS      e.g. scripts/fuzz.sh lcm_edge 600
#   scripts/fuzz.sh all SECONDS         every target, SECONDS each
# TARGET is a target's name without "fuzz_" (g2o_reader, lcm_edge, lcm_prior, lcm_edge_command,
# lcm_command, lcm_estimate, lcm_status, lcm_covariance, lcm_journal_mark, journal_reader,
# udpm_datagram, bus_envelope). With Clang's libFuzzer (scripts/install-deps.sh installs it) the
# targets are built in build-fuzz (ARBOR_FUZZ: libFuzzer, AddressSanitizer, UBSan) and run
# coverage-guided; what they find new is kept in build-fuzz/tests/fuzz/work/TARGET/corpus for the
# next run. Without it, build-fuzz is a GCC sanitizer build and the targets run the seeded
# mutation driver for SECONDS. Extra arguments after SECONDS go to the target (libFuzzer's flags,
# e.g. -jobs=2 -workers=2, or -seed=7). A crash ends the run with its input in
# build-fuzz/tests/fuzz/work/TARGET/artifacts/ (run `build-fuzz/tests/fuzz/fuzz_TARGET FILE`
# to reproduce it); add it to tests/fuzz/corpus/TARGET/ once fixed.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ $# -lt 2 ]; then
  sed -n '2,15p' "$0" | sed 's/^# \{0,1\}//'
  exit 2
fi
target=$1
seconds=$2
shift 2
build=${ARBOR_FUZZ_BUILD_DIR:-build-fuzz}

# Whether clang++ links a libFuzzer target (clang and its libclang-rt-dev).
have_libfuzzer() {
  command -v clang++ >/dev/null || return 1
  local probe
  probe=$(mktemp -d)
  echo 'extern "C" int LLVMFuzzerTestOneInput(const unsigned char*, unsigned long) { return 0; }' \
    > "$probe/p.cc"
  clang++ -fsanitize=fuzzer "$probe/p.cc" -o "$probe/p" 2>/dev/null
  local ok=$?
  rm -rf "$probe"
  return $ok
}

launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache
                                         -DCMAKE_C_COMPILER_LAUNCHER=ccache)
if [ ! -f "$build/CMakeCache.txt" ]; then
  if have_libfuzzer; then
    CC=clang CXX=clang++ cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=Release -DARBOR_WERROR=ON \
      -DARBOR_FUZZ=ON -DARBOR_BUILD_BENCHMARKS=OFF "${launcher[@]}" >/dev/null
  else
    echo "fuzz.sh: no libFuzzer (clang++ -fsanitize=fuzzer fails): the mutation driver, GCC," \
         "ARBOR_SANITIZE" >&2
    cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=Release -DARBOR_WERROR=ON -DARBOR_SANITIZE=ON \
      -DARBOR_BUILD_BENCHMARKS=OFF "${launcher[@]}" >/dev/null
  fi
fi
libfuzzer=$(grep -q '^ARBOR_FUZZ:BOOL=ON' "$build/CMakeCache.txt" && echo 1 || echo 0)

if [ "$target" = all ]; then
  targets=$(sed -n 's/^arbor_fuzz_target(\([a-z0-9_]*\).*/\1/p' tests/fuzz/CMakeLists.txt)
  targets+=" $(sed -n 's/^set(decoders \(.*\))/\1/p' tests/fuzz/CMakeLists.txt |
               tr ' ' '\n' | sed 's/^/lcm_/')"
else
  targets=$target
fi
names=()
for t in $targets; do names+=("fuzz_$t"); done
cmake --build "$build" -j "$(nproc)" --target "${names[@]}"

export UBSAN_OPTIONS=${UBSAN_OPTIONS:-halt_on_error=1:print_stacktrace=1}
for t in $targets; do
  work=$build/tests/fuzz/work/$t
  mkdir -p "$work/corpus" "$work/artifacts"
  if [ "$libfuzzer" = 1 ]; then
    bound=(-max_total_time="$seconds")
  else
    bound=(-max_total_time="$seconds" -runs=1000000000000 -seed="$RANDOM")
  fi
  echo "== fuzz_$t for $seconds s"
  "$build/tests/fuzz/fuzz_$t" "${bound[@]}" -timeout=10 -print_final_stats=1 \
    -artifact_prefix="$work/artifacts/" "$@" "$work/corpus" "tests/fuzz/corpus/$t"
done
