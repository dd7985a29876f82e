#!/usr/bin/env bash
# The quick rig of docs/heap-angle.md: the rough-base pile (bench/validation/dem_pile.json) poured
# to the end of its pour (frame 96, velocities kept), loaded as a source and run on to frame 119
# with the settings given, then the DEM collapse with the same settings. Prints the heap (grains
# heap) and the last frame's kinetic energy, and the collapse's run-out and H/L0 (the DEM
# reference's metrics.py). The pour's end measures about 59 deg only because the falling stream
# still counts; once it has landed the heap stands at 46-48 deg and ends near 44 (docs/heap-angle.md).
#   bash bench/dem/rest_rig.sh [OUT] [--set NODE.PARAM=VALUE ...]   (from the repository root)
set -euo pipefail
cd "$(dirname "$0")/../.."
out=out/rest_rig
if [ $# -gt 0 ] && [ "${1#--}" = "$1" ]; then out=$1; shift; fi
mkdir -p "$out"
out=$(cd "$out" && pwd)
G=$(pwd)/build/grains
data=$(pwd)/bench/validation/data
# the pour's end, once (the settings under test start from it)
if [ ! -f "$out/pour/frame_0096.ply" ]; then
  rm -rf "$out/pour"
  sed -e 's/"frames": 119/"frames": 96/' -e 's/"every": 119/"every": 96/' \
      -e 's/"attributes": \["id", "mass"\]/"attributes": ["id", "mass", "v"]/' \
      -e "s#data/dem_base.ply#$data/dem_base.ply#" bench/validation/dem_pile.json > "$out/pour.json"
  $G run "$out/pour.json" --quiet --out "$out/pour" > /dev/null
fi
cat > "$out/rest.json" <<JSON
{
  "grains_graph": 1, "name": "rest_rig", "fps": 24, "frames": 23, "seed": 5,
  "nodes": [
    {"name": "heap", "type": "source", "params": {"shape": "file", "file": "$out/pour/frame_0096.ply", "separation": 0.01}},
    {"name": "gravity", "type": "force", "inputs": ["heap"], "params": {"force": [0, -9.81, 0], "ignore_mass": true}},
    {"name": "grains", "type": "grains", "inputs": ["gravity"], "params": {
      "particle_separation": 0.01, "friction_with_particles": 0.5, "friction_with_colliders": 0.5,
      "static_threshold": 1, "scale_kinetic": 1}},
    {"name": "floor", "type": "collider", "params": {"shape": "plane"}},
    {"name": "solver", "type": "solver", "inputs": ["grains"], "params": {"colliders": ["floor"]}}
  ],
  "output": {"dir": "rest", "every": 23, "attributes": ["id", "mass"]}
}
JSON
rm -rf "$out/rest"
$G run "$out/rest.json" --quiet --threads 1 --out "$out/rest" "$@" > /dev/null
echo "rest: $($G heap "$out/rest/frame_0023.ply" --d 0.01 | cut -d: -f2), kinetic energy $(tail -1 "$out/rest/stats.csv" | cut -d, -f9) J"
rm -rf "$out/collapse"
$G run bench/validation/dem_collapse.json --quiet --threads 1 --out "$out/collapse" "$@" > /dev/null
echo "collapse: $(bash bench/dem/collapse_metrics.sh "$out/collapse") (DEM runout 0.863, H/L0 2.001)"
