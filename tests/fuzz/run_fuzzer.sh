#!/usr/bin/env bash
# Fuzzes the glTF loader (tests/fuzz/fuzz_gltf.cpp) with libFuzzer, AddressSanitizer
# and UndefinedBehaviorSanitizer.
#
#   tests/fuzz/run_fuzzer.sh [SECONDS]      (default 60; run from anywhere)
#
# 1. Installs clang, the libFuzzer/sanitizer runtime and the header's dependencies with
#    apt-get when they are missing (sudo when not root).
# 2. Builds build/fuzz/fuzz_gltf (again only when the target or smallvcm.hpp changed).
# 3. Seeds the working corpus build/fuzz/corpus (not committed; it grows from run to
#    run) from scenes/*.gltf, tests/data/bad/*, tests/data/gltf/* and tests/data/compressed/*.glb (and tests/data/fuzz/*
#    with FUZZ_SEED_REGRESSIONS=1).
# 4. Fuzzes for SECONDS on both cores (libFuzzer's fork mode, 2 workers, going on past
#    crashes, hangs and out-of-memory; the dictionary tests/fuzz/gltf.dict of glTF keys),
#    artifacts in build/fuzz/artifacts/, the log in build/fuzz/last_run.log.
# 5. Ends with one summary line:
#      fuzz_gltf: N executions in S s (E exec/s), K new artifacts (crash C, timeout T, oom O)
#    and exits 1 when the run left new artifacts, 0 otherwise.
#
# Environment: FUZZ_JOBS (default 2) workers; FUZZ_EXTRA extra libFuzzer flags (e.g.
# -use_value_profile=1); FUZZ_SEED_REGRESSIONS=1 (see 3.).
# A finding is reproduced with   build/fuzz/fuzz_gltf build/fuzz/artifacts/crash-...
# and minimised with             build/fuzz/fuzz_gltf -minimize_crash=1 -max_total_time=120 \
#                                    -exact_artifact_path=min.gltf ARTIFACT
set -euo pipefail

SECONDS_TO_RUN="${1:-60}"
if ! [[ "$SECONDS_TO_RUN" =~ ^[0-9]+$ ]] || [ "$SECONDS_TO_RUN" -lt 1 ]; then
    echo "usage: $0 [SECONDS]   (a positive whole number of seconds, default 60)" >&2
    exit 2
fi
JOBS="${FUZZ_JOBS:-2}"

cd "$(dirname "$0")/../.."   # the repository root
OUT=build/fuzz
BIN=$OUT/fuzz_gltf
CORPUS=$OUT/corpus
ARTIFACTS=$OUT/artifacts
LOG=$OUT/last_run.log

# --- 1. packages -------------------------------------------------------------------
find_clang() {
    CLANGXX=""
    for candidate in clang++ clang++-19 clang++-18 clang++-17 clang++-16 clang++-15 clang++-14; do
        if command -v "$candidate" >/dev/null 2>&1; then CLANGXX="$candidate"; return 0; fi
    done
    return 1
}
# The libFuzzer runtime of the installed clang (libclang_rt.fuzzer-<arch>.a).
have_fuzzer_runtime() {
    local dir
    dir="$("$CLANGXX" -print-resource-dir 2>/dev/null)" || return 1
    compgen -G "$dir/lib/linux/libclang_rt.fuzzer-*.a" >/dev/null || compgen -G "$dir/lib/*/libclang_rt.fuzzer.a" >/dev/null
}
missing=""
for p in libglm-dev libtinygltf-dev libstb-dev nlohmann-json3-dev libdraco-dev libmeshoptimizer-dev; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
done
if ! find_clang; then missing="$missing clang"; fi
if [ -n "$missing" ] || ! have_fuzzer_runtime; then
    if [ "$(id -u)" = 0 ]; then SUDO=""; else SUDO="sudo"; fi
    $SUDO apt-get update -q
    # The runtime package is named after clang's major version (libclang-rt-14-dev for
    # Debian 12's clang 14); install clang first to learn the version.
    [ -n "$missing" ] && DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q $missing
    find_clang || { echo "run_fuzzer.sh: clang++ is still missing" >&2; exit 2; }
    if ! have_fuzzer_runtime; then
        major="$("$CLANGXX" -dumpversion | cut -d. -f1)"
        DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q "libclang-rt-$major-dev" ||
            DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q libclang-rt-dev
    fi
    have_fuzzer_runtime || { echo "run_fuzzer.sh: no libFuzzer runtime for $CLANGXX" >&2; exit 2; }
fi

# --- 2. build ----------------------------------------------------------------------
mkdir -p "$OUT" "$CORPUS" "$ARTIFACTS"
if [ ! -x "$BIN" ] || [ tests/fuzz/fuzz_gltf.cpp -nt "$BIN" ] || [ smallvcm.hpp -nt "$BIN" ] || [ "$0" -nt "$BIN" ]; then
    echo "run_fuzzer.sh: building $BIN with $CLANGXX (about a minute)"
    "$CLANGXX" -std=c++17 -g -O1 -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined \
        -I. tests/fuzz/fuzz_gltf.cpp -o "$BIN" -pthread -ltinyexr -ldraco -lmeshoptimizer
fi

# --- 3. seeds ----------------------------------------------------------------------
# Regular files only (tests/data/bad/directory.gltf is a folder); at most 64 KiB. The
# regression inputs of tests/data/fuzz join only with FUZZ_SEED_REGRESSIONS=1: until
# their fixes are in smallvcm.hpp every run would report them again as new crashes.
seeds="scenes/*.gltf tests/data/bad/* tests/data/gltf/* tests/data/compressed/*.glb"
[ "${FUZZ_SEED_REGRESSIONS:-0}" = 1 ] && seeds="$seeds tests/data/fuzz/*"
for f in $seeds; do
    [ -f "$f" ] || continue
    case "$f" in *.md) continue ;; esac
    [ "$(stat -c %s "$f")" -le 65536 ] || continue
    cp -p "$f" "$CORPUS/seed_$(basename "$f")"
done

# --- 4. fuzz -----------------------------------------------------------------------
count_artifacts() { find "$ARTIFACTS" -maxdepth 1 -type f -name "$1*" | wc -l; }
before_crash=$(count_artifacts crash-); before_timeout=$(count_artifacts timeout-)
before_oom=$(count_artifacts oom-); before_leak=$(count_artifacts leak-)
echo "run_fuzzer.sh: fuzzing for $SECONDS_TO_RUN s with $JOBS workers; corpus $CORPUS ($(ls "$CORPUS" | wc -l) files), log $LOG"
# Fork mode: the parent merges the workers' corpora and keeps going after a finding.
# Leaks are findings too (libFuzzer's default), and so is a single allocation above
# -rss_limit_mb (libFuzzer's malloc limit). The target's temporary folders go to
# $TMP_DIR, emptied afterwards (a crashed worker leaves its input file behind).
TMP_DIR="$PWD/$OUT/tmp"
rm -rf "$TMP_DIR"; mkdir -p "$TMP_DIR"
set +e
TMPDIR="$TMP_DIR" \
UBSAN_OPTIONS="${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}" \
"$BIN" -fork="$JOBS" -ignore_crashes=1 -ignore_timeouts=1 -ignore_ooms=1 \
    -max_len=65536 -timeout=10 -rss_limit_mb=2048 -max_total_time="$SECONDS_TO_RUN" \
    -dict=tests/fuzz/gltf.dict -artifact_prefix="$ARTIFACTS/" -print_final_stats=1 -print_funcs=0 ${FUZZ_EXTRA:-} \
    "$CORPUS" >"$LOG" 2>&1
status=$?
set -e
rm -rf "$TMP_DIR"

# --- 5. summary --------------------------------------------------------------------
crash=$(( $(count_artifacts crash-) - before_crash )); timeout=$(( $(count_artifacts timeout-) - before_timeout ))
oom=$(( $(count_artifacts oom-) - before_oom )); leak=$(( $(count_artifacts leak-) - before_leak ))
new=$((crash + timeout + oom + leak))
# Fork mode prints "#EXECS: cov: ... exec/s: R ... time: Ts" lines; take the last one.
stats=$(grep -E '^#[0-9]+: cov:' "$LOG" | tail -n 1 || true)
execs=$(echo "$stats" | sed -nE 's/^#([0-9]+):.*/\1/p'); [ -n "$execs" ] || execs=0
elapsed=$(echo "$stats" | sed -nE 's/.* time: ([0-9]+)s.*/\1/p'); [ -n "$elapsed" ] || elapsed=$SECONDS_TO_RUN
rate=$(( elapsed > 0 ? execs / elapsed : 0 ))
grep -E '^(INFO: log from|==[0-9]+==ERROR|SUMMARY:|.*FINDING:)' "$LOG" | sort | uniq -c | sort -rn | head -n 20 || true
echo "fuzz_gltf: $execs executions in $elapsed s ($rate exec/s), $new new artifacts (crash $crash, timeout $timeout, oom $oom, leak $leak) in $ARTIFACTS/; libFuzzer exit $status"
[ "$new" -eq 0 ]
