#!/usr/bin/env bash
# The OpenCL backend against the CPU path on one scene (BENCHMARKS.md "OpenCL backend"): the
# same graph at fixed substeps (error control off, so both backends do the same work), run on
# the CPU (all cores) and with every grains node's iterations on the OpenCL device
# (GRAINS_OPENCL_DEVICE picks it). Prints, per backend: seconds a frame (stats.csv's wall_ms,
# frames 2 on: frame 1 includes building the kernels), the last frame's mean and max overlap
# (the error measure), and the largest position difference between the two runs' last frames.
#
# usage: bench/opencl.sh GRAPH FRAMES [GRAINS_BINARY] [OUT_DIR]
set -euo pipefail
graph=$1
frames=$2
grains=${3:-build/grains}
out=${4:-out/bench-opencl}
mkdir -p "$out"
for backend in cpu opencl; do
  flag=""
  [ "$backend" = opencl ] && flag="--opencl"
  "$grains" run "$graph" --quiet --frames "$frames" --set solver.error_control=false $flag \
    --out "$out/$backend" --overwrite
  awk -F, -v b="$backend" 'NR == 1 { for (i = 1; i <= NF; ++i) col[$i] = i; next }
    NR > 2 { wall += $col["wall_ms"]; n++ }
    { pen = $col["mean_penetration"]; maxpen = $col["max_penetration"]; pts = $col["points"] }
    END { printf "%s: %d grains, %.4f s a frame (frames 2-%d), last frame mean overlap %.4g, max %.4g\n",
          b, pts, wall / n / 1000, n + 1, pen, maxpen }' "$out/$backend/stats.csv"
done
last=$(printf "frame_%04d.ply" "$frames")
python3 - "$out/cpu/$last" "$out/opencl/$last" <<'PY'
import struct, sys
def positions(path):
    with open(path, "rb") as f:
        data = f.read()
    head, _, body = data.partition(b"end_header\n")
    lines = head.decode().splitlines()
    n, props, fmt = 0, [], "<"
    for line in lines:
        w = line.split()
        if w[:2] == ["element", "vertex"]: n = int(w[2])
        elif w[0] == "element" and n: break
        elif w[0] == "property" and n: props.append((w[1], w[2]))
    sizes = {"float": ("f", 4), "int": ("i", 4), "uchar": ("B", 1), "double": ("d", 8)}
    fmt += "".join(sizes[t][0] for t, _ in props)
    step = struct.calcsize(fmt)
    names = [p for _, p in props]
    ix, iy, iz = names.index("x"), names.index("y"), names.index("z")
    iid = names.index("id") if "id" in names else None
    out = {}
    for k in range(n):
        row = struct.unpack_from(fmt, body, k * step)
        out[row[iid] if iid is not None else k] = (row[ix], row[iy], row[iz])
    return out
a, b = positions(sys.argv[1]), positions(sys.argv[2])
worst = max(sum((p - q) ** 2 for p, q in zip(a[k], b[k])) ** 0.5 for k in a if k in b)
print(f"largest position difference between the backends' last frames: {worst:.3g} m")
PY
