#!/usr/bin/env bash
# Coverage-guided fuzzing of everything dualgeo parses (tests/fuzz; docs/reliability.md).
#
#   scripts/fuzz.sh                     # 20 s per target: the CI run
#   scripts/fuzz.sh --seconds 600       # the 10-minute run whose figures are in the docs
#   scripts/fuzz.sh --targets "image recording" --seconds 60
#
# Installs cargo-afl (and builds AFL++) when missing, builds the targets instrumented in
# target/afl, replays the committed corpus (tests/fuzz/corpus) without AFL++, then runs
# `cargo afl fuzz` on each target, as many at a time as there are cores. Prints one row
# per target (executions, speed, paths, crashes, hangs) and writes it to
# target/afl/summary.md; exits 1 if any target crashed or hung. Crashing inputs are kept
# in target/afl/out/<target>/default/crashes: replay one with
#   target/afl/release/replay <target> <file>
set -euo pipefail
cd "$(dirname "$0")/.."

seconds=20
targets="recording image config checkpoint frames observations flight"
jobs=$(nproc)
while (($#)); do
  case "$1" in
    --seconds) seconds="$2"; shift 2 ;;
    --targets) targets="$2"; shift 2 ;;
    --jobs) jobs="$2"; shift 2 ;;
    *) echo "fuzz.sh: unknown option $1" >&2; exit 2 ;;
  esac
done

if ! cargo afl --version >/dev/null 2>&1; then
  echo "fuzz: installing cargo-afl" >&2
  cargo install cargo-afl --version '^0.18' --locked --quiet
fi
# AFL++ itself is built once per toolchain; "already built" is not an error.
cargo afl config --build >/dev/null 2>&1 || true

export CARGO_TARGET_DIR="$PWD/target/afl"
cargo afl build --release --quiet --manifest-path tests/fuzz/Cargo.toml
bin="$CARGO_TARGET_DIR/release"

echo "fuzz: replaying the committed corpus" >&2
# A panic names the file it replayed last (stderr), so a regression is found at once.
"$bin/replay" --corpus tests/fuzz/corpus 2>"$CARGO_TARGET_DIR/replay.log" ||
  { tail -n 20 "$CARGO_TARGET_DIR/replay.log" >&2; exit 1; }

out="$CARGO_TARGET_DIR/out"
rm -rf "$out"
mkdir -p "$out"
export AFL_NO_UI=1 AFL_SKIP_CPUFREQ=1 AFL_I_DONT_CARE_ABOUT_MISSING_CRASHES=1
export AFL_NO_AFFINITY=1 RUST_LOG=off
run_one() {
  local t="$1"
  # -t: a run over 2 s is a hang. No -m: OpenCV's and rayon's threads reserve more
  # address space than any useful limit (-m 4096 refused every seed), so a bound on
  # allocation is the targets' own (frames and images are capped before allocating).
  cargo afl fuzz -i "tests/fuzz/corpus/$t" -o "$out/$t" -V "$seconds" -t 2000 \
    "$bin/$t" >"$out/$t.log" 2>&1 || echo "fuzz: afl-fuzz of $t exited $? (see $out/$t.log)" >&2
}
echo "fuzz: $seconds s per target, $jobs at a time" >&2
running=0
for t in $targets; do
  run_one "$t" &
  running=$((running + 1))
  if ((running >= jobs)); then wait -n; running=$((running - 1)); fi
done
wait

status=0
summary="$CARGO_TARGET_DIR/summary.md"
# Built in this shell (not a pipeline's subshell), so `status` survives.
{
  echo "| target | executions | execs/s | corpus entries | coverage map | crashes | hangs |"
  echo "| --- | ---: | ---: | ---: | ---: | ---: | ---: |"
} >"$summary"
for t in $targets; do
  stats="$out/$t/default/fuzzer_stats"
  if [[ ! -f $stats ]]; then
    echo "| $t | did not run (see $out/$t.log) | | | | | |" >>"$summary"
    status=1
    continue
  fi
  get() { awk -F' *: *' -v k="$1" '$1 == k { print $2 }' "$stats"; }
  crashes=$(find "$out/$t/default/crashes" -type f ! -name README.txt | wc -l)
  hangs=$(find "$out/$t/default/hangs" -type f | wc -l)
  echo "| $t | $(get execs_done) | $(get execs_per_sec) | $(get corpus_count) | $(get bitmap_cvg) | $crashes | $hangs |" >>"$summary"
  if ((crashes + hangs > 0)); then status=1; fi
done
cat "$summary"
if ((status)); then
  echo "fuzz: FAILED (crashes, hangs or a target that did not run); inputs in $out/<target>/default/" >&2
fi
exit $status
