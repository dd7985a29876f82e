#!/usr/bin/env bash
# Grains against the LIGGGHTS references (../shared/reference/dem), the same scenes on the same
# machine: runs each Grains scene with one thread (LIGGGHTS runs serial), measures its last frame
# with the reference's own metrics.py, and with --liggghts also runs LIGGGHTS (Debian package
# `liggghts`) on the rotation-frozen scenes to time it the same day.
#   bash bench/dem/compare.sh [--liggghts] [OUT]      (from the repository root; OUT: out/dem)
# Prints one line per run: scene, setting, CPU seconds, metric, value, DEM value.
set -euo pipefail
cd "$(dirname "$0")/../.."
lig=0
if [ "${1:-}" = "--liggghts" ]; then lig=1; shift; fi
# before the Grains rows: without LIGGGHTS its rows would be missing at the end of a long run
if [ $lig = 1 ] && ! command -v liggghts > /dev/null; then
  echo "compare.sh: --liggghts needs the liggghts command (Debian package liggghts: sudo apt-get install liggghts)" >&2
  exit 2
fi
out=${1:-out/dem}
ref=$(cd ../shared/reference/dem && pwd)
mkdir -p "$out"
out=$(cd "$out" && pwd)  # absolute: LIGGGHTS runs elsewhere
G=build/grains
cpu() { /usr/bin/time -f "%U %S" "$@" 2>&1 >/dev/null | tail -1 | awk '{print $1 + $2}'; }

collapse() {  # name, extra --set arguments
  local name=$1; shift
  local d="$out/collapse_$name"
  rm -rf "$d"  # run refuses a used folder: the measuring folder m/ comes after
  local t; t=$(cpu $G run bench/validation/dem_collapse.json --quiet --threads 1 --out "$d" "$@")
  local m; m=$(bash bench/dem/collapse_metrics.sh "$d")
  echo "collapse $name cpu_s $t $m (dem runout 0.863 H/L0 2.001)"
}

pile() {
  local name=$1; shift
  local d="$out/pile_$name"
  rm -rf "$d"  # run refuses a used folder: the measuring folder m/ comes after
  local t; t=$(cpu $G run bench/validation/dem_pile.json --quiet --threads 1 --out "$d" "$@")
  mkdir -p "$d/m"
  python3 "$ref/ply_to_dump.py" "$d/frame_0119.ply" "$d/m/final.dump" > /dev/null
  # the frozen base (mass 0) is type 2 in the reference; the dump has no type: measure with
  # grains heap, which skips mass-0 grains, as metrics.py skips type 2
  echo "pile $name cpu_s $t $($G heap "$d/frame_0119.ply" --d 0.01) dem 55.4"
}

# the defaults: the contacts one at a time with their loads carried (contact_solver gauss_seidel;
# docs/heap-angle.md, "Gauss-Seidel"), error control with the motion bounds this solver asks
# for; then at 64 fixed substeps, and without sleeping (on by default at half a radius a second;
# docs/heap-angle.md, "Sleeping")
collapse defaults
pile defaults
fixed=(--set solver.error_control=0 --set solver.substeps=64)
collapse 64x10 "${fixed[@]}"
pile 64x10 "${fixed[@]}"
collapse awake --set grains.sleep_speed=0
pile awake --set grains.sleep_speed=0
# POP Grains' Jacobi average (contact_solver jacobi) at its error-control bounds, awake, and at
# 128 x 20 fixed; 128 x 20 is past internal_collisions_stiffness 1000, so that row removes
# 1000 / 2560 of each overlap an iteration, and friction, bounded by the overlap each iteration
# sees, counts it about 2.6 times: the same at full stiffness (docs/heap-angle.md)
jacobi=(--set grains.contact_solver=jacobi)
collapse jacobi "${jacobi[@]}"
pile jacobi "${jacobi[@]}"
collapse jacobi_awake "${jacobi[@]}" --set grains.sleep_speed=0
pile jacobi_awake "${jacobi[@]}" --set grains.sleep_speed=0
collapse jacobi_128x20 "${jacobi[@]}" --set solver.error_control=0 --set solver.substeps=128 \
  --set grains.constraint_iterations=20
collapse jacobi_128x20_full_stiffness "${jacobi[@]}" --set solver.error_control=0 --set solver.substeps=128 \
  --set grains.constraint_iterations=20 --set grains.internal_collisions_stiffness=2560
if [ $lig = 1 ]; then
  # run_all.sh writes its results beside itself: a writable copy
  rm -rf "$out/ref"; cp -r "$ref" "$out/ref"; chmod -R u+w "$out/ref"
  for s in collapse_norot pile_norot; do
    OUT="$out/liggghts" bash "$out/ref/run_all.sh" 1 "$s" | grep -E "total_wall|runout|angle" || true
  done
fi
