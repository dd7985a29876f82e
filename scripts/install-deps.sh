#!/usr/bin/env bash
# Installs the Debian packages Grains builds with, only those that are missing.
# Idempotent: on a machine that has everything it does nothing and needs no network.
# With --clients, also what make test-clients needs (Blender).
set -euo pipefail

packages=(
  build-essential cmake ninja-build pkg-config
  libeigen3-dev nlohmann-json3-dev libspdlog-dev libfmt-dev catch2
  libmuparser-dev libcli11-dev libstb-dev
  ocl-icd-opencl-dev opencl-headers opencl-clhpp-headers pocl-opencl-icd
  # the graph schema's test checks the examples with an independent validator
  python3 python3-jsonschema
  # the VTK frames' test reads them with VTK's own reader, as ParaView does
  python3-vtk9 python3-numpy
  # render --video: the MP4 test checks what the real ffmpeg writes
  ffmpeg
  # the fuzz targets (make fuzz-short, part of make test): clang 14, its libFuzzer and sanitizer
  # runtimes, its OpenMP, and llvm-symbolizer for readable stacks
  clang-14 libclang-rt-14-dev libomp-14-dev llvm-14
)

# make test-clients: Blender, which imports a run with the add-on in tools/blender
if [ "${1:-}" = "--clients" ]; then
  packages+=(blender)
fi

missing=()
for p in "${packages[@]}"; do
  dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done

if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi

line="apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends ${missing[*]}"
echo "install-deps: missing packages: ${missing[*]}"
if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then
    sudo sh -c "$line"
    exit 0
  fi
  echo "install-deps: need root to install them; run as root:" >&2
  echo "  $line" >&2
  exit 1
fi
echo "install-deps: $line"
apt-get update
DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "${missing[@]}"
