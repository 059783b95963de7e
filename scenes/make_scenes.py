#!/usr/bin/env python3
"""Generate the SmallVCM Cornell-box family as self-contained glTF 2.0 files.

SmallVCM (Davidovic & Georgiev) builds all of its scenes from one function that
reads a bit mask of `Scene::BoxMask` flags. This script does the same: the
function `build_cornell_box(mask)` turns a mask into a small scene description
(camera, triangle groups, spheres, lights), and `to_gltf()` writes that
description in the glTF subset of docs/scene_format.md.

All numbers are SmallVCM's float32 literals (the project's reference table
shared/SMALLVCM_SCENES.md; the format is docs/scene_format.md). Coordinates are SmallVCM's, NOT rotated to glTF's
+y-up convention: right-handed, +z up, the camera looks along roughly +y.

Usage:   python3 scenes/make_scenes.py      (writes scenes/cornell_*.gltf)
Needs:   Python 3, standard library only.
"""

import base64
import json
import math
import os
import struct

# ---------------------------------------------------------------------------
# Scene flags (SmallVCM's Scene::BoxMask) and the configurations we ship
# ---------------------------------------------------------------------------

LIGHT_CEILING = 1          # area light: light-box bottom (or whole ceiling)
LIGHT_SUN = 2              # directional light
LIGHT_POINT = 4            # point light; also removes the light box
LIGHT_BACKGROUND = 8       # constant environment light
LARGE_MIRROR_SPHERE = 16   # r = 0.8, centre of the floor
LARGE_GLASS_SPHERE = 32    # r = 0.8 (dropped if LARGE_MIRROR_SPHERE is set)
SMALL_MIRROR_SPHERE = 64   # r = 0.5, left
SMALL_GLASS_SPHERE = 128   # r = 0.5, right
GLOSSY_FLOOR = 256         # glossy floor (2) and blue back wall (8)
BOTH_SMALL_SPHERES = SMALL_MIRROR_SPHERE | SMALL_GLASS_SPHERE      # 192
DEFAULT = LIGHT_CEILING | BOTH_SMALL_SPHERES                       # 193

# (file name, mask) in the order of the renderer's `-s` index.
# -s 0..3 are SmallVCM's g_SceneConfigs; -s 4 is SmallVCM's kDefault.
SCENE_CONFIGS = [
    ("cornell_0_sun.gltf", GLOSSY_FLOOR | BOTH_SMALL_SPHERES | LIGHT_SUN),
    ("cornell_1_mirror_ceiling.gltf", GLOSSY_FLOOR | LARGE_MIRROR_SPHERE | LIGHT_CEILING),
    ("cornell_2_point.gltf", GLOSSY_FLOOR | BOTH_SMALL_SPHERES | LIGHT_POINT),
    ("cornell_3_background.gltf", GLOSSY_FLOOR | BOTH_SMALL_SPHERES | LIGHT_BACKGROUND),
    ("cornell_4_default.gltf", DEFAULT),
]


def has(mask, flags):
    """True when every bit of `flags` is set in `mask`."""
    return (mask & flags) == flags


def scene_name(mask):
    """The name SmallVCM prints for a mask: floor, box content, lighting."""
    name = "glossy " if has(mask, GLOSSY_FLOOR) else ""
    if has(mask, BOTH_SMALL_SPHERES):
        name += "small spheres"
    elif has(mask, SMALL_MIRROR_SPHERE):
        name += "small mirror sphere"
    elif has(mask, SMALL_GLASS_SPHERE):
        name += "small glass sphere"
    elif has(mask, LARGE_MIRROR_SPHERE):
        name += "large mirror sphere"
    elif has(mask, LARGE_GLASS_SPHERE):
        name += "large glass sphere"
    else:
        name += "empty"
    if has(mask, LIGHT_CEILING):
        name += " + ceiling (area)"
    elif has(mask, LIGHT_SUN):
        name += " + sun (directional)"
    elif has(mask, LIGHT_POINT):
        name += " + point"
    elif has(mask, LIGHT_BACKGROUND):
        name += " + background (env. lighting)"
    return name


# ---------------------------------------------------------------------------
# Small vector helpers and float32 handling
# ---------------------------------------------------------------------------

def f32(x):
    """Round a Python float to the nearest float32 value."""
    return struct.unpack("<f", struct.pack("<f", x))[0]


def f32_json(x):
    """The shortest decimal that reads back as the same float32 (for JSON)."""
    v = f32(x)
    for digits in range(1, 10):
        s = "%.*g" % (digits, v)
        if f32(float(s)) == v:
            return float(s) + 0.0   # + 0.0 turns -0.0 into 0.0
    raise AssertionError("unreachable: 9 digits always round-trip a float32")


def f32_point(p):
    """A point with float32 coordinates (SmallVCM's Vec3f)."""
    return (f32(p[0]), f32(p[1]), f32(p[2]))


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0])


def neg(a):
    return (-a[0], -a[1], -a[2])


def normalize(a):
    length = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    return (a[0] / length, a[1] / length, a[2] / length)


def f32_vec(values):
    """A list of float32 values (shortest decimals) for JSON."""
    return [f32_json(v) for v in values]


# ---------------------------------------------------------------------------
# Materials: SmallVCM ids 0..8 (a file holds the ones its scene uses, in id order)
# ---------------------------------------------------------------------------

def material(name, diffuse=(0.0, 0.0, 0.0), phong=(0.0, 0.0, 0.0),
             exponent=1.0, mirror=(0.0, 0.0, 0.0), ior=-1.0):
    """SmallVCM's Material: Lambert + modified Phong + mirror (+ glass if ior >= 0)."""
    return {"name": name, "diffuse": diffuse, "phong": phong,
            "exponent": exponent, "mirror": mirror, "ior": ior}


MATERIALS = [
    material("light 0 (emitter)"),                                    # 0
    material("light 1 (emitter)"),                                    # 1
    material("glossy floor", diffuse=(0.1, 0.1, 0.1),
             phong=(0.7, 0.7, 0.7), exponent=90.0),                   # 2
    material("green (left wall)", diffuse=(0.156863, 0.803922, 0.172549)),  # 3
    material("red (right wall)", diffuse=(0.803922, 0.152941, 0.152941)),   # 4
    material("white", diffuse=(0.803922, 0.803922, 0.803922)),       # 5
    material("mirror", mirror=(1.0, 1.0, 1.0)),                       # 6
    material("glass", mirror=(1.0, 1.0, 1.0), ior=1.6),               # 7
    material("blue (back wall)", diffuse=(0.156863, 0.172549, 0.803922)),   # 8
]
EMITTER_0, EMITTER_1, GLOSSY, GREEN, RED, WHITE, MIRROR, GLASS, BLUE = range(9)

# Radiance of the light-box bottom (configs with LIGHT_CEILING and the light box).
LIGHT_BOX_RADIANCE = 25.03329895614464
# Radiance of the whole-ceiling variant (LIGHT_CEILING | LIGHT_POINT, not shipped).
WHOLE_CEILING_RADIANCE = 0.95492965


# ---------------------------------------------------------------------------
# The scene built from a mask
# ---------------------------------------------------------------------------

def build_cornell_box(mask):
    """Build SmallVCM's Cornell box for `mask` as a plain description.

    Returns a dict with
      camera:     (position, forward, up_hint), fov_deg (horizontal)
      walls:      [(name, [(material_id, [(p0, p1, p2), ...]), ...]), ...]
      spheres:    [(name, centre, radius, material_id), ...]
      light_box:  like walls (empty without the light box)
                  (walls, spheres, light box is SmallVCM's insertion order)
      emission:   {material_id: radiance} for the emitters used
      point, sun: punctual lights or None; background: radiance or None
    """
    light_ceiling = has(mask, LIGHT_CEILING)
    light_sun = has(mask, LIGHT_SUN)
    light_point = has(mask, LIGHT_POINT)
    light_background = has(mask, LIGHT_BACKGROUND)
    light_box = not light_point

    scene = {"mask": mask, "name": scene_name(mask)}

    # Camera: the numbers of SmallVCM's LoadCornellBox, horizontal fov 45 deg.
    scene["camera"] = ((-0.0439815, -4.12529, 0.222539),
                       (0.00688625, 0.998505, -0.0542161),
                       (3.73896e-4, 0.0542148, 0.998529))
    scene["fov_deg"] = 45.0

    # Box corners: cb0..cb3 at the back (y = 1.30455), cb4..cb7 at the open front.
    cb = [f32_point(p) for p in [
        (-1.27029, 1.30455, -1.28002), (1.28975, 1.30455, -1.28002),
        (1.28975, 1.30455, 1.28002), (-1.27029, 1.30455, 1.28002),
        (-1.27029, -1.25549, -1.28002), (1.28975, -1.25549, -1.28002),
        (1.28975, -1.25549, 1.28002), (-1.27029, -1.25549, 1.28002)]]

    def tri(points, i, j, k):
        return (points[i], points[j], points[k])

    walls = []
    emission = {}
    glossy = has(mask, GLOSSY_FLOOR)

    # Box walls, all facing the interior; there is no front wall.
    walls.append(("floor", [(GLOSSY if glossy else WHITE,
                             [tri(cb, 0, 4, 5), tri(cb, 5, 1, 0)])]))
    walls.append(("back wall", [(BLUE if glossy else WHITE,
                                 [tri(cb, 0, 1, 2), tri(cb, 2, 3, 0)])]))
    if light_ceiling and not light_box:
        # The whole ceiling is the light (two lights, one per triangle).
        walls.append(("ceiling light (emitter)",
                      [(EMITTER_0, [tri(cb, 2, 6, 7)]),
                       (EMITTER_1, [tri(cb, 7, 3, 2)])]))
        emission[EMITTER_0] = emission[EMITTER_1] = WHOLE_CEILING_RADIANCE
    else:
        walls.append(("ceiling", [(WHITE, [tri(cb, 2, 6, 7), tri(cb, 7, 3, 2)])]))
    walls.append(("left wall", [(GREEN, [tri(cb, 3, 7, 4), tri(cb, 4, 0, 3)])]))
    walls.append(("right wall", [(RED, [tri(cb, 1, 5, 6), tri(cb, 6, 2, 1)])]))

    # Spheres, placed as SmallVCM places them, in float32 arithmetic (every
    # operation rounded to float32, as the original computes with floats):
    # large: floor centre + (0, 0, r); small: the left/right wall mid-points at
    # floor height + r, moved 2/7 of the box width towards the centre.
    # Results: large (0.009729981, 0.024530053, -0.48002), small x -0.53885 and
    # 0.55831 (the reference table prints them rounded: 0.00972998, 0.02453005).
    floor_centre = tuple(f32(f32(f32(f32(cb[0][i] + cb[1][i]) + cb[4][i]) + cb[5][i]) * 0.25)
                         for i in range(3))
    large_centre = (floor_centre[0], floor_centre[1], f32(floor_centre[2] + 0.8))
    left_mid = tuple(f32(f32(cb[0][i] + cb[4][i]) * 0.5) for i in range(3))
    right_mid = tuple(f32(f32(cb[1][i] + cb[5][i]) * 0.5) for i in range(3))
    shift = f32(f32(2.0 * f32(right_mid[0] - left_mid[0])) / 7.0)
    small_left = (f32(left_mid[0] + shift), left_mid[1], f32(left_mid[2] + 0.5))
    small_right = (f32(right_mid[0] - shift), right_mid[1], f32(right_mid[2] + 0.5))
    spheres = []
    if has(mask, LARGE_MIRROR_SPHERE):
        spheres.append(("large mirror sphere", large_centre, 0.8, MIRROR))
    elif has(mask, LARGE_GLASS_SPHERE):
        spheres.append(("large glass sphere", large_centre, 0.8, GLASS))
    if has(mask, SMALL_MIRROR_SPHERE):
        spheres.append(("small mirror sphere", small_left, 0.5, MIRROR))
    if has(mask, SMALL_GLASS_SPHERE):
        spheres.append(("small glass sphere", small_right, 0.5, GLASS))

    # Light box: a 0.5 x 0.5 x 0.02 box hanging from the ceiling, sides facing
    # outwards, no top; its bottom faces down and is the area light if any.
    light_box_meshes = []
    if light_box:
        lb = [f32_point(p) for p in [
            (-0.25, 0.25, 1.26002), (0.25, 0.25, 1.26002),
            (0.25, 0.25, 1.28002), (-0.25, 0.25, 1.28002),
            (-0.25, -0.25, 1.26002), (0.25, -0.25, 1.26002),
            (0.25, -0.25, 1.28002), (-0.25, -0.25, 1.28002)]]
        light_box_meshes.append(("light box sides", [(WHITE, [
            tri(lb, 0, 2, 1), tri(lb, 2, 0, 3),     # back  (+y)
            tri(lb, 3, 4, 7), tri(lb, 4, 3, 0),     # left  (-x)
            tri(lb, 1, 6, 5), tri(lb, 6, 1, 2),     # right (+x)
            tri(lb, 4, 5, 6), tri(lb, 6, 7, 4),     # front (-y)
        ])]))
        if light_ceiling:
            # Two emitter materials, hence two primitives, hence two lights.
            light_box_meshes.append(("light (emitter)",
                                     [(EMITTER_0, [tri(lb, 0, 5, 4)]),
                                      (EMITTER_1, [tri(lb, 5, 0, 1)])]))
            emission[EMITTER_0] = emission[EMITTER_1] = LIGHT_BOX_RADIANCE
        else:
            light_box_meshes.append(("light box bottom",
                                     [(WHITE, [tri(lb, 0, 5, 4), tri(lb, 5, 0, 1)])]))

    scene["walls"] = walls
    scene["spheres"] = spheres
    scene["light_box"] = light_box_meshes
    scene["emission"] = emission

    # Punctual and environment lights.
    # Sun: travels along normalize(-1, 1.5, -1); irradiance (0.5, 0.2, 0) * 20.
    scene["sun"] = ((-1.0, 1.5, -1.0), (1.0, 0.4, 0.0), 10.0) if light_sun else None
    # Point: total power 70 W, isotropic -> intensity 70 / (4 pi) W/sr.
    scene["point"] = ((0.0, -0.5, 1.0), (1.0, 1.0, 1.0), 70.0 / (4.0 * math.pi)) if light_point else None
    # Background: the colour (135, 206, 250) / 255, scale 1.
    scene["background"] = (tuple(c / 255.0 for c in (135, 206, 250))
                           if light_background else None)
    return scene


# ---------------------------------------------------------------------------
# glTF output
# ---------------------------------------------------------------------------

def pbr_approximation(m, emissive):
    """pbrMetallicRoughness values for ordinary viewers (docs/scene_format.md,
    mapping used backwards); the renderer reads SMALLVCM_material instead."""
    extensions = {}
    if emissive:
        base, metallic, roughness = (0.0, 0.0, 0.0), 0.0, 1.0
    elif m["ior"] >= 0.0:       # clear glass
        base, metallic, roughness = (1.0, 1.0, 1.0), 0.0, 0.0
        extensions["KHR_materials_transmission"] = {"transmissionFactor": 1.0}
        extensions["KHR_materials_ior"] = {"ior": m["ior"]}
    elif max(m["mirror"]) > 0.0:  # perfect mirror: ks = baseColor at metallic 1
        base, metallic, roughness = m["mirror"], 1.0, 0.0
    elif max(m["phong"]) > 0.0:
        # Grey diffuse d + grey Phong s: solve kd = (1-m) 0.96 b and
        # ks = 0.04 (1-m) + m b for u = 1 - m (the root in [0, 1]):
        # 0.0384 u^2 - (0.96 s + d) u + d = 0.
        d, s = m["diffuse"][0], m["phong"][0]
        if d == 0.0:            # pure Phong: a rough metal, ks = b
            metallic, base = 1.0, (s,) * 3
        else:
            bq = 0.96 * s + d
            u = (bq - math.sqrt(bq * bq - 4.0 * 0.0384 * d)) / (2.0 * 0.0384)
            metallic = 1.0 - u
            base = (d / (0.96 * u),) * 3
        roughness = (2.0 / (m["exponent"] + 2.0)) ** 0.25   # n = 2/r^4 - 2
    else:                       # Lambert
        base = tuple(c / 0.96 for c in m["diffuse"])
        metallic, roughness = 0.0, 1.0
    pbr = {"baseColorFactor": [round(c, 6) for c in base] + [1.0],
           "metallicFactor": round(metallic, 6),
           "roughnessFactor": round(roughness, 6)}
    return pbr, extensions


def camera_matrix(position, forward, up_hint):
    """Column-major matrix with columns right, up, -forward, position."""
    forward = normalize(forward)
    right = normalize(cross(up_hint, neg(forward)))
    up = cross(neg(forward), right)
    return (f32_vec(right) + [0.0] + f32_vec(up) + [0.0] +
            f32_vec(neg(forward)) + [0.0] + f32_vec(position) + [1.0])


def direction_matrix(travel):
    """Rotation whose local -Z axis is `travel` (an orthonormal, right-handed basis)."""
    z = neg(normalize(travel))
    x = normalize(cross((0.0, 0.0, 1.0), z))
    y = cross(z, x)
    return f32_vec(x) + [0.0] + f32_vec(y) + [0.0] + f32_vec(z) + [0.0, 0.0, 0.0, 0.0, 1.0]


def to_gltf(scene):
    """The glTF 2.0 document (a dict) of a scene from build_cornell_box()."""
    used = set()
    required = set()
    positions = bytearray()   # bufferView 0: float32 VEC3, stride 12
    indices = bytearray()     # bufferView 1: uint32
    accessors, meshes, nodes, materials = [], [], [], []
    material_index = {}       # SmallVCM id -> glTF material index

    # Only the materials the scene uses, in SmallVCM id order.
    palette = scene.get("materials", MATERIALS)   # figure scenes bring their own
    used_ids = {mid for _, prims in scene["walls"] + scene["light_box"] for mid, _ in prims}
    used_ids |= {mid for _, _, _, mid in scene["spheres"]}
    used_ids |= {smooth["material"] for smooth in scene.get("smooth", [])}
    for mid in sorted(used_ids):
        m = palette[mid]
        emissive = mid in scene["emission"]
        pbr, ext = pbr_approximation(m, emissive)
        ext["SMALLVCM_material"] = {
            "diffuse": f32_vec(m["diffuse"]), "phong": f32_vec(m["phong"]),
            "phongExponent": f32_json(m["exponent"]), "mirror": f32_vec(m["mirror"]),
            "ior": f32_json(m["ior"])}
        gm = {"name": ("SmallVCM material %d: %s" % (mid, m["name"])) if palette is MATERIALS
              else m["name"],
              "pbrMetallicRoughness": pbr}
        if emissive:
            gm["emissiveFactor"] = [1.0, 1.0, 1.0]
            if scene.get("two_sided_emitters"):
                gm["doubleSided"] = True
            ext["KHR_materials_emissive_strength"] = {
                "emissiveStrength": scene["emission"][mid]}
        gm["extensions"] = ext
        used.update(ext)
        material_index[mid] = len(materials)
        materials.append(gm)

    # Camera node first, as SmallVCM sets the camera up first.
    position, forward, up_hint = scene["camera"]
    # Square aspect: the vertical fov equals SmallVCM's horizontal 45 degrees.
    yfov = math.radians(scene["fov_deg"])
    cameras = [{"name": "camera", "type": "perspective",
                "perspective": {"aspectRatio": 1.0, "yfov": yfov, "znear": 0.01}}]
    nodes.append({"name": "camera", "camera": 0,
                  "matrix": camera_matrix(position, forward, up_hint)})

    # The POSITION accessor of a primitive's vertices (bufferView 0), with the bounds the
    # glTF spec requires.
    def add_positions(verts):
        accessors.append({"bufferView": 0, "byteOffset": len(positions),
                          "componentType": 5126, "count": len(verts), "type": "VEC3",
                          "min": [f32_json(min(v[i] for v in verts)) for i in range(3)],
                          "max": [f32_json(max(v[i] for v in verts)) for i in range(3)]})
        for v in verts:
            positions.extend(struct.pack("<3f", *v))
        return len(accessors) - 1

    def add_primitive(mid, triangles):
        """One primitive: unique vertices in first-use order, triangle order kept."""
        verts, idx = [], []
        for t in triangles:
            for p in t:
                key = f32_point(p)
                if key not in verts:
                    verts.append(key)
                idx.append(verts.index(key))
        pos_acc = add_positions(verts)
        idx_acc = len(accessors)
        accessors.append({"bufferView": 1, "byteOffset": len(indices),
                          "componentType": 5125, "count": len(idx), "type": "SCALAR"})
        indices.extend(struct.pack("<%dI" % len(idx), *idx))
        return {"attributes": {"POSITION": pos_acc}, "indices": idx_acc,
                "material": material_index[mid], "mode": 4}

    # Geometry in SmallVCM's insertion order: walls, spheres, light box.
    def add_mesh(name, prims):
        meshes.append({"name": name,
                       "primitives": [add_primitive(mid, tris) for mid, tris in prims]})
        nodes.append({"name": name, "mesh": len(meshes) - 1})

    for name, prims in scene["walls"]:
        add_mesh(name, prims)
    for name, centre, radius, mid in scene["spheres"]:
        nodes.append({"name": name, "translation": f32_vec(centre),
                      "extensions": {"SMALLVCM_sphere": {
                          "radius": f32_json(radius), "material": material_index[mid]}}})
        used.add("SMALLVCM_sphere")
        required.add("SMALLVCM_sphere")
    for name, prims in scene["light_box"]:
        add_mesh(name, prims)

    # Smooth-shaded meshes: indexed vertices with a NORMAL each (bufferView 2), only
    # in the scenes that have them, so the other files stay as they were.
    normals = bytearray()
    for smooth in scene.get("smooth", []):
        verts = [f32_point(p) for p in smooth["positions"]]
        pos_acc = add_positions(verts)
        normal_acc = len(accessors)
        accessors.append({"bufferView": 2, "byteOffset": len(normals),
                          "componentType": 5126, "count": len(verts), "type": "VEC3"})
        for n in smooth["normals"]:
            normals.extend(struct.pack("<3f", *n))
        idx_acc = len(accessors)
        accessors.append({"bufferView": 1, "byteOffset": len(indices),
                          "componentType": 5125, "count": len(smooth["indices"]), "type": "SCALAR"})
        indices.extend(struct.pack("<%dI" % len(smooth["indices"]), *smooth["indices"]))
        meshes.append({"name": smooth["name"], "primitives": [
            {"attributes": {"POSITION": pos_acc, "NORMAL": normal_acc}, "indices": idx_acc,
             "material": material_index[smooth["material"]], "mode": 4}]})
        nodes.append({"name": smooth["name"], "mesh": len(meshes) - 1})

    # Punctual lights (KHR_lights_punctual): 1 cd := 1 W/sr, 1 lux := 1 W/m^2.
    lights = []
    if scene["sun"] is not None:
        travel, color, intensity = scene["sun"]
        lights.append({"name": "sun", "type": "directional",
                       "color": list(color), "intensity": intensity})
        nodes.append({"name": "sun", "matrix": direction_matrix(travel),
                      "extensions": {"KHR_lights_punctual": {"light": len(lights) - 1}}})
    if scene["point"] is not None:
        pos, color, intensity = scene["point"]
        lights.append({"name": "point light", "type": "point",
                       "color": list(color), "intensity": intensity})
        nodes.append({"name": "point light", "translation": f32_vec(pos),
                      "extensions": {"KHR_lights_punctual": {"light": len(lights) - 1}}})
    if scene.get("spot") is not None:
        pos, travel, color, intensity, inner, outer = scene["spot"]
        lights.append({"name": "spot light", "type": "spot", "color": list(color),
                       "intensity": intensity,
                       "spot": {"innerConeAngle": inner, "outerConeAngle": outer}})
        matrix = direction_matrix(travel)   # the light shines down its local -Z
        matrix[12:15] = f32_vec(pos)
        nodes.append({"name": "spot light", "matrix": matrix,
                      "extensions": {"KHR_lights_punctual": {"light": len(lights) - 1}}})

    # Buffer: positions then indices (positions are 12-byte aligned, so the
    # index view starts 4-byte aligned), then normals if any.
    data = bytes(positions) + bytes(indices) + bytes(normals)
    gltf = {
        "asset": {
            "version": "2.0",
            "generator": "smallvcm scenes/make_scenes.py",
            "extras": {"note": "Coordinates are SmallVCM's, not rotated to glTF's +y-up: "
                               "right-handed, +z up, the camera looks along about +y. "
                               "Radiometric values as in SmallVCM (radiance; W/sr; W/m^2). "
                               "See docs/scene_format.md."}},
        "scene": 0,
        "scenes": [{"name": scene["name"], "nodes": list(range(len(nodes))),
                    "extras": {"smallvcm": {"mask": scene["mask"], "name": scene["name"]}
                               if scene.get("mask") is not None else
                               {"name": scene["name"], "figures": scene["figures"]}}}],
        "nodes": nodes,
        "cameras": cameras,
        "meshes": meshes,
        "materials": materials,
        "accessors": accessors,
        "bufferViews": [
            {"name": "positions", "buffer": 0, "byteOffset": 0,
             "byteLength": len(positions), "byteStride": 12, "target": 34962},
            {"name": "indices", "buffer": 0, "byteOffset": len(positions),
             "byteLength": len(indices), "target": 34963}] +
            ([{"name": "normals", "buffer": 0, "byteOffset": len(positions) + len(indices),
               "byteLength": len(normals), "byteStride": 12, "target": 34962}] if normals else []),
        "buffers": [{"byteLength": len(data),
                     "uri": "data:application/octet-stream;base64,"
                            + base64.b64encode(data).decode("ascii")}],
    }
    root_ext = {}
    if lights:
        root_ext["KHR_lights_punctual"] = {"lights": lights}
        used.add("KHR_lights_punctual")
    if scene["background"] is not None:
        root_ext["SMALLVCM_background"] = {"radiance": list(scene["background"])}
        used.add("SMALLVCM_background")
        required.add("SMALLVCM_background")
    if root_ext:
        gltf["extensions"] = root_ext
    gltf["extensionsUsed"] = sorted(used)
    if required:
        gltf["extensionsRequired"] = sorted(required)
    return gltf


# ---------------------------------------------------------------------------
# The figure scenes (docs/figures.md): each models no more than its figure needs
# ---------------------------------------------------------------------------

def quad(corner, edge_u, edge_v):
    """Two triangles of the parallelogram corner + [0,1] edge_u + [0,1] edge_v; the
    front side (counter-clockwise) faces cross(edge_u, edge_v)."""
    p = [corner, tuple(corner[i] + edge_u[i] for i in range(3)),
         tuple(corner[i] + edge_u[i] + edge_v[i] for i in range(3)),
         tuple(corner[i] + edge_v[i] for i in range(3))]
    p = [f32_point(q) for q in p]
    return [(p[0], p[1], p[2]), (p[2], p[3], p[0])]


def cornell_variant(mask, name, figures):
    """A SmallVCM Cornell box from its mask, renamed for the figures that use it."""
    scene = build_cornell_box(mask)
    scene["mask"] = None
    scene["name"] = name
    scene["figures"] = figures
    return scene


def build_indirect_room():
    """F06: the white-floored Cornell box lit almost only indirectly. The light-box
    bottom is replaced by a 0.5 x 0.5 emitter at z = 0.9 that faces the CEILING, with a
    white shade just under it facing down: no light reaches the floor or the walls
    without bouncing off the ceiling first, so next-event estimation from a floor point
    always finds the emitter's back. Same radiance and area as the Cornell light."""
    scene = cornell_variant(LIGHT_CEILING, "indirect room: light facing the ceiling", ["F06"])
    half = 0.25
    scene["light_box"] = [
        ("lamp (emitter, facing the ceiling)",
         [(EMITTER_0, quad((-half, -half, 0.9), (2 * half, 0.0, 0.0), (0.0, 2 * half, 0.0)))]),
        ("lamp shade (facing the floor)",
         [(WHITE, quad((-half, -half, 0.89), (0.0, 2 * half, 0.0), (2 * half, 0.0, 0.0)))]),
    ]
    scene["emission"] = {EMITTER_0: LIGHT_BOX_RADIANCE}
    return scene


def build_sds_glass_sphere():
    """F08, F13, F16, F17: light that reaches the eye only by specular-diffuse-specular
    paths. SmallVCM's large glass sphere (mask 36: white box, point light) with the point
    light moved from the ceiling to between the camera and the sphere, (0, -1.1, -0.1):
    the sphere focuses it onto the back wall, and the camera sees that caustic through the
    same sphere (light -> glass -> wall -> glass -> eye). With the light at SmallVCM's
    ceiling position the caustic falls under the sphere, where the camera barely sees it
    (measured: 0.2% of the light through the sphere; here most of it)."""
    scene = cornell_variant(LIGHT_POINT | LARGE_GLASS_SPHERE,
                            "SDS: a point light focused by a glass sphere onto the wall, seen through the sphere",
                            ["F08", "F13", "F16", "F17"])
    _, colour, intensity = scene["point"]
    scene["point"] = ((0.0, -1.1, -0.1), colour, intensity)
    return scene


def build_spot_light():
    """The empty white Cornell box (mask 4: no light box, no spheres) lit by a spot
    light (KHR_lights_punctual) instead of the point light: hung under the ceiling,
    tilted towards the back right, inner cone 0.35 rad, outer 0.6 rad, so that the
    image shows the full-intensity disc, the falloff ring and the dark outside on the
    floor and the back wall. Only diffuse surfaces: every estimator can render it (the
    tests compare pt, lt, bpt and vcm on it). Intensity 20 W/sr on the axis."""
    scene = cornell_variant(LIGHT_POINT, "spot light in the empty white box", [])
    scene["point"] = None
    scene["spot"] = ((0.0, -0.3, 1.2), (0.35, 0.45, -1.0), (1.0, 1.0, 1.0), 20.0, 0.35, 0.6)
    return scene


def build_two_sided_emitter():
    """The empty white Cornell box (mask 4, no point light) lit by one 0.6 x 0.6 lamp
    whose emissive material is doubleSided: it hangs in the middle, tilted 60 degrees so
    that its front faces the floor and the back wall, its BACK the camera and the ceiling:
    a renderer that ignores doubleSided shows a black lamp lighting only the floor. Both
    sides emit radiance 10. Only diffuse surfaces (the tests compare pt, lt, bpt and vcm
    on it)."""
    scene = cornell_variant(LIGHT_POINT, "two-sided lamp in the empty white box", [])
    scene["point"] = None
    scene["walls"].append(("two-sided lamp (emitter)", [(EMITTER_0, quad(
        (-0.3, 0.05, 0.0), (0.0, 0.3, 0.6 * math.sin(math.radians(60.0))), (0.6, 0.0, 0.0)))]))
    scene["emission"] = {EMITTER_0: 10.0}
    scene["two_sided_emitters"] = True
    return scene


# Veach's glossy plates (Veach 1997, fig. 9.2): four plates of four Phong exponents,
# four sphere lights of four radii whose radiance scales as 1/r^2 (equal power).
PLATE_EXPONENTS = [20.0, 150.0, 1200.0, 10000.0]     # nearest (roughest) to farthest
PLATE_LIGHT_RADII = [0.03, 0.1, 0.3, 0.9]
PLATE_LIGHT_COLOURS = [(1.0, 0.85, 0.5), (0.6, 1.0, 0.6), (0.55, 0.75, 1.0), (1.0, 0.6, 0.9)]


def build_veach_plates():
    """F04. +y up. The plates are 8 wide and 1 deep, stepped away from the camera and
    each tilted so that it mirrors the middle of the light row towards the camera: each
    plate shows all four lights as highlights, whose size depends on both the light
    and the plate's exponent. The radiance of light k is 1.23 (0.9 / r_k)^2 (Veach's
    values are 1.23, 11.1, 100, 901.8)."""
    camera = (0.0, 2.0, 15.0)
    target = (0.0, -2.0, 2.5)
    light_row = [(x, 0.0, 0.0) for x in (-3.75, -1.25, 1.25, 3.75)]
    row_centre = (0.0, 0.0, 0.0)

    materials = [material("plate light %d (emitter)" % k) for k in range(4)]
    for k, n in enumerate(PLATE_EXPONENTS):
        materials.append(material("plate %d, Phong exponent %g" % (k, n),
                                  phong=(0.75, 0.75, 0.75), exponent=n))
    materials.append(material("backdrop", diffuse=(0.05, 0.05, 0.05)))

    def sub(a, b):
        return tuple(a[i] - b[i] for i in range(3))

    walls = []
    centres = [(0.0, -3.4, 3.9), (0.0, -2.7, 2.6), (0.0, -2.0, 1.3), (0.0, -1.3, 0.0)]
    for k, c in enumerate(centres):
        n = normalize(tuple(a + b for a, b in zip(normalize(sub(camera, c)), normalize(sub(row_centre, c)))))
        width = (8.0, 0.0, 0.0)
        depth = normalize(cross(n, (1.0, 0.0, 0.0)))        # in the plate, across its width
        depth = tuple(1.2 * d for d in depth)
        corner = tuple(c[i] - 0.5 * width[i] - 0.5 * depth[i] for i in range(3))
        tris = quad(corner, width, depth)                     # front = cross(width, depth) = n
        walls.append(("plate %d (exponent %g)" % (k, PLATE_EXPONENTS[k]), [(4 + k, tris)]))
    # A dark backdrop behind the lights and under the plates, so the picture has a ground.
    walls.append(("backdrop", [(8, quad((-12.0, -4.5, -6.0), (24.0, 0.0, 0.0), (0.0, 0.0, 16.0)))]))

    spheres = []
    emission = {}
    for k, (centre, r) in enumerate(zip(light_row, PLATE_LIGHT_RADII)):
        spheres.append(("light %d (radius %g)" % (k, r), centre, r, k))
        emission[k] = 1.23 * (0.9 / r) ** 2
    scene = {"mask": None, "name": "Veach's glossy plates", "figures": ["F04"],
             "materials": materials, "walls": walls, "spheres": spheres, "light_box": [],
             "emission": emission, "sun": None, "point": None, "background": None,
             "fov_deg": 34.0,
             "camera": (camera, sub(target, camera), (0.0, 1.0, 0.0))}
    return scene


def icosphere(subdivisions):
    """A unit geodesic sphere: the icosahedron, each triangle split in four
    `subdivisions` times, vertices pushed onto the sphere. Returns (vertices,
    triangles as index triples), wound counter-clockwise seen from outside.
    20 * 4^subdivisions triangles (1: 80, 2: 320)."""
    t = (1.0 + math.sqrt(5.0)) / 2.0
    verts = [normalize(v) for v in [
        (-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t),
        (0, -1, -t), (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
             (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
             (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(subdivisions):
        midpoints = {}

        def middle(a, b):
            key = (min(a, b), max(a, b))
            if key not in midpoints:
                midpoints[key] = len(verts)
                verts.append(normalize(tuple(verts[a][i] + verts[b][i] for i in range(3))))
            return midpoints[key]
        finer = []
        for a, b, c in faces:
            ab, bc, ca = middle(a, b), middle(b, c), middle(c, a)
            finer += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = finer
    return verts, faces


def build_smooth_sphere_box():
    """The shading-normal test (tests/test_integrators.cpp): an 80-triangle geodesic
    sphere (radius 0.6, white Lambert) with its exact sphere normals as NORMAL, on the
    floor of the white-floored Cornell box under its area light. Its vertex normals differ
    from the faces' by up to ~21 degrees, so estimators that transport importance (light
    tracing, BPT, VCM) agree with path tracing only with Veach's adjoint correction."""
    scene = cornell_variant(LIGHT_CEILING, "smooth-shaded low-polygon sphere in the Cornell box", [])
    verts, faces = icosphere(1)
    centre, radius = (0.0, 0.1, -1.28002 + 0.6 + 0.02), 0.6
    scene["smooth"] = [{
        "name": "smooth sphere (80 triangles, vertex normals)", "material": WHITE,
        "positions": [tuple(centre[i] + radius * v[i] for i in range(3)) for v in verts],
        "normals": [f32_point(v) for v in verts],
        "indices": [i for face in faces for i in face]}]
    return scene


# (file name, builder) of the figure scenes.
FIGURE_SCENES = [
    ("veach_plates.gltf", build_veach_plates),
    ("spot_light.gltf", build_spot_light),
    ("two_sided_emitter.gltf", build_two_sided_emitter),
    ("indirect_room.gltf", build_indirect_room),
    ("sds_glass_sphere.gltf", build_sds_glass_sphere),
    ("diffuse_box.gltf", lambda: cornell_variant(
        LIGHT_CEILING, "diffuse: the empty Cornell box under its area light", ["F14", "F16"])),
    ("caustic_glass_sphere.gltf", lambda: cornell_variant(
        LIGHT_CEILING | LARGE_GLASS_SPHERE,
        "caustic: a large glass sphere under the small area light", ["F07", "F09", "F10", "F11", "F12"])),
    ("smooth_sphere_box.gltf", build_smooth_sphere_box),
]


# ---------------------------------------------------------------------------
# A model as people bring them: textured, smooth-shaded, no camera, no light
# ---------------------------------------------------------------------------

def png_rgb(width, height, pixels):
    """An 8-bit RGB PNG (pixels: (r, g, b) tuples, row by row from the top)."""
    import zlib
    raw = b"".join(b"\x00" + bytes(c for p in pixels[y * width:(y + 1) * width] for c in p)
                   for y in range(height))

    def chunk(kind, data):
        return (struct.pack(">I", len(data)) + kind + data +
                struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))
    return (b"\x89PNG\r\n\x1a\n" +
            chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)) +
            chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


def build_textured_torus():
    """A smooth-shaded torus (major radius 1, minor 0.4, 48 x 24 quads) with a checker
    baseColorTexture (a 64 x 64 PNG in a data URI, sRGB as glTF says), NORMAL and
    TEXCOORD_0, tilted 35 degrees towards the viewer, glTF's +y up. No camera and no light:
    smallvcm frames it with its default camera and lights it with its default sky and sun."""
    rings, sides, major, minor = 48, 24, 1.0, 0.4
    positions, normals, uvs, indices = [], [], [], []
    for i in range(rings + 1):              # seams duplicated: the texture wraps cleanly
        u = i / rings
        phi = 2.0 * math.pi * u
        for j in range(sides + 1):
            v = j / sides
            theta = 2.0 * math.pi * v
            n = (math.cos(theta) * math.cos(phi), math.sin(theta), math.cos(theta) * math.sin(phi))
            positions.append(f32_point((major * math.cos(phi) + minor * n[0], minor * n[1],
                                        major * math.sin(phi) + minor * n[2])))
            normals.append(f32_point(n))
            uvs.append((f32(4.0 * u), f32(2.0 * v)))   # 4 x 2 texture repeats around
    for i in range(rings):
        for j in range(sides):
            a, b = i * (sides + 1) + j, (i + 1) * (sides + 1) + j
            # Counter-clockwise seen from outside (the side the normals face).
            indices += [a, a + 1, b, b, a + 1, b + 1]
    cells, size = 8, 64
    light, dark = (235, 214, 170), (176, 58, 46)
    texels = [light if ((x * cells // size) + (y * cells // size)) % 2 == 0 else dark
              for y in range(size) for x in range(size)]
    png = png_rgb(size, size, texels)
    data = bytearray()
    views = []
    for raw, target in [(b"".join(struct.pack("<3f", *p) for p in positions), 34962),
                        (b"".join(struct.pack("<3f", *n) for n in normals), 34962),
                        (b"".join(struct.pack("<2f", *t) for t in uvs), 34962),
                        (struct.pack("<%dH" % len(indices), *indices), 34963)]:
        views.append({"buffer": 0, "byteOffset": len(data), "byteLength": len(raw), "target": target})
        data += raw
        data += b"\0" * (-len(data) % 4)
    tilt = math.radians(35.0)
    return {
        "asset": {"version": "2.0", "generator": "smallvcm scenes/make_scenes.py",
                  "extras": {"note": "A model as people bring them: textured, smooth-shaded "
                                     "(NORMAL), no camera, no light. glTF conventions: +y up, "
                                     "metres, sRGB texture. See docs/scene_format.md."}},
        "scene": 0,
        "scenes": [{"name": "textured torus", "nodes": [0]}],
        "nodes": [{"name": "torus", "mesh": 0,
                   "rotation": [round(math.sin(tilt / 2.0), 9), 0.0, 0.0, round(math.cos(tilt / 2.0), 9)]}],
        "meshes": [{"name": "torus", "primitives": [{
            "attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2}, "indices": 3,
            "material": 0, "mode": 4}]}],
        "materials": [{"name": "checker plastic",
                       "pbrMetallicRoughness": {"baseColorTexture": {"index": 0},
                                                "metallicFactor": 0.0, "roughnessFactor": 0.5}}],
        "textures": [{"sampler": 0, "source": 0}],
        "samplers": [{"magFilter": 9729, "minFilter": 9729, "wrapS": 10497, "wrapT": 10497}],
        "images": [{"name": "checker", "uri": "data:image/png;base64," + base64.b64encode(png).decode("ascii")}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": len(positions), "type": "VEC3",
             "min": f32_vec([min(p[k] for p in positions) for k in range(3)]),
             "max": f32_vec([max(p[k] for p in positions) for k in range(3)])},
            {"bufferView": 1, "componentType": 5126, "count": len(normals), "type": "VEC3"},
            {"bufferView": 2, "componentType": 5126, "count": len(uvs), "type": "VEC2"},
            {"bufferView": 3, "componentType": 5123, "count": len(indices), "type": "SCALAR"}],
        "bufferViews": views,
        "buffers": [{"byteLength": len(data),
                     "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(data)).decode("ascii")}],
    }


def png_rgba(width, height, pixels):
    """An 8-bit RGBA PNG (pixels: (r, g, b, a) tuples, row by row from the top)."""
    import zlib
    raw = b"".join(b"\x00" + bytes(c for p in pixels[y * width:(y + 1) * width] for c in p)
                   for y in range(height))

    def chunk(kind, data):
        return (struct.pack(">I", len(data)) + kind + data +
                struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))
    return (b"\x89PNG\r\n\x1a\n" +
            chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 6, 0, 0, 0)) +
            chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


def build_cutout_leaves():
    """SmallVCM's default Cornell box (mask 193) with a canopy of 400 leaves between its
    ceiling light and the floor: double-sided quads whose base colour's alpha (a 32 x 32
    RGBA PNG, an ellipse of alpha 1 in alpha 0) cuts out the leaf (alphaMode MASK, the
    default cutoff 0.5). Every kind of ray crosses the holes: the scene for the cost of
    alpha testing and for the BVH builds' agreement with cut-outs."""
    import random
    doc = to_gltf(build_cornell_box(193))
    rng = random.Random(35)
    positions, uvs, indices = [], [], []
    for _ in range(400):
        centre = (rng.uniform(-1.1, 1.1), rng.uniform(-1.1, 1.1), rng.uniform(-0.1, 0.9))
        # Two perpendicular edges of length 0.3, in a random orientation.
        def unit(v):
            n = math.sqrt(sum(c * c for c in v))
            return tuple(c / n for c in v)
        a = unit((rng.gauss(0, 1), rng.gauss(0, 1), rng.gauss(0, 1)))
        b = unit(cross(a, unit((rng.gauss(0, 1), rng.gauss(0, 1), rng.gauss(0, 1)))))
        first = len(positions)
        for su, sv in [(-1, -1), (1, -1), (1, 1), (-1, 1)]:
            positions.append(f32_point(tuple(centre[k] + 0.15 * (su * a[k] + sv * b[k]) for k in range(3))))
            uvs.append((0.5 + 0.5 * su, 0.5 - 0.5 * sv))
        indices += [first, first + 1, first + 2, first + 2, first + 3, first]
    size = 32
    texels = []
    for y in range(size):
        for x in range(size):
            u, v = (x + 0.5) / size - 0.5, (y + 0.5) / size - 0.5
            inside = (u / 0.48) ** 2 + (v / 0.3) ** 2 <= 1.0
            texels.append((60, 150, 50, 255 if inside else 0))
    png = png_rgba(size, size, texels)
    data = bytearray()
    views = len(doc["bufferViews"])
    for raw, target in [(b"".join(struct.pack("<3f", *p) for p in positions), 34962),
                        (b"".join(struct.pack("<2f", *t) for t in uvs), 34962),
                        (struct.pack("<%dH" % len(indices), *indices), 34963)]:
        doc["bufferViews"].append({"buffer": 1, "byteOffset": len(data), "byteLength": len(raw), "target": target})
        data += raw
        data += b"\0" * (-len(data) % 4)
    doc["buffers"].append({"byteLength": len(data),
                           "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(data)).decode("ascii")})
    accessors = len(doc["accessors"])
    doc["accessors"] += [
        {"bufferView": views, "componentType": 5126, "count": len(positions), "type": "VEC3",
         "min": f32_vec([min(p[k] for p in positions) for k in range(3)]),
         "max": f32_vec([max(p[k] for p in positions) for k in range(3)])},
        {"bufferView": views + 1, "componentType": 5126, "count": len(uvs), "type": "VEC2"},
        {"bufferView": views + 2, "componentType": 5123, "count": len(indices), "type": "SCALAR"}]
    doc["materials"].append({"name": "leaf", "alphaMode": "MASK", "doubleSided": True,
                             "pbrMetallicRoughness": {"baseColorTexture": {"index": 0},
                                                      "metallicFactor": 0.0, "roughnessFactor": 1.0}})
    doc["textures"] = [{"sampler": 0, "source": 0}]
    doc["samplers"] = [{"magFilter": 9729, "minFilter": 9729, "wrapS": 33071, "wrapT": 33071}]
    doc["images"] = [{"name": "leaf", "uri": "data:image/png;base64," + base64.b64encode(png).decode("ascii")}]
    doc["meshes"].append({"name": "leaves", "primitives": [{
        "attributes": {"POSITION": accessors, "TEXCOORD_0": accessors + 1}, "indices": accessors + 2,
        "material": len(doc["materials"]) - 1, "mode": 4}]})
    doc["nodes"].append({"name": "leaves", "mesh": len(doc["meshes"]) - 1})
    doc["scenes"][doc.get("scene", 0)]["nodes"].append(len(doc["nodes"]) - 1)
    doc["asset"]["extras"]["note"] = ("SmallVCM's default Cornell box with 400 leaf cut-outs (alphaMode MASK) "
                                      "under its light. " + doc["asset"]["extras"]["note"])
    return doc


# ---------------------------------------------------------------------------
# Participating media (issue #43, docs/scene_format.md 4.4): rooms of plain glTF
# materials, +z up like the Cornell files, every wall a mesh of its own (an open quad,
# so the room is no closed mesh: a scene medium fills it). A medium's mesh is closed:
# every edge shared by exactly two triangles, wound outwards (check_closed).
# ---------------------------------------------------------------------------

def check_closed(positions, triangles):
    """Asserts that the triangles (index triples) form a closed, consistently wound
    surface (each directed edge once, and its reverse once) enclosing a positive volume
    (wound outwards); returns the volume."""
    edges = {}
    for a, b, c in triangles:
        for e in ((a, b), (b, c), (c, a)):
            assert e not in edges, "edge %s used twice in one direction" % (e,)
            edges[e] = True
    for a, b in edges:
        assert (b, a) in edges, "edge %s has no twin: the mesh is open" % ((a, b),)
    volume = sum(dot3(positions[a], cross(positions[b], positions[c])) for a, b, c in triangles) / 6.0
    assert volume > 0.0, "the mesh is wound inwards"
    return volume


def dot3(a, b):
    return sum(a[i] * b[i] for i in range(3))


def look_at_camera(position, target, yfov_deg, aspect=1.0):
    forward = tuple(target[i] - position[i] for i in range(3))
    return {"matrix": camera_matrix(position, forward, (0.0, 0.0, 1.0)),
            "perspective": {"aspectRatio": aspect, "yfov": math.radians(yfov_deg), "znear": 0.01}}


class MediaScene:
    """A glTF document built mesh by mesh (indexed float32 positions, optional NORMAL)."""

    def __init__(self, name, note):
        self.name, self.note = name, note
        self.nodes, self.meshes, self.materials, self.accessors, self.views = [], [], [], [], []
        self.data = bytearray()
        self.lights = []
        self.material_index = {}

    def material(self, key, gltf_material):
        self.material_index[key] = len(self.materials)
        self.materials.append(gltf_material)

    def view(self, raw, target):
        self.views.append({"buffer": 0, "byteOffset": len(self.data), "byteLength": len(raw), "target": target})
        self.data += raw
        self.data += b"\0" * (-len(self.data) % 4)
        return len(self.views) - 1

    def mesh(self, name, positions, triangles, material, normals=None):
        positions = [f32_point(p) for p in positions]
        attributes = {"POSITION": len(self.accessors)}
        self.accessors.append({
            "bufferView": self.view(b"".join(struct.pack("<3f", *p) for p in positions), 34962),
            "componentType": 5126, "count": len(positions), "type": "VEC3",
            "min": f32_vec([min(p[k] for p in positions) for k in range(3)]),
            "max": f32_vec([max(p[k] for p in positions) for k in range(3)])})
        if normals is not None:
            attributes["NORMAL"] = len(self.accessors)
            self.accessors.append({
                "bufferView": self.view(b"".join(struct.pack("<3f", *f32_point(n)) for n in normals), 34962),
                "componentType": 5126, "count": len(normals), "type": "VEC3"})
        flat = [i for t in triangles for i in t]
        self.accessors.append({"bufferView": self.view(struct.pack("<%dI" % len(flat), *flat), 34963),
                               "componentType": 5125, "count": len(flat), "type": "SCALAR"})
        self.meshes.append({"name": name, "primitives": [{
            "attributes": attributes, "indices": len(self.accessors) - 1,
            "material": self.material_index[material], "mode": 4}]})
        self.nodes.append({"name": name, "mesh": len(self.meshes) - 1})

    def quad(self, name, corner, edge_u, edge_v, material):
        """A parallelogram whose front side faces cross(edge_u, edge_v)."""
        p = [corner, tuple(corner[i] + edge_u[i] for i in range(3)),
             tuple(corner[i] + edge_u[i] + edge_v[i] for i in range(3)),
             tuple(corner[i] + edge_v[i] for i in range(3))]
        self.mesh(name, p, [(0, 1, 2), (2, 3, 0)], material)

    def room(self, x, y, z, materials):
        """The six walls of the box x[0]..x[1], y[0]..y[1], z[0]..z[1], facing inwards,
        each its own mesh; materials: floor, ceiling, back, front, left, right."""
        (x0, x1), (y0, y1), (z0, z1) = x, y, z
        dx, dy, dz = x1 - x0, y1 - y0, z1 - z0
        floor, ceiling, back, front, left, right = materials
        self.quad("floor", (x0, y0, z0), (dx, 0, 0), (0, dy, 0), floor)
        self.quad("ceiling", (x0, y0, z1), (0, dy, 0), (dx, 0, 0), ceiling)
        self.quad("back wall", (x0, y1, z0), (dx, 0, 0), (0, 0, dz), back)
        self.quad("front wall (behind the camera)", (x0, y0, z0), (0, 0, dz), (dx, 0, 0), front)
        self.quad("left wall", (x0, y0, z0), (0, dy, 0), (0, 0, dz), left)
        self.quad("right wall", (x1, y0, z0), (0, 0, dz), (0, dy, 0), right)

    def spot(self, name, position, travel, intensity, inner, outer):
        """A KHR_lights_punctual spot light (W/sr on its axis) at position, shining along travel."""
        self.lights.append({"name": name, "type": "spot", "color": [1.0, 1.0, 1.0], "intensity": intensity,
                            "spot": {"innerConeAngle": inner, "outerConeAngle": outer}})
        # The light shines down its local -Z: straight down needs no turn.
        matrix = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0] \
            if tuple(travel) == (0.0, 0.0, -1.0) else direction_matrix(travel)
        matrix[12:15] = f32_vec(position)
        self.nodes.append({"name": name, "matrix": matrix, "extensions": {"KHR_lights_punctual": {"light": len(self.lights) - 1}}})

    def sphere(self, name, centre, radius, material):
        self.nodes.append({"name": name, "translation": f32_vec(centre),
                           "extensions": {"SMALLVCM_sphere": {"radius": f32_json(radius),
                                                              "material": self.material_index[material]}}})

    def finish(self, camera, figures, scene_extensions=None):
        nodes = [dict(name="camera", camera=0, matrix=camera["matrix"])] + self.nodes
        used = set(scene_extensions or {})
        for m in self.materials:
            used.update(m.get("extensions", {}))
        for n in nodes:
            used.update(n.get("extensions", {}))
        scene = {"name": self.name, "nodes": list(range(len(nodes))),
                 "extras": {"smallvcm": {"name": self.name, "figures": figures}}}
        if scene_extensions:
            scene["extensions"] = scene_extensions
        if self.lights:
            used.add("KHR_lights_punctual")
        doc = {
            "asset": {"version": "2.0", "generator": "smallvcm scenes/make_scenes.py",
                      "extras": {"note": self.note + " +z up, as the Cornell files. See docs/scene_format.md 4.4."}},
            "scene": 0, "scenes": [scene], "nodes": nodes,
            "cameras": [{"name": "camera", "type": "perspective", "perspective": camera["perspective"]}],
            "meshes": self.meshes, "materials": self.materials, "accessors": self.accessors,
            "bufferViews": self.views,
            "buffers": [{"byteLength": len(self.data),
                         "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(self.data)).decode("ascii")}],
            "extensionsUsed": sorted(used)}
        if self.lights:
            doc["extensions"] = {"KHR_lights_punctual": {"lights": self.lights}}
        if "SMALLVCM_sphere" in used:
            doc["extensionsRequired"] = ["SMALLVCM_sphere"]
        return doc


def lambert(name, colour):
    """A Lambert wall: exact in SMALLVCM_material, approximated for other viewers."""
    return {"name": name, "pbrMetallicRoughness": {"baseColorFactor": list(colour) + [1.0],
                                                   "metallicFactor": 0.0, "roughnessFactor": 1.0},
            "extensions": {"SMALLVCM_material": {"diffuse": f32_vec(colour)}}}


def emitter(name, radiance):
    return {"name": name, "emissiveFactor": [1.0, 1.0, 1.0],
            "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0]},
            "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": radiance}}}


def room_materials(scene):
    scene.material("white", lambert("white wall", (0.75, 0.75, 0.75)))
    scene.material("green", lambert("green wall", (0.2, 0.6, 0.2)))
    scene.material("red", lambert("red wall", (0.65, 0.2, 0.2)))
    return ("white", "white", "white", "white", "green", "red")


def closed_sphere_mesh(subdivisions, centre, radius):
    """The icosphere (welded vertices, wound outwards) placed at centre, with its exact
    normals; asserts it is closed."""
    verts, faces = icosphere(subdivisions)
    positions = [tuple(centre[i] + radius * v[i] for i in range(3)) for v in verts]
    check_closed([f32_point(p) for p in positions], faces)
    return positions, faces, verts


# Fog of F20: in a room 2 wide, 2 high and 4.5 deep, extinction 0.11 per unit: 30% of
# the light is scattered or absorbed over the 3.3 from the camera to the sphere.
FOG = {"sigmaA": [0.01, 0.01, 0.01], "sigmaS": [0.1, 0.1, 0.1], "g": 0.3}


def add_dense_block(scene, lo, hi):
    """A closed box from lo to hi of DENSE_BLOCK behind an index-matched boundary."""
    scene.material("block", {"name": "dense medium (index-matched boundary)",
                             "pbrMetallicRoughness": {"baseColorFactor": [0.95, 0.95, 0.95, 1.0],
                                                      "metallicFactor": 0.0, "roughnessFactor": 0.6},
                             "extensions": {"SMALLVCM_medium": DENSE_BLOCK}})
    positions, faces = closed_box_mesh(lo, hi)
    scene.mesh("dense block (closed box)", positions, faces, "block")


def build_fog_caustic_box(with_block=False):
    """F20, the volumetric twin of F08/F13: a closed room filled with fog (the scene
    medium), a spot light under the ceiling whose beam falls wholly on a floating glass
    sphere (r 0.25, ior 1.5, 0.85 below the spot: the sphere spans 17.1 degrees, the beam
    16) that focuses it into a cone converging about 0.65 below the sphere's centre, in
    the fog: a volumetric caustic (light -> glass -> glass -> fog -> eye). A mirror panel
    standing by the left wall, turned towards the camera, shows the cone from its side.
    The spot is a delta light: no camera path can hit it, so the cone seen in the mirror
    (light -> S -> S -> fog -> mirror -> eye) is out of reach of every technique but
    merging in the medium.

    with_block: F22's scene, the same with a dense block (F21's dense medium, mean free
    path 0.1, behind an index-matched boundary) on the floor where the cone lands. Three
    kinds of transport side by side: the cone in the thin fog (photon beams' case), the
    block (photon points' and paths' case), and both seen in the mirror, where no
    connection reaches them: only merging in a medium renders them there."""
    if with_block:
        scene = MediaScene("glass fog block: a glass sphere focuses a lamp into a cone of light in fog, onto a dense block",
                           "F22: fog (scene-wide SMALLVCM_medium), a glass sphere under a small lamp, a mirror, "
                           "a dense block (SMALLVCM_medium on a closed box) on the floor.")
    else:
        scene = MediaScene("fog caustic box: a glass sphere focuses a lamp into a cone of light in fog",
                           "F20: fog (scene-wide SMALLVCM_medium), a glass sphere under a small lamp, a mirror.")
    walls = room_materials(scene)
    scene.material("glass", {"name": "glass", "pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 1.0],
                                                                       "metallicFactor": 0.0, "roughnessFactor": 0.0},
                             "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1.0},
                                            "KHR_materials_ior": {"ior": 1.5}}})
    scene.material("mirror", {"name": "mirror", "pbrMetallicRoughness": {"baseColorFactor": [0.95, 0.95, 0.95, 1.0],
                                                                         "metallicFactor": 1.0, "roughnessFactor": 0.0}})
    scene.room((-1.0, 1.0), (-3.5, 1.0), (0.0, 2.0), walls)
    scene.spot("spot light (down onto the glass sphere)", (0.0, 0.0, 1.95), (0.0, 0.0, -1.0), 30.0,
               math.radians(13.0), math.radians(16.0))
    scene.sphere("glass sphere", (0.0, 0.0, 1.1), 0.25, "glass")
    # The mirror: 0.7 wide, 1.3 high, its normal halfway between the camera and the cone.
    eye, cone, centre = (0.3, -3.3, 1.0), (0.0, 0.0, 0.6), (-0.62, 0.25, 0.85)
    to_eye = normalize(tuple(eye[i] - centre[i] for i in range(3)))
    to_cone = normalize(tuple(cone[i] - centre[i] for i in range(3)))
    n = normalize((to_eye[0] + to_cone[0], to_eye[1] + to_cone[1], 0.0))  # upright
    u = normalize(cross(n, (0.0, 0.0, 1.0)))   # cross(up, u) = n: the front faces n
    half_w, half_h = 0.35, 0.65
    corner = tuple(centre[i] - half_w * u[i] - half_h * (0.0, 0.0, 1.0)[i] for i in range(3))
    scene.quad("mirror panel (facing the room)", corner, (0.0, 0.0, 2 * half_h), tuple(2 * half_w * c for c in u), "mirror")
    if with_block:
        add_dense_block(scene, (-0.3, -0.3, 0.001), (0.3, 0.3, 0.25))
    return scene.finish(look_at_camera(eye, (0.0, 0.0, 0.75), 45.0), ["F22" if with_block else "F20"],
                        {"SMALLVCM_medium": FOG})


def build_dense_scattering_sphere():
    """A sphere (radius 0.4) of dense scattering medium behind an index-matched boundary
    (SMALLVCM_medium without transmission: rays cross its surface unbent): sigma_t about
    20, a mean free path of 0.05 (the radius is 8 of them), single-scattering albedo 0.97,
    0.95, 0.92 (warm: the look of marble or skin), isotropic; lit from above and behind by
    a 0.6 x 0.6 area light in a closed room."""
    scene = MediaScene("dense scattering sphere: subsurface-like transport behind an index-matched boundary",
                       "A sphere of dense scattering medium (SMALLVCM_medium, no transmission) under an area light.")
    walls = room_materials(scene)
    scene.material("lamp", emitter("ceiling lamp (emitter)", 20.0))
    scene.material("marble", {"name": "marble medium (index-matched boundary)",
                              "pbrMetallicRoughness": {"baseColorFactor": [0.95, 0.92, 0.88, 1.0],
                                                       "metallicFactor": 0.0, "roughnessFactor": 0.6},
                              "extensions": {"SMALLVCM_medium": {"sigmaA": [0.6, 1.0, 1.6], "sigmaS": [19.0, 19.0, 18.5],
                                                                 "g": 0.0}}})
    scene.room((-1.0, 1.0), (-2.5, 1.0), (0.0, 2.0), walls)
    scene.quad("ceiling lamp (emitter, 0.6 x 0.6, facing down)", (-0.3, 0.2, 1.98), (0.0, 0.6, 0.0), (0.6, 0.0, 0.0), "lamp")
    positions, faces, _ = closed_sphere_mesh(3, (0.0, 0.0, 0.41), 0.4)
    scene.mesh("marble sphere (1280 triangles, closed)", positions, faces, "marble")
    return scene.finish(look_at_camera((0.0, -2.3, 1.0), (0.0, 0.0, 0.45), 40.0), [])


def build_absorbing_glass():
    """Absorbing glass by KHR_materials_volume (attenuationColor (0.9, 0.5, 0.2) after
    attenuationDistance 0.3): a wedge 0.9 long rising from 0 to 0.45 (its thick end
    darker, redder, than its thin edge) and a sphere of radius 0.3 (darkest through its
    centre, 0.6 of glass: (0.81, 0.25, 0.04) of the light kept), both closed triangle
    meshes, under an area light in a closed room."""
    scene = MediaScene("absorbing glass: KHR_materials_volume in a wedge and a sphere",
                       "Absorbing glass (KHR_materials_volume): thick parts darker than thin ones.")
    walls = room_materials(scene)
    scene.material("lamp", emitter("ceiling lamp (emitter)", 20.0))
    scene.material("amber", {"name": "amber glass",
                             "pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 1.0],
                                                      "metallicFactor": 0.0, "roughnessFactor": 0.0},
                             "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1.0},
                                            "KHR_materials_ior": {"ior": 1.5},
                                            "KHR_materials_volume": {"attenuationColor": [0.9, 0.5, 0.2],
                                                                     "attenuationDistance": 0.3,
                                                                     "thicknessFactor": 0.3}}})
    scene.room((-1.0, 1.0), (-2.5, 1.0), (0.0, 2.0), walls)
    scene.quad("ceiling lamp (emitter, 0.6 x 0.6, facing down)", (-0.3, -0.3, 1.98), (0.0, 0.6, 0.0), (0.6, 0.0, 0.0), "lamp")
    # The wedge: a right-triangle prism, thin edge at x = -0.95, 0.45 high at x = -0.05.
    x0, x1, y0, y1, z0, h = -0.95, -0.05, -0.25, 0.25, 0.002, 0.45
    wedge = [(x0, y0, z0), (x1, y0, z0), (x1, y0, z0 + h), (x0, y1, z0), (x1, y1, z0), (x1, y1, z0 + h)]
    wedge_faces = [(0, 1, 2), (3, 5, 4), (0, 3, 4), (0, 4, 1), (1, 4, 5), (1, 5, 2), (0, 2, 5), (0, 5, 3)]
    check_closed([f32_point(p) for p in wedge], wedge_faces)
    scene.mesh("amber wedge (closed prism)", wedge, wedge_faces, "amber")
    positions, faces, normals = closed_sphere_mesh(3, (0.45, 0.0, 0.31), 0.3)
    scene.mesh("amber sphere (1280 triangles, closed, smooth normals)", positions, faces, "amber", normals)
    return scene.finish(look_at_camera((0.0, -2.3, 1.0), (0.0, 0.0, 0.3), 40.0), [])


# F21's media: the same grey medium, albedo 0.95, isotropic, at two densities (per unit).
# Thin: a fog filling the room, a mean free path of 10 (the room is 3.5 deep: the light
# crosses it nearly unscattered). Dense: a block of mean free path 0.1 (0.8 across: most
# light scatters many times before it leaves), in a room of clear air.
THIN_FOG = {"sigmaA": [0.005, 0.005, 0.005], "sigmaS": [0.095, 0.095, 0.095], "g": 0.0}
DENSE_BLOCK = {"sigmaA": [0.5, 0.5, 0.5], "sigmaS": [9.5, 9.5, 9.5], "g": 0.0}


def closed_box_mesh(low, high):
    """The box low..high as 12 triangles wound outwards; asserts it is closed."""
    positions = [(x, y, z) for z in (low[2], high[2]) for y in (low[1], high[1]) for x in (low[0], high[0])]
    faces = [(0, 2, 3), (3, 1, 0), (4, 5, 7), (7, 6, 4), (0, 1, 5), (5, 4, 0),
             (2, 6, 7), (7, 3, 2), (0, 4, 6), (6, 2, 0), (1, 3, 7), (7, 5, 1)]
    check_closed([f32_point(p) for p in positions], faces)
    return positions, faces


def build_spot_in_medium(dense):
    """F21: one spot light in a dark room, its cone crossing the view from the upper left
    down to the right: through a thin fog filling the room, or into a dense block (an
    index-matched closed box: rays cross its surface unbent) standing where the cone meets
    the floor. The walls are black (diffuse, reflectance 0), so all the light in the image
    was scattered in the medium: photon points and photon beams are compared on the
    medium alone (both merge on surfaces alike)."""
    density = "dense" if dense else "thin"
    scene = MediaScene("spot in a %s medium: one light's cone in a dark room" % density,
                       "F21: a spot light into a %s medium, black walls." % (
                           "dense block (SMALLVCM_medium on a closed box)" if dense else "thin fog (scene-wide SMALLVCM_medium)"))
    scene.material("black", lambert("black wall", (0.0, 0.0, 0.0)))
    scene.room((-1.0, 1.0), (-2.5, 1.0), (0.0, 2.0), ("black",) * 6)
    scene.spot("spot light (across the room, down onto the middle)", (-0.8, 0.6, 1.85), normalize((0.8, -0.6, -1.05)),
               100.0, math.radians(8.0), math.radians(11.0))
    camera = look_at_camera((0.0, -2.3, 1.0), (0.0, 0.2, 0.9), 50.0)
    if not dense:
        return scene.finish(camera, ["F21"], {"SMALLVCM_medium": THIN_FOG})
    add_dense_block(scene, (-0.4, -0.4, 0.001), (0.4, 0.4, 0.8))
    return scene.finish(camera, ["F21"])


# (file name, builder) of the media scenes: builders return the glTF document.
MEDIA_SCENES = [
    ("fog_caustic_box.gltf", build_fog_caustic_box),
    ("glass_fog_block.gltf", lambda: build_fog_caustic_box(with_block=True)),
    ("dense_scattering_sphere.gltf", build_dense_scattering_sphere),
    ("absorbing_glass.gltf", build_absorbing_glass),
    ("spot_in_thin_fog.gltf", lambda: build_spot_in_medium(False)),
    ("spot_in_dense_block.gltf", lambda: build_spot_in_medium(True)),
]


# ---------------------------------------------------------------------------
# Compact JSON: number arrays and short objects on one line, the rest indented
# ---------------------------------------------------------------------------

def dumps(value, indent=0, width=100):
    flat = json.dumps(value, separators=(", ", ": "))
    numbers = isinstance(value, list) and all(isinstance(v, (int, float)) for v in value)
    if len(flat) + indent <= width or numbers or not isinstance(value, (dict, list)) or not value:
        return flat
    pad = " " * (indent + 2)
    if isinstance(value, dict):
        items = ["%s%s: %s" % (pad, json.dumps(k), dumps(v, indent + 2, width))
                 for k, v in value.items()]
        return "{\n" + ",\n".join(items) + "\n" + " " * indent + "}"
    items = [pad + dumps(v, indent + 2, width) for v in value]
    return "[\n" + ",\n".join(items) + "\n" + " " * indent + "]"


def main():
    out_dir = os.path.dirname(os.path.abspath(__file__))
    for file_name, mask in SCENE_CONFIGS:
        text = dumps(to_gltf(build_cornell_box(mask))) + "\n"
        with open(os.path.join(out_dir, file_name), "w", encoding="ascii", newline="\n") as f:
            f.write(text)
        print("wrote scenes/%s  (mask %d: %s)" % (file_name, mask, scene_name(mask)))
    for file_name, builder in FIGURE_SCENES:
        scene = builder()
        text = dumps(to_gltf(scene)) + "\n"
        with open(os.path.join(out_dir, file_name), "w", encoding="ascii", newline="\n") as f:
            f.write(text)
        print("wrote scenes/%s  (%s)" % (file_name, scene["name"]))
    with open(os.path.join(out_dir, "textured_torus.gltf"), "w", encoding="ascii", newline="\n") as f:
        f.write(dumps(build_textured_torus()) + "\n")
    print("wrote scenes/textured_torus.gltf  (textured, smooth-shaded, no camera, no light)")
    with open(os.path.join(out_dir, "cutout_leaves.gltf"), "w", encoding="ascii", newline="\n") as f:
        f.write(dumps(build_cutout_leaves()) + "\n")
    print("wrote scenes/cutout_leaves.gltf  (the default Cornell box with 400 leaf cut-outs)")
    for file_name, builder in MEDIA_SCENES:
        doc = builder()
        with open(os.path.join(out_dir, file_name), "w", encoding="ascii", newline="\n") as f:
            f.write(dumps(doc) + "\n")
        print("wrote scenes/%s  (%s)" % (file_name, doc["scenes"][0]["name"]))


if __name__ == "__main__":
    main()
