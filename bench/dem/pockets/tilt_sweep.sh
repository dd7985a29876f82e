#!/usr/bin/env bash
# The DEM reference tilts of tests/nodes/grains/test_pockets.cpp: for each scene, friction and
# azimuth, the tilt (degrees, to 0.1) past which a free grain moves more than the threshold in
# 1 s, by bisection. About 20 s for the pocket, 1 min for the pyramid, on one core.
#   bash bench/dem/pockets/tilt_sweep.sh      (needs the Debian package liggghts)
set -euo pipefail
cd "$(dirname "$0")"
moved() {  # scene tilt azimuth friction
  liggghts -in "$1.in" -var th "$2" -var az "$3" -var mu "$4" -log none -echo none |
    awk '/^MOVED/ {print $2}'
}
critical() {  # scene azimuth friction threshold
  local lo=0 hi=89 m d
  for _ in $(seq 10); do
    m=$(awk -v a="$lo" -v b="$hi" 'BEGIN {print (a + b) / 2}')
    d=$(moved "$1" "$m" "$2" "$3")
    if awk -v d="$d" -v t="$4" 'BEGIN {exit !(d >= 0 && d < t)}'; then lo=$m; else hi=$m; fi
  done
  printf '%s azimuth %s friction %s: %.1f deg\n' "$1" "$2" "$3" "$lo"
}
for mu in 0 0.5; do
  critical pocket 270 $mu 0.0005   # 0.1 r
  critical pocket 90 $mu 0.0005
  critical pyramid 0 $mu 0.005     # r
  critical pyramid 45 $mu 0.005
done
