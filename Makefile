SHELL := /bin/bash
# smallvcm — build, demo, tests.
#   make demo   installs missing Debian packages, builds, renders the default scene
#   make test   installs missing Debian packages, builds and runs every test
#   make deps   only the package check/installation
# Objects go to build/. The two slow translation units (Catch2's main, ~15 s, and the
# implementation unit with tinygltf and stb, ~10 s) compile once and are reused.

CXX      ?= g++
CXXFLAGS ?= -std=c++17 -O2 -g -Wall -Wextra -Wpedantic -Wshadow
CPPFLAGS += -I.
LDFLAGS  += -pthread
BUILD    := build

DEB_PACKAGES := g++ make libglm-dev libtinygltf-dev libstb-dev catch2 nlohmann-json3-dev

HEADER   := smallvcm.hpp
IMPL_OBJ := $(BUILD)/smallvcm_impl.o
TEST_SRC := $(filter-out tests/catch_main.cpp,$(wildcard tests/*.cpp))
TEST_OBJ := $(patsubst tests/%.cpp,$(BUILD)/tests/%.o,$(TEST_SRC))

.PHONY: all deps demo test clean

all: $(BUILD)/smallvcm $(BUILD)/tests/run_tests

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

$(IMPL_OBJ): examples/smallvcm_impl.cpp $(HEADER) | $(BUILD)
	$(CXX) $(CPPFLAGS) $(CXXFLAGS) -c $< -o $@

# Every examples/NAME.cpp is a program build/NAME linked with the implementation unit.
$(BUILD)/%.o: examples/%.cpp $(HEADER) | $(BUILD)
	$(CXX) $(CPPFLAGS) $(CXXFLAGS) -c $< -o $@

$(BUILD)/%: $(BUILD)/%.o $(IMPL_OBJ)
	$(CXX) $^ -o $@ $(LDFLAGS)

.PRECIOUS: $(BUILD)/%.o

$(BUILD)/tests/catch_main.o: tests/catch_main.cpp | $(BUILD)/tests
	$(CXX) $(CPPFLAGS) $(CXXFLAGS) -c $< -o $@

$(BUILD)/tests/%.o: tests/%.cpp $(HEADER) $(wildcard tests/*.hpp) | $(BUILD)/tests
	$(CXX) $(CPPFLAGS) $(CXXFLAGS) -c $< -o $@

$(BUILD)/tests/run_tests: $(BUILD)/tests/catch_main.o $(TEST_OBJ) $(IMPL_OBJ)
	$(CXX) $^ -o $@ $(LDFLAGS)

# The default scene (kDefault: mirror and glass spheres, ceiling light) by VCM.
DEMO_ARGS := -s 4 -a vcm -i 32 -r 512x512 -o $(BUILD)/demo.png
demo: deps
	$(MAKE) --no-print-directory $(BUILD)/smallvcm
	$(BUILD)/smallvcm $(DEMO_ARGS)

# Runs the Catch2 suite (tests tagged [.] are slow and run only when asked for) and
# ends with the plain line "tests: N passed, N failed" that CI reads, derived from
# Catch2's own summary of test cases.
test: deps
	$(MAKE) --no-print-directory all
	@cd tests && ../$(BUILD)/tests/run_tests $(TEST_ARGS) 2>&1 | tee ../$(BUILD)/tests/last_run.txt; \
	status=$${PIPESTATUS[0]}; \
	summary=$$(grep -E "^(All tests passed|test cases:)" ../$(BUILD)/tests/last_run.txt | tail -n 1); \
	total=$$(echo "$$summary" | sed -nE 's/.*in ([0-9]+) test cases?.*/\1/p; s/^test cases: *([0-9]+).*/\1/p' | head -n 1); \
	failed=$$(echo "$$summary" | sed -nE 's/.*\| *([0-9]+) failed.*/\1/p'); \
	[ -n "$$total" ] || total=0; [ -n "$$failed" ] || failed=0; \
	if [ "$$status" != 0 ] && [ "$$failed" = 0 ]; then failed=1; fi; \
	echo "tests: $$((total - failed)) passed, $$failed failed"; \
	exit $$status

clean:
	rm -rf $(BUILD)
