#!/bin/bash
# The large-scene benchmark (docs/performance.md, "A large scene"): builds the scene with
# benchmarks/large_scene.py from the models in ASSETS, then, ROUNDS times (default 3),
# loads it alone (8x8, one iteration, one thread) and renders it with the defaults (512x512,
# default camera and lights) with pt (4 iterations) and vcm (2 iterations) on 1 and 2
# threads, each under /usr/bin/time: the summary line's load, BVH and per-iteration
# seconds (wall clock) and the process's user and system CPU seconds and peak memory.
# On a shared machine compare the CPU seconds: the wall clock counts the waits.
#   benchmarks/large_scene.sh ASSETS [ROUNDS]      (make bench-large ASSETS=... runs it)
# Without the models it says where to get them and exits 0: nothing to measure.
set -u
assets=${1:-}
rounds=${2:-3}
here=$(cd "$(dirname "$0")" && pwd)
binary=$here/../build/smallvcm
if [ -z "$assets" ] || [ ! -f "$assets/models/FlightHelmet/glTF/FlightHelmet.gltf" ] ||
   [ ! -f "$assets/assets/sponza/curtains/sponza_curtains.gltf" ] || [ ! -f "$assets/assets/sponza/ivy/sponza_ivy.gltf" ]; then
    echo "large-scene benchmark skipped: the models are not in '${assets:-<no ASSETS given>}'"
    echo "  (benchmarks/README.md, 'The large scene', says where to get them; then: make bench-large ASSETS=DIR)"
    exit 0
fi
[ -x "$binary" ] || { echo "build/smallvcm is missing: make build/smallvcm" >&2; exit 1; }
python3 "$here/large_scene.py" "$assets" 2>/dev/null || exit 1
scene=$assets/large_atrium.gltf
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
for round in $(seq 1 "$rounds"); do
    echo "round $round, $(date -u +%H:%M:%S) UTC, load average $(cut -d' ' -f1-3 /proc/loadavg)"
    /usr/bin/time -f "  load only: user %U s, sys %S s, wall %e s, peak %M KB" \
        "$binary" "$scene" -a pt -i 1 -r 8x8 -j 1 -o "$out/load.png" 2>&1 |
        grep -v ': note: ' | grep -o 'loaded in .*checks [0-9.]* s)\|  load only.*'
    for algorithm in pt vcm; do
        iterations=4
        [ "$algorithm" = vcm ] && iterations=2
        for threads in 1 2; do
            /usr/bin/time -f "  $algorithm -j $threads: user %U s, sys %S s, wall %e s, peak %M KB" \
                "$binary" "$scene" -a "$algorithm" -i "$iterations" -j "$threads" -o "$out/$algorithm.png" 2>&1 |
                grep -v ': note: ' | grep -o '[0-9]* iterations in [0-9.]* s ([0-9.]* s/iteration)\|loaded in [0-9.]* s\|  [a-z]* -j .*'
        done
    done
done
