SHELL := /bin/bash
# smallvcm — build, demo, tests.
#   make demo   installs missing Debian packages, builds, renders the default scene
#   make test   installs missing Debian packages, builds and runs every test
#   make deps   only the package check/installation
# Objects go to build/. The two slow translation units (Catch2's main, ~15 s, and the
# implementation unit with tinygltf, stb and tinyexr, ~10 s) compile once and are reused.

CXX      ?= g++
# The BVH's vector width follows the build machine ([SECTION] Appendix: BVH): on a CPU with
# AVX2 (/proc/cpuinfo) the default flags add -mavx2, which gives 8-wide nodes and leaf
# blocks (faster than the 4-wide SSE tree: docs/performance.md, the Embree section);
# elsewhere the tree is 4-wide SSE, which every x86-64 runs. The images are the same bit
# for bit either way (-mavx2 brings no FMA, so no multiply-add is contracted). The
# binaries then need a CPU with AVX2: for ones that run on any x86-64, `make BVH_ARCH=`
# (or give the whole CXXFLAGS, which are then used as given, without BVH_ARCH).
HAVE_AVX2 := $(shell grep -qw avx2 /proc/cpuinfo 2>/dev/null && echo yes)
BVH_ARCH ?= $(if $(HAVE_AVX2),-mavx2)
CXXFLAGS ?= -std=c++17 -O2 -g -Wall -Wextra -Wpedantic -Wshadow $(BVH_ARCH)
# Whether the flags in effect give the 8-wide tree (the compiler says: -march=native may too).
DEFAULT_IS_AVX2 := $(shell $(CXX) $(CXXFLAGS) -dM -E -x c++ /dev/null 2>/dev/null | grep -qw __AVX2__ && echo yes)
# The Catch2 suite's objects (build/tests/) compile without -g: its ~30 translation units
# are most of `make test`'s compile time, and the debug information costs a fifth to a
# quarter of their compile CPU (docs/testing.md). To debug a test, rebuild them with it:
#   rm -r build/tests && make build/tests/run_tests TEST_CXXFLAGS="-std=c++17 -O2 -g $(BVH_ARCH)"
# (with the BVH_ARCH of the build, e.g. -mavx2: the tests link with the implementation unit,
# and both must see the same BVH width).
# (make check's sanitizer build, build/check/, keeps -g as well).
TEST_CXXFLAGS ?= $(filter-out -g,$(CXXFLAGS))
CPPFLAGS += -I.
# Every program that links the implementation unit links Debian's tinyexr too (the
# OpenEXR reader and writer; the library brings zlib itself).
LDFLAGS  += -pthread -ltinyexr -ldraco -lmeshoptimizer
BUILD    := build
# Programs and tests build in parallel, one job per core.
JOBS     ?= $(shell nproc 2>/dev/null || echo 2)

# Every object depends on the compiler and flags it was built with (build/cxxflags.txt,
# rewritten only when they change): a build with other CXXFLAGS, e.g. -mavx2, which
# changes the BVH's node layout, rebuilds every object instead of linking objects that
# disagree about it.
FLAGS_STAMP := $(BUILD)/cxxflags.txt

DEB_PACKAGES := g++ make libglm-dev libtinygltf-dev libstb-dev libtinyexr-dev catch2 nlohmann-json3-dev libdraco-dev libmeshoptimizer-dev

HEADER   := smallvcm.hpp
IMPL_OBJ := $(BUILD)/smallvcm_impl.o
TEST_SRC := $(filter-out tests/catch_main.cpp,$(wildcard tests/*.cpp))
TEST_OBJ := $(patsubst tests/%.cpp,$(BUILD)/tests/%.o,$(TEST_SRC))

.PHONY: all deps demo model-image envmap-image test unit check fuzz convergence bench bench-embree bench-large figures clean exercise grade compare student-figures

all: $(BUILD)/smallvcm $(BUILD)/minimal $(BUILD)/my_path_tracer $(BUILD)/convergence $(BUILD)/bench $(BUILD)/tests/run_tests

# Installs what is missing, with sudo when not root; does nothing when all is there.
deps:
	@missing=""; for p in $(DEB_PACKAGES); do \
	  dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q "install ok installed" || missing="$$missing $$p"; \
	done; \
	if [ -n "$$missing" ]; then \
	  echo "make deps: installing$$missing"; \
	  if [ "$$(id -u)" = 0 ]; then SUDO=""; else SUDO="sudo"; fi; \
	  $$SUDO apt-get update -q && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -q $$missing; \
	fi

$(BUILD) $(BUILD)/tests:
	mkdir -p $@

$(IMPL_OBJ): examples/smallvcm_impl.cpp $(HEADER) $(FLAGS_STAMP) | $(BUILD)
	$(CXX) $(CPPFLAGS) $(CXXFLAGS) -c $< -o $@

# Every examples/NAME.cpp, benchmarks/NAME.cpp and figures/NAME.cpp is a program
# build/NAME linked with the implementation unit (the three folders share no name). The
# benchmarks include examples/command_line.hpp, the figure programs figures/figure_kit.hpp
# (which includes it too).
$(BUILD)/%.o: examples/%.cpp $(HEADER) $(wildcard examples/*.hpp) $(FLAGS_STAMP) | $(BUILD)
	$(CXX) $(CPPFLAGS) $(CXXFLAGS) -c $< -o $@
$(BUILD)/%.o: benchmarks/%.cpp $(HEADER) $(wildcard examples/*.hpp) $(FLAGS_STAMP) | $(BUILD)
	$(CXX) $(CPPFLAGS) $(CXXFLAGS) -c $< -o $@
$(BUILD)/%.o: figures/%.cpp $(HEADER) $(wildcard examples/*.hpp figures/*.hpp) $(FLAGS_STAMP) | $(BUILD)
	$(CXX) $(CPPFLAGS) $(CXXFLAGS) -c $< -o $@

$(BUILD)/%: $(BUILD)/%.o $(IMPL_OBJ)
	$(CXX) $^ -o $@ $(LDFLAGS)

.PRECIOUS: $(BUILD)/%.o

# Integrators compiled into the command-line renderer: .cpp files that each register
# theirs with a smallvcm::IntegratorRegistration (docs/writing-an-integrator.md); -a NAME
# then runs one and --help lists them. The default adds the course's example, -a mypt.
#   make build/smallvcm INTEGRATORS="examples/integrators/my_path_tracer.cpp ~/mine.cpp"
# Each file compiles to build/integrators/<its name>.o (so two files need two names), and
# the sanitized command line (build/check/smallvcm) links the same files. The list is kept
# in build/integrators.list, so a different list relinks the program.
INTEGRATORS ?= examples/integrators/my_path_tracer.cpp
INTEGRATOR_LIST := $(BUILD)/integrators.list
integrator_obj = $(foreach f,$(INTEGRATORS),$(1)/integrators/$(basename $(notdir $(f))).o)
define INTEGRATOR_RULES
$(BUILD)/integrators/$(basename $(notdir $(1))).o: $(1) $(HEADER) $(wildcard examples/*.hpp) $(FLAGS_STAMP) | $(BUILD)/integrators
	$$(CXX) $$(CPPFLAGS) $$(CXXFLAGS) -c $$< -o $$@
$(BUILD)/check/integrators/$(basename $(notdir $(1))).o: $(1) $(HEADER) $(wildcard examples/*.hpp) | $(BUILD)/check/integrators
	$$(CXX) $$(CPPFLAGS) $$(SAN_FLAGS) -c $$< -o $$@
endef
$(foreach f,$(INTEGRATORS),$(eval $(call INTEGRATOR_RULES,$(f))))
$(BUILD)/integrators $(BUILD)/check/integrators:
	mkdir -p $@
# Rewritten only when the list changes, so an unchanged list relinks nothing.
$(INTEGRATOR_LIST): FORCE | $(BUILD)
	@echo '$(INTEGRATORS)' | cmp -s - $@ || echo '$(INTEGRATORS)' > $@
.PHONY: FORCE
FORCE:

$(BUILD)/smallvcm: $(BUILD)/smallvcm.o $(IMPL_OBJ) $(call integrator_obj,$(BUILD)) $(INTEGRATOR_LIST)
	$(CXX) $(filter %.o,$^) -o $@ $(LDFLAGS)

# The command line records `git describe --always --dirty` of the sources it was built
# from in every image's sidecar. build/commit.txt changes only when that does, so only
# the command line's object is rebuilt, and only then.
COMMIT := $(shell git describe --always --dirty 2>/dev/null)
$(FLAGS_STAMP): FORCE | $(BUILD)
	@echo '$(CXX) $(CXXFLAGS) | $(TEST_CXXFLAGS)' | cmp -s - $@ || echo '$(CXX) $(CXXFLAGS) | $(TEST_CXXFLAGS)' > $@
$(BUILD)/commit.txt: FORCE | $(BUILD)
	@echo '$(COMMIT)' | cmp -s - $@ || echo '$(COMMIT)' > $@
$(BUILD)/smallvcm.o $(BUILD)/check/smallvcm.o: $(BUILD)/commit.txt
$(BUILD)/smallvcm.o $(BUILD)/check/smallvcm.o: CPPFLAGS += -DSMALLVCM_COMMIT='"$(COMMIT)"'

# The header's first-screen example is a whole program: it defines SMALLVCM_IMPLEMENTATION
# itself, so it is built alone, not linked with the implementation unit.
$(BUILD)/minimal: examples/minimal.cpp $(HEADER) $(FLAGS_STAMP) | $(BUILD)
	$(CXX) $(CPPFLAGS) $(CXXFLAGS) $< -o $@ $(LDFLAGS)

$(BUILD)/tests/catch_main.o: tests/catch_main.cpp $(FLAGS_STAMP) | $(BUILD)/tests
	$(CXX) $(CPPFLAGS) $(TEST_CXXFLAGS) -c $< -o $@

$(BUILD)/tests/%.o: tests/%.cpp $(HEADER) $(wildcard tests/*.hpp) $(FLAGS_STAMP) | $(BUILD)/tests
	$(CXX) $(CPPFLAGS) $(TEST_CXXFLAGS) -c $< -o $@

$(BUILD)/tests/run_tests: $(BUILD)/tests/catch_main.o $(TEST_OBJ) $(IMPL_OBJ)
	$(CXX) $^ -o $@ $(LDFLAGS)

# PNGs committed under docs/ are re-encoded losslessly (stb's deflate hardly compresses
# a noisy render; docs/compact_png.py says why and checks the pixels stay the same).
COMPACT_PNG := /usr/bin/python3 docs/compact_png.py

# The default scene (kDefault: mirror and glass spheres, ceiling light) by VCM.
DEMO_ARGS := -s 4 -a vcm -i 32 -r 512x512 -o $(BUILD)/demo.png
demo: deps
	$(MAKE) --no-print-directory $(BUILD)/smallvcm
	$(BUILD)/smallvcm $(DEMO_ARGS)

# make model-image: the README's real-world model, the Khronos sample Avocado
# (scenes/avocado: no camera and no light in the file), rendered with every default but
# the resolution and iterations (made-up camera, default sky and sun, vcm) into
# docs/images/avocado_vcm.png and its sidecar (docs/images/README.md: settings and time).
MODEL_IMAGE_ARGS := -s scenes/avocado/Avocado.gltf -i 64 -r 512x512 -o docs/images/avocado_vcm.png
model-image: deps
	$(MAKE) --no-print-directory $(BUILD)/smallvcm
	$(BUILD)/smallvcm $(MODEL_IMAGE_ARGS)
	$(COMPACT_PNG) docs/images/avocado_vcm.png

# make envmap-image: the same model lit by an environment map instead, the CC0 HDRI
# scenes/hdri/royal_esplanade_1k.hdr (licence beside it), unturned, with every other
# setting as model-image's, into docs/images/avocado_envmap_vcm.png.
ENVMAP_IMAGE_ARGS := -s scenes/avocado/Avocado.gltf --envmap scenes/hdri/royal_esplanade_1k.hdr \
                     -i 64 -r 512x512 -o docs/images/avocado_envmap_vcm.png
envmap-image: deps
	$(MAKE) --no-print-directory $(BUILD)/smallvcm
	$(BUILD)/smallvcm $(ENVMAP_IMAGE_ARGS)
	$(COMPACT_PNG) docs/images/avocado_envmap_vcm.png

# The sanitizer build (AddressSanitizer + UndefinedBehaviorSanitizer, and the renderer's
# own invariant checks, SMALLVCM_CHECKS) lives in build/check/; its BVH has the default
# build's width.
SAN_FLAGS := -std=c++17 -O1 -g -fno-omit-frame-pointer -fsanitize=address,undefined \
             -fno-sanitize-recover=undefined -DSMALLVCM_CHECKS -Wall -Wextra -Wpedantic -Wshadow \
             $(if $(DEFAULT_IS_AVX2),-mavx2)
SAN_TEST_OBJ := $(patsubst tests/%.cpp,$(BUILD)/check/tests/%.o,$(TEST_SRC))

$(BUILD)/check/tests:
	mkdir -p $@
# Only the command line and the implementation unit (examples/) are built sanitized.
$(BUILD)/check/%.o: examples/%.cpp $(HEADER) $(wildcard examples/*.hpp) | $(BUILD)/check/tests
	$(CXX) $(CPPFLAGS) $(SAN_FLAGS) -c $< -o $@
$(BUILD)/check/smallvcm: $(BUILD)/check/smallvcm.o $(BUILD)/check/smallvcm_impl.o $(call integrator_obj,$(BUILD)/check) $(INTEGRATOR_LIST)
	$(CXX) $(SAN_FLAGS) $(filter %.o,$^) -o $@ $(LDFLAGS)
$(BUILD)/check/tests/catch_main.o: tests/catch_main.cpp | $(BUILD)/check/tests
	$(CXX) $(CPPFLAGS) $(SAN_FLAGS) -c $< -o $@
$(BUILD)/check/tests/%.o: tests/%.cpp $(HEADER) $(wildcard tests/*.hpp) | $(BUILD)/check/tests
	$(CXX) $(CPPFLAGS) $(SAN_FLAGS) -c $< -o $@
$(BUILD)/check/tests/run_tests: $(BUILD)/check/tests/catch_main.o $(SAN_TEST_OBJ) $(BUILD)/check/smallvcm_impl.o
	$(CXX) $(SAN_FLAGS) $^ -o $@ $(LDFLAGS)

# The BVH's other builds ([SECTION] Appendix: BVH): the default build is 8-wide AVX2 where
# the CPU has it (BVH_ARCH above), else 4-wide SSE; SMALLVCM_BVH_SCALAR selects the portable
# scalar loops. make test builds each other variant's geometry tests and command line into
# build/bvh-VARIANT/ (every unit of a variant with its flag: the header's BVH types change
# with it) and tests/run_suite.sh --bvh-variants runs its [geometry] tests and checks that
# its renders equal the default build's bit for bit, as the BVH promises the same hits in
# every build. The variants are scalar and whichever of SSE and AVX2 the default build is
# not (the compiler says whether the default flags enable AVX2); AVX2 only where the CPU
# can run it (make test says when it is left out). A variant compiles with the default
# flags less BVH_ARCH, plus its own (-mno-avx also undoes a -march that brings AVX).
BVH_FLAGS_scalar := -DSMALLVCM_BVH_SCALAR
BVH_FLAGS_sse    := -mno-avx
BVH_FLAGS_avx2   := -mavx2
BVH_VARIANTS := scalar $(if $(DEFAULT_IS_AVX2),sse,$(if $(HAVE_AVX2),avx2))
BVH_VARIANT_PROGRAMS := $(foreach v,$(BVH_VARIANTS),$(BUILD)/bvh-$(v)/run_geometry $(BUILD)/bvh-$(v)/smallvcm)
define BVH_VARIANT_RULES
$(BUILD)/bvh-$(1):
	mkdir -p $$@
$(BUILD)/bvh-$(1)/%.o: examples/%.cpp $(HEADER) $(wildcard examples/*.hpp) $(FLAGS_STAMP) | $(BUILD)/bvh-$(1)
	$$(CXX) $$(CPPFLAGS) $$(filter-out $$(BVH_ARCH),$$(TEST_CXXFLAGS)) $$(BVH_FLAGS_$(1)) -c $$< -o $$@
$(BUILD)/bvh-$(1)/test_geometry.o: tests/test_geometry.cpp $(HEADER) $(wildcard tests/*.hpp) $(FLAGS_STAMP) | $(BUILD)/bvh-$(1)
	$$(CXX) $$(CPPFLAGS) $$(filter-out $$(BVH_ARCH),$$(TEST_CXXFLAGS)) $$(BVH_FLAGS_$(1)) -c $$< -o $$@
$(BUILD)/bvh-$(1)/run_geometry: $(BUILD)/tests/catch_main.o $(BUILD)/bvh-$(1)/test_geometry.o $(BUILD)/bvh-$(1)/smallvcm_impl.o
	$$(CXX) $$^ -o $$@ $$(LDFLAGS)
$(BUILD)/bvh-$(1)/smallvcm: $(BUILD)/bvh-$(1)/smallvcm.o $(BUILD)/bvh-$(1)/smallvcm_impl.o
	$$(CXX) $$^ -o $$@ $$(LDFLAGS)
endef
$(foreach v,scalar sse avx2,$(eval $(call BVH_VARIANT_RULES,$(v))))

# make test: the Catch2 suite (tests tagged [.] are slow and run only when asked for),
# then the sanitizer smoke stage: the sanitized command line renders every algorithm on
# every Cornell scene and is fed every bad scene file, then the BVH's other builds (scalar,
# and SSE or AVX2) against the default one (see BVH_VARIANTS above), then the coursework kit's proof
# (tests/exercises/kit.py prove: every exercise cut from the header compiles, fails its
# own grader and passes the others'), then every figure program runs at quick settings
# and the gallery check passes (tests/run_suite.sh says how each run counts). Ends with
# the plain line "tests: N passed, N failed" that CI reads.
test: deps
	$(MAKE) -j$(JOBS) --no-print-directory all $(BUILD)/check/smallvcm $(FIGURE_PROGRAMS:%=$(BUILD)/%) $(BVH_VARIANT_PROGRAMS)
	@$(ENSURE_MATPLOTLIB)
	@tests/run_suite.sh --catch ../$(BUILD)/tests/run_tests $(TEST_ARGS) -- --smoke ../$(BUILD)/check/smallvcm \
	    --bvh-variants ../$(BUILD)/smallvcm $(BVH_VARIANTS:%=../$(BUILD)/bvh-%) -- \
	    --exercises --figures $(FIGURE_PROGRAMS:%=../$(BUILD)/%)

# make unit: the fast loop while changing the header: the Catch2 tests that render no
# whole scenes statistically (sampling, BSDF, geometry, camera, film, loading, untrusted
# input, command line, MIS weights, golden images: about 11 s on 2 cores after a build),
# plus the coursework graders ([exercise]: tiny furnaces and brute-force MIS, ~2 s).
# make test stays the whole suite.
UNIT_TAGS := ~[figures] ~[convergence] ~[bench] ~[integrators] ~[stability] ~[photon_mapping] ~[my_path_tracer] ~[transport]
unit: deps
	$(MAKE) -j$(JOBS) --no-print-directory $(BUILD)/smallvcm $(BUILD)/minimal $(BUILD)/tests/run_tests
	cd tests && ../$(BUILD)/tests/run_tests "$(UNIT_TAGS)"

# make check: the whole Catch2 suite under the sanitizers and invariant checks, then the
# same smoke stage (slower: about 3x the normal suite; not run by CI, see docs/testing.md).
check: deps
	$(MAKE) -j$(JOBS) --no-print-directory all $(BUILD)/check/smallvcm $(BUILD)/check/tests/run_tests
	@tests/run_suite.sh --catch ../$(BUILD)/check/tests/run_tests $(TEST_ARGS) -- --smoke ../$(BUILD)/check/smallvcm

# make bench: seconds per iteration of every estimator on every Cornell scene (512x512,
# 1 and 2 threads), rays per second, peak memory, BVH build and tracing as the triangle
# count grows from 1e2 to 1e6, the environment light's cost (scene 3's constant background
# against scenes/hdri/royal_esplanade_1k.hdr, pt and vcm) (each configuration the fastest
# of two measurements, to ride out the machine's own drift; about 10 minutes on 2 cores); the report goes to
# docs/performance/bench.md, its numbers to docs/performance/bench_bvh.csv and
# bench_render.csv, and benchmarks/plot_bench.py draws them (matplotlib, installed if missing)
# into docs/performance/bvh_scaling.png and speed_per_iteration.png. Then the samplers at
# equal time (bench-samplers below) with SAMPLER_SECONDS=2 (under a minute more).
bench: deps $(BUILD)/bench
	@$(ENSURE_MATPLOTLIB)
	$(BUILD)/bench --repeat 2 --markdown docs/performance/bench.md --csv docs/performance/bench
	/usr/bin/python3 benchmarks/plot_bench.py docs/performance/bench_bvh.csv docs/performance/bench_render.csv
	$(COMPACT_PNG) docs/performance
	$(MAKE) --no-print-directory bench-samplers SAMPLER_SECONDS=2

# make bench-samplers [SAMPLER_SECONDS=10]: independent numbers against Sobol points at
# equal CPU time on every Cornell scene (0-4), pt, bpt, vcm and ppm, 64x64, one thread,
# SAMPLER_SECONDS of CPU time per run (the two samplers run side by side, one core each):
# seconds per iteration, RMSE on the whole image and on the diffuse region, the MSE gain
# and the fitted slopes, against the Sobol references in docs/performance/references_sobol
# (made first if missing: BPT, or VCM with the sun and the point light, 4096 iterations, a
# few minutes). The table goes to docs/performance/samplers/equal_time_<S>s.md (its runs
# beside it); at 10 s about 4 minutes on 2 idle cores, at 2 s under one.
SAMPLER_SECONDS ?= 10
SAMPLER_STUDY := --references docs/performance/references_sobol --resolution 64x64 --algorithms pt,bpt,vcm,ppm \
                 --max-iterations 1048576 --max-seconds $(SAMPLER_SECONDS) --clock cpu -q
SAMPLER_OUT := docs/performance/samplers/equal_time_$(SAMPLER_SECONDS)s
.PHONY: bench-samplers
bench-samplers: deps $(BUILD)/convergence
	mkdir -p docs/performance/samplers
	@for s in 0 1 2 3 4; do [ -f docs/performance/references_sobol/cornell_$${s}_64x64.pfm ] || missing=1; done; \
	if [ -n "$$missing" ]; then $(BUILD)/convergence --make-references --reference-sampler sobol \
	    --reference-iterations 4096 --resolution 64x64 --references docs/performance/references_sobol \
	    --algorithms pt --max-iterations 1 --out $(BUILD)/references_sobol.csv; fi
	$(BUILD)/convergence $(SAMPLER_STUDY) --sampler independent --out $(SAMPLER_OUT)_independent.csv & \
	  $(BUILD)/convergence $(SAMPLER_STUDY) --sampler sobol --out $(SAMPLER_OUT)_sobol.csv; status=$$?; wait $$! && [ $$status = 0 ]
	/usr/bin/python3 benchmarks/sampler_table.py $(SAMPLER_OUT)_independent.csv $(SAMPLER_OUT)_sobol.csv > $(SAMPLER_OUT).md
	cat $(SAMPLER_OUT).md

# make bench-large ASSETS=DIR: the large benchmark scene (benchmarks/large_scene.py: a closed
# atrium hall furnished with real models that stay outside the repository) loaded and
# rendered with the defaults, pt and vcm on 1 and 2 threads, 3 rounds (ROUNDS=N); about 3
# minutes. Without the models in DIR it says where to get them (benchmarks/README.md) and
# does nothing else.
ROUNDS ?= 3
bench-large: deps $(BUILD)/smallvcm
	benchmarks/large_scene.sh "$(ASSETS)" $(ROUNDS)

# make bench-embree: smallvcm's BVH beside Embree 3 (Debian's libembree-dev, installed if
# missing; a benchmark-only dependency the header never includes) on generated meshes and
# the same incoherent rays, one thread: a ratio table of closest-hit and any-hit Mrays/s,
# build time and bytes per triangle, and how often the two agree (benchmarks/bench_embree.cpp
# says what it measures; about half a minute). docs/performance.md keeps the current table.
ENSURE_EMBREE = dpkg-query -W -f='$${Status}' libembree-dev 2>/dev/null | grep -q "install ok installed" || \
	  { if [ "$$(id -u)" = 0 ]; then SUDO=""; else SUDO="sudo"; fi; \
	    $$SUDO apt-get update -q && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -q libembree-dev; }
bench-embree: deps
	@$(ENSURE_EMBREE)
	$(MAKE) --no-print-directory $(BUILD)/bench_embree
	$(BUILD)/bench_embree $(BENCH_EMBREE_ARGS)
$(BUILD)/bench_embree: benchmarks/bench_embree.cpp $(HEADER) $(FLAGS_STAMP) | $(BUILD)
	$(CXX) $(CPPFLAGS) $(CXXFLAGS) $< -o $@ $(LDFLAGS) -lembree3

# make bench-mitsuba: smallvcm's path tracer beside Mitsuba 3's (`llvm_ad_rgb` and
# `scalar_rgb`), one core each, on scene 4 and a generated mesh scene converted by
# benchmarks/mitsuba_compare.py: first whether the converged images agree, then efficiency
# 1/(CPU seconds x MSE) at several sample budgets (about 15 minutes; results in
# build/mitsuba/, the current table in docs/performance.md). Benchmark-only: Mitsuba and
# NumPy are installed with pip into the virtual environment build/mitsuba-venv (python3-venv
# from Debian), and Dr.Jit's LLVM back end gets Debian's libllvm19 (the LLVM 14 and 15 of
# Debian 12 abort compiling its kernels on AVX-512 machines). BENCH_MITSUBA_ARGS=--quick:
# tiny settings (under a minute).
MITSUBA_VENV := $(BUILD)/mitsuba-venv
MITSUBA_LLVM := /usr/lib/x86_64-linux-gnu/libLLVM-19.so
.PHONY: bench-mitsuba
bench-mitsuba: deps $(BUILD)/smallvcm
	@if [ "$$(id -u)" = 0 ]; then SUDO=""; else SUDO="sudo"; fi; \
	for p in python3-venv libllvm19; do \
	  dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q "install ok installed" || \
	    { $$SUDO apt-get update -q && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -q $$p; }; \
	done
	@$(MITSUBA_VENV)/bin/python -c "import mitsuba, numpy" 2>/dev/null || \
	  { python3 -m venv $(MITSUBA_VENV) && $(MITSUBA_VENV)/bin/pip install -q mitsuba==3.9.1 numpy; }
	DRJIT_LIBLLVM_PATH=$(MITSUBA_LLVM) $(MITSUBA_VENV)/bin/python benchmarks/mitsuba_compare.py $(BENCH_MITSUBA_ARGS)

# make bench-luxcore [BENCH_LUXCORE_ARGS="--budgets 10,20"]: smallvcm's BPT and VCM (both
# samplers) beside LuxCore's BIDIRCPU and BIDIRVMCPU (Sobol) on scene 4 at 128x128, one
# thread each, efficiency 1/(MSE x CPU s) at CPU budgets of 10 to 120 s (LuxCore renders on
# to 240 s for its variance), and our MSE slopes on the diffuse region
# (benchmarks/luxcore_compare.py says how; about 18 minutes of CPU;
# results in build/luxcore/, the current table in docs/performance.md). Benchmark-only:
# pyluxcore and NumPy are installed with pip into build/luxcore-venv; the reference (Sobol
# BPT, 4096 iterations) is made first if missing.
LUXCORE_VENV := $(BUILD)/luxcore-venv
.PHONY: bench-luxcore
bench-luxcore: deps $(BUILD)/convergence
	@dpkg-query -W -f='$${Status}' python3-venv 2>/dev/null | grep -q "install ok installed" || \
	  { if [ "$$(id -u)" = 0 ]; then SUDO=""; else SUDO="sudo"; fi; \
	    $$SUDO apt-get update -q && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -q python3-venv; }
	@$(LUXCORE_VENV)/bin/python -c "import numpy, pyluxcore" >/dev/null 2>&1 || \
	  { python3 -m venv $(LUXCORE_VENV) && $(LUXCORE_VENV)/bin/pip install -q pyluxcore==2.11.2 numpy; }
	@[ -f docs/performance/references_sobol/cornell_4_128x128.pfm ] || $(BUILD)/convergence --make-references \
	    --reference-sampler sobol --reference-iterations 4096 --resolution 128x128 --scenes 4 \
	    --references docs/performance/references_sobol --algorithms pt --max-iterations 1 --out $(BUILD)/references_sobol.csv
	$(LUXCORE_VENV)/bin/python benchmarks/luxcore_compare.py $(BENCH_LUXCORE_ARGS)

# make mutants [MUTANTS=M01,M02]: mutation testing of the transport code (tests/mutants.py,
# the list in tests/mutant_list.py): each mutant is one edited line of the header, built
# in a temporary copy of the tree and run against the suite without the golden images,
# cheap stages first, stopping at the first failing test; prints one line per mutant and
# the score, and writes them to build/mutants/report.txt (docs/testing.md). The suite's
# chart tests need python3-matplotlib, installed if missing as by make test (without it the
# unmutated header fails the last stage and no mutant runs).
.PHONY: mutants
mutants: deps $(BUILD)/tests/catch_main.o
	@$(ENSURE_MATPLOTLIB)
	/usr/bin/python3 tests/mutants.py $(if $(MUTANTS),--only $(MUTANTS))

# make fuzz [FUZZ_SECONDS=600]: libFuzzer over the glTF loader (installs clang if missing).
FUZZ_SECONDS ?= 300
fuzz:
	tests/fuzz/run_fuzzer.sh $(FUZZ_SECONDS)

# The charts are drawn by matplotlib (Debian's python3-matplotlib), installed if missing.
ENSURE_MATPLOTLIB = dpkg-query -W -f='$${Status}' python3-matplotlib 2>/dev/null | grep -q "install ok installed" || \
	  { if [ "$$(id -u)" = 0 ]; then SUDO=""; else SUDO="sudo"; fi; \
	    $$SUDO apt-get update -q && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -q python3-matplotlib; }

# make figures: every course figure (F01-F21) at publication settings into docs/figures/,
# then the charts and the gallery docs/figures.md (docs/figures.md says how long it takes;
# references missing from docs/figures/references/ are rendered first).
# make figures QUICK=1: the same programs at tiny settings into build/figures-quick/ (a
# couple of minutes; the gallery check fails if a file the page shows was not made).
FIGURE_PROGRAMS := fig_path_tracing fig_mis fig_bidirectional fig_photon_mapping fig_vcm fig_volumetric fig_convergence fig_report
FIGURE_OUT := $(if $(QUICK),$(BUILD)/figures-quick,docs/figures)
FIGURE_PAGE := $(if $(QUICK),$(BUILD)/figures-quick/figures.md,docs/figures.md)
figures: deps
	$(MAKE) -j$(JOBS) --no-print-directory $(FIGURE_PROGRAMS:%=$(BUILD)/%)
	@$(ENSURE_MATPLOTLIB)
	@start=$$(date +%s); for program in $(FIGURE_PROGRAMS); do \
	  $(BUILD)/$$program $(if $(QUICK),--quick) --out $(FIGURE_OUT) || exit 1; done; \
	  echo "figures: the programs took $$(( $$(date +%s) - start )) s"
	/usr/bin/python3 figures/plot_figures.py $(FIGURE_OUT)
	/usr/bin/python3 figures/make_gallery.py $(FIGURE_OUT) $(FIGURE_PAGE)
	$(COMPACT_PNG) $(FIGURE_OUT)

# make convergence: the convergence study and its charts (docs/performance.md says how
# long; references are made if missing). Needs python3-matplotlib (installed if missing).
convergence: deps $(BUILD)/convergence
	@$(ENSURE_MATPLOTLIB)
	$(BUILD)/convergence --make-references --reference-iterations 2048 --max-iterations 4096 \
	    --max-seconds 10 --clock cpu --out docs/performance/convergence.csv
	/usr/bin/python3 benchmarks/plot_convergence.py docs/performance/convergence.csv
	$(COMPACT_PNG) docs/performance

# The coursework kit (docs/exercises/README.md): tests/exercises/kit.py, Python 3 only.
#   make exercise NAME=<name>|all [OUT=dir]  a student copy of the header with that exercise's
#       marked code replaced by its stub, into build/exercise/<name>/ or OUT (NAME=a,b works)
#   make grade STUDENT=path/to/smallvcm.hpp [EXERCISE=<name>]  builds the graders (the tests
#       tagged [ex:<name>]) against that copy and prints a score and diagnoses per exercise
#   make compare STUDENT=... ARGS='-s 4 -a pt -i 16'  renders with that copy and with the
#       reference, side by side, into build/compare/compare.png
#   make student-figures STUDENT=... [QUICK=1] [ONLY=fig_mis,...]  the course figures built
#       with that copy into build/student-figures/ (docs/exercises/README.md says how)
exercise:
	@/usr/bin/python3 tests/exercises/kit.py cut "$(NAME)" $(if $(OUT),--out "$(OUT)")
grade:
	@/usr/bin/python3 tests/exercises/kit.py grade $(if $(EXERCISE),--exercise "$(EXERCISE)") "$(STUDENT)"
compare:
	@/usr/bin/python3 tests/exercises/kit.py compare "$(STUDENT)" -- $(ARGS)
student-figures:
	@/usr/bin/python3 tests/exercises/kit.py figures "$(STUDENT)" $(if $(QUICK),--quick) $(if $(ONLY),--only "$(ONLY)")

clean:
	rm -rf $(BUILD)
