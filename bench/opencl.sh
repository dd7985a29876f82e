#!/usr/bin/env bash
# The OpenCL backend against the CPU path on one scene (BENCHMARKS.md "OpenCL backend"): the
# same graph at fixed substeps (error control off, so both backends do the same work), run on
# the CPU (all cores) and with every grains node's iterations on the OpenCL device
# (GRAINS_OPENCL_DEVICE picks it). Prints, per backend: seconds a frame (stats.csv's wall_ms,
# frames 2 on: frame 1 includes building the kernels), the last frame's mean and max overlap
# (the error measure), and the largest position difference between the two runs' last frames.
#
# usage (from the repository root, ../shared beside it):
#   bench/opencl.sh GRAPH FRAMES [GRAINS_BINARY] [OUT_DIR] [RUN_ARGUMENTS...]
# RUN_ARGUMENTS go to both runs (--set NODE.PARAM=VALUE ...).
set -euo pipefail
graph=$1
frames=$2
grains=${3:-build/grains}
out=${4:-out/bench-opencl}
extra=("${@:5}")
mkdir -p "$out"
for backend in cpu opencl; do
  flag=""
  [ "$backend" = opencl ] && flag="--opencl"
  "$grains" run "$graph" --quiet --frames "$frames" --set solver.error_control=false $flag \
    --out "$out/$backend" --overwrite "${extra[@]}"
  awk -F, -v b="$backend" 'NR == 1 { for (i = 1; i <= NF; ++i) col[$i] = i; next }
    NR > 2 { wall += $col["wall_ms"]; n++ }
    { pen = $col["mean_penetration"]; maxpen = $col["max_penetration"]; pts = $col["points"] }
    END { printf "%s: %d grains, %.4f s a frame (frames 2-%d), last frame mean overlap %.4g, max %.4g\n",
          b, pts, wall / n / 1000, n + 1, pen, maxpen }' "$out/$backend/stats.csv"
done
last=$(printf "frame_%04d.ply" "$frames")
# the frames read with the DEM reference's PLY reader (../shared/reference/dem/ply.py)
python3 - "$(cd ../shared/reference/dem && pwd)" "$out/cpu/$last" "$out/opencl/$last" <<'PY'
import sys
sys.path.insert(0, sys.argv[1])
import ply
def positions(path):
    v = ply.read(path)["vertex"]
    return {i: (x, y, z) for i, x, y, z in zip(v["id"], v["x"], v["y"], v["z"])}
a, b = positions(sys.argv[2]), positions(sys.argv[3])
worst = max(sum((p - q) ** 2 for p, q in zip(a[k], b[k])) ** 0.5 for k in a if k in b)
print(f"largest position difference between the backends' last frames: {worst:.3g} m")
PY
