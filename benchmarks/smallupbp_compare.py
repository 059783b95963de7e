#!/usr/bin/env python3
"""smallvcm's media beside SmallUPBP (Krivanek et al. 2014, the UPBP paper's own renderer)
on its predefined scene 1, "isosph": time per iteration and error, 1 and 2 threads.

    python3 benchmarks/smallupbp_compare.py --smallupbp /tmp/smallupbp/smallupbp [--out DIR]
        [--resolution 128] [--iterations 16] [--rounds 3] [--threads 1,2] [--pairs vptmis:pt,...]

SmallUPBP is not part of this repository: build it with
`MIRROR=<mirror of github PetrVevoda/smallupbp> bash /work/shared/peers/smallupbp/build.sh DIR`
(its README: the Linux port, its algorithms and upstream quirks). The script needs its
`smallupbp` and the `exrtool` built beside it (EXR -> PFM), NumPy, and build/smallvcm.

The scene. SmallUPBP's scene 1 ("large isoscattering sphere + small area light") is the
SmallVCM Cornell box with a diffuse white floor and ceiling, green left, red right and blue
back wall, no front wall, the small light box under the ceiling (white sides, its bottom the
two emitting triangles, radiance 25.0333) and a sphere of radius 0.8 standing 0.01 above the
middle of the floor, with no surface (an "imaginary", index-matched boundary) around a
medium that only scatters: sigma_s = 0.9 per unit in every channel, sigma_a = 0, g = 0
(isotropic); outside it is empty space. Its coordinates, the light box and the camera are
exactly those of SmallVCM's box, which scenes/cornell_4_default.gltf already holds, so the
equivalent glTF (DIR/isosph.gltf) is that file with SmallUPBP's reflectances (0.803922 /
0.152941 / 0.156863 / 0.172549: SmallVCM's files use other values), its spheres removed, the
back wall blue, and a SMALLVCM_sphere whose material carries only SMALLVCM_medium (an
index-matched boundary: docs/scene_format.md 4.4).

Pairs (SmallUPBP algorithm : smallvcm algorithm), default
  vptmis : pt    volumetric path tracers, both with MIS of light and phase/BSDF sampling
  vbpt   : bpt   volumetric bidirectional path tracing
  upbp_vcm : vcm SmallUPBP's VCM inside UPBP (BPT + merging of surface photons); ours also
                 merges photons in media (its own medium radius). upbp_vcm renders the same
                 image as upbp_bpt+surf+pp3d (volumetric photon points too) seed for seed
                 (checked on scene 1), so it is the same combination as ours; the radii
                 differ (each program's defaults).
Both are run at the same resolution, iterations and maximum path length (-l 10 /
--max-path-length 10: both count segments from the camera, a medium scattering vertex
is a vertex, crossing the index-matched sphere is not). One iteration is one camera path
per pixel (and one light path per pixel for the bidirectional ones) in both.

Timing: the runs are interleaved (every pair and thread count once per round) and timed
by CPU seconds of the child (user + system, from rusage) and wall seconds; the tables give
medians over the rounds. Everything includes process start, scene loading and writing
(SmallUPBP builds an Embree BVH; smallvcm its own), which at these sizes is a few ms.
Error: each run's RMSE per pixel and channel against a reference, the mean of every run
of the two path tracers (all seeds differ), and 8 x 8 regions' z of each pair
(difference of the two programs' region means over its standard error from the spread of
their runs). Writes DIR/smallupbp.md, DIR/runs.csv, DIR/log.txt (DIR: build/smallupbp).
"""

import argparse
import json
import math
import os
import resource
import subprocess
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SMALLVCM = os.path.join(ROOT, "build", "smallvcm")
MAX_PATH_LENGTH = 10

# SmallUPBP scene 1's reflectances (its Cornell-box material list).
WHITE = [0.803922] * 3
RED = [0.803922, 0.152941, 0.152941]
GREEN = [0.156863, 0.803922, 0.172549]
BLUE = [0.156863, 0.172549, 0.803922]


def write_scene(out_dir):
    """DIR/isosph.gltf: SmallUPBP's scene 1 for smallvcm (the opening comment)."""
    with open(os.path.join(ROOT, "scenes", "cornell_4_default.gltf")) as f:
        gltf = json.load(f)
    buffers = gltf["buffers"]
    for buffer in buffers:  # the copy lives elsewhere: embed external buffers' paths
        if not buffer["uri"].startswith("data:"):
            buffer["uri"] = os.path.join(ROOT, "scenes", buffer["uri"])

    def lambert(name, rgb):
        return {"name": name, "pbrMetallicRoughness": {"baseColorFactor": rgb + [1.0], "metallicFactor": 0.0,
                                                       "roughnessFactor": 1.0},
                "extensions": {"SMALLVCM_material": {"diffuse": rgb}}}

    materials = gltf["materials"]
    index = {"white": len(materials), "red": len(materials) + 1, "green": len(materials) + 2,
             "blue": len(materials) + 3, "medium": len(materials) + 4}
    materials += [lambert("SmallUPBP diffuse white", WHITE), lambert("SmallUPBP diffuse red", RED),
                  lambert("SmallUPBP diffuse green", GREEN), lambert("SmallUPBP diffuse blue", BLUE),
                  {"name": "SmallUPBP white isoscattering medium (index-matched sphere)",
                   "extensions": {"SMALLVCM_medium": {"sigmaA": [0.0, 0.0, 0.0], "sigmaS": [0.9, 0.9, 0.9], "g": 0.0}}}]
    wanted = {"floor": "white", "ceiling": "white", "back wall": "blue", "left wall": "green",
              "right wall": "red", "light box sides": "white"}
    for mesh in gltf["meshes"]:
        if mesh.get("name") in wanted:
            for primitive in mesh["primitives"]:
                primitive["material"] = index[wanted[mesh["name"]]]
        elif mesh.get("name") != "light (emitter)":
            sys.exit(f"smallupbp_compare: unexpected mesh {mesh.get('name')!r} in cornell_4_default.gltf")
    nodes = gltf["nodes"]
    spheres = [i for i, n in enumerate(nodes) if "SMALLVCM_sphere" in n.get("extensions", {})]
    for i in spheres:  # drop the mirror and glass spheres (keep the indices: make them empty)
        nodes[i] = {"name": nodes[i]["name"] + " (removed)"}
    # SmallUPBP: centre of the floor + (0, 0, 0.8 + 0.01), radius 0.8.
    floor_centre = [(-1.27029 + 1.28975) / 2, (1.30455 - 1.25549) / 2, -1.28002]
    nodes.append({"name": "isotropic scattering sphere", "translation": [floor_centre[0], floor_centre[1], floor_centre[2] + 0.81],
                  "extensions": {"SMALLVCM_sphere": {"radius": 0.8, "material": index["medium"]}}})
    gltf["scenes"][gltf.get("scene", 0)]["nodes"].append(len(nodes) - 1)
    used = set(gltf.get("extensionsUsed", [])) | {"SMALLVCM_medium", "SMALLVCM_sphere", "SMALLVCM_material"}
    gltf["extensionsUsed"] = sorted(used)
    gltf.setdefault("asset", {})["extras"] = {"note": "SmallUPBP scene 1 (isosph) for smallvcm, written by"
                                              " benchmarks/smallupbp_compare.py"}
    path = os.path.join(out_dir, "isosph.gltf")
    with open(path, "w") as f:
        json.dump(gltf, f, indent=1)
    return path


def read_pfm(path):
    with open(path, "rb") as f:
        if f.readline().strip() != b"PF":
            raise ValueError(f"{path}: not a colour PFM file")
        width, height = map(int, f.readline().split())
        scale = float(f.readline())
        pixels = np.frombuffer(f.read(), dtype=">f4" if scale > 0 else "<f4").reshape(height, width, 3)
    return pixels[::-1].astype(np.float64)  # PFM stores the bottom row first


def timed(command):
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    wall = time.perf_counter()
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - wall
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime, wall


def run_smallupbp(binary, exrtool, algorithm, resolution, iterations, threads, seed, out_dir):
    exr = os.path.join(out_dir, "smallupbp_run.exr")
    command = [binary, "-s", "1", "-a", algorithm, "-l", str(MAX_PATH_LENGTH), "-i", str(iterations),
               "-r", f"{resolution}x{resolution}", "-th", str(threads), "-seed", str(seed), "-o", exr]
    cpu, wall = timed(command)
    pfm = os.path.join(out_dir, "smallupbp_run.pfm")
    subprocess.run([exrtool, exr, pfm], check=True, stdout=subprocess.DEVNULL)
    return read_pfm(pfm), cpu, wall


def run_smallvcm(gltf, algorithm, resolution, iterations, threads, seed, out_dir):
    pfm = os.path.join(out_dir, "smallvcm_run.pfm")
    command = [SMALLVCM, "-q", "-s", gltf, "-a", algorithm, "--sampler", "independent", "-j", str(threads),
               "-r", f"{resolution}x{resolution}", "-i", str(iterations), "--seed", str(seed),
               "--max-path-length", str(MAX_PATH_LENGTH), "-o", pfm]
    cpu, wall = timed(command)
    return read_pfm(pfm), cpu, wall


def region_z(a_runs, b_runs, regions=8):
    """(regions x regions x 3) z of the region means: difference over its standard error."""
    h, w = a_runs[0].shape[:2]
    shape = (regions, h // regions, regions, w // regions, 3)
    a, b = [np.stack([x[:h // regions * regions, :w // regions * regions].reshape(shape).mean(axis=(1, 3)) for x in runs])
            for runs in (a_runs, b_runs)]
    se = np.sqrt(a.var(0, ddof=1) / len(a) + b.var(0, ddof=1) / len(b))
    return (a.mean(0) - b.mean(0)) / np.maximum(se, 1e-30)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--smallupbp", required=True, help="the SmallUPBP binary (exrtool beside it)")
    parser.add_argument("--out", default=os.path.join(ROOT, "build", "smallupbp"))
    parser.add_argument("--resolution", type=int, default=128)
    parser.add_argument("--iterations", type=int, default=16)
    parser.add_argument("--rounds", type=int, default=3, help="interleaved runs per program and thread count")
    parser.add_argument("--threads", default="1,2")
    parser.add_argument("--pairs", default="vptmis:pt,vbpt:bpt,upbp_vcm:vcm")
    args = parser.parse_args()
    exrtool = os.path.join(os.path.dirname(os.path.abspath(args.smallupbp)), "exrtool")
    for program in (args.smallupbp, exrtool, SMALLVCM):
        if not os.access(program, os.X_OK):
            sys.exit(f"smallupbp_compare: {program} is missing")
    if args.rounds < 2:
        sys.exit("smallupbp_compare: --rounds must be at least 2 (the regions' standard errors)")
    os.makedirs(args.out, exist_ok=True)
    gltf = write_scene(args.out)
    pairs = [tuple(p.split(":")) for p in args.pairs.split(",")]
    threads = [int(t) for t in args.threads.split(",")]
    log_file = open(os.path.join(args.out, "log.txt"), "a")

    def log(line):
        print(line, flush=True)
        log_file.write(line + "\n")
        log_file.flush()

    log(f"start {time.strftime('%Y-%m-%d %H:%M:%S')} load {os.getloadavg()}: scene 1 / {gltf},"
        f" {args.resolution}^2, {args.iterations} iterations, -l {MAX_PATH_LENGTH}, rounds {args.rounds}")
    runs = {}  # (program, algorithm, threads) -> list of (image, cpu, wall)
    for r in range(args.rounds):
        for t in threads:
            for p, (theirs, ours) in enumerate(pairs):
                seed = 1000 * r + 100 * p + 10 * t + 1  # every run its own seed
                image, cpu, wall = run_smallupbp(args.smallupbp, exrtool, theirs, args.resolution, args.iterations, t,
                                                 seed, args.out)
                runs.setdefault(("smallupbp", theirs, t), []).append((image, cpu, wall))
                log(f"round {r} threads {t}: smallupbp {theirs}: {cpu:.2f} CPU s, {wall:.2f} s, mean {image.mean():.5f}")
                image, cpu, wall = run_smallvcm(gltf, ours, args.resolution, args.iterations, t, seed + 5, args.out)
                runs.setdefault(("smallvcm", ours, t), []).append((image, cpu, wall))  # pooled if two pairs share it
                log(f"round {r} threads {t}: smallvcm {ours}: {cpu:.2f} CPU s, {wall:.2f} s, mean {image.mean():.5f}")
    # Reference: every run of the two path tracers (first pair), all thread counts.
    first_theirs, first_ours = pairs[0]
    pool = [x[0] for key, v in runs.items() if key[1] in (first_theirs, first_ours) for x in v]
    reference = np.mean(pool, axis=0)
    np.save(os.path.join(args.out, "reference.npy"), reference)
    with open(os.path.join(args.out, "runs.csv"), "w") as f:
        f.write("program,algorithm,threads,run,cpu_seconds,wall_seconds,mean_r,mean_g,mean_b,rmse\n")
        for (program, algorithm, t), v in runs.items():
            for k, (image, cpu, wall) in enumerate(v):
                m = image.mean(axis=(0, 1))
                rmse = math.sqrt(float(np.mean((image - reference) ** 2)))
                f.write(f"{program},{algorithm},{t},{k},{cpu:.4f},{wall:.4f},{m[0]:.6f},{m[1]:.6f},{m[2]:.6f},{rmse:.6e}\n")
    table = [f"Scene 1 (isosph), {args.resolution}x{args.resolution}, {args.iterations} iterations a run, -l {MAX_PATH_LENGTH},"
             f" {args.rounds} interleaved runs each; medians; load average at the end {os.getloadavg()[0]:.1f}."
             f" RMSE against the mean of all {len(pool)} path-tracer runs.", "",
             "| program | algorithm | threads | CPU s per iteration | wall s per iteration | mean R | mean G | mean B |"
             " RMSE |", "|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    for theirs, ours in pairs:
        for t in threads:
            for program, algorithm in (("smallupbp", theirs), ("smallvcm", ours)):
                v = runs[(program, algorithm, t)]
                cpu = np.median([x[1] for x in v]) / args.iterations
                wall = np.median([x[2] for x in v]) / args.iterations
                m = np.mean([x[0].mean(axis=(0, 1)) for x in v], axis=0)
                se = np.std([x[0].mean(axis=(0, 1)) for x in v], axis=0, ddof=1) / math.sqrt(len(v))
                rmse = np.median([math.sqrt(float(np.mean((x[0] - reference) ** 2))) for x in v])
                table.append(f"| {program} | {algorithm} | {t} | {cpu:.4f} | {wall:.4f} | {m[0]:.4f} ± {se[0]:.4f} |"
                             f" {m[1]:.4f} ± {se[1]:.4f} | {m[2]:.4f} ± {se[2]:.4f} | {rmse:.4f} |")
    table += ["", "Agreement, all thread counts pooled: image means and 8 x 8 regions per channel"
              " (z = difference over its standard error from the runs' spread).", "",
              "| SmallUPBP | smallvcm | ratio of means R, G, B | regions: mean z, std z, worst abs z, abs z > 3 |",
              "|---|---|---|---|"]
    for theirs, ours in pairs:
        a = [x[0] for t in threads for x in runs[("smallupbp", theirs, t)]]
        b = [x[0] for t in threads for x in runs[("smallvcm", ours, t)]]
        ratio = np.mean(b, axis=(0, 1, 2)) / np.mean(a, axis=(0, 1, 2))
        z = region_z(b, a)
        table.append(f"| {theirs} | {ours} | {ratio[0]:.4f}, {ratio[1]:.4f}, {ratio[2]:.4f} |"
                     f" {z.mean():+.2f}, {z.std():.2f}, {np.abs(z).max():.1f}, {int(np.sum(np.abs(z) > 3))}/{z.size} |")
        np.save(os.path.join(args.out, f"smallupbp_{theirs}.npy"), np.mean(a, axis=0))
        np.save(os.path.join(args.out, f"smallvcm_{ours}.npy"), np.mean(b, axis=0))
    with open(os.path.join(args.out, "smallupbp.md"), "w") as f:
        f.write("\n".join(table) + "\n")
    for line in table:
        log(line)
    log(f"end {time.strftime('%Y-%m-%d %H:%M:%S')} load {os.getloadavg()}")


if __name__ == "__main__":
    main()
