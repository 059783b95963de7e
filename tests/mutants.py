#!/usr/bin/env python3
"""Mutation testing of smallvcm's transport code: `make mutants` (docs/testing.md).

Each mutant of tests/mutant_list.py is one small edit of smallvcm.hpp, found by an exact
text match (a match must be unique, so the edit survives unrelated changes of the header;
a mutant whose text is gone is reported "not applicable", never skipped in silence). For
each mutant the script writes the edited header into a copy of the tree in a temporary
folder, rebuilds the test objects that include it and runs the Catch2 suite without the
golden-image test ([regression]) in stages of rising cost, stopping at the first failing
test (Catch2 -a). A mutant is

  killed          a test failed (or a stage crashed or timed out: CI would fail too),
  survived        every stage passed,
  equivalent      it survived and the list argues why it cannot change what a test sees
                  (the argument is printed; a listed "equivalent" that is killed counts
                  as killed and says so),
  not applicable  its text is not in the header (or not once).

Score = killed / (applicable - equivalent). The last stage, which builds and runs the
whole remaining suite with the Makefile, runs only for a mutant no earlier stage killed.

Before the mutants, the unmutated header runs through the same stages and must pass
(--no-baseline skips that): a stage that fails by itself would kill every mutant.

Usage: tests/mutants.py [--only ID,ID,...] [--list] [--check] [--jobs N] [--keep] [--no-baseline]
       (from the repository root; `make mutants` runs it with no arguments).
"""
import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ElementTree

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "tests"))
from mutant_list import MUTANTS  # noqa: E402

HEADER = "smallvcm.hpp"
CXX = os.environ.get("CXX", "g++")
# -O2 as the suite is built (the statistical stages run faster than at -O1, and a TU takes
# only ~1 s more); no debug information, which is a third of the compile time.
# Plus the machine flags (-m...) the suite's objects in build/ were compiled with
# (build/cxxflags.txt; without it the Makefile's default, -mavx2 where the CPU has AVX2):
# the BVH's layout depends on its vector width, so objects linked together must agree.
def machine_flags():
    try:
        with open(os.path.join(ROOT, "build", "cxxflags.txt")) as f:
            return [w for w in f.read().split("|")[0].split() if w.startswith("-m") or w.startswith("-ffp-contract")]
    except OSError:
        with open("/proc/cpuinfo") as f:
            return ["-mavx2"] if " avx2" in f.read() else []


CXXFLAGS = ["-std=c++17", "-O2", "-w"] + machine_flags() + ["-I."]

# Stages in order of cost: (name, test sources to add, Catch2 test spec, timeout in s,
# programs NAME the stage's tests run as ../build/NAME, built from the NAME.cpp of
# examples/, benchmarks/ or figures/ (PROGRAM_FOLDERS) with the mutated header). The
# timeouts are 10-30x what a stage takes unmutated on 2 idle cores
# (after a baseline run, at least 10x what it took then): a mutant that makes a walk
# endless is killed by the timeout, as it would be in CI.
STAGES = [
    ("mis", ["test_vcm_mis"], "[mis]", 120, []),
    ("units", ["test_sampling", "test_bsdf", "test_shading", "test_camera", "test_light_units", "test_exercises"],
     "[sampling],[bsdf],[camera],[light_units],[exercise]", 300, []),
    ("scenes", ["test_transport", "test_integrators", "test_lights", "test_environment"],
     "[transport],[integrators],[lights]", 600, []),
    ("photons+stability", ["test_photon_mapping", "test_stability"], "[photon_mapping],[stability]", 600, []),
    ("figures+convergence", ["test_figures", "test_convergence"], "[figures],[convergence]", 900, ["convergence"]),
    # Last: a scene without cut-outs runs none of their code, and no render runs the glTF
    # loader's glass rule, so only cut-out and loader mutants (and the survivors of the
    # stages above) get here.
    ("cutouts+glass", ["test_cutouts", "test_geometry", "test_gltf"], "[cutouts],[gltf][glass]", 120, []),
    # The glTF loader's default camera of an interior and its 8-bit textures: no Cornell
    # scene runs that code (each has a camera and no texture), so their mutants get here.
    ("loader", ["test_gltf"], "[interior],[textures]", 120, []),
]
# A mutant of these classes runs the stages named here first, then the others in order:
# the outcome is the same (killed by any failing stage, survived only through all), but
# the loader's mutants no longer wait for five stages that never run the loader.
FIRST_STAGES = {"textures": ("loader", "cutouts+glass"), "camera": ("loader",),
                "cutouts": ("cutouts+glass",), "glass": ("cutouts+glass",)}


def stage_order(mutant, stage_count):
    stages = STAGES[:stage_count]
    first = FIRST_STAGES.get(mutant["class"], ()) if mutant is not None else ()
    return [s for s in stages if s[0] in first] + [s for s in stages if s[0] not in first]


# The rest of the suite (every other test file; built with the Makefile, with the
# programs its tests run: build/smallvcm for the command line, build/bench, build/minimal):
# everything except the golden images and what the stages above already ran.
REST_TARGETS = ["build/tests/run_tests", "build/smallvcm", "build/bench", "build/minimal"]
REST_SPEC = "~[regression]~[sampling]~[bsdf]~[camera]~[mis]~[light_units]~[lights]~[exercise]~[transport]" \
            "~[integrators]~[photon_mapping]~[stability]~[figures]~[convergence]~[cutouts]~[glass]~[interior]~[textures]"
REST_TIMEOUT = 900
REST_BUILD_TIMEOUT = 5400


def log(message):
    print(message, flush=True)


def find_unique(text, needle):
    """The offset of needle in text, or None unless it occurs exactly once."""
    first = text.find(needle)
    if first < 0 or text.find(needle, first + 1) >= 0:
        return None
    return first


def applicability(header, mutant):
    count = header.count(mutant["find"])
    if count == 0:
        return "text not found"
    if count > 1:
        return "text found %d times (must be unique)" % count
    if mutant["replace"] == mutant["find"]:
        return "replacement equals the original"
    return None


def mutated_header(header, mutant):
    offset = find_unique(header, mutant["find"])
    return header[:offset] + mutant["replace"] + header[offset + len(mutant["find"]):]


def line_of(header, mutant):
    return header[:find_unique(header, mutant["find"])].count("\n") + 1


def run(command, cwd, timeout):
    """(exit code or 'timeout', combined output)."""
    try:
        done = subprocess.run(command, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                              timeout=timeout, text=True, errors="replace")
        return done.returncode, done.stdout
    except subprocess.TimeoutExpired as expired:
        out = expired.stdout.decode(errors="replace") if isinstance(expired.stdout, bytes) else (expired.stdout or "")
        return "timeout", out


def compile_objects(tree, sources, objdir, jobs):
    """Compiles tests/NAME.cpp for each NAME into objdir, jobs at a time. None or the error."""
    # (An object already in objdir is this mutant's, from an earlier stage.)
    pending = [s for s in sources if os.path.exists(os.path.join(tree, "tests", s + ".cpp"))
               and not os.path.exists(os.path.join(objdir, s + ".o"))]
    running = []
    while pending or running:
        while pending and len(running) < jobs:
            name = pending.pop(0)
            command = [CXX] + CXXFLAGS + ["-c", "tests/%s.cpp" % name, "-o", os.path.join(objdir, name + ".o")]
            running.append((name, subprocess.Popen(command, cwd=tree, stdout=subprocess.PIPE,
                                                   stderr=subprocess.STDOUT, text=True, errors="replace")))
        name, process = running.pop(0)
        out, _ = process.communicate()
        if process.returncode != 0:
            for _, other in running:
                other.wait()
            return "%s.cpp does not compile:\n%s" % (name, out[-2000:])
    return None


def failed_tests(junit_path, output):
    """Names of the failing test cases in a Catch2 JUnit report (or a hint from the output)."""
    names = []
    try:
        for case in ElementTree.parse(junit_path).getroot().iter("testcase"):
            if case.find("failure") is not None or case.find("error") is not None:
                name = case.get("name", "?")
                if name not in names:
                    names.append(name)
    except (ElementTree.ParseError, OSError):
        pass
    if not names:
        signal = re.search(r"(SIGSEGV|SIGABRT|SIGFPE|Segmentation|terminate called|Aborted)", output)
        names.append("(no report: %s)" % (signal.group(1) if signal else "the run ended abnormally"))
    return names


def prepare_tree(workdir):
    """A copy of the files the tests need (no build/, no .git, no docs/figures). The
    ignore patterns apply below the top level: the program folder figures/ is copied."""
    tree = os.path.join(workdir, "tree")
    ignore = shutil.ignore_patterns(".git", "build", "figures", "performance", "*.png", "*.pfm", "*.exr")
    os.makedirs(tree)
    for entry in os.listdir(ROOT):
        source = os.path.join(ROOT, entry)
        if entry in (".git", "build"):
            continue
        if os.path.isdir(source):
            shutil.copytree(source, os.path.join(tree, entry), ignore=ignore, symlinks=True)
        else:
            shutil.copy2(source, os.path.join(tree, entry))
    return tree


def shared_objects(tree, jobs):
    """catch_main.o and the implementation unit, compiled once from the unmutated header
    (or copied from build/ when the suite's are current)."""
    objdir = os.path.join(tree, "shared-obj")
    os.makedirs(objdir, exist_ok=True)
    commands = [
        [CXX] + CXXFLAGS + ["-c", "tests/catch_main.cpp", "-o", os.path.join(objdir, "catch_main.o")],
        [CXX] + CXXFLAGS + ["-c", "examples/smallvcm_impl.cpp", "-o", os.path.join(objdir, "smallvcm_impl.o")],
    ]
    reuse = os.path.join(ROOT, "build", "tests", "catch_main.o")
    if os.path.exists(reuse):  # Catch2's main does not include the header: reuse the suite's
        shutil.copy2(reuse, os.path.join(objdir, "catch_main.o"))
        commands = [c for c in commands if "tests/catch_main.cpp" not in c]
    # The suite's implementation unit, if it is newer than the header and its source.
    impl = os.path.join(ROOT, "build", "smallvcm_impl.o")
    if os.path.exists(impl) and all(os.path.getmtime(impl) > os.path.getmtime(os.path.join(ROOT, f))
                                    for f in (HEADER, "examples/smallvcm_impl.cpp", "build/cxxflags.txt")):
        shutil.copy2(impl, os.path.join(objdir, "smallvcm_impl.o"))
        commands = [c for c in commands if "examples/smallvcm_impl.cpp" not in c]
    # With line tables (-g1), for implementation_lines: a copy of the unit not linked.
    commands.append([CXX] + CXXFLAGS + ["-g1", "-c", "examples/smallvcm_impl.cpp", "-o", os.path.join(objdir, "impl_lines.o")])
    processes = [subprocess.Popen(c, cwd=tree, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
                 for c in commands]
    for p in processes:
        out, _ = p.communicate()
        if p.returncode != 0:
            sys.exit("mutants: the unmutated tree does not build:\n" + out[-3000:])
    return objdir


def implementation_lines(shared):
    """The header's lines that have code in the implementation unit: the loader's own and
    every inline function it calls and the compiler inlined there (UvTransform::Make,
    the tangent frames, the glass rule...), read from the unit's DWARF line table. A mutant
    on such a line must rebuild the unit, or the loader would keep the unmutated copy."""
    code, out = run(["objdump", "--dwarf=decodedline", os.path.join(shared, "impl_lines.o")], shared, 300)
    if code != 0:
        sys.exit("mutants: objdump cannot read the implementation unit's line table:\n" + out[-1000:])
    lines = set()
    for row in out.splitlines():
        fields = row.split()
        if len(fields) >= 2 and fields[0] == HEADER and fields[1].isdigit():
            lines.add(int(fields[1]))
    if not lines:
        sys.exit("mutants: the implementation unit's line table names no line of " + HEADER)
    return lines


# The line table names the line an instruction came from, and an optimized unit often
# gives a declaration's arithmetic to the lines that use it (M89's `up = -dPdv / vLength`
# is on no line of the table; the two after it are): a mutant within this many lines of
# code in the unit counts as reaching it.
IMPL_LINE_WINDOW = 5


def needs_implementation_unit(header, mutant, impl_lines):
    """Whether the mutant's lines reach the implementation unit: listed so (impl=True), or
    one of its lines, or one within IMPL_LINE_WINDOW of them, has code there."""
    first = line_of(header, mutant)
    last = first + mutant["find"].count("\n")
    return bool(mutant.get("impl")) or any(
        line in impl_lines for line in range(first - IMPL_LINE_WINDOW, last + IMPL_LINE_WINDOW + 1))


IMPL_LINES = set()  # implementation_lines of the unmutated header, filled by main

# The folders whose NAME.cpp is a program build/NAME, as in the Makefile.
PROGRAM_FOLDERS = ("examples", "benchmarks", "figures")


def program_source(tree, name):
    """The source of program NAME in the tree: the first FOLDER/NAME.cpp that exists."""
    for folder in PROGRAM_FOLDERS:
        if os.path.exists(os.path.join(tree, folder, name + ".cpp")):
            return "%s/%s.cpp" % (folder, name)
    return "examples/%s.cpp" % name  # the compiler's error names it


def build_programs(tree, programs, objdir, impl):
    """Builds NAME.cpp (examples/, benchmarks/ or figures/) into the tree's build/NAME for
    each NAME. None or the error."""
    os.makedirs(os.path.join(tree, "build"), exist_ok=True)
    for name in programs:
        obj = os.path.join(objdir, name + ".prog.o")
        source = program_source(tree, name)
        code, out = run([CXX] + CXXFLAGS + ["-c", source, "-o", obj], tree, 600)
        if code != 0:
            return "%s does not compile: %s" % (source, out[-500:])
        code, out = run([CXX, obj, impl, "-o", os.path.join(tree, "build", name), "-pthread", "-ltinyexr", "-ldraco", "-lmeshoptimizer"], tree, 300)
        if code != 0:
            return "build/%s does not link: %s" % (name, out[-500:])
    return None


def test_mutant(tree, shared, mutant, header, jobs, stage_count, timeouts=None, times=None):
    """('killed' | 'survived' | 'broken', stage, details). mutant None: the header as it is
    (the baseline run, which must survive). timeouts: a test run's limit per stage name
    (default: the STAGES' own); times: filled with each stage's test run time."""
    timeouts = timeouts or {}
    with open(os.path.join(tree, HEADER), "w") as f:
        f.write(header if mutant is None else mutated_header(header, mutant))
    objdir = os.path.join(tree, "mutant-obj")
    shutil.rmtree(objdir, ignore_errors=True)
    for stage in STAGES:  # the previous mutant's programs
        for program in stage[4]:
            if os.path.exists(os.path.join(tree, "build", program)):
                os.remove(os.path.join(tree, "build", program))
    os.makedirs(objdir)
    impl = os.path.join(shared, "smallvcm_impl.o")
    if mutant is not None and needs_implementation_unit(header, mutant, IMPL_LINES):
        # The mutated line is compiled into the implementation unit too (Scene::Finalize is
        # emitted there and may be inlined into the loader): rebuild it for this mutant.
        impl = os.path.join(objdir, "smallvcm_impl.o")
        code, out = run([CXX] + CXXFLAGS + ["-c", "examples/smallvcm_impl.cpp", "-o", impl], tree, 600)
        if code != 0:
            return "broken", "build", "the implementation unit does not compile: " + out[-500:]
    objects = []
    for name, sources, spec, timeout, programs in stage_order(mutant, stage_count):
        error = compile_objects(tree, sources, objdir, jobs) or build_programs(tree, programs, objdir, impl)
        if error:
            return "broken", name, error.splitlines()[0]
        # (A test file of an earlier stage is linked once: twice, Catch2 would find every
        # test case defined twice and stop before running any.)
        objects += [o for o in (os.path.join(objdir, s + ".o") for s in sources) if os.path.exists(o) and o not in objects]
        binary = os.path.join(objdir, "run_tests")
        # The mutated objects come first: where an inline function of the header is also
        # emitted in the (unmutated) implementation unit, the linker keeps the first copy.
        code, out = run([CXX] + objects + [os.path.join(shared, "catch_main.o"), impl, "-o", binary, "-pthread", "-ltinyexr", "-ldraco", "-lmeshoptimizer"], tree, 300)
        if code != 0:
            return "broken", name, "link failed: " + out[-500:]
        junit = os.path.join(objdir, "report.xml")
        timeout = timeouts.get(name, timeout)
        started = time.time()
        code, out = run([binary, spec, "-a", "-r", "junit", "-o", junit], os.path.join(tree, "tests"), timeout)
        if times is not None:
            times[name] = time.time() - started
        if code == "timeout":
            return "killed", name, "timed out after %d s" % timeout
        if code != 0:
            return "killed", name, "; ".join(failed_tests(junit, out))
    if stage_count <= len(STAGES):
        return "survived", "(%d stages only)" % stage_count, ""
    # The rest of the suite, with the Makefile.
    # A build cannot loop, so its limit only guards against a hung machine: on 2 cores
    # shared by a dozen jobs the whole suite took more than 20 minutes to compile.
    code, out = run(["make", "-j%d" % jobs, "--no-print-directory"] + REST_TARGETS +
                    ["CXXFLAGS=" + " ".join(CXXFLAGS[:-1])], tree, REST_BUILD_TIMEOUT)
    if code == "timeout":
        return "broken", "rest", "the build took more than %d s" % REST_BUILD_TIMEOUT
    if code != 0:
        return "broken", "rest", "make failed: " + out[-500:]
    junit = os.path.join(tree, "build", "report.xml")
    rest_timeout = timeouts.get("rest", REST_TIMEOUT)
    started = time.time()
    code, out = run(["../build/tests/run_tests", REST_SPEC, "-a", "-r", "junit", "-o", junit],
                    os.path.join(tree, "tests"), rest_timeout)
    if times is not None:
        times["rest"] = time.time() - started
    if code == "timeout":
        return "killed", "rest", "timed out after %d s" % rest_timeout
    if code != 0:
        return "killed", "rest", "; ".join(failed_tests(junit, out))
    return "survived", "", ""


def main():
    parser = argparse.ArgumentParser(description="Mutation testing of smallvcm's transport code.")
    parser.add_argument("--only", help="comma-separated mutant ids (default: all)")
    parser.add_argument("--list", action="store_true", help="list the mutants and whether each applies, then stop")
    parser.add_argument("--check", action="store_true", help="like --list, exit 1 if any does not apply")
    parser.add_argument("--jobs", type=int, default=2, help="parallel compilations (default 2)")
    parser.add_argument("--stages", type=int, default=len(STAGES) + 1,
                        help="run only the first N stages (a quick survey; survivors then are 'survived (N stages)')")
    parser.add_argument("--keep", action="store_true", help="keep the temporary tree (its path is printed)")
    parser.add_argument("--no-baseline", action="store_true",
                        help="skip the first run, of the unmutated header through the same stages (it must pass, "
                             "or every mutant would count as killed)")
    parser.add_argument("--report", default=os.path.join(ROOT, "build", "mutants", "report.txt"),
                        help="where the report is written (default build/mutants/report.txt)")
    args = parser.parse_args()

    with open(os.path.join(ROOT, HEADER)) as f:
        header = f.read()
    ids = [m["id"] for m in MUTANTS]
    if len(set(ids)) != len(ids):
        sys.exit("mutants: duplicate ids in tests/mutant_list.py")
    selected = MUTANTS
    if args.only:
        wanted = args.only.split(",")
        unknown = [w for w in wanted if w not in ids]
        if unknown:
            sys.exit("mutants: --only: unknown id(s) " + ", ".join(unknown))
        selected = [m for m in MUTANTS if m["id"] in wanted]

    if args.list or args.check:
        bad = 0
        for m in selected:
            why = applicability(header, m)
            bad += why is not None
            where = "line %d" % line_of(header, m) if why is None else "NOT APPLICABLE: " + why
            log("%-4s %-12s %-10s %s%s" % (m["id"], m["class"], where, m["what"],
                                          "  [listed equivalent]" if m.get("equivalent") else ""))
        log("%d mutants, %d applicable" % (len(selected), len(selected) - bad))
        return 1 if (args.check and bad) else 0

    workdir = tempfile.mkdtemp(prefix="smallvcm-mutants-")
    log("mutants: %d mutants; temporary tree in %s" % (len(selected), workdir))
    start = time.time()
    tree = prepare_tree(workdir)
    shared = shared_objects(tree, args.jobs)
    IMPL_LINES.update(implementation_lines(shared))
    results = []
    os.makedirs(os.path.dirname(args.report), exist_ok=True)
    report = open(args.report, "w")

    def emit(line):
        log(line)
        report.write(line + "\n")
        report.flush()

    emit("# make mutants: %s, header %s" % (time.strftime("%Y-%m-%d %H:%M"), HEADER))
    timeouts = {name: limit for name, _, _, limit, _ in STAGES}
    timeouts["rest"] = REST_TIMEOUT
    baseline_times = {}
    try:
        if not args.no_baseline:
            # The unmutated header through the same stages: a stage that fails without any
            # mutant (a program its tests need is missing, a flaky bound) would kill every
            # mutant that reaches it, and the score would mean nothing.
            t0 = time.time()
            outcome, stage, details = test_mutant(tree, shared, None, header, args.jobs, args.stages, times=baseline_times)
            emit("base %-14s %-12s %-20s %5.0f s  the unmutated header%s" % (
                "passed" if outcome == "survived" else "FAILED", "", stage, time.time() - t0,
                "" if outcome == "survived" else " -- " + details))
            if outcome != "survived":
                emit("mutants: stopped: the unmutated header fails stage %s, so no mutant's outcome would mean "
                     "anything" % stage)
                return 1
            # On a loaded machine a stage takes several times its idle time: a mutant's limit
            # is at least 10 times what the unmutated header took here and now.
            for name, seconds in baseline_times.items():
                timeouts[name] = max(timeouts.get(name, 0), 10 * seconds)
        for m in selected:
            why = applicability(header, m)
            t0 = time.time()
            if why:
                outcome, stage, details = "not applicable", "", why
            else:
                outcome, stage, details = test_mutant(tree, shared, m, header, args.jobs, args.stages, timeouts)
                if outcome == "survived" and m.get("equivalent"):
                    outcome, details = "equivalent", m["equivalent"]
                elif outcome == "killed" and m.get("equivalent"):
                    details += " (listed as equivalent: the argument is wrong)"
            results.append((m, outcome))
            emit("%-4s %-14s %-12s %-20s %5.0f s  %s -- %s" % (
                m["id"], outcome, m["class"], stage, time.time() - t0, m["what"], details))
    finally:
        with open(os.path.join(tree, HEADER), "w") as f:
            f.write(header)
        if not args.keep:
            shutil.rmtree(workdir, ignore_errors=True)

    count = {k: sum(1 for _, o in results if o == k) for k in ("killed", "survived", "equivalent", "not applicable", "broken")}
    applicable = len(results) - count["not applicable"]
    scored = applicable - count["equivalent"] - count["broken"]
    score = 100.0 * count["killed"] / scored if scored else 0.0
    emit("mutants: %d killed, %d survived, %d equivalent, %d not applicable, %d do not build; "
         "score %d/%d = %.1f %% (%.0f s)" % (count["killed"], count["survived"], count["equivalent"],
                                              count["not applicable"], count["broken"], count["killed"], scored,
                                              score, time.time() - start))
    report.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
