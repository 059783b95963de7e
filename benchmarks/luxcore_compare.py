#!/usr/bin/env python3
"""smallvcm's BPT and VCM beside LuxCore's BIDIRCPU and BIDIRVMCPU on SmallVCM's default
scene, one thread each, at equal CPU time: efficiency = 1 / (MSE x CPU seconds).

    build/luxcore-venv/bin/python benchmarks/luxcore_compare.py [--budgets 10,20,40,80,120]
        [--luxcore-extra-seconds S] [--resolution 128] [--out DIR] [--reuse]

(`make bench-luxcore` makes that virtual environment, with pyluxcore and NumPy from pip,
and runs this; LuxCore is a benchmark-only dependency, never needed by make test.)

Scene: scenes/cornell_4_default.gltf (SmallVCM's kDefault: the Cornell box under the
light box, a mirror and a glass sphere), converted to LuxCore's scene description here:
- flat triangles (each glTF primitive one LuxCore mesh, from a PLY file), the two
  spheres as icospheres of 20 480 triangles with the sphere's own normal as the shading
  normal (LuxCore has no analytic sphere: the one geometric difference);
- Lambert walls -> `matte`, the mirror -> `mirror` (kr 1), the glass -> `glass` (kr = kt
  = 1, IOR 1.6 inside, 1.0 outside), the light triangles -> black `matte` with
  `emission` = the glTF radiance (gain 1, no power normalisation);
- the pinhole camera with smallvcm's horizontal field of view (square image), a box
  filter of one pixel (`BOX`, width 0.5), no tone mapping (the film's RGB output, linear
  radiance, is compared). LuxCore's film comes bottom-up and one row off against
  smallvcm's raster (the light's edges show it): `align` flips it and shifts it by at
  most one pixel, whichever is nearest the reference, and every LuxCore MSE is taken
  over all pixels but a one-pixel border (smallvcm's, from build/convergence, over all);
- path depth: `path.maxdepth` and `light.maxdepth` 10 (LuxCore limits each sub-path,
  smallvcm the whole path to 10 segments, so LuxCore renders some longer paths: the log
  gives the ratio of its image's mean to the reference's, which the MSE contains);
- the Sobol sampler (`SOBOL`, adaptive strength 0: every pixel the same samples, as in
  smallvcm) and LuxCore's other defaults (for BIDIRVMCPU: its light paths per pass,
  start radius and alpha).

The reference is smallvcm's (ours, converged): build/convergence's reference of scene 4 at
this resolution, BPT with Sobol points in two halves of their own seeds (--make-references
--reference-sampler sobol, 4096 iterations), whose noise (from its halves) is known on the
whole image and on the diffuse region (the pixels that see only Lambert surfaces; its
mask is written beside the reference). "own MSE" is the MSE against it less the
reference's noise^2 on the same pixels; efficiency = 1 / (own MSE x CPU seconds).

Timing: CPU time of one rendering thread, since the machine may be shared. LuxCore runs
in a worker process of this script: the process's CPU time from the session's start
(LuxCore's preprocessing and BVH build included), and the film is read whenever it
reaches a budget (10, 20, ... s) and once more at T = the largest budget + S
(--luxcore-extra-seconds; S defaults to the largest budget, so T = 240 s for the default
budgets), where the render stops. That later film is reported at no budget: LuxCore's
variance alone (without its difference from the reference) at each budget b is estimated
from the MSE of the budget's film against it, which contains the budget's samples and
T - b seconds more: var_b = MSE x T / (T - b) if the variance falls as 1/time
(`efficiency` says why). The estimate is best when T is well past b: the MSE is
var_b + var_T - 2 cov(film_b, film_T), so whatever var_T and the covariance depart from
b/T var_b each (a variance that does not fall exactly as 1/time, passes not in
proportion to CPU time, Sobol passes that are not independent) counts T / (T - b) times.
With S = 0 the largest budget has no estimate at all; the default makes that factor 2 at
the largest budget (the later film has half its variance) and at most 1.5 from two
thirds of it down (80 of 120 s), for S CPU seconds more per engine (ours stop at
the largest budget). Ours: one
build/convergence run per sampler (--clock cpu: the rendering thread's CPU time,
renderer creation included, scene loading not), checkpoints at 1, 2, 4, ... iterations
and where the largest budget ran out; the MSE at a budget is interpolated log-log
between the checkpoints around it. The same runs give our MSE slopes per iteration (F18's
fit: checkpoints from 8 iterations on whose own MSE is at least half the noise^2). One
run per renderer, estimator and sampler, all one after the other.

Writes DIR/efficiency.csv, DIR/efficiency.md, DIR/log.txt (DIR: build/luxcore).
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

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import mitsuba_compare as mc  # noqa: E402  (glTF reading, PLY writing, PFM reading)

ROOT = mc.ROOT
CONVERGENCE = os.path.join(ROOT, "build", "convergence")
REFERENCES = os.path.join(ROOT, "docs", "performance", "references_sobol")
SCENE = os.path.join(ROOT, "scenes", "cornell_4_default.gltf")
MAX_PATH_LENGTH = 10
SPHERE_LEVEL = 5  # icosphere subdivisions: 20 480 triangles


# ----------------------------------------------------------------------------------------
# Conversion to LuxCore's scene description
# ----------------------------------------------------------------------------------------

def write_ply_with_normals(path, positions, normals, faces):
    with open(path, "wb") as f:
        f.write((f"ply\nformat binary_little_endian 1.0\nelement vertex {len(positions)}\n"
                 "property float x\nproperty float y\nproperty float z\n"
                 "property float nx\nproperty float ny\nproperty float nz\n"
                 f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n").encode())
        f.write(np.ascontiguousarray(np.c_[positions, normals], dtype="<f4").tobytes())
        rows = np.zeros(len(faces), dtype=[("n", "u1"), ("i", "<i4", 3)])
        rows["n"] = 3
        rows["i"] = faces
        f.write(rows.tobytes())


def lux_material(name, material):
    """LuxCore property lines of a glTF material of the converted scene."""
    m = material["extensions"]["SMALLVCM_material"]
    diffuse, mirror, ior = m.get("diffuse", [0, 0, 0]), m.get("mirror", [0, 0, 0]), m.get("ior", -1.0)
    if any(m.get("phong", [0, 0, 0])):
        raise mc.ConversionError(f"material {name}: a Phong lobe has no exact LuxCore equivalent")
    key = f"scene.materials.{name}"
    if ior > 0:
        lines = [f'{key}.type = "glass"', f"{key}.kr = 1 1 1", f"{key}.kt = 1 1 1",
                 f"{key}.interiorior = {ior}", f"{key}.exteriorior = 1.0"]
    elif any(mirror):
        lines = [f'{key}.type = "mirror"', f"{key}.kr = {' '.join(map(str, mirror))}"]
    else:
        lines = [f'{key}.type = "matte"', f"{key}.kd = {' '.join(map(str, diffuse))}"]
    factor = material.get("emissiveFactor", [0, 0, 0])
    if any(factor):
        strength = material["extensions"].get("KHR_materials_emissive_strength", {}).get("emissiveStrength", 1.0)
        lines += [f"{key}.emission = {' '.join(str(f * strength) for f in factor)}",
                  f"{key}.emission.gain = 1 1 1", f"{key}.emission.power = 0", f"{key}.emission.efficency = 0",
                  f"{key}.emission.normalizebycolor = 0"]
    return lines


def convert(out_dir):
    """LuxCore scene properties (text) of SCENE; PLY files go to out_dir."""
    with open(SCENE) as f:
        gltf = json.load(f)
    buffers = mc.read_buffers(gltf, os.path.dirname(SCENE))
    lines = []
    for i, material in enumerate(gltf["materials"]):
        lines += lux_material(f"m{i}", material)
    camera = None
    for node, world in mc.world_nodes(gltf):
        if "camera" in node and camera is None:
            camera = (node, world)
        sphere = node.get("extensions", {}).get("SMALLVCM_sphere")
        shapes = []
        if sphere:
            v, faces = mc.icosphere(SPHERE_LEVEL)
            radius = sphere["radius"] * np.linalg.norm(world[:3, 0])
            positions = world[:3, 3] + radius * v
            shapes.append((positions, v, faces, sphere["material"]))
        for p, primitive in enumerate(gltf["meshes"][node["mesh"]]["primitives"] if "mesh" in node else []):
            positions = mc.read_accessor(gltf, buffers, primitive["attributes"]["POSITION"]).astype(np.float64)
            positions = (np.c_[positions, np.ones(len(positions))] @ world.T)[:, :3]
            faces = mc.read_accessor(gltf, buffers, primitive["indices"]).reshape(-1, 3).astype(np.int32)
            shapes.append((positions, None, faces, primitive["material"]))
        for positions, normals, faces, material in shapes:
            name = f"s{len(lines)}"
            ply = os.path.join(out_dir, name + ".ply")
            if normals is None:
                mc.write_ply(ply, positions, faces)
            else:
                write_ply_with_normals(ply, positions, normals, faces)
            lines += [f'scene.shapes.{name}.type = "mesh"', f'scene.shapes.{name}.ply = "{ply}"',
                      f'scene.objects.{name}.shape = "{name}"', f'scene.objects.{name}.material = "m{material}"']
    fov_x, position, forward, up = mc.camera_pose(gltf, camera)
    vec = lambda a: " ".join(f"{x:.9g}" for x in a)  # noqa: E731
    lines += ['scene.camera.type = "perspective"', f"scene.camera.lookat.orig = {vec(position)}",
              f"scene.camera.lookat.target = {vec(position + forward)}", f"scene.camera.up = {vec(up)}",
              f"scene.camera.fieldofview = {math.degrees(fov_x):.9g}"]
    return "\n".join(lines) + "\n"


def lux_config(engine, size, seconds, seed):
    lines = [f'renderengine.type = "{engine}"', 'sampler.type = "SOBOL"', "sampler.sobol.adaptive.strength = 0",
             "native.threads.count = 1", f"film.width = {size}", f"film.height = {size}",
             'film.filter.type = "BOX"', "film.filter.width = 0.5",
             f"path.maxdepth = {MAX_PATH_LENGTH}", f"light.maxdepth = {MAX_PATH_LENGTH}",
             f"batch.halttime = {seconds}", f"renderengine.seed = {seed}",
             'film.outputs.0.type = "RGB"', 'film.outputs.0.filename = "unused.exr"']
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------------------
# Renders: a LuxCore worker process, smallvcm's command line
# ----------------------------------------------------------------------------------------

def properties_from(pyluxcore, text):
    properties = pyluxcore.Properties()
    properties.SetFromString(text)
    return properties


def lux_worker(scene_file, engine, size, budgets, seed, out):
    """Runs in its own process: renders with one thread until the process has spent the
    largest of `budgets` (the later film's T included) of CPU time since the session
    started, and at each writes the RGB film (out_<budget>.npy) and its passes and CPU
    seconds (out.json)."""
    import pyluxcore
    pyluxcore.Init()  # its log goes to stdout, which the parent discards
    with open(scene_file) as f:
        scene_text = f.read()
    scene = pyluxcore.Scene()
    scene.Parse(properties_from(pyluxcore, scene_text))
    config = pyluxcore.RenderConfig(properties_from(pyluxcore, lux_config(engine, size, 1e6, seed)), scene)
    session = pyluxcore.RenderSession(config)
    start = time.process_time()
    session.Start()
    records = []
    for budget in budgets:
        while time.process_time() - start < budget:
            time.sleep(0.02)
        session.UpdateStats()
        stats = session.GetStats()
        image = np.zeros((size, size, 3), dtype=np.float32)
        session.GetFilm().GetOutputFloat(pyluxcore.FilmOutputType.RGB, image)
        np.save(f"{out}_{budget}.npy", image)
        records.append({"budget": budget, "cpu": time.process_time() - start,
                        "passes": stats.Get("stats.renderengine.pass").GetInt()})
    session.Stop()
    with open(out + ".json", "w") as f:
        json.dump(records, f)


def render_lux(out_dir, engine, size, budgets, seed, reuse):
    """{budget: (image, CPU seconds, passes)} of one LuxCore run to max(budgets) (with reuse,
    of the one already in out_dir if it went that far)."""
    out = os.path.join(out_dir, f"lux_{engine}")
    if reuse and os.path.exists(out + ".json"):
        with open(out + ".json") as f:
            reuse = max(r["budget"] for r in json.load(f)) >= max(budgets)
    if not (reuse and os.path.exists(out + ".json")):
        subprocess.run([sys.executable, os.path.abspath(__file__), "--worker", os.path.join(out_dir, "scene.scn"), engine,
                        str(size), ",".join(map(str, budgets)), str(seed), out], check=True, stdout=subprocess.DEVNULL)
    with open(out + ".json") as f:
        records = json.load(f)
    result = {}
    for r in records:
        image = np.load(f"{out}_{r['budget']}.npy").astype(np.float64)
        result[r["budget"]] = (image, r["cpu"], r["passes"])
    return result


def render_ours(out_dir, sampler, algorithms, size, budget, seed, reuse):
    """build/convergence's checkpoints (iterations 1, 2, 4, ... and the last at the budget) of
    one run per estimator, CPU time of the rendering thread, against the same reference."""
    out = os.path.join(out_dir, f"ours_{sampler}.csv")
    if not (reuse and os.path.exists(out)):
        subprocess.run([CONVERGENCE, "-q", "--scenes", "4", "--resolution", f"{size}x{size}", "--algorithms", algorithms,
                    "--sampler", sampler, "--seed", str(seed), "--max-iterations", "1048576", "--max-seconds", str(budget),
                        "--clock", "cpu", "--references", REFERENCES, "--out", out], check=True)
    runs = {}
    with open(out) as f:
        next(f)
        for line in f:
            _, algorithm, iterations, seconds, rmse, _, rmse_diffuse = line.strip().split(",")
            runs.setdefault(algorithm, []).append((int(iterations), float(seconds), float(rmse) ** 2,
                                                   float(rmse_diffuse) ** 2))
    return runs


def at_budget(checkpoints, budget, column):
    """MSE at `budget` CPU seconds: log-log interpolation between the checkpoints around it
    (the last checkpoint is where the budget ran out)."""
    points = [(t, c[column]) for c in checkpoints for t in [c[1]] if t > 0]
    below = [p for p in points if p[0] <= budget]
    above = [p for p in points if p[0] >= budget]
    if not above:
        return points[-1][1], points[-1][0]
    (t0, e0), (t1, e1) = below[-1], above[0]
    if t1 == t0:
        return e0, t0
    w = math.log(budget / t0) / math.log(t1 / t0)
    return math.exp((1 - w) * math.log(e0) + w * math.log(e1)), budget


def fitted_slope(checkpoints, column, noise2):
    """F18's fit: least squares of log(own MSE) against log(iterations) over the checkpoints
    from 8 iterations on whose own MSE (MSE - reference noise^2) is at least 0.5 noise^2."""
    points = [(math.log(c[0]), math.log(c[column] - noise2)) for c in checkpoints
              if c[0] >= 8 and c[column] - noise2 >= 0.5 * noise2]
    if len(points) < 3:
        return float("nan"), len(points)
    mx = sum(p[0] for p in points) / len(points)
    my = sum(p[1] for p in points) / len(points)
    return (sum((p[0] - mx) * (p[1] - my) for p in points) / sum((p[0] - mx) ** 2 for p in points)), len(points)


# ----------------------------------------------------------------------------------------
# Steps
# ----------------------------------------------------------------------------------------

def load_reference(size):
    stem = os.path.join(REFERENCES, f"cornell_4_{size}x{size}")
    if not os.path.exists(stem + ".pfm"):
        raise SystemExit(f"{stem}.pfm: no reference; make it with build/convergence --scenes 4 --resolution {size}x{size} "
                         "--make-references --reference-sampler sobol --references docs/performance/references_sobol ...")
    settings = {}
    with open(stem + ".txt") as f:
        for line in f:
            if " = " in line:
                key, value = line.rstrip("\n").split(" = ", 1)
                settings[key] = value.split(" ")[0]
    mask = mc.read_pfm(stem + "_diffuse.pfm")[:, :, 0] > 0.5
    return mc.read_pfm(stem + ".pfm"), float(settings["noise_rmse"]), float(settings["noise_rmse_diffuse"]), mask


def interior(size):
    """All pixels but a one-pixel border: the alignment below may roll a row or column over."""
    mask = np.zeros((size, size), dtype=bool)
    mask[1:-1, 1:-1] = True
    return mask


def mse(image, reference, mask):
    return float(((image - reference) ** 2)[mask].mean())


def align(image, reference, mask):
    """LuxCore's film the way up, and shifted by at most one pixel, that is nearest the
    reference: its rows come bottom-up, and one row off against smallvcm's raster (seen at
    the light's edges, which every render of it shows at the same place)."""
    best = None
    for flipped in (image, image[::-1]):
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                candidate = np.roll(flipped, (dy, dx), axis=(0, 1))
                error = mse(candidate, reference, mask)
                if best is None or error < best[0]:
                    best = (error, candidate, (flipped is not image, dy, dx))
    return best[1], best[2]


def efficiency(out_dir, size, budgets, luxcore_later, reference, noise2, noise2_diffuse, mask, log, reuse):
    rows = []
    whole = interior(size)
    mask = mask & whole
    longest = max(budgets)
    for k, engine in enumerate(["BIDIRCPU", "BIDIRVMCPU"]):
        renders = render_lux(out_dir, engine, size, sorted(set(budgets) | {luxcore_later}), 100 + k, reuse)
        # the later film: at luxcore_later, or later still in a reused run
        run_longest = max(renders)
        last, _ = align(renders[run_longest][0], reference, whole)
        log(f"efficiency: luxcore {engine} later film (variance only) {run_longest} s: {renders[run_longest][1]:.1f} s "
            f"CPU, {renders[run_longest][2]} passes")
        for budget, (image, cpu, passes) in sorted(renders.items()):
            if budget not in budgets:
                continue
            image, (flipped, dy, dx) = align(image, reference, whole)
            e, ed = mse(image, reference, whole), mse(image, reference, mask)
            row = dict(renderer="luxcore", estimator=engine, sampler="sobol", budget=budget, cpu=cpu, samples=passes,
                       mse=e, mse_d=ed, later=run_longest)
            # LuxCore's variance alone, without its difference from our reference: from the
            # MSE against its own later film B (at T) of the same run. That film holds this
            # one's b seconds of samples and B - b more: img_B = (b img_b + (B - b) rest) / B,
            # so img_b - img_B = (B - b) / B (img_b - rest), whose mean square is
            # ((B - b) / B)^2 var_b (1 + b / (B - b)) = var_b (B - b) / B if the variance
            # falls as 1 / time (the common bias cancels). In general it is var_b + var_B -
            # 2 cov(img_b, img_B), so a var_B or covariance off b / B var_b counts B / (B - b)
            # times in the estimate: B well past b.
            if budget < run_longest:
                scale = run_longest / (run_longest - budget)
                row["var"] = mse(image, last, whole) * scale
                row["var_d"] = mse(image, last, mask) * scale
            rows.append(row)
            log(f"efficiency: luxcore {engine} {budget} s: {cpu:.1f} s CPU, {passes} passes, rows "
                f"{'bottom-up' if flipped else 'top-down'}, shifted by ({dx}, {dy}) px, mean "
                f"{image.mean() / reference.mean():.4f} x the reference's, MSE {e:.4g}, diffuse {ed:.4g}")
    slopes = {}
    for sampler, algorithms in (("independent", "bpt,vcm"), ("sobol", "pt,bpt,vcm")):
        runs = render_ours(out_dir, sampler, algorithms, size, longest, 1234, reuse)
        for algorithm, checkpoints in runs.items():
            for budget in budgets:
                if checkpoints[-1][1] < 0.99 * budget:
                    continue  # (a reused run shorter than this budget)
                e, cpu = at_budget(checkpoints, budget, 2)
                ed, _ = at_budget(checkpoints, budget, 3)
                iterations = [c[0] for c in checkpoints if c[1] <= budget][-1]
                rows.append(dict(renderer="smallvcm", estimator=algorithm, sampler=sampler, budget=budget, cpu=cpu,
                                 samples=iterations, mse=e, mse_d=ed))
            slopes[(algorithm, sampler)] = (fitted_slope(checkpoints, 3, noise2_diffuse), fitted_slope(checkpoints, 2, noise2))
            log(f"efficiency: smallvcm {algorithm} {sampler}: {checkpoints[-1][0]} iterations in {checkpoints[-1][1]:.1f} s "
                f"CPU; MSE slope per iteration, diffuse region {slopes[(algorithm, sampler)][0][0]:+.3f} "
                f"({slopes[(algorithm, sampler)][0][1]} points), whole image {slopes[(algorithm, sampler)][1][0]:+.3f}")
    with open(os.path.join(out_dir, "efficiency.csv"), "w") as csv:
        csv.write("renderer,estimator,sampler,budget,cpu_seconds,samples,mse,mse_own,mse_diffuse,mse_diffuse_own,"
                  "efficiency,efficiency_diffuse,variance,variance_diffuse\n")
        for r in rows:
            r["own"], r["own_d"] = max(r["mse"] - noise2, 1e-30), max(r["mse_d"] - noise2_diffuse, 1e-30)
            r["eff"], r["eff_d"] = 1.0 / (r["own"] * r["cpu"]), 1.0 / (r["own_d"] * r["cpu"])
            if "var" in r:
                r["eff_var"], r["eff_var_d"] = 1.0 / (r["var"] * r["cpu"]), 1.0 / (r["var_d"] * r["cpu"])
            csv.write(f"{r['renderer']},{r['estimator']},{r['sampler']},{r['budget']},{r['cpu']:.3f},{r['samples']},"
                      f"{r['mse']:.6g},{r['own']:.6g},{r['mse_d']:.6g},{r['own_d']:.6g},{r['eff']:.6g},{r['eff_d']:.6g},"
                      f"{r.get('var', float('nan')):.6g},{r.get('var_d', float('nan')):.6g}\n")
    return rows, slopes


def write_table(out_dir, rows, slopes, noise2, noise2_diffuse):
    lines = ["| budget (CPU s) | renderer | estimator | sampler | CPU s | samples/px | RMSE | own MSE | own MSE, diffuse | "
             "efficiency | efficiency, diffuse | ours / BIDIR | ours / BIDIRVM | ours / BIDIR, diffuse | ours / BIDIRVM, diffuse |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    lines_var = ["| budget (CPU s) | estimator | sampler | ours / BIDIR (variance) | ours / BIDIRVM (variance) | "
                 "ours / BIDIR, diffuse (variance) | ours / BIDIRVM, diffuse (variance) |", "|---|---|---|---|---|---|---|"]
    for budget in sorted({r["budget"] for r in rows}):
        at = [r for r in rows if r["budget"] == budget]
        lux = {r["estimator"]: r for r in at if r["renderer"] == "luxcore"}
        for r in at:
            def ratio(engine, key, lux_key=None):
                lux_key = lux_key or key
                if r["renderer"] != "smallvcm" or engine not in lux or lux_key not in lux[engine]:
                    return ""
                return f"{r[key] / lux[engine][lux_key]:.2f}"
            lines.append(f"| {budget} | {r['renderer']} | {r['estimator']} | {r['sampler']} | {r['cpu']:.1f} | "
                         f"{r['samples']} | {math.sqrt(r['mse']):.4g} | {r['own']:.3g} | {r['own_d']:.3g} | "
                         f"{r['eff']:.4g} | {r['eff_d']:.4g} | {ratio('BIDIRCPU', 'eff')} | {ratio('BIDIRVMCPU', 'eff')} | "
                         f"{ratio('BIDIRCPU', 'eff_d')} | {ratio('BIDIRVMCPU', 'eff_d')} |")
            if r["renderer"] == "smallvcm" and any("eff_var" in x for x in lux.values()):
                lines_var.append(f"| {budget} | {r['estimator']} | {r['sampler']} | {ratio('BIDIRCPU', 'eff', 'eff_var')} | "
                                 f"{ratio('BIDIRVMCPU', 'eff', 'eff_var')} | {ratio('BIDIRCPU', 'eff_d', 'eff_var_d')} | "
                                 f"{ratio('BIDIRVMCPU', 'eff_d', 'eff_var_d')} |")
    later = " and ".join(sorted({f"{r['later']}" for r in rows if "later" in r}, key=int))
    lines += ["", f"Reference noise^2 subtracted (own MSE): {noise2:.3g} (whole image), {noise2_diffuse:.3g} (diffuse region).",
              "Efficiency = 1 / (own MSE x CPU s).", "",
              "LuxCore's variance alone (its MSE against its own later film B x B / (B - budget), "
              f"B = {later} s), our own MSE against it:", ""] + lines_var
    lines += ["", "| estimator | sampler | MSE slope per iteration, diffuse region (points) | whole image (points) |",
              "|---|---|---|---|"]
    for (algorithm, sampler), ((slope_d, n_d), (slope, n)) in sorted(slopes.items()):
        lines.append(f"| {algorithm} | {sampler} | {slope_d:+.3f} ({n_d}) | {slope:+.3f} ({n}) |")
    with open(os.path.join(out_dir, "efficiency.md"), "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))


def main():
    if len(sys.argv) > 1 and sys.argv[1] == "--worker":
        scene_file, engine, size, budgets, seed, out = sys.argv[2:8]
        lux_worker(scene_file, engine, int(size), [int(b) for b in budgets.split(",")], int(seed), out)
        return
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", default=os.path.join(ROOT, "build", "luxcore"))
    parser.add_argument("--resolution", type=int, default=128)
    parser.add_argument("--budgets", default="10,20,40,80,120")
    parser.add_argument("--luxcore-extra-seconds", type=int, default=None,
                        help="LuxCore renders this many CPU seconds past the largest budget, to the film that "
                             "its variance is estimated against (default: the largest budget, i.e. to twice it)")
    parser.add_argument("--reuse", action="store_true",
                        help="use the renders already in --out (same budgets), render only what is missing")
    args = parser.parse_args()
    os.makedirs(args.out, exist_ok=True)
    budgets = [int(b) for b in args.budgets.split(",")]
    later = max(budgets) + (max(budgets) if args.luxcore_extra_seconds is None else args.luxcore_extra_seconds)
    log_file = open(os.path.join(args.out, "log.txt"), "a")

    def log(line):
        print(line, flush=True)
        log_file.write(line + "\n")
        log_file.flush()

    with open(os.path.join(args.out, "scene.scn"), "w") as f:
        f.write(convert(args.out))
    reference, noise, noise_diffuse, mask = load_reference(args.resolution)
    log(f"luxcore_compare {time.strftime('%Y-%m-%d %H:%M:%S')}: {args.resolution}x{args.resolution}, budgets {budgets}, "
        f"LuxCore's later film at {later} s, "
        f"reference noise RMSE {noise:.4g} (diffuse {noise_diffuse:.4g}, {int(mask.sum())} pixels)")
    rows, slopes = efficiency(args.out, args.resolution, budgets, later, reference, noise ** 2, noise_diffuse ** 2, mask,
                              log, args.reuse)
    write_table(args.out, rows, slopes, noise ** 2, noise_diffuse ** 2)


if __name__ == "__main__":
    main()
