#!/usr/bin/env bash
# Runs each libFuzzer target for SECONDS from its seed corpus (fuzz/corpus/TARGET) and fails on
# the first finding. Usage: fuzz/run.sh SECONDS [BUILD_DIR] [TARGET...]  (targets: graph
# expression ply obj; default all). New inputs go to BUILD_DIR/corpus/TARGET (not the repository);
# a crashing input is saved as BUILD_DIR/findings/TARGET-crash-..., with its stack on stderr.
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:?usage: fuzz/run.sh SECONDS [BUILD_DIR] [TARGET...]}
build=${2:-build-fuzz}
shift $(( $# >= 2 ? 2 : 1 ))
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(graph expression ply obj)

mkdir -p "$build/findings"
# readable stacks in a finding's report
[ -x /usr/lib/llvm-14/bin/llvm-symbolizer ] && export ASAN_SYMBOLIZER_PATH=/usr/lib/llvm-14/bin/llvm-symbolizer
for t in "${targets[@]}"; do
  mkdir -p "$build/corpus/$t"
  dict=()
  [ -f "fuzz/$t.dict" ] && dict=(-dict="fuzz/$t.dict")
  log="$build/findings/$t.log"
  echo "fuzz: $t for ${seconds}s (log $log)"
  # -timeout: one input running 10 s is a finding (a hang); -rss_limit_mb: 2 GB is a finding;
  # -entropic=0: libFuzzer 14's entropic scheduler spent 60% of the graph target's time
  # weighting features, so the plain scheduler runs about twice as many inputs
  if ! UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1 \
      "$build/fuzz_$t" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -entropic=0 \
      -print_final_stats=1 -artifact_prefix="$build/findings/$t-" "${dict[@]}" \
      "$build/corpus/$t" "fuzz/corpus/$t" >"$log" 2>&1; then
    tail -n 60 "$log" >&2
    if grep -q "libFuzzer: run interrupted" "$log"; then echo "fuzz: $t interrupted" >&2; exit 130; fi
    echo "fuzz: $t FOUND A PROBLEM; the input is in $build/findings/ (reproduce: $build/fuzz_$t FILE)" >&2
    exit 1
  fi
  # libFuzzer's final stats: executions and speed
  execs=$(awk '/stat::number_of_executed_units/ {print $2}' "$log")
  speed=$(awk '/stat::average_exec_per_sec/ {print $2}' "$log")
  echo "fuzz: $t ok: $execs executions, $speed/s"
done
