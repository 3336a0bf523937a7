#!/usr/bin/env bash
# Installs every Debian package Arbor needs to build, test and benchmark.
# Safe to re-run: apt-get skips what is already there.
set -euo pipefail

packages=(
  build-essential cmake pkg-config git clang-format ccache jq nftables iproute2 util-linux
  libeigen3-dev libsuitesparse-dev libboost-program-options-dev
  liblcm-dev libglib2.0-dev liblcm-bin liblcm-java default-jre-headless zlib1g-dev
  default-jdk-headless libjchart2d-java
  libgtest-dev libgmock-dev libbenchmark-dev libspectra-dev
  libceres-dev nlohmann-json3-dev libsodium-dev
  libopenblas0-pthread libopenblas-pthread-dev
  python3-matplotlib python3-numpy python3-pytest python3-dev python3-pybind11 pybind11-dev
  python3-mypy python3-build python3-pip python3-venv patchelf
  # The fuzz targets' libFuzzer build (tests/fuzz): Debian's default Clang and its runtime
  # libraries (libclang-rt-dev: libclang_rt.fuzzer and the sanitizers, libclang-rt-14-dev on
  # Debian 12).
  clang libclang-rt-dev
)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
