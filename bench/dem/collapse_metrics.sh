#!/usr/bin/env bash
# The a = 2 collapse's measures for a finished run of bench/validation/dem_collapse.json in DIR,
# by the DEM reference's own scripts (../shared/reference/dem: ply_to_dump.py, metrics.py, from
# the reference's settled packing): prints "runout R H/L0 H". Used by compare.sh and rest_rig.sh.
#   bash bench/dem/collapse_metrics.sh DIR      (from the repository root)
set -euo pipefail
d=${1:?usage: collapse_metrics.sh DIR}
ref=$(cd "$(dirname "$0")/../../../shared/reference/dem" && pwd)
mkdir -p "$d/m"
cp "$ref/results/collapse_np1_initial.dump" "$d/m/initial.dump"
python3 "$ref/ply_to_dump.py" "$d/frame_0023.ply" "$d/m/final.dump" > /dev/null
python3 "$ref/metrics.py" collapse "$d/m" | python3 -c "import json,sys; j=json.load(sys.stdin); \
print('runout', j['runout'], 'H/L0', j['H_inf_over_L0'])"
