#!/usr/bin/env bash
# Runs the test stages of `make test` / `make check` and ends with the one line CI reads:
#   tests: N passed, N failed
# Usage: tests/run_suite.sh [--catch BINARY [CATCH ARGS...] --] [--smoke SMALLVCM_BINARY]
#                           [--exercises] [--figures PROGRAM...]
#   --catch   a Catch2 test binary, run from tests/; its summary counts test cases
#   --smoke   a smallvcm binary (the sanitized build): every algorithm on every Cornell
#             scene (16x16, 2 iterations) and every rejected file of tests/data/bad run
#             through it; each run counts as one test: renders must exit 0 and write their
#             image, bad command lines must exit 2 and write nothing,
#             bad files must exit 1 (fuzz regression inputs 0 or 1: some load after
#             their fix, tests/test_gltf.cpp checks which), and no run may
#             print a sanitizer report (AddressSanitizer / UndefinedBehaviorSanitizer) or
#             fail a SMALLVCM_CHECKS invariant.
#   --bvh-variants REFERENCE DIR... --
#             the BVH's other builds (Makefile: BVH_VARIANTS; build/bvh-scalar, and
#             build/bvh-sse when the default build is 8-wide AVX2, else build/bvh-avx2):
#             each DIR's run_geometry runs the [geometry] tests (its test cases count), and
#             its command line renders pt, lt, bpt and vcm on every Cornell scene and seven
#             glTF scenes (meshes, textures, smooth normals, spot light, glass, alpha
#             cut-outs) at 32x32,
#             2 iterations; each scene counts as one test and passes when all four images
#             equal the REFERENCE build's byte for byte (the BVH returns the same hits in
#             every build, so any difference is a bug of one of them)
#   --exercises the coursework kit's proof (tests/exercises/kit.py prove): the markers
#             pair up, bad input is refused as documented, and every exercise cut from the
#             header compiles, fails its own grader and passes the others' (each check
#             one test; 72 tests, 40-57 s of CPU, most of it compiling the graders per cut)
#   --figures the figure programs (build/fig_*), run with --quick into a temporary folder
#             (each run one test: exit 0), then figures/plot_figures.py and
#             figures/make_gallery.py on that folder (one test each: the gallery fails when
#             a figure or a file it shows is missing) -- `make figures QUICK=1`, checked.
set -u
cd "$(dirname "$0")"
suite_start=$(date +%s)
stage_start=$suite_start
stage_done() {  # the seconds a stage took, on one line of its own (what to trim when the suite grows)
  local now; now=$(date +%s)
  echo "stage time: $1 $(( now - stage_start )) s"
  stage_start=$now
}
passed=0
failed=0
status=0

run_catch() {  # a Catch2 binary and its arguments: its test cases are counted
  local binary=$1 log code summary total bad; shift
  log=$(mktemp)
  "$binary" "$@" 2>&1 | tee "$log"
  code=${PIPESTATUS[0]}
  summary=$(grep -E "^(All tests passed|test cases:)" "$log" | tail -n 1)
  total=$(echo "$summary" | sed -nE 's/.*in ([0-9]+) test cases?.*/\1/p; s/^test cases: *([0-9]+).*/\1/p' | head -n 1)
  bad=$(echo "$summary" | sed -nE 's/.*\| *([0-9]+) failed.*/\1/p')
  total=${total:-0}; bad=${bad:-0}
  if [ "$code" != 0 ] && [ "$bad" = 0 ]; then bad=1; total=$((total + 1)); fi
  passed=$((passed + total - bad)); failed=$((failed + bad))
  [ "$code" != 0 ] && status=1
  rm -f "$log"
}

if [ "${1:-}" = "--catch" ]; then
  shift
  binary=$1; shift
  args=()
  while [ $# -gt 0 ] && [ "$1" != "--" ]; do args+=("$1"); shift; done
  [ "${1:-}" = "--" ] && shift
  run_catch "$binary" "${args[@]}"
  stage_done catch2
fi

if [ "${1:-}" = "--smoke" ]; then
  binary=$2
  out=$(mktemp -d)
  run_one() {  # name expected_code command...
    local name=$1 expected=$2; shift 2
    local err="$out/stderr.txt"
    "$@" > /dev/null 2> "$err"
    local code=$?
    if { [ "$code" = "$expected" ] || { [ "$expected" = any ] && [ "$code" -le 1 ]; }; } &&
       ! grep -qE "Sanitizer|runtime error|check failed" "$err"; then
      passed=$((passed + 1))
    else
      failed=$((failed + 1)); status=1
      echo "smoke FAILED: $name (exit $code, expected $expected)"; head -n 20 "$err"
    fi
  }
  # The built-ins, and the example path tracer when the Makefile's INTEGRATORS linked it in.
  algorithms="el pt lt ppm bpm bpt vcm pm pmfg"
  "$binary" --help | grep -qE "^ +mypt " && algorithms="$algorithms mypt"
  for scene in 0 1 2 3 4; do
    for algorithm in $algorithms; do
      layers="--layers"; [ "$algorithm" = el ] && layers=""  # the eye light has no techniques
      run_one "render -s $scene -a $algorithm" 0 "$binary" -q -s "$scene" -a "$algorithm" -r 16x16 -i 2 \
        --photons 5000 $layers -o "$out/s${scene}_${algorithm}.pfm"
    done
  done
  # A second seed of one run, merged with the first through both sidecars.
  run_one "render -s 2 -a pt --seed 7" 0 "$binary" -q -s 2 -a pt -r 16x16 -i 3 --seed 7 -o "$out/s2_pt_seed7.pfm"
  run_one "merge" 0 "$binary" merge -q --tonemap aces "$out/s2_pt_merged.png" "$out/s2_pt.pfm" "$out/s2_pt_seed7.pfm"
  for file in data/bad/*.gltf data/bad/*.glb data/fuzz/*.gltf data/fuzz/*.glb; do
    [ -e "$file" ] || continue
    case "$file" in
      data/bad/degenerate_*) expected=0 ;;  # these load, with the zero-area triangles skipped
      data/fuzz/*) expected=any ;;          # some load after their fix; test_gltf checks which
      *) expected=1 ;;
    esac
    run_one "load $file" "$expected" "$binary" -q -s "$file" -a el -r 8x8 -o "$out/bad.pfm"
  done
  # Bad command lines: exit code 2 and no output file, under the sanitizers too.
  while IFS= read -r options; do
    # shellcheck disable=SC2086
    run_one "options $options" 2 "$binary" -q $options -o "$out/never.pfm"
    if [ -e "$out/never.pfm" ]; then failed=$((failed + 1)); status=1; echo "smoke FAILED: $options wrote an output"; fi
  done <<'OPTIONS'
-a nosuch
-i -3
-i 0
-i 12abc
-r 0x10
-r 100
-j 0
--radius-alpha 0
--radius-factor -1
--mis foo
--min-path-length 5 --max-path-length 3
--photons 0
--knn -2
--max-radius nan
-s 9
--no-such-option
-i
--exposure nan
--tonemap foo
--medium 0.1,0.1,1
--medium -1,0,0
--medium nan,0,0
--medium 0.1,0.1
OPTIONS
  echo "smoke stage with $binary: $((passed)) passed so far, $failed failed so far"
  rm -rf "$out"
  shift 2
  stage_done smoke
fi

if [ "${1:-}" = "--bvh-variants" ]; then
  shift
  reference=$1; shift
  variants=()
  while [ $# -gt 0 ] && [ "$1" != "--" ]; do variants+=("$1"); shift; done
  [ "${1:-}" = "--" ] && shift
  out=$(mktemp -d)
  scenes="0 1 2 3 4 ../scenes/textured_torus.gltf ../scenes/smooth_sphere_box.gltf ../scenes/avocado/Avocado.gltf
          ../scenes/veach_plates.gltf ../scenes/spot_light.gltf ../scenes/caustic_glass_sphere.gltf
          ../scenes/cutout_leaves.gltf"
  render_all() {  # binary, folder: four algorithms on every scene
    local binary=$1 folder=$2 scene algorithm
    mkdir -p "$folder"
    for scene in $scenes; do
      for algorithm in pt lt bpt vcm; do
        "$binary" -q -s "$scene" -a "$algorithm" -r 32x32 -i 2 -j 1 \
          -o "$folder/$(basename "$scene" .gltf)_$algorithm.pfm" > /dev/null 2>&1 || return 1
      done
    done
  }
  render_all "$reference" "$out/reference" || { echo "bvh variants: the reference renders failed"; status=1; }
  for variant in "${variants[@]}"; do
    name=$(basename "$variant")
    run_catch "$variant/run_geometry" "[geometry]"
    render_all "$variant/smallvcm" "$out/$name"
    for scene in $scenes; do
      same=yes
      for algorithm in pt lt bpt vcm; do
        image="$(basename "$scene" .gltf)_$algorithm.pfm"
        cmp -s "$out/reference/$image" "$out/$name/$image" || { same=no; echo "bvh variant FAILED: $name $image differs from the default build's"; }
      done
      if [ "$same" = yes ]; then passed=$((passed + 1)); else failed=$((failed + 1)); status=1; fi
    done
  done
  grep -qw avx2 /proc/cpuinfo 2>/dev/null || echo "bvh variants: this CPU has no AVX2, so the 8-wide build was not tested"
  echo "bvh variants stage: ${variants[*]##*/}"
  rm -rf "$out"
  stage_done bvh-variants
fi

if [ "${1:-}" = "--exercises" ]; then
  shift
  log=$(mktemp)
  /usr/bin/python3 ../tests/exercises/kit.py prove 2>&1 | tee "$log"
  code=${PIPESTATUS[0]}
  ok=$(sed -nE 's/^prove: ([0-9]+) passed, ([0-9]+) failed.*/\1/p' "$log" | tail -n 1)
  bad=$(sed -nE 's/^prove: ([0-9]+) passed, ([0-9]+) failed.*/\2/p' "$log" | tail -n 1)
  ok=${ok:-0}; bad=${bad:-0}
  if [ "$code" != 0 ] && [ "$bad" = 0 ]; then bad=1; fi
  passed=$((passed + ok)); failed=$((failed + bad))
  [ "$code" != 0 ] && status=1
  rm -f "$log"
  stage_done exercises
fi

if [ "${1:-}" = "--figures" ]; then
  shift
  out=$(mktemp -d)
  count() {  # name, then the command
    local name=$1; shift
    if "$@" > "$out/log.txt" 2>&1; then
      passed=$((passed + 1))
    else
      failed=$((failed + 1)); status=1
      echo "figures FAILED: $name"; tail -n 20 "$out/log.txt"
    fi
  }
  start=$(date +%s)
  for program in "$@"; do count "$program --quick" "$program" --quick --out "$out/figures"; done
  count "plot_figures" /usr/bin/python3 ../figures/plot_figures.py "$out/figures"
  count "make_gallery" /usr/bin/python3 ../figures/make_gallery.py "$out/figures" "$out/figures/figures.md"
  echo "figures stage (quick): $(( $(date +%s) - start )) s"
  rm -rf "$out"
  stage_done figures
fi

echo "stage time: all stages $(( $(date +%s) - suite_start )) s"

echo "tests: $passed passed, $failed failed"
exit $status
