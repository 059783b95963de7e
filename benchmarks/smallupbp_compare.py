#!/usr/bin/env python3
"""smallvcm's media beside SmallUPBP (Krivanek et al. 2014, the UPBP paper's own renderer)
on its predefined scene 1, "isosph": time per iteration and error, 1 and 2 threads.

    python3 benchmarks/smallupbp_compare.py --smallupbp /tmp/smallupbp/smallupbp [--out DIR]
        [--resolution 128] [--iterations 16] [--rounds 3] [--threads 1,2] [--pairs vptmis:pt,...]
        [--surf-radius R] [--medium-radius R] [--beam-radius R] [--radius-alpha A]
        [--beam-paths N] [--short-beams]

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
A side of a pair is an algorithm, optionally followed by [LIST] (smallvcm only: its
--techniques LIST, so "upbp[bpt,surf,pp3d]" is `-a upbp --techniques bpt,surf,pp3d`) and
by {ARGS} (more command-line arguments for that program, split at spaces, e.g.
"upbp_all{-previous}"). Commas inside [] or {} do not separate pairs. UPBP technique by
technique, SmallUPBP's combinations beside ours:
    --pairs "vptmis:pt,upbp_bpt:upbp[bpt],upbp_bpt+surf+pp3d:upbp[bpt,surf,pp3d],
             upbp_bpt+surf+pb2d:upbp[bpt,surf,pb2d],upbp_bpt+surf+bb1d:upbp[bpt,surf,bb1d],
             upbp_all:upbp[bpt,surf,pp3d,pb2d,bb1d]" (one line)
(SmallUPBP's standalone pb2d and bb1d render only the medium radiance along camera rays,
and its standalone bb1d mixes up the beam types: its README; so compare the upbp_
combinations.) The first pair should stay the path tracers: they make the reference.

Matched merging settings: by default each program uses its own radii (SmallUPBP: surf
0.0015, pp3d/pb2d/bb1d 0.001 of its scene radius, alpha 0.75 for surf and 1 for the
others; smallvcm: 0.003 / 0.03 / 0.003 of its scene radius, alpha 0.75 for all), its own
number of light sub-paths storing photon beams (SmallUPBP: all N_L, smallvcm 4096) and
SmallUPBP its own beam types (long query beams, short photon beams). These options give
both programs the same, and go to every run of both (the path tracers ignore them),
before a side's own {ARGS} (both programs take the last of a repeated option, so a side
can override one, e.g. "upbp_bpt+surf+bb1d{-qbt L}"):
  --surf-radius R    surface merging radius, absolute, in scene units (SmallUPBP
                     -r_initial_surf R; smallvcm --radius-factor R / its scene radius)
  --medium-radius R  pp3d and pb2d radius (smallvcm has one radius for both:
                     --medium-radius-factor; SmallUPBP -r_initial_pp3d R -r_initial_pb2d R)
  --beam-radius R    bb1d photon beam radius (-r_initial_bb1d; --beam-radius-factor)
  --radius-alpha A   radius shrinking exponent for all techniques, 1 = fixed radii
                     (-r_alpha A; --radius-alpha A). Both shrink surf as r0 i^((A-1)/2);
                     SmallUPBP pp3d as i^((A-1)/3) and bb1d as i^(A-1): use 1 to match.
  --beam-paths N     light sub-paths per iteration that store photon beams (-pbc N;
                     --beam-paths N)
  --short-beams      SmallUPBP -qbt S -pbt S: short query and photon beams, as smallvcm's
                     pb2d and bb1d are (both end where the free flight did; T / P)
SmallUPBP takes a positive radius as absolute (a negative one is relative to its scene
radius). Its scene radius is half the diagonal of the bounding box of its geometry and
its media spheres (Scene::BuildSceneSphere); smallvcm's is half the diagonal of the box
of its triangles and spheres (Scene::FinalizeGeometry). Both boxes are the Cornell box,
[-1.27029, 1.28975] x [-1.25549, 1.30455] x [-1.28002, 1.28002], so both radii are
2.56004 sqrt(3) / 2 = 2.21706; the script computes smallvcm's from the glTF and prints
both. Same radius is not the same kernel: SmallUPBP's pb2d and bb1d weight photons by
Epanechnikov kernels (2D: 2 (1 - d^2/r^2) / (pi r^2), 1D: 3 (1 - d^2/r^2) / (4 r)),
smallvcm's by constant ones (1 / (pi r^2), 1 / (2 r)), so at the same r smallvcm's blur
is wider (its bias larger) there; surf and pp3d use constant kernels in both.

Seen with matched settings (fixed radii surf 0.006651, pp3d/pb2d 0.06651, bb1d 0.006651,
4096 beam paths, short beams): SmallUPBP's upbp_bpt+surf+bb1d is about 5% too bright
inside the medium (about 1% on the image) against both path tracers and our
upbp[bpt,surf,bb1d], for every -qbt/-pbt pair and at half the beam radius. It shows
already at -l 2 (single scattering): there +4.9% in the sphere's pixels against its own
upbp_bpt, which agrees there with our upbp[bpt] and upbp[bpt,surf,bb1d] within 0.3%.
Its upbp_all, where pb2d and pp3d take most of the medium's weight, does not show it.

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
their runs). RMSE at equal iterations and CPU time per iteration, side by side per pair,
give the error at equal time: (RMSE^2 x time) is the inverse efficiency. The reference's
own noise adds to every RMSE alike (it is the mean of 2 x rounds x threads runs).
Writes DIR/smallupbp.md, DIR/runs.csv, DIR/log.txt (DIR: build/smallupbp).
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


def scene_radius(gltf_path):
    """smallvcm's scene radius of DIR/isosph.gltf: half the diagonal of the box of its meshes'
    vertices (the accessors' min/max; the meshes' nodes have no transforms) and spheres."""
    with open(gltf_path) as f:
        gltf = json.load(f)
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for node in gltf["nodes"]:
        if "mesh" in node:
            if any(k in node for k in ("matrix", "translation", "rotation", "scale")):
                sys.exit("smallupbp_compare: a mesh node with a transform (scene_radius does not apply it)")
            for primitive in gltf["meshes"][node["mesh"]]["primitives"]:
                accessor = gltf["accessors"][primitive["attributes"]["POSITION"]]
                lo, hi = np.minimum(lo, accessor["min"]), np.maximum(hi, accessor["max"])
        sphere = node.get("extensions", {}).get("SMALLVCM_sphere")
        if sphere:
            centre = np.array(node.get("translation", [0.0, 0.0, 0.0]))
            lo, hi = np.minimum(lo, centre - sphere["radius"]), np.maximum(hi, centre + sphere["radius"])
    return 0.5 * float(np.linalg.norm(hi - lo))


# SmallUPBP's scene radius of scene 1: half the diagonal of its Cornell box (Scene.hxx's
# cb[] corners; its light box and sphere lie inside), as Scene::BuildSceneSphere takes it.
SMALLUPBP_SCENE_RADIUS = 0.5 * math.sqrt((1.28975 + 1.27029) ** 2 + (1.30455 + 1.25549) ** 2 + (2 * 1.28002) ** 2)


def split_pairs(text):
    """The --pairs list: split at the commas outside [] and {}."""
    pairs, depth, start = [], 0, 0
    for i, c in enumerate(text + ","):
        depth += (c in "[{") - (c in "]}")
        if c == "," and depth == 0:
            if text[start:i].strip():
                theirs, ours = text[start:i].strip().split(":")
                pairs.append((theirs.strip(), ours.strip()))
            start = i + 1
    return pairs


def parse_side(spec, program):
    """A pair's side, "ALG[LIST]{ARGS}" (both optional): the algorithm and the extra arguments."""
    algorithm, extra = spec, []
    if "{" in algorithm:
        algorithm, args = algorithm.split("{", 1)
        extra += args.rstrip("}").split()
    if "[" in algorithm:
        if program != "smallvcm":
            sys.exit(f"smallupbp_compare: {spec}: [techniques] is for smallvcm's side (SmallUPBP: upbp_a+b)")
        algorithm, techniques = algorithm.split("[", 1)
        extra = ["--techniques", techniques.rstrip("]")] + extra
    return algorithm.strip(), extra


def file_name(side):
    """A pair's side as written, made fit for a file name."""
    return "".join(c if c.isalnum() or c in "_-" else "_" for c in side)


def matched_arguments(args, our_radius):
    """The --surf-radius etc. options as each program's arguments: (SmallUPBP's, smallvcm's)."""
    theirs, ours = [], []
    if args.surf_radius is not None:
        theirs += ["-r_initial_surf", repr(args.surf_radius)]
        ours += ["--radius-factor", repr(args.surf_radius / our_radius)]
    if args.medium_radius is not None:
        theirs += ["-r_initial_pp3d", repr(args.medium_radius), "-r_initial_pb2d", repr(args.medium_radius)]
        ours += ["--medium-radius-factor", repr(args.medium_radius / our_radius)]
    if args.beam_radius is not None:
        theirs += ["-r_initial_bb1d", repr(args.beam_radius)]
        ours += ["--beam-radius-factor", repr(args.beam_radius / our_radius)]
    if args.radius_alpha is not None:
        theirs += ["-r_alpha", repr(args.radius_alpha)]
        ours += ["--radius-alpha", repr(args.radius_alpha)]
    if args.beam_paths is not None:
        theirs += ["-pbc", str(args.beam_paths)]
        ours += ["--beam-paths", str(args.beam_paths)]
    if args.short_beams:
        theirs += ["-qbt", "S", "-pbt", "S"]
    return theirs, ours


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


def run_smallupbp(binary, exrtool, algorithm, extra, resolution, iterations, threads, seed, out_dir):
    exr = os.path.join(out_dir, "smallupbp_run.exr")
    command = [binary, "-s", "1", "-a", algorithm, "-l", str(MAX_PATH_LENGTH), "-i", str(iterations),
               "-r", f"{resolution}x{resolution}", "-th", str(threads), "-seed", str(seed), "-o", exr] + extra
    cpu, wall = timed(command)
    pfm = os.path.join(out_dir, "smallupbp_run.pfm")
    subprocess.run([exrtool, exr, pfm], check=True, stdout=subprocess.DEVNULL)
    return read_pfm(pfm), cpu, wall


def run_smallvcm(gltf, algorithm, extra, resolution, iterations, threads, seed, out_dir):
    pfm = os.path.join(out_dir, "smallvcm_run.pfm")
    command = [SMALLVCM, "-q", "-s", gltf, "-a", algorithm, "--sampler", "independent", "-j", str(threads),
               "-r", f"{resolution}x{resolution}", "-i", str(iterations), "--seed", str(seed),
               "--max-path-length", str(MAX_PATH_LENGTH), "-o", pfm] + extra
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
    parser.add_argument("--pairs", default="vptmis:pt,vbpt:bpt,upbp_vcm:vcm",
                        help="THEIRS:OURS,... each side ALG[LIST]{ARGS} (the opening comment)")
    # Matched merging settings, for both programs (the opening comment); default: their own.
    parser.add_argument("--surf-radius", type=float, help="surface merging radius, scene units")
    parser.add_argument("--medium-radius", type=float, help="pp3d and pb2d radius, scene units")
    parser.add_argument("--beam-radius", type=float, help="bb1d photon beam radius, scene units")
    parser.add_argument("--radius-alpha", type=float, help="radius shrinking exponent, 1 = fixed")
    parser.add_argument("--beam-paths", type=int, help="light sub-paths per iteration storing photon beams")
    parser.add_argument("--short-beams", action="store_true", help="SmallUPBP -qbt S -pbt S (as smallvcm's)")
    args = parser.parse_args()
    exrtool = os.path.join(os.path.dirname(os.path.abspath(args.smallupbp)), "exrtool")
    for program in (args.smallupbp, exrtool, SMALLVCM):
        if not os.access(program, os.X_OK):
            sys.exit(f"smallupbp_compare: {program} is missing")
    if args.rounds < 2:
        sys.exit("smallupbp_compare: --rounds must be at least 2 (the regions' standard errors)")
    os.makedirs(args.out, exist_ok=True)
    gltf = write_scene(args.out)
    our_radius = scene_radius(gltf)
    matched_theirs, matched_ours = matched_arguments(args, our_radius)
    pairs = split_pairs(args.pairs)  # (SmallUPBP's side, smallvcm's side), as written
    sides = {}  # side as written -> (algorithm, the matched arguments, then its own: the last one counts)
    for theirs, ours in pairs:
        algorithm, extra = parse_side(theirs, "smallupbp")
        sides[("smallupbp", theirs)] = (algorithm, matched_theirs + extra)
        algorithm, extra = parse_side(ours, "smallvcm")
        sides[("smallvcm", ours)] = (algorithm, matched_ours + extra)
    threads = [int(t) for t in args.threads.split(",")]
    log_file = open(os.path.join(args.out, "log.txt"), "a")

    def log(line):
        print(line, flush=True)
        log_file.write(line + "\n")
        log_file.flush()

    log(f"start {time.strftime('%Y-%m-%d %H:%M:%S')} load {os.getloadavg()}: scene 1 / {gltf},"
        f" {args.resolution}^2, {args.iterations} iterations, -l {MAX_PATH_LENGTH}, rounds {args.rounds}")
    log(f"scene radius: smallvcm {our_radius:.6f}, SmallUPBP {SMALLUPBP_SCENE_RADIUS:.6f};"
        f" matched: SmallUPBP {' '.join(matched_theirs) or '(own defaults)'};"
        f" smallvcm {' '.join(matched_ours) or '(own defaults)'}")
    for (program, side), (algorithm, extra) in sides.items():
        log(f"{program} {side}: -a {algorithm} {' '.join(extra)}")
    runs = {}  # (program, side, threads) -> list of (image, cpu, wall)
    for r in range(args.rounds):
        for t in threads:
            for p, (theirs, ours) in enumerate(pairs):
                seed = 1000 * r + 100 * p + 10 * t + 1  # every run its own seed
                algorithm, extra = sides[("smallupbp", theirs)]
                image, cpu, wall = run_smallupbp(args.smallupbp, exrtool, algorithm, extra, args.resolution,
                                                 args.iterations, t, seed, args.out)
                runs.setdefault(("smallupbp", theirs, t), []).append((image, cpu, wall))
                log(f"round {r} threads {t}: smallupbp {theirs}: {cpu:.2f} CPU s, {wall:.2f} s, mean {image.mean():.5f}")
                algorithm, extra = sides[("smallvcm", ours)]
                image, cpu, wall = run_smallvcm(gltf, algorithm, extra, args.resolution, args.iterations, t, seed + 5,
                                                args.out)
                runs.setdefault(("smallvcm", ours, t), []).append((image, cpu, wall))  # pooled if two pairs share it
                log(f"round {r} threads {t}: smallvcm {ours}: {cpu:.2f} CPU s, {wall:.2f} s, mean {image.mean():.5f}")
    # Reference: every run of the two path tracers (first pair), all thread counts.
    first_theirs, first_ours = pairs[0]
    pool = [x[0] for key, v in runs.items() if (key[0], key[1]) in (("smallupbp", first_theirs), ("smallvcm", first_ours))
            for x in v]
    reference = np.mean(pool, axis=0)
    np.save(os.path.join(args.out, "reference.npy"), reference)

    def rmse(image):
        return math.sqrt(float(np.mean((image - reference) ** 2)))

    with open(os.path.join(args.out, "runs.csv"), "w") as f:
        f.write("program,algorithm,threads,run,cpu_seconds,wall_seconds,mean_r,mean_g,mean_b,rmse\n")
        for (program, side, t), v in runs.items():
            for k, (image, cpu, wall) in enumerate(v):
                m = image.mean(axis=(0, 1))
                f.write(f'{program},"{side}",{t},{k},{cpu:.4f},{wall:.4f},{m[0]:.6f},{m[1]:.6f},{m[2]:.6f},{rmse(image):.6e}\n')
    matched = " ".join(matched_theirs) if matched_theirs else "each program's own defaults"
    table = [f"Scene 1 (isosph), {args.resolution}x{args.resolution}, {args.iterations} iterations a run, -l {MAX_PATH_LENGTH},"
             f" {args.rounds} interleaved runs each; medians; load average at the end {os.getloadavg()[0]:.1f}."
             f" RMSE against the mean of all {len(pool)} path-tracer runs. Scene radius: smallvcm {our_radius:.5f},"
             f" SmallUPBP {SMALLUPBP_SCENE_RADIUS:.5f}. Merging settings: {matched}"
             f"{' (smallvcm: ' + ' '.join(matched_ours) + ')' if matched_ours else ''}.", "",
             "| program | algorithm | threads | CPU s per iteration | wall s per iteration | mean R | mean G | mean B |"
             " RMSE |", "|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    for theirs, ours in pairs:
        for t in threads:
            for program, side in (("smallupbp", theirs), ("smallvcm", ours)):
                v = runs[(program, side, t)]
                cpu = np.median([x[1] for x in v]) / args.iterations
                wall = np.median([x[2] for x in v]) / args.iterations
                m = np.mean([x[0].mean(axis=(0, 1)) for x in v], axis=0)
                se = np.std([x[0].mean(axis=(0, 1)) for x in v], axis=0, ddof=1) / math.sqrt(len(v))
                table.append(f"| {program} | {side} | {t} | {cpu:.4f} | {wall:.4f} | {m[0]:.4f} ± {se[0]:.4f} |"
                             f" {m[1]:.4f} ± {se[1]:.4f} | {m[2]:.4f} ± {se[2]:.4f} | {np.median([rmse(x[0]) for x in v]):.4f} |")
    table += ["", "Agreement, all thread counts pooled: image means and 8 x 8 regions per channel"
              " (z = difference over its standard error from the runs' spread); time and error per pair"
              " (CPU s per iteration, medians at the first thread count; RMSE medians, all thread counts).", "",
              "| SmallUPBP | smallvcm | ratio of means R, G, B | regions: mean z, std z, worst abs z, abs z > 3 |"
              " CPU s/it theirs, ours, ours/theirs | RMSE theirs, ours, ours/theirs |",
              "|---|---|---|---|---|---|"]
    for theirs, ours in pairs:
        a = [x[0] for t in threads for x in runs[("smallupbp", theirs, t)]]
        b = [x[0] for t in threads for x in runs[("smallvcm", ours, t)]]
        ratio = np.mean(b, axis=(0, 1, 2)) / np.mean(a, axis=(0, 1, 2))
        z = region_z(b, a)
        cpu_a, cpu_b = [np.median([x[1] for x in runs[(program, side, threads[0])]]) / args.iterations
                        for program, side in (("smallupbp", theirs), ("smallvcm", ours))]
        rmse_a, rmse_b = np.median([rmse(x) for x in a]), np.median([rmse(x) for x in b])
        table.append(f"| {theirs} | {ours} | {ratio[0]:.4f}, {ratio[1]:.4f}, {ratio[2]:.4f} |"
                     f" {z.mean():+.2f}, {z.std():.2f}, {np.abs(z).max():.1f}, {int(np.sum(np.abs(z) > 3))}/{z.size} |"
                     f" {cpu_a:.4f}, {cpu_b:.4f}, {cpu_b / cpu_a:.3f} | {rmse_a:.4f}, {rmse_b:.4f}, {rmse_b / rmse_a:.3f} |")
        np.save(os.path.join(args.out, f"smallupbp_{file_name(theirs)}.npy"), np.mean(a, axis=0))
        np.save(os.path.join(args.out, f"smallvcm_{file_name(ours)}.npy"), np.mean(b, axis=0))
    with open(os.path.join(args.out, "smallupbp.md"), "w") as f:
        f.write("\n".join(table) + "\n")
    for line in table:
        log(line)
    log(f"end {time.strftime('%Y-%m-%d %H:%M:%S')} load {os.getloadavg()}")


if __name__ == "__main__":
    main()
