#!/usr/bin/env python3
"""The coursework kit: exercises cut from smallvcm.hpp, graded by the test suite.

    kit.py list                          the exercises, their handouts and regions
    kit.py check [HEADER]                markers pair up, every region has a stub
    kit.py cut NAME[,NAME...]|all [--header H] [--out DIR]
                                         write DIR/smallvcm.hpp (default build/exercise/NAME/)
    kit.py grade STUDENT [--exercise NAME[,NAME...]] [--json FILE] [--reuse-impl]
                                         build the graders against STUDENT and run them
    kit.py compare STUDENT -- SMALLVCM ARGS
                                         render with the student's copy and the reference,
                                         side by side in build/compare/compare.png
    kit.py figures STUDENT [--quick] [--only PROGRAM,...]
                                         the course figures (figures/fig_*) built with the
                                         student's copy, measured against the reference's
                                         reference images, with their gallery
    kit.py prove                         the kit's own test (make test runs it)

The header marks each exercise's code with comment lines

    // BEGIN EXERCISE <name>[/<part>]
    ...
    // END EXERCISE <name>[/<part>]

(no nesting; an exercise may have several parts). tests/exercises/stubs/<name>.inc holds,
after a line "// STUB <name>[/<part>]", the code that replaces each region in the student
copy: it compiles, runs and returns an obviously wrong but safe value, with a TODO naming
the handout. The markers stay in the student copy, so a cut copy can be cut again.
Graders are the Catch2 test cases tagged [ex:<name>] (tests/test_exercises.cpp and
tests/test_vcm_mis.cpp); docs/exercises/README.md is the instructors' page.
Python 3 standard library only. Run from anywhere; paths are relative to the repository.
"""
import hashlib
import json
import os
import re
import shutil
import struct
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
import zlib

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
STUB_DIR = os.path.join(ROOT, "tests", "exercises", "stubs")
HEADER = os.path.join(ROOT, "smallvcm.hpp")
BUILD = os.path.join(ROOT, "build")

# number, name, title, handout, exercises whose graders may fail while this one is cut
# (because this exercise's code is their foundation).
EXERCISES = [
    ("01", "cosine_hemisphere", "Cosine-weighted hemisphere sampling and its pdf", "01-cosine-hemisphere.md", []),
    ("02", "pt_nee_mis", "Next-event estimation with MIS in the path tracer", "02-pt-nee-mis.md", []),
    ("03", "phong_bsdf", "The Phong BSDF: sample, evaluate, pdf", "03-phong-bsdf.md", []),
    ("04", "lt_camera", "Light tracing: connecting a light vertex to the camera", "04-lt-camera.md", []),
    ("05", "ppm_merging", "Progressive photon mapping: the merging kernel and the radius schedule",
     "05-ppm-merging.md", []),
    ("06", "bpt_mis", "BPT MIS: the recursive quantities dVCM and dVC, and the weights", "06-bpt-mis.md",
     ["vcm_mis"]),
    ("07", "vcm_mis", "VCM: merging in the same MIS (eta_VCM, dVM, the merge weight)", "07-vcm-mis.md", []),
]
NAMES = [e[1] for e in EXERCISES]
# Not an exercise: the test tagged [ex:safety] renders every algorithm on every Cornell
# scene and fails on NaN, infinite or negative pixels; every grading run includes it.
SAFETY = "safety"
BY_NAME = {e[1]: e for e in EXERCISES}

# The graders: test files compiled against a student copy (tags [ex:<name>] inside).
GRADE_SOURCES = ["tests/test_exercises.cpp", "tests/test_vcm_mis.cpp"]
CXX = os.environ.get("CXX", "g++")
# The graders compile at -O1 without debug information: half the compile time of the
# suite's -O2 -g (measured: 7 s instead of 13 s of CPU per cut for the two grader files),
# and they still run in well under a second.
CXXFLAGS = os.environ.get("GRADE_CXXFLAGS", "-std=c++17 -O1 -Wall -Wextra -Wpedantic -Wshadow").split()
# What renders (make compare, make student-figures) compile with: the Makefile's flags.
RENDER_CXXFLAGS = ["-std=c++17", "-O2", "-Wall", "-Wextra", "-Wpedantic", "-Wshadow"]

MARKER = re.compile(r"^(\s*)// (BEGIN|END) EXERCISE ([a-z0-9_]+)(?:/([a-z0-9_]+))?\s*$")
LOOSE_MARKER = re.compile(r"//.*\b(BEGIN|END)\s+EXERCISE\b")
STUB_LINE = re.compile(r"^// STUB ([a-z0-9_]+(?:/[a-z0-9_]+)?)\s*$")


class KitError(Exception):
    """A problem with input: printed as one line, exit status 2 (1 for marker errors)."""

    def __init__(self, message, status=2):
        super().__init__(message)
        self.status = status


def rel(path):
    path = os.path.abspath(path)
    return os.path.relpath(path, ROOT) if path.startswith(ROOT + os.sep) else path


def known_list():
    return ", ".join(f"{e[0]} {e[1]}" for e in EXERCISES) + ", all"


# ---------------------------------------------------------------------------------------
# Markers and stubs
# ---------------------------------------------------------------------------------------

class Region:
    def __init__(self, name, part, begin, end, indent):
        self.name, self.part, self.begin, self.end, self.indent = name, part, begin, end, indent

    @property
    def id(self):
        return self.name + ("/" + self.part if self.part else "")


def parse_regions(lines, label):
    """The marked regions of a header given as lines; KitError (status 1) naming the line
    of the first problem: a malformed, unpaired, nested or duplicated marker, or an
    unknown exercise."""
    regions, open_region, seen = [], None, {}
    for number, line in enumerate(lines, 1):
        match = MARKER.match(line)
        if not match:
            if LOOSE_MARKER.search(line):
                raise KitError(f"{label}:{number}: malformed exercise marker '{line.strip()}' "
                               "(expected '// BEGIN EXERCISE name' or '// END EXERCISE name[/part]' alone on its line)", 1)
            continue
        indent, kind, name, part = match.group(1), match.group(2), match.group(3), match.group(4)
        region_id = name + ("/" + part if part else "")
        if name not in BY_NAME:
            raise KitError(f"{label}:{number}: unknown exercise '{name}' in a marker; known: {known_list()}", 1)
        if kind == "BEGIN":
            if open_region:
                raise KitError(f"{label}:{number}: BEGIN EXERCISE {region_id} inside {open_region.id} "
                               f"opened at line {open_region.begin} (regions do not nest)", 1)
            if region_id in seen:
                raise KitError(f"{label}:{number}: region {region_id} is marked twice (first at line {seen[region_id]})", 1)
            seen[region_id] = number
            open_region = Region(name, part, number, None, indent)
        else:
            if not open_region:
                raise KitError(f"{label}:{number}: END EXERCISE {region_id} without a BEGIN", 1)
            if open_region.id != region_id:
                raise KitError(f"{label}:{number}: END EXERCISE {region_id} closes BEGIN EXERCISE {open_region.id} "
                               f"of line {open_region.begin}", 1)
            open_region.end = number
            regions.append(open_region)
            open_region = None
    if open_region:
        raise KitError(f"{label}:{open_region.begin}: BEGIN EXERCISE {open_region.id} is never closed", 1)
    return regions


def load_stubs(name):
    """Stub parts of one exercise: {region id: [lines]} from stubs/<name>.inc."""
    path = os.path.join(STUB_DIR, name + ".inc")
    if not os.path.isfile(path):
        raise KitError(f"{rel(path)}: missing: every exercise needs its stubs", 1)
    stubs, current = {}, None
    with open(path, encoding="utf-8") as f:
        for number, line in enumerate(f.read().split("\n"), 1):
            match = STUB_LINE.match(line)
            if match:
                current = match.group(1)
                if current.split("/")[0] != name:
                    raise KitError(f"{rel(path)}:{number}: stub {current} belongs to another exercise", 1)
                if current in stubs:
                    raise KitError(f"{rel(path)}:{number}: stub {current} given twice", 1)
                stubs[current] = []
            elif current:
                stubs[current].append(line)
    for part in stubs.values():
        while part and not part[-1].strip():
            part.pop()
    return stubs


def check_header(lines, label):
    """Regions of the header, checked against the stubs: every exercise has regions and
    every region has a stub and every stub a region."""
    regions = parse_regions(lines, label)
    for name in NAMES:
        ids = [r.id for r in regions if r.name == name]
        stubs = load_stubs(name)
        if not ids:
            raise KitError(f"{label}: exercise {name} has no marked region", 1)
        for region_id in ids:
            if region_id not in stubs:
                raise KitError(f"{label}: region {region_id} has no stub in tests/exercises/stubs/{name}.inc", 1)
        for stub_id in stubs:
            if stub_id not in ids:
                raise KitError(f"tests/exercises/stubs/{name}.inc: stub {stub_id} has no region in {label}", 1)
    return regions


def parse_names(text):
    if text in (None, ""):
        raise KitError(f"make exercise: say which exercise, NAME=<name>; known: {known_list()}")
    names = []
    for name in text.split(","):
        name = name.strip()
        if name == "all":
            names.extend(NAMES)
        elif name in BY_NAME:
            names.append(name)
        else:
            by_number = [e[1] for e in EXERCISES if e[0] == name or e[0].lstrip("0") == name]
            if not by_number:
                raise KitError(f"make exercise: unknown exercise '{name}'; known: {known_list()}")
            names.extend(by_number)
    return list(dict.fromkeys(names))


def cut_lines(lines, label, names):
    """The header with the regions of the named exercises replaced by their stubs."""
    regions = check_header(lines, label)
    out, cursor = [], 0
    for region in regions:
        if region.name not in names:
            continue
        out.extend(lines[cursor:region.begin])  # up to and including the BEGIN line
        for stub_line in load_stubs(region.name)[region.id]:
            out.append(region.indent + stub_line if stub_line.strip() else "")
        cursor = region.end - 1  # the END line stays
    out.extend(lines[cursor:])
    return out


def write_atomically(path, text):
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    handle, temporary = tempfile.mkstemp(dir=folder, prefix=".smallvcm.", suffix=".tmp")
    with os.fdopen(handle, "w", encoding="utf-8") as f:
        f.write(text)
    os.replace(temporary, path)


def read_lines(path):
    try:
        with open(path, encoding="utf-8") as f:
            return f.read().split("\n")
    except OSError as e:
        raise KitError(f"{rel(path)}: cannot read: {e.strerror}")


# ---------------------------------------------------------------------------------------
# Commands: list, check, cut
# ---------------------------------------------------------------------------------------

def command_list():
    regions = check_header(read_lines(HEADER), "smallvcm.hpp")
    for number, name, title, handout, _ in EXERCISES:
        parts = [r for r in regions if r.name == name]
        print(f"{number} {name:18s} {title}")
        print(f"   handout docs/exercises/{handout}; regions: " +
              ", ".join(f"{r.id} (lines {r.begin}-{r.end})" for r in parts))


def command_check(header):
    regions = check_header(read_lines(header), rel(header))
    print(f"{rel(header)}: {len(regions)} regions of {len(NAMES)} exercises, markers paired, every region has a stub")


def command_cut(names_text, header, out):
    names = parse_names(names_text)
    label = "all" if names == NAMES else ",".join(names)
    out = out or os.path.join(BUILD, "exercise", label)
    target = os.path.join(out, "smallvcm.hpp")
    if os.path.abspath(target) == os.path.abspath(header):
        raise KitError(f"make exercise: OUT={rel(out)} would overwrite the reference header")
    lines = cut_lines(read_lines(header), rel(header), names)
    write_atomically(target, "\n".join(lines))
    for name in names:
        number, _, title, handout, _ = BY_NAME[name]
        print(f"exercise {number} {name}: {title}; handout docs/exercises/{handout}")
    print(f"wrote {rel(target)}; grade it with: make grade STUDENT={rel(target)}")


# ---------------------------------------------------------------------------------------
# Grading
# ---------------------------------------------------------------------------------------

def resolve_student(student):
    if not student:
        raise KitError("make grade: say which copy to grade: make grade STUDENT=path/to/smallvcm.hpp "
                       "(make exercise NAME=<name> cuts one into build/exercise/<name>/)")
    path = os.path.abspath(student)
    if os.path.isdir(path):
        candidate = os.path.join(path, "smallvcm.hpp")
        if not os.path.isfile(candidate):
            raise KitError(f"make grade: {rel(path)} holds no smallvcm.hpp: cut a student copy into it with "
                           f"make exercise NAME=<name> OUT={rel(path)}, or pass STUDENT=path/to/smallvcm.hpp")
        path = candidate
    if not os.path.isfile(path):
        raise KitError(f"make grade: STUDENT={student}: no such file; cut a student copy with "
                       "make exercise NAME=<name> (it writes build/exercise/<name>/smallvcm.hpp)")
    if os.path.abspath(path) == HEADER:
        print("grade: STUDENT is the reference header itself; grading it", file=sys.stderr)
    return path


def newer(target, sources):
    if not os.path.exists(target):
        return False
    t = os.path.getmtime(target)
    return all(os.path.getmtime(s) <= t for s in sources)


def run_jobs(jobs, parallel):
    """Runs (command, log) pairs, `parallel` at a time; returns the failed ones."""
    failed, running, queue = [], [], list(jobs)
    while queue or running:
        while queue and len(running) < parallel:
            command, log = queue.pop(0)
            running.append((subprocess.Popen(command, cwd=ROOT, stdout=open(log, "w"), stderr=subprocess.STDOUT),
                            command, log))
        time.sleep(0.05)
        for item in list(running):
            if item[0].poll() is not None:
                running.remove(item)
                if item[0].returncode != 0:
                    failed.append((item[1], item[2]))
    return failed


# The machine flags (-m...) the reference objects were compiled with (build/cxxflags.txt,
# which make keeps current): the BVH's layout depends on its vector width (-mavx2 gives the
# 8-wide tree, the Makefile's default on CPUs with AVX2), so the graders, compiled with
# their own CXXFLAGS, take these too before they are linked with the reference objects.
def reference_machine_flags():
    try:
        with open(os.path.join(BUILD, "cxxflags.txt")) as f:
            return [w for w in f.read().split("|")[0].split() if w.startswith("-m") or w.startswith("-ffp-contract")]
    except OSError:
        return []


def ensure_reference_objects(need_impl):
    targets = ["build/tests/catch_main.o"] + (["build/smallvcm_impl.o"] if need_impl else [])
    code = subprocess.call(["make", "--no-print-directory", "-s"] + targets, cwd=ROOT)
    if code != 0:
        raise KitError("make grade: could not build " + " ".join(targets))


# Classes and functions that hold exercise regions: the reference implementation unit may
# be linked with a student's graders only if it defines none of them (no inline function
# of the cut code then has two definitions to choose from).
EXERCISE_SYMBOLS = re.compile(r"smallvcm::(SampleCosHemisphereW|CosHemispherePdfW|SamplePowerCosHemisphereW|"
                              r"PowerCosHemispherePdfW|Bsdf::|PathTracer::|VertexCM::|VcmMis::|VcmMisConstants::)")


def reference_impl_is_safe():
    nm = subprocess.run(["nm", "-C", "--defined-only", os.path.join(BUILD, "smallvcm_impl.o")],
                        capture_output=True, text=True)
    return nm.returncode == 0 and not EXERCISE_SYMBOLS.search(nm.stdout)


def build_grader(student, work, reuse_impl, parallel=2):
    """Compiles the graders against the student copy in `work`; returns (binary, None) or
    (None, compiler messages)."""
    include = os.path.join(work, "include")
    os.makedirs(include, exist_ok=True)
    copy = os.path.join(include, "smallvcm.hpp")
    with open(student, "rb") as f:
        content = f.read()
    if not os.path.exists(copy) or open(copy, "rb").read() != content:
        with open(copy, "wb") as f:
            f.write(content)
    impl_reused = reuse_impl and reference_impl_is_safe()
    ensure_reference_objects(impl_reused)
    flags = CXXFLAGS + reference_machine_flags() + ["-I" + include, "-I" + ROOT]
    # Objects made with other flags are not reused.
    stamp = os.path.join(work, "flags.txt")
    if not os.path.exists(stamp) or open(stamp).read() != " ".join(flags):
        for name in os.listdir(work):
            if name.endswith(".o"):
                os.remove(os.path.join(work, name))
        with open(stamp, "w") as f:
            f.write(" ".join(flags))
    helpers = [os.path.join(ROOT, "tests", h) for h in os.listdir(os.path.join(ROOT, "tests")) if h.endswith(".hpp")]
    objects, jobs = [], []
    sources = list(GRADE_SOURCES) + ([] if impl_reused else ["examples/smallvcm_impl.cpp"])
    for source in sources:
        obj = os.path.join(work, os.path.basename(source).replace(".cpp", ".o"))
        objects.append(obj)
        if not newer(obj, [copy, os.path.join(ROOT, source)] + helpers):
            jobs.append(([CXX] + flags + ["-c", source, "-o", obj], obj + ".log"))
    if impl_reused:
        objects.append(os.path.join(BUILD, "smallvcm_impl.o"))
    failed = run_jobs(jobs, parallel)
    if failed:
        messages = []
        for _, log in failed:
            with open(log) as f:
                messages.append(f.read())
        return None, "\n".join(messages)
    binary = os.path.join(work, "grade_tests")
    link = [CXX] + objects + [os.path.join(BUILD, "tests", "catch_main.o"), "-o", binary, "-pthread", "-ltinyexr", "-ldraco", "-lmeshoptimizer"]
    result = subprocess.run(link, cwd=ROOT, capture_output=True, text=True)
    if result.returncode != 0:
        return None, result.stdout + result.stderr
    return binary, None


def run_graders(binary, names, log):
    """Runs the tests tagged for each named exercise, one process per exercise (a crash in
    one cannot hide another's result); {name: (passed, total, [diagnoses])}. `log` names
    the XML logs: <log>.<name>.xml."""
    return {name: run_one_grader(binary, name, f"{log}.{name}.xml") for name in names}


def run_one_grader(binary, name, log):
    with open(log, "w") as out:
        code = subprocess.call([binary, f"[ex:{name}]", "-r", "xml", "--order", "decl"], cwd=os.path.join(ROOT, "tests"),
                               stdout=out, stderr=subprocess.STDOUT)
    with open(log, encoding="utf-8", errors="replace") as f:
        text = f.read()
    passed, total, diagnoses = 0, 0, []
    for case in re.findall(r"<TestCase [^>]*>.*?</TestCase>", text, re.S):
        try:
            node = ET.fromstring(case)
        except ET.ParseError:
            continue
        total += 1
        overall = node.find("OverallResult")
        if overall is not None and overall.get("success") == "true":
            passed += 1
            continue
        found = [" ".join((f.text or "").split()) for f in node.iter("Failure")]
        found += [f"it crashed ({' '.join((f.text or '').split())}) in '{node.get('name', '')}'"
                  for f in node.iter("FatalErrorCondition")]
        found += ["an exception: " + " ".join((f.text or "").split()) for f in node.iter("Exception")]
        if not found:
            found = ["a failed check at " + os.path.basename(e.get("filename", "")) + ":" + e.get("line", "")
                     for e in node.iter("Expression") if e.get("success") == "false"]
        diagnoses.extend(found or ["test case '" + node.get("name", "") + "' failed"])
    # A crash Catch2 could not report ends the XML inside the case it was in.
    opened = re.findall(r'<TestCase name="([^"]*)"', text)
    if code != 0 and len(opened) > total:
        total += 1
        diagnoses.append(f"the test '{opened[total - 1]}' crashed (exit status {code}); see {rel(log)}")
    if total == 0:
        diagnoses.append(f"no grader ran (exit status {code}); see {rel(log)}")
    return passed, max(total, 1), diagnoses


def grade(student, names, reuse_impl=False, quiet=False, work=None, parallel=2):
    key = hashlib.sha1(os.path.abspath(student).encode()).hexdigest()[:10]
    work = work or os.path.join(BUILD, "grade", key)
    os.makedirs(work, exist_ok=True)
    start = time.time()
    binary, errors = build_grader(student, work, reuse_impl, parallel)
    if not binary:
        if not quiet:
            copy = os.path.join(work, "include", "smallvcm.hpp")
            print(f"grade: {rel(student)} does not compile with the graders:")
            print("\n".join(errors.replace(copy, rel(student)).splitlines()[:40]))
            print(f"grade: 0 of {len(names)} exercises pass: fix the first error above (its line numbers are your copy's)")
        return {name: (0, 1, ["the student copy does not compile"]) for name in names + [SAFETY]}, None
    results = run_graders(binary, names + [SAFETY], os.path.join(work, "graders"))
    safety = results.pop(SAFETY)
    if not quiet:
        print(f"grade: {rel(student)} (graders built and run in {time.time() - start:.0f} s; "
              f"logs {rel(os.path.join(work, 'graders'))}.<name>.xml)")
        for name in names:
            passed, total, diagnoses = results[name]
            number, _, title, handout, _ = BY_NAME[name]
            verdict = "PASS" if passed == total and total > 0 else "FAIL"
            print(f"  {number} {name:18s} {passed}/{total} tests  {verdict}")
            for diagnosis in diagnoses[:6]:
                print(f"       - {diagnosis}")
            if verdict == "FAIL":
                print(f"       handout: docs/exercises/{handout}")
        safe = safety[1] > 0 and safety[0] == safety[1]
        print(f"  every algorithm on every Cornell scene renders finite, non-negative images: {'yes' if safe else 'NO'}")
        for diagnosis in safety[2][:6]:
            print(f"       - {diagnosis}")
        done = sum(1 for n in names if results[n][0] == results[n][1] and results[n][1] > 0)
        print(f"grade: {done} of {len(names)} exercises pass")
    results[SAFETY] = safety
    return results, binary


# ---------------------------------------------------------------------------------------
# Side-by-side renders (the figure command of the handouts)
# ---------------------------------------------------------------------------------------

def read_pfm(path):
    with open(path, "rb") as f:
        kind = f.readline().strip()
        width, height = map(int, f.readline().split())
        scale = float(f.readline())
        data = f.read()
    if kind != b"PF":
        raise KitError(f"{rel(path)}: not a colour PFM")
    fmt = "<" if scale < 0 else ">"
    values = struct.unpack(fmt + "f" * (width * height * 3), data[:width * height * 12])
    rows = [values[(height - 1 - y) * width * 3:(height - y) * width * 3] for y in range(height)]  # PFM is bottom-up
    return width, height, rows


def write_png(path, width, height, rows):
    raw = b"".join(b"\x00" + bytes(row) for row in rows)
    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xffffffff)
    png = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)) +
           chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))
    write_atomically_bytes(path, png)


def write_atomically_bytes(path, data):
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    handle, temporary = tempfile.mkstemp(dir=folder, prefix=".compare.", suffix=".tmp")
    with os.fdopen(handle, "wb") as f:
        f.write(data)
    os.replace(temporary, path)


def command_compare(student, args):
    student = resolve_student(student)
    work = os.path.join(BUILD, "compare")
    include = os.path.join(work, "include")
    os.makedirs(include, exist_ok=True)
    shutil.copyfile(student, os.path.join(include, "smallvcm.hpp"))
    program = os.path.join(work, "smallvcm_student")
    subprocess.check_call(["make", "--no-print-directory", "-s", "build/smallvcm"], cwd=ROOT)
    print(f"compare: building the command line against {rel(student)} (about 25 s)")
    code = subprocess.call([CXX] + RENDER_CXXFLAGS + ["-I" + include, "-I" + ROOT, "examples/smallvcm.cpp",
                            "examples/smallvcm_impl.cpp", "-o", program, "-pthread", "-ltinyexr", "-ldraco", "-lmeshoptimizer"], cwd=ROOT)
    if code != 0:
        raise KitError(f"compare: {rel(student)} does not compile", 1)
    images = []
    for label, binary in (("student", program), ("reference", os.path.join(BUILD, "smallvcm"))):
        out = os.path.join(work, label + ".pfm")
        if subprocess.call([binary] + args + ["-q", "-o", out], cwd=ROOT) != 0:
            raise KitError(f"compare: the {label} render failed (arguments: {' '.join(args)})", 1)
        images.append(read_pfm(out))
    (w, h, student_rows), (w2, h2, reference_rows) = images
    if (w, h) != (w2, h2):
        raise KitError("compare: the two renders differ in size", 1)
    # Tone map: the reference's mean luminance maps to 0.18 of white, then sRGB gamma.
    mean = sum(reference_rows[y][i] for y in range(h) for i in range(w * 3)) / (w * h * 3) or 1.0
    exposure = 0.18 / mean * 2.0
    def tone(v):
        v = max(0.0, v * exposure)
        return int(255 * min(1.0, v ** (1 / 2.2)) + 0.5)
    gap = 4
    rows = []
    for y in range(h):
        row = [tone(v) for v in student_rows[y]] + [255] * (3 * gap) + [tone(v) for v in reference_rows[y]]
        rows.append(row)
    png = os.path.join(work, "compare.png")
    write_png(png, 2 * w + gap, h, rows)
    s = sum(sum(r) for r in student_rows) / (w * h * 3)
    print(f"compare: wrote {rel(png)}: yours (left) and the reference (right), same exposure; "
          f"mean pixel value yours {s:.4g}, reference {mean:.4g} ({100 * (s / mean - 1):+.1f} %)")


FIGURE_PROGRAMS = ["fig_path_tracing", "fig_mis", "fig_bidirectional", "fig_photon_mapping", "fig_vcm",
                   "fig_convergence", "fig_report"]


def command_figures(student, quick, only):
    """The course figures rendered with a student's copy, against the reference's
    reference images, into build/student-figures/<quick|full>/student/, with the gallery
    (figures/make_gallery.py) saying which course claims hold."""
    student = resolve_student(student)
    programs = [p for p in FIGURE_PROGRAMS if not only or p in only.split(",")]
    if not programs:
        raise KitError(f"make student-figures: ONLY={only}: no such figure program; known: {', '.join(FIGURE_PROGRAMS)}")
    out = os.path.join(BUILD, "student-figures", "quick" if quick else "full")
    student_out, reference_out = os.path.join(out, "student"), os.path.join(out, "reference")
    flag = ["--quick"] if quick else []
    # The reference images every figure measures against must come from the reference
    # renderer: the committed ones at full settings, a reference run at quick settings.
    subprocess.check_call(["make", "--no-print-directory", f"-j{2}"] + [f"build/{p}" for p in programs], cwd=ROOT)
    if quick:
        for program in programs:
            subprocess.check_call([os.path.join(BUILD, program), "--out", reference_out] + flag, cwd=ROOT)
        source = os.path.join(reference_out, "references")
    else:
        source = os.path.join(ROOT, "docs", "figures", "references")
    if os.path.isdir(source):
        shutil.copytree(source, os.path.join(student_out, "references"), dirs_exist_ok=True)
    work = os.path.join(out, "obj")
    include = os.path.join(work, "include")
    os.makedirs(include, exist_ok=True)
    shutil.copyfile(student, os.path.join(include, "smallvcm.hpp"))
    flags = RENDER_CXXFLAGS + ["-I" + include, "-I" + ROOT]
    sources = [f"figures/{p}.cpp" for p in programs] + ["examples/smallvcm_impl.cpp"]
    jobs = [([CXX] + flags + ["-c", source, "-o", os.path.join(work, p + ".o")], os.path.join(work, p + ".log"))
            for source, p in zip(sources, programs + ["smallvcm_impl"])]
    print(f"student-figures: compiling {len(jobs)} units against {rel(student)}")
    failed = run_jobs(jobs, 2)
    if failed:
        raise KitError(f"student-figures: {rel(student)} does not compile; see {rel(failed[0][1])}", 1)
    for program in programs:
        binary = os.path.join(work, program)
        subprocess.check_call([CXX, os.path.join(work, program + ".o"), os.path.join(work, "smallvcm_impl.o"),
                               "-o", binary, "-pthread", "-ltinyexr", "-ldraco", "-lmeshoptimizer"], cwd=ROOT)
        code = subprocess.call([binary, "--out", student_out] + flag, cwd=ROOT)
        print(f"student-figures: {program} exited with {code}")
    subprocess.call(["/usr/bin/python3", "figures/make_gallery.py", student_out, os.path.join(student_out, "figures.md")], cwd=ROOT)
    print(f"student-figures: the student's figures and gallery are in {rel(student_out)}"
          + (f", the reference's in {rel(reference_out)}" if quick else ", the reference's in docs/figures/"))


# ---------------------------------------------------------------------------------------
# The kit's own test
# ---------------------------------------------------------------------------------------

def command_prove():
    """Cuts every exercise and grades each cut copy with every grader (reusing the Catch2
    main and the implementation unit, two cuts at a time): its own grader must fail, the
    others pass (except those declared to build on it). Plus the bad-input rules. Prints
    one line per check and 'prove: N passed, M failed'."""
    start = time.time()
    passed, failed = 0, 0
    def report(ok, what):
        nonlocal passed, failed
        if ok:
            passed += 1
        else:
            failed += 1
        print(f"prove: {'ok  ' if ok else 'FAIL'} {what}", flush=True)

    reference = read_lines(HEADER)
    try:
        regions = check_header(reference, "smallvcm.hpp")
        report(True, f"markers of smallvcm.hpp pair up: {len(regions)} regions, each with a stub")
    except KitError as e:
        report(False, str(e))
        print(f"prove: {passed} passed, {failed} failed")
        return 1

    # Bad input: unknown names, broken markers, a folder without a student copy.
    def fails_with(function, fragment, status):
        try:
            function()
        except KitError as e:
            return fragment in str(e) and e.status == status, str(e)
        return False, "no error"
    ok, message = fails_with(lambda: parse_names("nosuch"), "known: 01 cosine_hemisphere", 2)
    report(ok, f"an unknown exercise name lists the known ones: {message}")
    for broken, fragment in (
            (["x", "// BEGIN EXERCISE bpt_mis/a", "y"], "smallvcm.hpp:2: BEGIN EXERCISE bpt_mis/a is never closed"),
            (["// BEGIN EXERCISE bpt_mis/a", "// BEGIN EXERCISE bpt_mis/b"], "smallvcm.hpp:2: BEGIN EXERCISE bpt_mis/b inside"),
            (["// END EXERCISE vcm_mis"], "smallvcm.hpp:1: END EXERCISE vcm_mis without a BEGIN"),
            (["// BEGIN EXERCISE vcm_mis", "", "// END EXERCISE bpt_mis"], "smallvcm.hpp:3: END EXERCISE bpt_mis closes"),
            (["", "//BEGIN EXERCISE vcm_mis"], "smallvcm.hpp:2: malformed exercise marker")):
        ok, message = fails_with(lambda: parse_regions(broken, "smallvcm.hpp"), fragment, 1)
        report(ok, f"a broken marker fails with its line number: {message}")
    empty = tempfile.mkdtemp()
    ok, message = fails_with(lambda: resolve_student(empty), "holds no smallvcm.hpp: cut a student copy", 2)
    report(ok, f"grading a folder without a student copy says what to do: {message}")
    os.rmdir(empty)

    work = os.path.join(BUILD, "prove")
    os.makedirs(work, exist_ok=True)
    # Every cut at once still compiles (warning-free: -Werror) as a whole program's header.
    all_copy = os.path.join(work, "all", "smallvcm.hpp")
    write_atomically(all_copy, "\n".join(cut_lines(reference, "smallvcm.hpp", NAMES)))
    compile_all = subprocess.run([CXX] + CXXFLAGS + ["-Werror", "-fsyntax-only", "-I" + os.path.dirname(all_copy),
                                  "-I" + ROOT, "examples/smallvcm.cpp"], cwd=ROOT, capture_output=True, text=True)
    report(compile_all.returncode == 0, "the copy with every exercise cut compiles without a warning" +
           ("" if compile_all.returncode == 0 else ":\n" + compile_all.stderr[:3000]))

    # The reference passes every grader: the suite's own binary holds them all.
    if subprocess.call(["make", "--no-print-directory", "-s", "build/tests/run_tests"], cwd=ROOT) == 0:
        results = run_graders(os.path.join(BUILD, "tests", "run_tests"), NAMES + [SAFETY], os.path.join(work, "reference"))
        for name in NAMES + [SAFETY]:
            p, t, diagnoses = results[name]
            report(t > 0 and p == t, f"the reference passes grader {name} ({p}/{t})" +
                   ("" if p == t else ": " + "; ".join(diagnoses[:2])[:400]))
    else:
        report(False, "the reference's test binary build/tests/run_tests does not build")

    # One grader binary per cut, built two at a time (each build uses one core).
    copies = {}
    for name in NAMES:
        copies[name] = os.path.join(work, name, "smallvcm.hpp")
        write_atomically(copies[name], "\n".join(cut_lines(reference, "smallvcm.hpp", [name])))
    ensure_reference_objects(True)
    if not reference_impl_is_safe():
        print("prove: the implementation unit defines exercise code; compiling it per cut (slower)")
    import threading
    outcomes, lock = {}, threading.Lock()
    def grade_one(name):
        results, _ = grade(copies[name], NAMES, reuse_impl=True, quiet=True,
                           work=os.path.join(work, name, "obj"), parallel=1)
        with lock:
            outcomes[name] = results
    pending = list(NAMES)
    while pending:
        threads = [threading.Thread(target=grade_one, args=(pending.pop(0),)) for _ in range(min(2, len(pending)))]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    for name in NAMES:
        results = outcomes[name]
        safety = results[SAFETY]
        report(safety[1] > 0 and safety[0] == safety[1], f"cut {name}: every algorithm renders finite, non-negative images" +
               ("" if safety[0] == safety[1] else ": " + "; ".join(safety[2][:2])[:400]))
        own = results[name]
        report(own[1] > 0 and own[0] < own[1],
               f"cut {name}: its grader fails ({own[0]}/{own[1]} tests pass): " + "; ".join(own[2][:2])[:400])
        for other in NAMES:
            if other == name:
                continue
            p, t, diagnoses = results[other]
            if other in BY_NAME[name][4]:
                print(f"prove: note cut {name}: grader {other} builds on it ({p}/{t} tests pass), not counted")
                continue
            report(t > 0 and p == t, f"cut {name}: grader {other} still passes ({p}/{t})" +
                   ("" if p == t else ": " + "; ".join(diagnoses[:2])[:400]))
    print(f"prove: {passed} passed, {failed} failed ({time.time() - start:.0f} s)")
    return 0 if failed == 0 else 1


def main(argv):
    if not argv or argv[0] in ("-h", "--help"):
        print(__doc__)
        return 0
    command, args = argv[0], argv[1:]
    def option(flag, default=None):
        if flag in args:
            i = args.index(flag)
            if i + 1 >= len(args):
                raise KitError(f"kit.py {command}: {flag} needs a value")
            value = args[i + 1]
            del args[i:i + 2]
            return value
        return default
    try:
        if command == "list":
            command_list()
        elif command == "check":
            command_check(os.path.abspath(args[0]) if args else HEADER)
        elif command == "cut":
            header = os.path.abspath(option("--header", HEADER))
            out = option("--out")
            command_cut(args[0] if args else None, header, out)
        elif command == "grade":
            names = parse_names(option("--exercise", "all"))
            json_path = option("--json")
            reuse = "--reuse-impl" in args
            args = [a for a in args if a != "--reuse-impl"]
            student = resolve_student(args[0] if args else None)
            results, _ = grade(student, names, reuse_impl=reuse)
            if json_path:
                write_atomically(json_path, json.dumps({n: {"passed": r[0], "total": r[1], "diagnoses": r[2]}
                                                        for n, r in results.items()}, indent=1))
            return 0 if all(r[1] > 0 and r[0] == r[1] for r in results.values()) else 1
        elif command == "compare":
            if "--" not in args:
                raise KitError("make compare: give the render's options, e.g. make compare STUDENT=... ARGS='-s 4 -a pt -i 16'")
            i = args.index("--")
            command_compare(args[0] if i > 0 else None, args[i + 1:])
        elif command == "figures":
            quick = "--quick" in args
            only = option("--only")
            args = [a for a in args if a != "--quick"]
            command_figures(args[0] if args else None, quick, only)
        elif command == "prove":
            return command_prove()
        else:
            raise KitError(f"kit.py: unknown command '{command}' (list, check, cut, grade, compare, figures, prove)")
    except KitError as e:
        print(str(e), file=sys.stderr)
        return e.status
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
