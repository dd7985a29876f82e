#!/usr/bin/env bash
# Prints one line per written frame of every example graph: graph, file, SHA-256. Two builds
# whose lists are equal wrote byte-identical frames, which is what a pure refactor must keep:
#   scripts/frame-hashes.sh build-before > before.txt
#   scripts/frame-hashes.sh build > after.txt && diff before.txt after.txt
# Usage: scripts/frame-hashes.sh BUILD_DIR [FRAMES]   (FRAMES: frames per graph, default 12)
set -euo pipefail
build=${1:?usage: scripts/frame-hashes.sh BUILD_DIR [FRAMES]}
frames=${2:-12}
here=$(cd "$(dirname "$0")/.." && pwd)
grains=$(cd "$build" && pwd)/grains
[ -x "$grains" ] || { echo "frame-hashes: no grains program in $build" >&2; exit 2; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
for graph in "$here"/graphs/*.json; do
  name=$(basename "$graph" .json)
  # two threads: the CPU path is bit-identical for any thread count, so any count would do
  "$grains" run "$graph" --out "$work/$name" --frames "$frames" --threads 2 --quiet --overwrite
  (cd "$work/$name" && find . -name 'frame_*.ply' | sort | xargs sha256sum) |
    while read -r sum file; do echo "$name ${file#./} $sum"; done
done
