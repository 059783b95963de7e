#!/usr/bin/env python3
"""Is a mutant equivalent? Renders that say whether it changes the image beyond noise.

A mutant of tests/mutant_list.py that no test kills is listed as *equivalent* only with an
argument and a render whose difference from the unmutated header is below noise
(docs/testing.md). This script makes that render: it builds the command line twice, from
the header as it is and with the mutant applied (in a temporary copy of the tree), renders
each (scene, algorithm) PAIRS times with the seeds 1..PAIRS on both, and compares them.

The two renders of one seed form a pair: both start from the same random numbers, so their
difference is less noisy than that of independent renders; the pairs are independent of
each other, so the standard error of the mean difference is measured from the PAIRS
differences (Student t with PAIRS - 1 degrees of freedom). For each (scene, algorithm) it
prints the image mean of both, their relative difference with its standard error, and the
largest |z| over 4 x 4 pixel blocks and channels. "below noise" means the image mean's
|z| < 4 and every block's |z| < 5: with 32 pairs (Student t, 31 degrees of freedom) that
is a false alarm of ~4e-4 for the image and ~2e-5 per block, ~4e-3 over the 192 blocks
and channels of 32 x 32 pixels. "resolves" is 4 standard errors of the image mean, the
smallest relative difference the comparison would have seen.

Usage: tests/mutant_equivalence.py M11 [--scenes 1,2] [--algorithms vcm,bpt,bpm,lt]
           [--pairs 32] [--iterations 64] [--resolution 32x32] [--extra "--max-path-length 3"]
"""
import argparse
import math
import os
import shutil
import struct
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "tests"))
from mutant_list import MUTANTS  # noqa: E402
from mutants import HEADER, applicability, mutated_header, prepare_tree  # noqa: E402


def read_pfm(path):
    """(width, height, [r, g, b, r, g, b, ...]) of a colour PFM."""
    with open(path, "rb") as f:
        data = f.read()
    parts = data.split(b"\n", 3)
    if parts[0].strip() != b"PF":
        sys.exit("mutant_equivalence: %s is not a colour PFM" % path)
    width, height = (int(v) for v in parts[1].split())
    scale = float(parts[2])
    endian = "<" if scale < 0 else ">"
    count = width * height * 3
    return width, height, struct.unpack(endian + "%df" % count, parts[3][:4 * count])


def build(tree, jobs):
    done = subprocess.run(["make", "-j%d" % jobs, "--no-print-directory", "build/smallvcm",
                           "CXXFLAGS=-std=c++17 -O2"], cwd=tree, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if done.returncode != 0:
        sys.exit("mutant_equivalence: build/smallvcm does not build in %s:\n%s" % (tree, done.stdout[-2000:]))
    return os.path.join(tree, "build", "smallvcm")


def render(program, scene, algorithm, seed, args, out):
    command = [program, "-q", "-s", scene, "-a", algorithm, "-i", str(args.iterations), "-r", args.resolution,
               "-j", "1", "--seed", str(seed), "-o", out] + args.extra.split()
    done = subprocess.run(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if done.returncode != 0:
        sys.exit("mutant_equivalence: %s failed:\n%s" % (" ".join(command), done.stdout))
    return read_pfm(out)


def mean_and_error(values):
    n = len(values)
    mean = sum(values) / n
    variance = sum((v - mean) ** 2 for v in values) / (n - 1)
    return mean, math.sqrt(variance / n)


def main():
    parser = argparse.ArgumentParser(description="Renders that show whether a mutant changes the image beyond noise.")
    parser.add_argument("mutant", help="a mutant id of tests/mutant_list.py")
    parser.add_argument("--scenes", default="1,2", help="Cornell scene numbers or glTF paths, comma-separated")
    parser.add_argument("--algorithms", default="vcm,bpt,bpm,lt")
    parser.add_argument("--pairs", type=int, default=32, help="renders per build and case (seeds 1..PAIRS)")
    parser.add_argument("--iterations", type=int, default=64)
    parser.add_argument("--resolution", default="32x32")
    parser.add_argument("--extra", default="--max-path-length 3",
                        help="more options for every render (default: a short maximum, so that limits matter often)")
    parser.add_argument("--jobs", type=int, default=2, help="parallel compilations")
    args = parser.parse_args()
    if args.pairs < 4:
        sys.exit("mutant_equivalence: --pairs: at least 4 pairs are needed for a standard error")

    mutant = next((m for m in MUTANTS if m["id"] == args.mutant), None)
    if mutant is None:
        sys.exit("mutant_equivalence: %s: no such mutant in tests/mutant_list.py" % args.mutant)
    with open(os.path.join(ROOT, HEADER)) as f:
        header = f.read()
    why = applicability(header, mutant)
    if why:
        sys.exit("mutant_equivalence: %s: not applicable: %s" % (args.mutant, why))

    workdir = tempfile.mkdtemp(prefix="smallvcm-equivalence-")
    try:
        programs = {}
        for name, text in (("main", header), ("mutant", mutated_header(header, mutant))):
            tree = prepare_tree(os.path.join(workdir, name))
            with open(os.path.join(tree, HEADER), "w") as f:
                f.write(text)
            programs[name] = build(tree, args.jobs)
        print("%s (%s): %d pairs of %d iterations at %s, options '%s'" % (
            args.mutant, mutant["what"], args.pairs, args.iterations, args.resolution, args.extra), flush=True)
        all_below = True
        for scene in args.scenes.split(","):
            for algorithm in args.algorithms.split(","):
                images = {"main": [], "mutant": []}
                for seed in range(1, args.pairs + 1):
                    for name, program in programs.items():
                        out = os.path.join(workdir, "%s.pfm" % name)
                        width, height, pixels = render(program, scene, algorithm, seed, args, out)
                        images[name].append(pixels)
                # Image means and their paired difference.
                means = {name: [sum(p) / len(p) for p in images[name]] for name in images}
                main_mean, _ = mean_and_error(means["main"])
                mutant_mean, _ = mean_and_error(means["mutant"])
                diff, diff_se = mean_and_error([b - a for a, b in zip(means["main"], means["mutant"])])
                z_image = diff / diff_se if diff_se > 0 else (0.0 if diff == 0 else math.inf)
                # 4 x 4 blocks, per channel.
                worst = 0.0
                for by in range(0, height, 4):
                    for bx in range(0, width, 4):
                        for c in range(3):
                            def block(pixels):
                                return sum(pixels[3 * (y * width + x) + c]
                                           for y in range(by, min(by + 4, height)) for x in range(bx, min(bx + 4, width)))
                            d, se = mean_and_error([block(b) - block(a) for a, b in zip(images["main"], images["mutant"])])
                            z = d / se if se > 0 else (0.0 if d == 0 else math.inf)
                            worst = max(worst, abs(z))
                below = abs(z_image) < 4 and worst < 5
                all_below = all_below and below
                relative = diff / main_mean if main_mean else 0.0
                print("  scene %-3s %-4s mean %.6g (main) %.6g (mutant): difference %+.4f %% +- %.4f %% (z %+.2f), "
                      "resolves %.3f %%; worst block |z| %.2f: %s" % (
                          scene, algorithm, main_mean, mutant_mean, 100 * relative,
                          100 * diff_se / main_mean if main_mean else 0.0, z_image,
                          400 * diff_se / main_mean if main_mean else 0.0, worst,
                          "below noise" if below else "DIFFERENT"), flush=True)
        print("%s: %s" % (args.mutant, "every difference below noise" if all_below else "a difference beyond noise"))
        return 0 if all_below else 1
    finally:
        shutil.rmtree(workdir, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
