#!/usr/bin/env python3
"""smallvcm's path tracer beside Mitsuba 3's, on the same scenes, one core each.

    build/mitsuba-venv/bin/python benchmarks/mitsuba_compare.py [--out DIR] [--quick] [--repeats N] [STEP ...]

(`make bench-mitsuba` makes that virtual environment and runs this.) STEP is any of
`convert`, `agree`, `efficiency` (default: all three, in that order) and `media` (only
when asked: `... mitsuba_compare.py media [--media-batches 8 --media-spp 16]`, the defaults).

convert     Converts two smallvcm glTF scenes to Mitsuba 3 scene dictionaries (the meshes
            as PLY files in DIR): scene 4 (`scenes/cornell_4_default.gltf`) and a mesh
            scene written here, `DIR/displaced_sphere_box.gltf`: the empty white-floored
            box under its area light (`scenes/diffuse_box.gltf`) with a flat-shaded,
            displaced sphere of 81 920 triangles on the floor. Only what Mitsuba
            represents exactly is converted (Lambert, perfect mirror, clear glass,
            one-sided area lights, flat triangles, spheres, a pinhole camera); anything
            else is refused with one line naming the file and what is not converted.
agree       Renders each scene with both programs in independent batches (other seeds)
            and compares the converged images: the mean of each, and per pixel the
            difference over its standard error (from the spread of the batches).
efficiency  One core each, several sample budgets, CPU seconds of the render and its MSE
            against one reference (the mean of the two long renders of `agree`, equal in
            samples, with whose seeds the timed runs share none); efficiency =
            1/(time x MSE).
media       Participating media (docs/scene_format.md 4.4) against Mitsuba's `volpath`
            (`scalar_rgb`, no LLVM needed), one core each: scenes/dense_scattering_sphere
            (a dense medium behind an index-matched boundary: `null` BSDF with an
            `interior` medium; path length 64 in both), scenes/absorbing_glass
            (KHR_materials_volume: `dielectric` with an absorbing `interior`; 20) and
            scenes/fog_caustic_box (the scene medium: the sensor's `medium`, and the
            `exterior` of the glass sphere, whose `interior` is a clear medium; 20).
            At half the resolution of `agree`, independent batches of smallvcm's pt, bpt
            and vcm and of volpath: per-channel image means, 8 x 8 regions' z per channel
            (difference over its standard error from the batches' spread), CPU time per
            sample. Writes DIR/media.md (appended) and the log. The medium conversion:
            sigma_t = sigma_a + sigma_s and albedo = sigma_s / sigma_t per channel, phase
            `hg` with the same g. Mitsuba's volpath counts depth as smallvcm counts path
            length: a medium scattering vertex increments it, a `null` crossing does not
            (smallvcm's index-matched boundaries are no vertex either), and direct light
            from a vertex at depth d needs d + 1 <= max_depth in both. Mitsuba keeps the
            current medium across a surface that names none, so a glass in a scene medium
            gets a clear medium (sigma_t 0) as interior, as smallvcm's glass is empty
            inside. A homogeneous medium in Mitsuba has no bounds: as the sensor's medium it
            fills all space outside the shapes' interiors, smallvcm's scene-medium rule.

What makes the two compute the same quantity (each item is checked by `agree`):
- camera: smallvcm keeps the horizontal field of view 2 atan(tan(yfov/2) aspect) and
  square pixels; Mitsuba's `perspective` sensor with `fov_axis: x` does the same.
  Pixel (x, y) covers [x, x+1) x [y, y+1), row 0 at the top, in both.
- reconstruction: smallvcm averages one uniform sample per pixel per iteration (a box
  filter of one pixel); Mitsuba's film gets `rfilter: box` (its default is gaussian).
- path length: smallvcm's `--max-path-length 10` counts segments from the camera (an
  emitter seen directly is 1, direct light on the first hit is 2); Mitsuba's
  `max_depth` counts the same way (1 = emitters seen directly, 2 = direct light), so 10.
- Russian roulette: smallvcm from the first hit, continuation = max albedo; Mitsuba's
  `path` from depth `rr_depth` (its default 5, kept), continuation = min(0.95, max of
  the throughput). Both are unbiased: they change noise, not the mean. So does the MIS
  heuristic (smallvcm's default balance, Mitsuba's `path` power).
- RGB: the `llvm_ad_rgb` and `scalar_rgb` variants, reflectances and radiance as the
  glTF gives them (linear RGB, no spectral upsampling).
- one-sided: smallvcm's Lambert surfaces and area lights are one-sided; so are
  Mitsuba's `diffuse` and `area` (no `twosided` wrapper). Lights are black.
- the meshes keep their flat faces (PLY with `face_normals: true`; Mitsuba otherwise
  makes smooth vertex normals), each glTF primitive one Mitsuba shape, so the two
  light triangles of scene 4 are two lights in both, each picked with probability 1/2.
Timing: the machine may be shared, so the two programs run interleaved (smallvcm,
Mitsuba, smallvcm, ...) and the time counted is the CPU time of the render (user +
system), which another process on the machine does not inflate as it does wall time;
wall time is printed too. Mitsuba's first render of a scene compiles its kernel (or
loads it from Dr.Jit's cache); that render is timed separately and not counted.
Writes DIR/agreement.txt, DIR/efficiency.csv, DIR/efficiency.md and appends to DIR/log.txt
(DIR: build/mitsuba). Mitsuba's LLVM variant needs DRJIT_LIBLLVM_PATH to name an LLVM
newer than Debian 12's default 14 (the Makefile target sets libLLVM-19).
"""

import argparse
import base64
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


class ConversionError(Exception):
    pass


# ----------------------------------------------------------------------------------------
# glTF reading: only what the converted scenes use (triangles, SMALLVCM_sphere, camera)
# ----------------------------------------------------------------------------------------

def read_buffers(gltf, folder):
    buffers = []
    for buffer in gltf.get("buffers", []):
        uri = buffer["uri"]
        if uri.startswith("data:"):
            buffers.append(base64.b64decode(uri.split(",", 1)[1]))
        else:
            with open(os.path.join(folder, uri), "rb") as f:
                buffers.append(f.read())
    return buffers


def read_accessor(gltf, buffers, index):
    accessor = gltf["accessors"][index]
    view = gltf["bufferViews"][accessor["bufferView"]]
    dtype = {5126: np.float32, 5125: np.uint32, 5123: np.uint16, 5121: np.uint8}[accessor["componentType"]]
    width = {"SCALAR": 1, "VEC3": 3}[accessor["type"]]
    item = np.dtype(dtype).itemsize * width
    stride = view.get("byteStride", item)
    start = view.get("byteOffset", 0) + accessor.get("byteOffset", 0)
    data = buffers[view["buffer"]]
    rows = [np.frombuffer(data, dtype, width, start + k * stride) for k in range(accessor["count"])] \
        if stride != item else [np.frombuffer(data, dtype, width * accessor["count"], start)]
    return np.concatenate(rows).reshape(-1, width)


def node_matrix(node):
    if "matrix" in node:
        return np.array(node["matrix"], dtype=np.float64).reshape(4, 4).T
    t = np.array(node.get("translation", [0, 0, 0]), dtype=np.float64)
    x, y, z, w = node.get("rotation", [0, 0, 0, 1])
    s = np.array(node.get("scale", [1, 1, 1]), dtype=np.float64)
    r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    m = np.eye(4)
    m[:3, :3] = r * s
    m[:3, 3] = t
    return m


def world_nodes(gltf):
    """(node, world matrix) in the depth-first order of the default scene."""
    out = []

    def visit(index, parent):
        node = gltf["nodes"][index]
        world = parent @ node_matrix(node)
        out.append((node, world))
        for child in node.get("children", []):
            visit(child, world)

    for root in gltf["scenes"][gltf.get("scene", 0)]["nodes"]:
        visit(root, np.eye(4))
    return out


# ----------------------------------------------------------------------------------------
# Conversion to a Mitsuba 3 scene dictionary
# ----------------------------------------------------------------------------------------

KNOWN_MATERIAL_KEYS = {"name", "pbrMetallicRoughness", "emissiveFactor", "extensions"}
KNOWN_MATERIAL_EXTENSIONS = {"SMALLVCM_material", "KHR_materials_emissive_strength",
                             "KHR_materials_transmission", "KHR_materials_ior",
                             "SMALLVCM_medium", "KHR_materials_volume"}


def medium_coefficients(m, where):
    """(sigma_a, sigma_s, g) of a SMALLVCM_medium object (docs/scene_format.md 4.4)."""
    if set(m) - {"sigmaA", "sigmaS", "g"}:
        raise ConversionError(f"{where}: SMALLVCM_medium member {sorted(set(m) - {'sigmaA', 'sigmaS', 'g'})}")
    return [float(x) for x in m.get("sigmaA", [0, 0, 0])], [float(x) for x in m.get("sigmaS", [0, 0, 0])], float(m.get("g", 0.0))


def mitsuba_medium(coefficients):
    """Mitsuba's `homogeneous` medium for (sigma_a, sigma_s, g): per RGB channel
    sigma_t = sigma_a + sigma_s and albedo = sigma_s / sigma_t (0 where sigma_t is 0), an
    `hg` phase function with the same g (Mitsuba's HG is the same function of the angle
    between the directions of travel: g > 0 scatters forwards in both)."""
    sigma_a, sigma_s, g = coefficients
    sigma_t = [a + s for a, s in zip(sigma_a, sigma_s)]
    albedo = [s / t if t > 0 else 0.0 for s, t in zip(sigma_s, sigma_t)]
    # An "rgb" value must lie in [0, 1]: sigma_t goes in as its largest channel (`scale`)
    # times the channels divided by it.
    scale = max(sigma_t) if max(sigma_t) > 0 else 1.0
    return {"type": "homogeneous", "sigma_t": {"type": "rgb", "value": [t / scale for t in sigma_t]}, "scale": scale,
            "albedo": {"type": "rgb", "value": albedo}, "phase": {"type": "hg", "g": g}}


# Empty space inside a glass in a scene medium (smallvcm: "its inside is empty space unless
# its material names a medium"). Mitsuba keeps the current medium across a surface that
# names none, so such a glass gets this clear medium as its interior.
CLEAR_MEDIUM = ([0.0, 0.0, 0.0], [0.0, 0.0, 0.0], 0.0)


def mitsuba_material(material, where):
    """(bsdf dict, emitter dict or None, medium inside or None) for a material Mitsuba
    represents exactly. The medium is (sigma_a, sigma_s, g); with it a material that does not
    refract is an index-matched boundary: Mitsuba's `null` BSDF."""
    unknown = set(material) - KNOWN_MATERIAL_KEYS
    if unknown:
        raise ConversionError(f"{where}: {sorted(unknown)} has no exact Mitsuba equivalent here")
    extensions = material.get("extensions", {})
    if set(extensions) - KNOWN_MATERIAL_EXTENSIONS:
        raise ConversionError(f"{where}: extension {sorted(set(extensions) - KNOWN_MATERIAL_EXTENSIONS)} not converted")
    if "baseColorTexture" in material.get("pbrMetallicRoughness", {}):
        raise ConversionError(f"{where}: textures are not converted")
    factor = material.get("emissiveFactor", [0, 0, 0])
    emitter = None
    if any(factor):
        strength = extensions.get("KHR_materials_emissive_strength", {}).get("emissiveStrength", 1.0)
        emitter = {"type": "area", "radiance": {"type": "rgb", "value": [f * strength for f in factor]}}
    if "SMALLVCM_material" in extensions:
        m = extensions["SMALLVCM_material"]
        diffuse = list(m.get("diffuse", [0, 0, 0]))
        phong = m.get("phong", [0, 0, 0])
        mirror = list(m.get("mirror", [0, 0, 0]))
        ior = m.get("ior", -1.0)
        transmittance = [1.0, 1.0, 1.0]
    else:
        # docs/scene_format.md 4.2 and 4.3, only where the result has an exact Mitsuba
        # equivalent: an emitter (black without SMALLVCM_material), a perfect mirror
        # (metallic 1, roughness 0), clear or tinted glass (transmission 1, metallic 0).
        pbr = material.get("pbrMetallicRoughness", {})
        b = [float(x) for x in pbr.get("baseColorFactor", [1, 1, 1, 1])[:3]]
        metallic, roughness = float(pbr.get("metallicFactor", 1.0)), float(pbr.get("roughnessFactor", 1.0))
        t = float(extensions.get("KHR_materials_transmission", {}).get("transmissionFactor", 0.0))
        diffuse, phong, mirror, ior, transmittance = [0, 0, 0], [0, 0, 0], [0, 0, 0], -1.0, [1.0, 1.0, 1.0]
        if emitter is not None:
            pass  # an emissive material without SMALLVCM_material is black (5.1)
        elif "SMALLVCM_medium" in extensions and not (t > 0 and metallic < 1):
            pass  # an index-matched boundary: no component at all (4.4)
        elif metallic == 1.0 and roughness == 0.0:
            mirror = b
        elif t == 1.0 and metallic == 0.0:
            ior = float(extensions.get("KHR_materials_ior", {}).get("ior", 1.5))
            mirror, transmittance = [1.0, 1.0, 1.0], b
            # (roughness shapes only the opaque share, which is 0 here: smooth glass)
        else:
            raise ConversionError(f"{where}: this pbrMetallicRoughness mapping has no exact Mitsuba equivalent"
                                  " (only emitters, perfect mirrors and glass of transmission 1 are converted)")
    # The medium inside (4.4): SMALLVCM_medium wins; KHR_materials_volume only on glass
    # that is not thin-walled (thicknessFactor > 0).
    medium = None
    if "SMALLVCM_medium" in extensions:
        medium = medium_coefficients(extensions["SMALLVCM_medium"], where)
    elif ("KHR_materials_volume" in extensions and ior > 0
          and float(extensions["KHR_materials_volume"].get("thicknessFactor", 0)) > 0):
        v = extensions["KHR_materials_volume"]
        distance = float(v.get("attenuationDistance", math.inf))
        colour = [float(c) for c in v.get("attenuationColor", [1, 1, 1])]
        if math.isfinite(distance) and any(c < 1 for c in colour):
            medium = ([-math.log(max(c, 1e-38)) / distance for c in colour], [0.0, 0.0, 0.0], 0.0)
    if any(phong):
        raise ConversionError(f"{where}: a Phong lobe has no exact Mitsuba equivalent")
    if any(diffuse) and (any(mirror) or ior > 0):
        raise ConversionError(f"{where}: a Lambert lobe mixed with a specular one is not converted")
    if ior > 0:
        if mirror != [1.0, 1.0, 1.0]:
            raise ConversionError(f"{where}: tinted glass is not converted")
        bsdf = {"type": "dielectric", "int_ior": float(ior), "ext_ior": 1.0}
        if transmittance != [1.0, 1.0, 1.0]:  # applied at each crossing, as smallvcm's (4.3)
            bsdf["specular_transmittance"] = {"type": "rgb", "value": transmittance}
    elif medium is not None and not any(diffuse) and not any(mirror):
        bsdf = {"type": "null"}
    elif medium is not None:
        raise ConversionError(f"{where}: a medium behind a surface that neither refracts nor is index-matched")
    elif any(mirror):
        # An IOR below 0 means no Fresnel term: a perfect mirror tinted by `mirror`. It
        # reflects on both sides in smallvcm (docs/scene_format.md, "one-sided"), so on
        # both in Mitsuba too (`twosided`; a bare conductor is black from behind).
        bsdf = {"type": "twosided", "bsdf": {"type": "conductor", "material": "none",
                                             "specular_reflectance": {"type": "rgb", "value": mirror}}}
    else:
        bsdf = {"type": "diffuse", "reflectance": {"type": "rgb", "value": diffuse}}
    return bsdf, emitter, medium


def camera_pose(gltf, camera):
    """The glTF camera (node, world matrix) as (horizontal field of view in radians,
    position, unit forward direction, up vector)."""
    node, world = camera
    perspective = gltf["cameras"][node["camera"]]["perspective"]
    aspect = perspective.get("aspectRatio", 1.0) or 1.0
    fov_x = 2 * math.atan(math.tan(perspective["yfov"] / 2) * aspect)
    position = world[:3, 3]
    forward = -world[:3, 2] / np.linalg.norm(world[:3, 2])
    return fov_x, position, forward, world[:3, 1]


def write_ply(path, positions, faces, normals=None):
    with open(path, "wb") as f:
        f.write((f"ply\nformat binary_little_endian 1.0\nelement vertex {len(positions)}\n"
                 "property float x\nproperty float y\nproperty float z\n"
                 + ("property float nx\nproperty float ny\nproperty float nz\n" if normals is not None else "")
                 + f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n").encode())
        vertices = positions if normals is None else np.c_[positions, normals]
        f.write(np.ascontiguousarray(vertices, dtype="<f4").tobytes())
        rows = np.zeros(len(faces), dtype=[("n", "u1"), ("i", "<i4", 3)])
        rows["n"] = 3
        rows["i"] = faces
        f.write(rows.tobytes())


def read_normals(gltf, buffers, primitive, world):
    """The primitive's vertex normals in world space (inverse transpose), or None."""
    if "NORMAL" not in primitive["attributes"]:
        return None
    normals = read_accessor(gltf, buffers, primitive["attributes"]["NORMAL"]).astype(np.float64)
    normals = normals @ np.linalg.inv(world[:3, :3])
    return normals / np.linalg.norm(normals, axis=1)[:, None]


def convert(gltf_path, out_dir, width, height, max_depth=MAX_PATH_LENGTH):
    """A Mitsuba 3 scene dictionary and the number of triangles; PLY files go to out_dir.
    The integrator is `path`, or `volpath` when the scene has a medium (4.4 of
    docs/scene_format.md): a material's medium becomes the `interior` of its shapes (their
    `exterior` the scene medium, if any), the scene medium the sensor's medium. max_depth
    counts as smallvcm's --max-path-length (the module's opening comment)."""
    with open(gltf_path) as f:
        gltf = json.load(f)
    name = os.path.splitext(os.path.basename(gltf_path))[0]
    unknown = set(gltf.get("extensionsUsed", [])) - KNOWN_MATERIAL_EXTENSIONS - {"SMALLVCM_sphere"}
    if unknown:  # punctual and background lights, texture transforms, ...
        raise ConversionError(f"{gltf_path}: extension {sorted(unknown)} is not converted")
    buffers = read_buffers(gltf, os.path.dirname(gltf_path))
    materials = [mitsuba_material(m, f"{gltf_path}: material {i}") for i, m in enumerate(gltf["materials"])]
    scene_extensions = gltf["scenes"][gltf.get("scene", 0)].get("extensions", {})
    scene_medium = None
    if "SMALLVCM_medium" in scene_extensions:
        scene_medium = medium_coefficients(scene_extensions["SMALLVCM_medium"], f"{gltf_path}: scene")
    has_media = scene_medium is not None or any(medium is not None for _, _, medium in materials)
    integrator = "volpath" if has_media else "path"
    scene = {"type": "scene",
             "integrator": {"type": integrator, "max_depth": max_depth, "rr_depth": 5, "hide_emitters": False}}
    if scene_medium is not None:
        scene["scene_medium"] = mitsuba_medium(scene_medium)
    media = {}  # material index -> the id of its interior medium

    def attach(shape, material_index):
        bsdf, emitter, medium = materials[material_index]
        shape["bsdf"] = bsdf
        if emitter:
            shape["emitter"] = emitter
        refracts = bsdf["type"] == "dielectric"
        if medium is None and refracts and scene_medium is not None:
            medium = CLEAR_MEDIUM  # glass around empty space, in the scene medium
        if medium is not None:
            if material_index not in media:
                media[material_index] = f"medium_{material_index}"
                scene[media[material_index]] = mitsuba_medium(medium)
            shape["interior"] = {"type": "ref", "id": media[material_index]}
            if scene_medium is not None:
                shape["exterior"] = {"type": "ref", "id": "scene_medium"}
        return shape

    triangles = 0
    camera = None
    for node, world in world_nodes(gltf):
        if "camera" in node and camera is None:
            camera = (node, world)
        sphere = node.get("extensions", {}).get("SMALLVCM_sphere")
        if sphere:
            scale = np.linalg.norm(world[:3, 0])
            shape = {"type": "sphere", "center": world[:3, 3].tolist(), "radius": sphere["radius"] * scale}
            scene[f"sphere_{len(scene)}"] = attach(shape, sphere["material"])
        if "mesh" in node:
            for p, primitive in enumerate(gltf["meshes"][node["mesh"]]["primitives"]):
                if primitive.get("mode", 4) != 4 or set(primitive["attributes"]) - {"POSITION", "NORMAL"}:
                    raise ConversionError(f"{gltf_path}: mesh {node['mesh']} primitive {p}: only triangles"
                                          " with positions and normals are converted")
                positions = read_accessor(gltf, buffers, primitive["attributes"]["POSITION"]).astype(np.float64)
                positions = (np.c_[positions, np.ones(len(positions))] @ world.T)[:, :3]
                normals = read_normals(gltf, buffers, primitive, world)
                faces = read_accessor(gltf, buffers, primitive["indices"]).reshape(-1, 3).astype(np.int32)
                ply = os.path.join(out_dir, f"{name}_mesh{node['mesh']}_{p}.ply")
                write_ply(ply, positions, faces, normals)
                # Flat faces unless the glTF gives normals (smooth shading normals then).
                shape = {"type": "ply", "filename": ply, "face_normals": normals is None}
                scene[f"mesh_{len(scene)}"] = attach(shape, primitive["material"])
                triangles += len(faces)
    if not any("emitter" in shape for shape in scene.values() if isinstance(shape, dict)):
        raise ConversionError(f"{gltf_path}: no light (the default sky and sun are not converted)")
    if camera is None:
        raise ConversionError(f"{gltf_path}: no camera (the made-up default camera is not converted)")
    fov_x, position, forward, up = camera_pose(gltf, camera)
    scene["sensor"] = {
        "type": "perspective", "fov_axis": "x", "fov": math.degrees(fov_x), "near_clip": 1e-3,
        "to_world": ("look_at", position.tolist(), (position + forward).tolist(), up.tolist()),
        "sampler": {"type": "independent", "sample_count": 1},
        "film": {"type": "hdrfilm", "width": width, "height": height, "pixel_format": "rgb",
                 "sample_border": False, "rfilter": {"type": "box"}}}
    if scene_medium is not None:
        # The camera is in the scene medium. Mitsuba's homogeneous medium has no bounds: a
        # sensor's medium fills all space not claimed by a shape's interior, so, as in
        # smallvcm, nothing from infinity gets through it.
        scene["sensor"]["medium"] = {"type": "ref", "id": "scene_medium"}
    return scene, triangles


def icosphere(level):
    t = (1 + 5 ** 0.5) / 2
    v = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t],
                  [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], dtype=np.float64)
    f = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
                  [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
                  [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]])
    v /= np.linalg.norm(v, axis=1)[:, None]
    for _ in range(level):
        n = len(f)
        edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        unique, inverse = np.unique(edges, axis=0, return_inverse=True)
        middle = v[unique[:, 0]] + v[unique[:, 1]]
        middle /= np.linalg.norm(middle, axis=1)[:, None]
        m = len(v) + inverse.reshape(-1)
        m01, m12, m20 = m[:n], m[n:2 * n], m[2 * n:]
        v = np.vstack([v, middle])
        f = np.concatenate([np.c_[f[:, 0], m01, m20], np.c_[f[:, 1], m12, m01],
                            np.c_[f[:, 2], m20, m12], np.c_[m01, m12, m20]])
    return v, f


def write_mesh_scene(out_dir):
    """scenes/diffuse_box.gltf plus a displaced sphere of 81 920 flat, outward triangles."""
    with open(os.path.join(ROOT, "scenes", "diffuse_box.gltf")) as f:
        gltf = json.load(f)
    directions, faces = icosphere(6)
    x, y, z = directions.T
    radius = 0.5 * (1 + 0.12 * np.sin(6 * x) * np.sin(7 * y) * np.sin(5 * z) + 0.04 * np.sin(23 * (x + z)))
    positions = directions * radius[:, None] + np.array([0.00973, 0.02453, -1.28002 + 0.58])
    normals = np.cross(positions[faces[:, 1]] - positions[faces[:, 0]], positions[faces[:, 2]] - positions[faces[:, 0]])
    inward = np.einsum("ij,ij->i", normals, directions[faces[:, 0]]) < 0
    faces[inward] = faces[inward][:, [0, 2, 1]]
    positions = positions.astype("<f4")
    faces = faces.astype("<u4")
    blob = positions.tobytes() + faces.tobytes()
    name = "displaced_sphere_box"
    with open(os.path.join(out_dir, name + ".bin"), "wb") as f:
        f.write(blob)
    b = len(gltf["buffers"])
    v = len(gltf["bufferViews"])
    a = len(gltf["accessors"])
    gltf["buffers"].append({"byteLength": len(blob), "uri": name + ".bin"})
    gltf["bufferViews"] += [{"buffer": b, "byteOffset": 0, "byteLength": positions.nbytes, "byteStride": 12},
                            {"buffer": b, "byteOffset": positions.nbytes, "byteLength": faces.nbytes}]
    gltf["accessors"] += [{"bufferView": v, "componentType": 5126, "count": len(positions), "type": "VEC3",
                           "min": positions.min(axis=0).tolist(), "max": positions.max(axis=0).tolist()},
                          {"bufferView": v + 1, "componentType": 5125, "count": faces.size, "type": "SCALAR"}]
    gltf["materials"].append({"name": "ochre Lambert", "extensions": {"SMALLVCM_material": {
        "diffuse": [0.75, 0.55, 0.25], "phong": [0, 0, 0], "phongExponent": 1.0, "mirror": [0, 0, 0], "ior": -1.0}}})
    gltf["meshes"].append({"name": "displaced sphere", "primitives": [
        {"attributes": {"POSITION": a}, "indices": a + 1, "material": len(gltf["materials"]) - 1, "mode": 4}]})
    gltf["nodes"].append({"name": "displaced sphere", "mesh": len(gltf["meshes"]) - 1})
    gltf["scenes"][gltf.get("scene", 0)]["nodes"].append(len(gltf["nodes"]) - 1)
    path = os.path.join(out_dir, name + ".gltf")
    with open(path, "w") as f:
        json.dump(gltf, f)
    return path


def load_mitsuba_scene(mi, scene_dict):
    d = dict(scene_dict)
    sensor = dict(d["sensor"])
    _, origin, target, up = sensor["to_world"]
    sensor["to_world"] = mi.ScalarTransform4f().look_at(origin=origin, target=target, up=up)
    d["sensor"] = sensor
    return mi.load_dict(d)


# ----------------------------------------------------------------------------------------
# Rendering with each program; CPU seconds of the render
# ----------------------------------------------------------------------------------------

def read_pfm(path):
    with open(path, "rb") as f:
        if f.readline().strip() != b"PF":
            raise ConversionError(f"{path}: not a colour PFM file")
        width, height = map(int, f.readline().split())
        scale = float(f.readline())
        pixels = np.frombuffer(f.read(), dtype=">f4" if scale > 0 else "<f4").reshape(height, width, 3)
    return pixels[::-1].astype(np.float64)  # PFM stores the bottom row first


def children_cpu():
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def render_smallvcm(gltf, width, height, iterations, seed, out_dir, algorithm="pt", max_path_length=MAX_PATH_LENGTH):
    """(image, CPU seconds of the whole process: loading and BVH build included, wall,
    seconds of the render alone). The last is the render loop's own clock from the image's
    sidecar (wall time of the one thread; at least its CPU time): what Mitsuba's time
    counts, which leaves out its scene loading."""
    path = os.path.join(out_dir, "smallvcm_run.pfm")
    # Independent numbers, as Mitsuba's "independent" sampler: like against like.
    command = [SMALLVCM, "-q", "-s", gltf, "-a", algorithm, "--sampler", "independent", "-j", "1", "-r", f"{width}x{height}",
               "-i", str(iterations), "--seed", str(seed), "--max-path-length", str(max_path_length), "-o", path]
    cpu, wall = children_cpu(), time.perf_counter()
    subprocess.run(command, check=True)
    cpu, wall = children_cpu() - cpu, time.perf_counter() - wall
    with open(path + ".json") as f:
        render_seconds = float(json.load(f)["seconds"])
    return read_pfm(path), cpu, wall, render_seconds


class Mitsuba:
    """One Mitsuba variant on one scene; the first render (kernel compilation) is timed apart."""

    def __init__(self, mi, dr, variant, scene_dict):
        mi.set_variant(variant)
        dr.set_thread_count(1)
        self.mi = mi
        cpu = time.process_time()
        self.scene = load_mitsuba_scene(mi, scene_dict)
        self.load_seconds = time.process_time() - cpu
        self.first_render_seconds = self.render(1, seed=999_999)[1]

    def render(self, spp, seed):
        """(image, CPU seconds of the render and of reading it back, wall)."""
        cpu, wall = time.process_time(), time.perf_counter()
        image = np.array(self.mi.render(self.scene, spp=spp, seed=seed), dtype=np.float64)
        return image, time.process_time() - cpu, time.perf_counter() - wall


# ----------------------------------------------------------------------------------------
# Steps
# ----------------------------------------------------------------------------------------

def scenes(out_dir, width, height):
    out = []
    for gltf in (os.path.join(ROOT, "scenes", "cornell_4_default.gltf"), write_mesh_scene(out_dir)):
        scene_dict, triangles = convert(gltf, out_dir, width, height)
        out.append((os.path.splitext(os.path.basename(gltf))[0], gltf, scene_dict, triangles))
    return out


def batches_stats(images):
    stack = np.stack(images)
    mean = stack.mean(axis=0)
    standard_error = stack.std(axis=0, ddof=1) / math.sqrt(len(images))
    return mean, standard_error


def t_tail(x, dof):
    """P(|T| > x) for Student's t with dof degrees of freedom (numerical integration)."""
    t = np.linspace(x, x + 200, 400_001)
    log_norm = math.lgamma((dof + 1) / 2) - math.lgamma(dof / 2) - 0.5 * math.log(dof * math.pi)
    density = np.exp(log_norm - (dof + 1) / 2 * np.log1p(t * t / dof))
    return 2 * float(np.sum((density[1:] + density[:-1]) / 2 * np.diff(t)))


def agree(mi, dr, out_dir, scene_list, width, height, batches, spp, log):
    """Per scene: the converged images of both programs and how far apart they are."""
    references = {}
    for name, gltf, scene_dict, _ in scene_list:
        mitsuba = Mitsuba(mi, dr, "llvm_ad_rgb", scene_dict)
        ours, theirs = [], []
        for k in range(batches):  # interleaved, other seeds than the efficiency runs
            ours.append(render_smallvcm(gltf, width, height, spp, 10_000 + k, out_dir)[0])
            theirs.append(mitsuba.render(spp, 20_000 + k)[0])
        a, a_se = batches_stats(ours)
        b, b_se = batches_stats(theirs)
        np.save(os.path.join(out_dir, f"{name}_smallvcm.npy"), a)
        np.save(os.path.join(out_dir, f"{name}_mitsuba.npy"), b)
        # Standard error of each image's mean from the spread of its batches' means.
        mean_a, mean_b = a.mean(), b.mean()
        se_mean_a = np.std([x.mean() for x in ours], ddof=1) / math.sqrt(batches)
        se_mean_b = np.std([x.mean() for x in theirs], ddof=1) / math.sqrt(batches)
        z = (a - b) / np.sqrt(a_se ** 2 + b_se ** 2 + 1e-30)
        valid = (a_se + b_se) > 0
        zv = z[valid]
        log(f"{name} ({width}x{height}, {batches} batches x {spp} spp each, pt, max path length {MAX_PATH_LENGTH}):")
        log(f"  mean  smallvcm {mean_a:.6f} +- {se_mean_a:.6f}   mitsuba llvm_ad_rgb {mean_b:.6f} +- {se_mean_b:.6f}"
            f"   ratio {mean_a / mean_b:.5f}   difference {(mean_a - mean_b) / math.hypot(se_mean_a, se_mean_b):+.2f} SE")
        for c, channel in enumerate("rgb"):
            log(f"  channel {channel}: smallvcm {a[..., c].mean():.6f}  mitsuba {b[..., c].mean():.6f}"
                f"  ratio {a[..., c].mean() / b[..., c].mean():.5f}")
        log(f"  per pixel and channel, z = difference / its standard error ({zv.size} values with noise,"
            f" {z.size - zv.size} exactly equal and noiseless):")
        log(f"    mean z {zv.mean():+.4f}  std z {zv.std():.4f}  |z|>3: {np.mean(np.abs(zv) > 3) * 100:.3f} %"
            f" (0.27 % for Gaussian noise)  |z|>5: {np.mean(np.abs(zv) > 5) * 100:.4f} %")
        log(f"    expected for the noise alone (Student t, {2 * batches - 2} degrees of freedom): |z|>3"
            f" {t_tail(3, 2 * batches - 2) * 100:.3f} %, |z|>5 {t_tail(5, 2 * batches - 2) * 100:.4f} %")
        block = 16  # 16 x 16 pixel blocks: their means are close to Gaussian even with fireflies
        shape = (height // block, block, width // block, block, 3)
        ba, bb = [np.stack([x.reshape(shape).mean(axis=(1, 3)) for x in images]) for images in (ours, theirs)]
        zb = (ba.mean(0) - bb.mean(0)) / np.sqrt((ba.var(0, ddof=1) + bb.var(0, ddof=1)) / batches + 1e-30)
        log(f"  {block}x{block} blocks ({zb.size} values): mean z {zb.mean():+.3f}  std z {zb.std():.3f}"
            f"  max |z| {np.abs(zb).max():.2f}  |z|>3: {np.sum(np.abs(zb) > 3)}")
        zabs = np.where(valid, np.abs(z), 0)
        rows, cols = zabs.max(axis=(1, 2)), zabs.max(axis=(0, 2))
        log(f"    worst row {rows.argmax()} (max |z| {rows.max():.2f}), worst column {cols.argmax()} (max |z| {cols.max():.2f})")
        if (~valid).any():
            still = np.abs(a - b)[~valid] / np.maximum(np.abs(b[~valid]), 1e-30)
            log(f"  noiseless values (the light seen directly, black): largest relative difference {still.max():.2e}")
        references[name] = (a + b) / 2, (a_se ** 2 + b_se ** 2) / 4
        np.save(os.path.join(out_dir, f"{name}_reference.npy"), references[name][0])
        np.save(os.path.join(out_dir, f"{name}_reference_variance.npy"), references[name][1])
    return references


def efficiency(mi, dr, out_dir, scene_list, references, width, height, budgets, repeats, log):
    """Rows: scene, program, spp, CPU seconds, wall seconds, MSE, efficiency (1/(CPU s x MSE))."""
    rows = []
    for name, gltf, scene_dict, triangles in scene_list:
        reference, reference_variance = references[name]
        programs = [("smallvcm pt", None)]
        startup = min(render_smallvcm(gltf, width, height, 1, 999_999, out_dir)[1] for _ in range(3))
        log(f"{name}: smallvcm: a whole run of 1 spp (loading, BVH build, 1 spp, writing) {startup:.3f} CPU s;"
            " its times below include that start-up")
        for variant in ("llvm_ad_rgb", "scalar_rgb"):
            mitsuba = Mitsuba(mi, dr, variant, scene_dict)
            log(f"{name}: Mitsuba {variant}: loading {mitsuba.load_seconds:.2f} CPU s and first render (1 spp,"
                f" kernel compilation or Dr.Jit's cache) {mitsuba.first_render_seconds:.2f} CPU s, neither counted")
            programs.append((f"mitsuba {variant}", mitsuba))
        for spp in budgets:
            for r in range(repeats):  # interleaved: each program once per round
                for program, mitsuba in programs:
                    if mitsuba is not None and mitsuba.mi.variant() != program.split()[1]:
                        mi.set_variant(program.split()[1])
                    if program.endswith("scalar_rgb") and spp > budgets[len(budgets) // 2]:
                        continue  # about 3x slower: the smaller budgets say enough
                    seed = 30_000 + 100 * spp + r
                    if mitsuba is None:
                        image, cpu, wall, render_only = render_smallvcm(gltf, width, height, spp, seed, out_dir)
                    else:
                        image, cpu, wall = mitsuba.render(spp, seed)
                        render_only = cpu  # Mitsuba's loading is already left out
                    mse = float(np.mean((image - reference) ** 2))
                    rows.append((name, triangles, program, spp, cpu, wall, mse, render_only))
        log(f"{name}: reference's own variance per pixel and channel {reference_variance.mean():.3e}"
            " (part of every MSE below)")
    with open(os.path.join(out_dir, "efficiency.csv"), "w") as f:
        f.write("scene,triangles,program,spp,cpu_seconds,wall_seconds,mse,efficiency,render_only_seconds\n")
        for name, triangles, program, spp, cpu, wall, mse, render_only in rows:
            f.write(f"{name},{triangles},{program},{spp},{cpu:.4f},{wall:.4f},{mse:.6e},{1 / (cpu * mse):.4f},"
                    f"{render_only:.4f}\n")
    # The table: per scene, program and budget the mean over the repeats; efficiency from
    # the summed time and mean MSE; the ratio is smallvcm's efficiency over the program's.
    # Two times: CPU s, smallvcm's whole process (loading and BVH build included, Mitsuba's
    # loading not: the conservative comparison), and render s, both without loading.
    table = ["| scene | program | spp | CPU s | wall s | render s | MSE | efficiency 1/(CPU s·MSE) |"
             " smallvcm ÷ this | render only: smallvcm ÷ this |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name, *_ in scene_list:
        ours = {}
        for program in ("smallvcm pt", "mitsuba llvm_ad_rgb", "mitsuba scalar_rgb"):
            for spp in budgets:
                picked = [r for r in rows if r[0] == name and r[2] == program and r[3] == spp]
                if not picked:
                    continue
                cpu = np.mean([r[4] for r in picked])
                wall = np.mean([r[5] for r in picked])
                mse = np.mean([r[6] for r in picked])
                render_only = np.mean([r[7] for r in picked])
                eff, render_eff = 1 / (cpu * mse), 1 / (render_only * mse)
                if program == "smallvcm pt":
                    ours[spp] = (eff, render_eff)
                table.append(f"| {name} | {program} | {spp} | {cpu:.3f} | {wall:.3f} | {render_only:.3f} | {mse:.3e} |"
                             f" {eff:.1f} | {ours[spp][0] / eff:.2f} | {ours[spp][1] / render_eff:.2f} |")
    with open(os.path.join(out_dir, "efficiency.md"), "w") as f:
        f.write("\n".join(table) + "\n")
    for line in table:
        log(line)


# The media scenes (docs/scene_format.md 4.4) and the path length both programs get: a
# dense medium needs many more vertices than smallvcm's default 10.
MEDIA_SCENES = (("dense_scattering_sphere", 64), ("absorbing_glass", 20), ("fog_caustic_box", 20))
MEDIA_ALGORITHMS = ("pt", "bpt", "vcm")


def region_z(ours, theirs, block):
    """Per block x block region and channel: (difference of the means) / its standard
    error, from the spread of each program's independent batches."""
    height, width = ours[0].shape[:2]
    shape = (height // block, block, width // block, block, 3)
    ba, bb = [np.stack([x.reshape(shape).mean(axis=(1, 3)) for x in images]) for images in (ours, theirs)]
    se = np.sqrt(ba.var(0, ddof=1) / len(ours) + bb.var(0, ddof=1) / len(theirs))
    return (ba.mean(0) - bb.mean(0)) / np.maximum(se, 1e-30)


def media(mi, dr, out_dir, width, height, batches, spp, log, only=None):
    """smallvcm's pt, bpt and vcm beside Mitsuba 3's `volpath` (scalar_rgb, one thread) on
    the media scenes, in independent batches: image means per channel, the 8 x 8 regions'
    z (difference over its standard error, per channel), and CPU time per sample of our pt
    and of volpath at equal path length. Returns the rows of the table."""
    rows = []
    block = width // 8
    for name, max_length in MEDIA_SCENES:
        if only and name not in only:
            continue
        gltf = os.path.join(ROOT, "scenes", name + ".gltf")
        scene_dict, _ = convert(gltf, out_dir, width, height, max_depth=max_length)
        mitsuba = Mitsuba(mi, dr, "scalar_rgb", scene_dict)
        ours = {a: [] for a in MEDIA_ALGORITHMS}
        cpu = {a: [] for a in MEDIA_ALGORITHMS + ("volpath",)}
        theirs = []
        for k in range(batches):  # interleaved; every batch its own seed
            for algorithm in MEDIA_ALGORITHMS:
                image, seconds, _, _ = render_smallvcm(gltf, width, height, spp, 40_000 + k, out_dir, algorithm, max_length)
                ours[algorithm].append(image)
                cpu[algorithm].append(seconds)
            image, seconds, _ = mitsuba.render(spp, 50_000 + k)
            theirs.append(image)
            cpu["volpath"].append(seconds)
        samples = spp * width * height
        b, b_se = batches_stats(theirs)
        np.save(os.path.join(out_dir, f"{name}_volpath.npy"), b)
        log(f"{name} ({width}x{height}, {batches} batches x {spp} spp, max path length {max_length} in both;"
            f" load {os.getloadavg()[0]:.1f}):")

        def channel_means(images):
            per_batch = np.array([x.mean(axis=(0, 1)) for x in images])
            return per_batch.mean(0), per_batch.std(0, ddof=1) / math.sqrt(len(images))

        mean_b, se_b = channel_means(theirs)
        t_b = np.median(cpu["volpath"]) / samples * 1e6
        log(f"  mitsuba volpath: mean r g b {mean_b[0]:.5f} {mean_b[1]:.5f} {mean_b[2]:.5f}"
            f" (+- {se_b[0]:.5f} {se_b[1]:.5f} {se_b[2]:.5f}); {t_b:.3f} CPU us per sample (median of {batches})")
        rows.append((name, max_length, "mitsuba volpath", mean_b, se_b, None, None, t_b))
        for algorithm in MEDIA_ALGORITHMS:
            a = np.mean(ours[algorithm], axis=0)
            np.save(os.path.join(out_dir, f"{name}_{algorithm}.npy"), a)
            mean_a, se_a = channel_means(ours[algorithm])
            z_image = (mean_a - mean_b) / np.sqrt(se_a ** 2 + se_b ** 2)
            z = region_z(ours[algorithm], theirs, block)
            t_a = np.median(cpu[algorithm]) / samples * 1e6
            log(f"  smallvcm {algorithm}: mean r g b {mean_a[0]:.5f} {mean_a[1]:.5f} {mean_a[2]:.5f}"
                f" (+- {se_a[0]:.5f} {se_a[1]:.5f} {se_a[2]:.5f}); ratio to volpath"
                f" {mean_a[0] / mean_b[0]:.4f} {mean_a[1] / mean_b[1]:.4f} {mean_a[2] / mean_b[2]:.4f};"
                f" image z {z_image[0]:+.2f} {z_image[1]:+.2f} {z_image[2]:+.2f}")
            worst = np.unravel_index(np.abs(z).argmax(), z.shape)
            log(f"    {z.size} region values ({block}x{block} px, per channel): mean z {z.mean():+.3f}, std z {z.std():.3f},"
                f" worst |z| {np.abs(z).max():.2f} (region row {worst[0]}, column {worst[1]}, channel {'rgb'[worst[2]]}),"
                f" |z| > 3: {int(np.sum(np.abs(z) > 3))} (expected {z.size * t_tail(3, 2 * batches - 2):.1f});"
                f" {t_a:.3f} CPU us per sample (whole process, median of {batches})")
            rows.append((name, max_length, f"smallvcm {algorithm}", mean_a, se_a, z_image, z, t_a))
    table = ["| scene | max path length | program | mean R | mean G | mean B | ÷ volpath (R, G, B) |"
             " image z (R, G, B) | regions: std z, worst abs z, abs z > 3 | CPU µs per sample |",
             "|---|---:|---|---:|---:|---:|---|---|---|---:|"]
    reference = {}
    for name, max_length, program, mean, se, z_image, z, t in rows:
        if z is None:
            reference[name] = mean
            table.append(f"| {name} | {max_length} | {program} | {mean[0]:.4f} ± {se[0]:.4f} | {mean[1]:.4f} ± {se[1]:.4f} |"
                         f" {mean[2]:.4f} ± {se[2]:.4f} | | | | {t:.2f} |")
        else:
            ratio = mean / reference[name]
            table.append(f"| {name} | {max_length} | {program} | {mean[0]:.4f} ± {se[0]:.4f} | {mean[1]:.4f} ± {se[1]:.4f} |"
                         f" {mean[2]:.4f} ± {se[2]:.4f} | {ratio[0]:.3f}, {ratio[1]:.3f}, {ratio[2]:.3f} |"
                         f" {z_image[0]:+.1f}, {z_image[1]:+.1f}, {z_image[2]:+.1f} |"
                         f" {z.std():.2f}, {np.abs(z).max():.1f}, {int(np.sum(np.abs(z) > 3))}/{z.size} | {t:.2f} |")
    with open(os.path.join(out_dir, "media.md"), "a") as f:
        f.write("\n".join(table) + "\n")
    for line in table:
        log(line)
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("steps", nargs="*", metavar="STEP", help="convert, agree, efficiency (default: all), media")
    parser.add_argument("--media-batches", type=int, default=8, help="media: independent batches (default 8)")
    parser.add_argument("--media-spp", type=int, default=16, help="media: samples per pixel per batch (default 16)")
    parser.add_argument("--media-scenes", default="", help="media: comma-separated scene names (default: all)")
    parser.add_argument("--out", default=os.path.join(ROOT, "build", "mitsuba"))
    parser.add_argument("--quick", action="store_true", help="tiny settings: checks that everything runs")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per program and budget (default 3)")
    args = parser.parse_args()
    args.steps = args.steps or ["convert", "agree", "efficiency"]
    for step in args.steps:
        if step not in ("convert", "agree", "efficiency", "media"):
            sys.exit(f"mitsuba_compare: unknown step '{step}' (convert, agree, efficiency or media)")
    width = height = 128 if args.quick else 256
    batches, agree_spp = (4, 8) if args.quick else (16, 64)
    budgets, repeats = ((1, 4), 1) if args.quick else ((4, 16, 64), args.repeats)
    if repeats < 1:
        sys.exit(f"mitsuba_compare: --repeats {repeats}: must be at least 1")
    os.makedirs(args.out, exist_ok=True)
    if not os.access(SMALLVCM, os.X_OK):
        sys.exit(f"mitsuba_compare: {SMALLVCM} is missing (make build/smallvcm)")
    log_file = open(os.path.join(args.out, "log.txt"), "a")

    def log(line):
        print(line, flush=True)
        log_file.write(line + "\n")
        log_file.flush()

    try:
        scene_list = scenes(args.out, width, height)
    except (ConversionError, OSError, KeyError, ValueError) as error:
        sys.exit(f"mitsuba_compare: {error}")
    log(f"start {time.strftime('%Y-%m-%d %H:%M:%S')}  load {os.getloadavg()}  "
        + ", ".join(f"{n}: {t} triangles" for n, _, _, t in scene_list))
    if args.steps == ["convert"]:
        for name, _, scene_dict, _ in scene_list:
            with open(os.path.join(args.out, name + ".mitsuba.json"), "w") as f:
                json.dump(scene_dict, f, indent=1)
            log(f"{name}: {os.path.join(args.out, name + '.mitsuba.json')}")
        for name, max_length in MEDIA_SCENES:
            scene_dict, _ = convert(os.path.join(ROOT, "scenes", name + ".gltf"), args.out, 128, 128, max_length)
            with open(os.path.join(args.out, name + ".mitsuba.json"), "w") as f:
                json.dump(scene_dict, f, indent=1)
            log(f"{name}: {os.path.join(args.out, name + '.mitsuba.json')}")
        return
    import drjit as dr
    import mitsuba as mi
    log(f"mitsuba {mi.__version__}, drjit {dr.__version__}, LLVM library {os.environ.get('DRJIT_LIBLLVM_PATH', 'default')}")
    if "agree" in args.steps:
        with open(os.path.join(args.out, "agreement.txt"), "w") as agreement:
            def log_agreement(line):
                log(line)
                agreement.write(line + "\n")
            references = agree(mi, dr, args.out, scene_list, width, height, batches, agree_spp, log_agreement)
    elif "efficiency" in args.steps:
        references = {name: (np.load(os.path.join(args.out, f"{name}_reference.npy")),
                             np.load(os.path.join(args.out, f"{name}_reference_variance.npy")))
                      for name, *_ in scene_list}
    if "efficiency" in args.steps:
        efficiency(mi, dr, args.out, scene_list, references, width, height, budgets, repeats, log)
    if "media" in args.steps:
        media(mi, dr, args.out, width // 2, height // 2, args.media_batches, args.media_spp, log,
              [n for n in args.media_scenes.split(",") if n])
    log(f"end {time.strftime('%Y-%m-%d %H:%M:%S')}  load {os.getloadavg()}")


if __name__ == "__main__":
    main()
