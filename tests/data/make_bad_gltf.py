#!/usr/bin/env python3
"""Write the glTF test inputs of tests/test_gltf.cpp and tests/test_cli.cpp.

  tests/data/bad/    one file per failure the loader must report (plus two files
                     with zero-area triangles that must load), and README.md, the
                     table file -> what is wrong -> expected message fragment that
                     the tests read.
  tests/data/gltf/   small valid scenes: the pbrMetallicRoughness mapping, the
                     SMALLVCM_material override, node transforms, a .glb.

Every file starts from one small valid scene (a 2 x 2 white floor at z = 0 facing +z,
a 0.5 x 0.5 emitter at z = 1 facing down, a camera at (0, -3, 0.5) looking along +y,
the scene of docs/scene_format.md section 10) and changes one thing.

Usage:   python3 tests/data/make_bad_gltf.py     (Python 3, standard library only)
Edit this script, not the files it writes; commit both.
"""

import base64
import copy
import json
import os
import shutil
import struct

HERE = os.path.dirname(os.path.abspath(__file__))
BAD = os.path.join(HERE, "bad")
GOOD = os.path.join(HERE, "gltf")
HOSTILE = os.path.join(HERE, "hostile")

FLOAT, UBYTE, USHORT, UINT = 5126, 5121, 5123, 5125


def png_bytes(width, height, rgb):
    """An 8-bit RGB PNG (rgb: a list of (r, g, b) tuples, row by row from the top), or
    RGBA when the tuples have four values."""
    import struct, zlib
    raw = b"".join(b"\x00" + bytes(c for p in rgb[y * width:(y + 1) * width] for c in p) for y in range(height))
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
    color_type = 6 if len(rgb[0]) == 4 else 2
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, color_type, 0, 0, 0)) +
            chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


TINY_PNG_BASE64 = __import__("base64").b64encode(png_bytes(2, 1, [(255, 0, 0), (0, 0, 255)])).decode()
NAN_BITS, INF_BITS = 0x7FC00000, 0x7F800000

FLOOR = [(-1.0, -1.0, 0.0), (1.0, -1.0, 0.0), (1.0, 1.0, 0.0), (-1.0, 1.0, 0.0)]
FLOOR_INDICES = [0, 1, 2, 2, 3, 0]              # counter-clockwise seen from +z
LIGHT = [(-0.25, -0.25, 1.0), (0.25, -0.25, 1.0), (0.25, 0.25, 1.0), (-0.25, 0.25, 1.0)]
LIGHT_INDICES = [0, 2, 1, 2, 0, 3]              # counter-clockwise seen from -z

# Camera at (0, -3, 0.5) looking along +y, +z up: columns right, up, -forward, position.
CAMERA_MATRIX = [1, 0, 0, 0, 0, 0, 1, 0, 0, -1, 0, 0, 0, -3, 0.5, 1]

WHITE = {"name": "white Lambert",
         "pbrMetallicRoughness": {"baseColorFactor": [0.833333, 0.833333, 0.833333, 1.0],
                                  "metallicFactor": 0.0, "roughnessFactor": 1.0},
         "extensions": {"SMALLVCM_material": {"diffuse": [0.8, 0.8, 0.8]}}}
EMITTER = {"name": "light", "emissiveFactor": [1.0, 1.0, 1.0],
           "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0]},
           "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 10.0}}}


class Builder:
    """A glTF document with one buffer; every accessor gets its own buffer view."""

    def __init__(self):
        self.data = bytearray()
        self.doc = {"asset": {"version": "2.0", "generator": "tests/data/make_bad_gltf.py"},
                    "scene": 0, "scenes": [{"nodes": []}], "nodes": [], "cameras": [],
                    "meshes": [], "materials": [], "accessors": [], "bufferViews": [],
                    "buffers": []}

    def view(self, raw):
        while len(self.data) % 4:
            self.data.append(0)
        self.doc["bufferViews"].append({"buffer": 0, "byteOffset": len(self.data),
                                        "byteLength": len(raw)})
        self.data.extend(raw)
        return len(self.doc["bufferViews"]) - 1

    def positions(self, points, raw=None):
        """FLOAT VEC3 accessor; raw (bytes) replaces the packed points if given."""
        packed = raw if raw is not None else b"".join(struct.pack("<3f", *p) for p in points)
        finite = [p for p in points if all(abs(c) < 1e30 for c in p)] or [(0, 0, 0)]
        self.doc["accessors"].append({
            "bufferView": self.view(packed), "componentType": FLOAT, "count": len(points),
            "type": "VEC3", "min": [min(p[i] for p in finite) for i in range(3)],
            "max": [max(p[i] for p in finite) for i in range(3)]})
        return len(self.doc["accessors"]) - 1

    def indices(self, values, component=UINT):
        fmt = {UBYTE: "B", USHORT: "H", UINT: "I"}[component]
        self.doc["accessors"].append({
            "bufferView": self.view(struct.pack("<%d%s" % (len(values), fmt), *values)),
            "componentType": component, "count": len(values), "type": "SCALAR"})
        return len(self.doc["accessors"]) - 1

    def node(self, node, root=True):
        self.doc["nodes"].append(node)
        index = len(self.doc["nodes"]) - 1
        if root:
            self.doc["scenes"][0]["nodes"].append(index)
        return index

    def mesh(self, name, points, indices, material, node=None, component=UINT, root=True):
        primitive = {"attributes": {"POSITION": self.positions(points)}, "mode": 4}
        if indices is not None:
            primitive["indices"] = self.indices(indices, component)
        if material is not None:
            primitive["material"] = material
        self.doc["meshes"].append({"name": name, "primitives": [primitive]})
        n = {"name": name, "mesh": len(self.doc["meshes"]) - 1}
        n.update(node or {})
        return self.node(n, root)

    def material(self, material):
        self.doc["materials"].append(copy.deepcopy(material))
        return len(self.doc["materials"]) - 1

    def camera(self, perspective=None, matrix=None):
        self.doc["cameras"].append({"type": "perspective", "perspective": perspective or
                                    {"yfov": 0.7853981633974483, "aspectRatio": 1.0, "znear": 0.01}})
        return self.node({"name": "camera", "camera": len(self.doc["cameras"]) - 1,
                          "matrix": list(matrix or CAMERA_MATRIX)})

    def finish(self):
        self.doc["buffers"] = [{"byteLength": len(self.data),
                                "uri": "data:application/octet-stream;base64," +
                                       base64.b64encode(bytes(self.data)).decode("ascii")}]
        used = set(self.doc.get("extensionsRequired", []))
        for m in self.doc["materials"]:
            used.update(m.get("extensions", {}).keys())
        for n in self.doc["nodes"]:
            used.update(n.get("extensions", {}).keys())
        used.update(self.doc.get("extensions", {}).keys())
        if used:
            self.doc["extensionsUsed"] = sorted(used)
        for key in ["cameras", "meshes", "materials", "accessors", "bufferViews"]:
            if not self.doc[key]:
                del self.doc[key]
        return self.doc


def base(floor_material=None, floor_node=None, floor_points=FLOOR, floor_indices=FLOOR_INDICES,
         floor_component=UINT, light=True):
    """The small valid scene: node 0 camera, node 1 floor (mesh 0), node 2 light (mesh 1).
    Accessors: 0 floor POSITION, 1 floor indices, 2 light POSITION, 3 light indices.
    Materials: 0 the floor's (white Lambert unless given), 1 the emitter."""
    b = Builder()
    b.camera()
    white = b.material(floor_material if floor_material is not None else WHITE)
    emitter = b.material(EMITTER)
    b.mesh("floor", floor_points, floor_indices, white, floor_node, floor_component)
    if light:
        b.mesh("light", LIGHT, LIGHT_INDICES, emitter)
    return b


def scene(**kwargs):
    return base(**kwargs).finish()


def dumps(doc):
    """JSON with short values on one line and the rest indented, so a diff of two
    files shows the one thing that differs."""
    def encode(value, indent):
        flat = json.dumps(value)
        if len(flat) + indent <= 96 or not isinstance(value, (dict, list)) or not value:
            return flat
        pad = " " * (indent + 2)
        if isinstance(value, dict):
            items = ["%s%s: %s" % (pad, json.dumps(k), encode(v, indent + 2)) for k, v in value.items()]
            return "{\n" + ",\n".join(items) + "\n" + " " * indent + "}"
        return "[\n" + ",\n".join(pad + encode(v, indent + 2) for v in value) + "\n" + " " * indent + "]"
    return encode(doc, 0) + "\n"


# ---------------------------------------------------------------------------
# The bad inputs: (file, what is wrong, expected message fragment, content)
# content: a dict (written as JSON), str or bytes (written as is), or None (special).
# ---------------------------------------------------------------------------

BAD_CASES = []


def bad(file, what, fragment):
    def register(make):
        BAD_CASES.append((file, what, fragment, make))
        return make
    return register


def modified(change, **kwargs):
    doc = scene(**kwargs)
    change(doc)
    return doc


# --- the file itself ---------------------------------------------------------
bad("malformed_json.gltf", "not JSON (a doubled comma)", "glTF parse error: [json.exception.parse_error")(
    lambda: '{"asset": {"version": "2.0"},, "scenes": []}\n')
bad("truncated.gltf", "a valid file cut in the middle of its JSON", "glTF parse error: [json.exception.parse_error")(
    lambda: dumps(scene())[:len(dumps(scene())) // 2])
bad("truncated.glb", "the first 20 bytes of a binary glTF", "glTF parse error: Invalid glTF binary")(
    lambda: make_glb(scene())[:20])
bad("empty.gltf", "an empty file (0 bytes)", "the file is empty")(lambda: "")
bad("directory.gltf", "a directory, not a file (holds a README.md)", "directory")(lambda: None)
bad("json_array.gltf", "JSON, but an array, not a glTF object", "Root element is not a JSON object")(
    lambda: "[1, 2, 3]\n")
bad("asset_missing.gltf", "no 'asset' object (not a glTF file)", "\"asset\" object not found")(
    lambda: modified(lambda d: d.pop("asset")))
bad("asset_version_1.gltf", "asset.version is \"1.0\" (glTF 1, not 2.0)", "this is a glTF 1.0 file")(
    lambda: modified(lambda d: d["asset"].update(version="1.0")))
bad("no_scene.gltf", "no 'scenes' at all", "has no scene")(
    lambda: modified(lambda d: (d.pop("scenes"), d.pop("scene"))))
bad("scene_out_of_range.gltf", "'scene': 3, but there is one scene", "the default scene 3 does not exist")(
    lambda: modified(lambda d: d.update(scene=3)))

# --- buffers and accessors -------------------------------------------------
bad("buffer_missing_file.gltf", "the buffer is an external .bin file that does not exist",
    "missing_buffer_does_not_exist.bin")(
    lambda: modified(lambda d: d["buffers"][0].update(uri="missing_buffer_does_not_exist.bin")))
bad("buffer_shorter_than_bytelength.gltf", "the data URI holds fewer bytes than byteLength",
    "Failed to decode 'uri'")(
    lambda: modified(lambda d: d["buffers"][0].update(byteLength=d["buffers"][0]["byteLength"] + 64)))
bad("accessor_past_buffer_end.gltf", "the floor POSITION accessor has count 100 (its view holds 4)",
    "reads past the end of its buffer")(
    lambda: modified(lambda d: d["accessors"][0].update(count=100)))
bad("bufferview_past_buffer_end.gltf", "the floor POSITION view is longer than the buffer",
    "reads past the end of its buffer")(
    lambda: modified(lambda d: d["bufferViews"][0].update(byteLength=4096)))
bad("bufferview_offset_overflow.gltf", "the floor POSITION view has byteOffset 2^64 - 16: offset + "
    "length wraps around in 64 bits", "reads past the end of its buffer")(
    lambda: modified(lambda d: d["bufferViews"][0].update(byteOffset=2**64 - 16)))
bad("accessor_offset_overflow.gltf", "the floor POSITION accessor has byteOffset 2^64 - 16: offset + "
    "length wraps around in 64 bits", "reads past the end of its buffer")(
    lambda: modified(lambda d: d["accessors"][0].update(byteOffset=2**64 - 16)))
bad("accessor_out_of_range.gltf", "POSITION refers to accessor 9 (there are 4)",
    "refers to accessor 9, which does not exist")(
    lambda: modified(lambda d: d["meshes"][0]["primitives"][0]["attributes"].update(POSITION=9)))
bad("indices_accessor_out_of_range.gltf", "indices refers to accessor 9 (there are 4)",
    "accessor out of bounds")(
    lambda: modified(lambda d: d["meshes"][0]["primitives"][0].update(indices=9)))
bad("bufferview_out_of_range.gltf", "the floor POSITION accessor refers to bufferView 7 (there are 4)",
    "missing or invalid bufferView")(
    lambda: modified(lambda d: d["accessors"][0].update(bufferView=7)))
bad("sparse_accessor.gltf", "the floor POSITION accessor is sparse", "sparse accessors are not supported")(
    lambda: modified(lambda d: d["accessors"][0].update(sparse={
        "count": 1, "indices": {"bufferView": 1, "componentType": UINT},
        "values": {"bufferView": 0}})))

# --- mesh primitives -------------------------------------------------------
bad("index_out_of_range.gltf", "an index is 7, the floor has 4 vertices",
    "index out of range in triangle 1 (vertex count 4)")(
    lambda: scene(floor_indices=[0, 1, 2, 2, 3, 7]))
bad("index_count_not_multiple_of_3.gltf", "5 indices", "the index count 5 is not a multiple of 3")(
    lambda: scene(floor_indices=[0, 1, 2, 2, 3]))
bad("position_vec2.gltf", "POSITION accessor of type VEC2", "wrong type (VEC3 expected)")(
    lambda: modified(lambda d: d["accessors"][0].update(type="VEC2")))
bad("position_unsigned_short.gltf", "POSITION accessor of component type UNSIGNED_SHORT",
    "positions must be FLOAT")(
    lambda: modified(lambda d: d["accessors"][0].update(componentType=USHORT)))
bad("indices_float.gltf", "an index accessor of component type FLOAT",
    "indices must be unsigned byte, short or int")(
    lambda: modified(lambda d: d["accessors"][1].update(componentType=FLOAT)))
bad("position_missing.gltf", "a primitive without POSITION", "has no POSITION attribute")(
    lambda: modified(lambda d: d["meshes"][0]["primitives"][0]["attributes"].update(
        {"NORMAL": d["meshes"][0]["primitives"][0]["attributes"].pop("POSITION")})))


def raw_floor(bits_of_vertex_2):
    b = base()
    raw = bytearray(b"".join(struct.pack("<3f", *p) for p in FLOOR))
    struct.pack_into("<I", raw, 2 * 12, bits_of_vertex_2)   # x of vertex 2
    view = b.doc["accessors"][0]["bufferView"]
    offset = b.doc["bufferViews"][view]["byteOffset"]
    b.data[offset:offset + len(raw)] = raw
    return b.finish()


bad("vertex_nan.gltf", "vertex 2 has x = NaN (raw float bits 0x7fc00000)",
    "vertex 2 is not finite")(lambda: raw_floor(NAN_BITS))
bad("vertex_infinite.gltf", "vertex 2 has x = +infinity (raw float bits 0x7f800000)",
    "vertex 2 is not finite")(lambda: raw_floor(INF_BITS))


def with_normals(normals, raw=None, component=FLOAT, kind="VEC3", floor_node=None):
    """The floor with a NORMAL accessor of the given values (raw bytes replace them)."""
    b = base(floor_node=floor_node)
    packed = raw if raw is not None else b"".join(struct.pack("<3f", *n) for n in normals)
    b.doc["accessors"].append({"bufferView": b.view(packed), "componentType": component,
                               "count": len(normals), "type": kind})
    b.doc["meshes"][0]["primitives"][0]["attributes"]["NORMAL"] = len(b.doc["accessors"]) - 1
    return b.finish()


UP4 = [(0.0, 0.0, 1.0)] * 4
bad("normal_count_mismatch.gltf", "3 NORMAL elements for the floor's 4 vertices",
    "NORMAL has 3 elements but POSITION has 4")(lambda: with_normals(UP4[:3]))
bad("normal_nan.gltf", "the NORMAL of vertex 2 has z = NaN (raw float bits 0x7fc00000)",
    "NORMAL of vertex 2 is not finite")(
    lambda: with_normals(UP4, raw=b"".join(struct.pack("<3f", *n) for n in UP4[:2]) +
                         struct.pack("<ffI", 0.0, 0.0, NAN_BITS) + struct.pack("<3f", *UP4[3])))
bad("normal_zero.gltf", "the NORMAL of vertex 1 is (0, 0, 0)", "NORMAL of vertex 1 has zero length")(
    lambda: with_normals([UP4[0], (0.0, 0.0, 0.0)] + UP4[2:]))
bad("normal_vec2.gltf", "a NORMAL accessor of type VEC2", "NORMAL (accessor 4): wrong type (VEC3 expected)")(
    lambda: with_normals(UP4, kind="VEC2"))
bad("normal_unsigned_short.gltf", "a NORMAL accessor of component type UNSIGNED_SHORT",
    "normals must be FLOAT")(lambda: with_normals(UP4, component=USHORT))
bad("normal_accessor_out_of_range.gltf", "NORMAL refers to accessor 9 (there are 4)",
    "NORMAL refers to accessor 9, which does not exist")(
    lambda: modified(lambda d: d["meshes"][0]["primitives"][0]["attributes"].update(NORMAL=9)))
bad("mode_lines.gltf", "primitive mode 1 (LINES)", "primitive mode 1 is not supported")(
    lambda: modified(lambda d: d["meshes"][0]["primitives"][0].update(mode=1)))
bad("mode_points.gltf", "primitive mode 0 (POINTS)", "primitive mode 0 is not supported")(
    lambda: modified(lambda d: d["meshes"][0]["primitives"][0].update(mode=0)))
bad("morph_targets.gltf", "a primitive with a morph target", "morph targets are not supported")(
    lambda: modified(lambda d: d["meshes"][0]["primitives"][0].update(targets=[{"POSITION": 0}])))
bad("skin.gltf", "a skin (joints: node 1), used by the floor node", "skins are not supported")(
    lambda: modified(lambda d: (d.update(skins=[{"joints": [1], "inverseBindMatrices": 0}]),
                                d["nodes"][1].update(skin=0))))
bad("mesh_out_of_range.gltf", "a node refers to mesh 4 (there are 2)", "refers to mesh 4, which does not exist")(
    lambda: modified(lambda d: d["nodes"][1].update(mesh=4)))

# --- materials ---------------------------------------------------------------
bad("material_out_of_range.gltf", "the floor primitive refers to material 5 (there are 2)",
    "refers to material 5, which does not exist")(
    lambda: modified(lambda d: d["meshes"][0]["primitives"][0].update(material=5)))
PBR_TEXTURED = {"name": "textured", "pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 1.0],
                                                           "metallicFactor": 0.0, "roughnessFactor": 1.0,
                                                           "baseColorTexture": {"index": 0}}}


def textured(image):
    def change(d):
        d["materials"][0] = PBR_TEXTURED
        d["images"] = [image]
        d["textures"] = [{"source": 0}]
    return change


bad("texture_without_image.gltf", "a baseColorTexture whose texture has no image source",
    "texture 0 has no image")(
    lambda: modified(lambda d: (textured({"uri": "x.png"})(d), d.update(textures=[{}]))))
bad("texture_image_missing.gltf", "the base colour image is a file that does not exist",
    "image 0 'texture_does_not_exist.png': no readable file of that name inside the scene's folder")(
    lambda: modified(textured({"uri": "texture_does_not_exist.png"})))
bad("texture_image_outside_folder.gltf", "the base colour image URI leaves the scene's folder",
    "image 0 '../hostile/README.md': no readable file of that name inside the scene's folder")(
    lambda: modified(textured({"uri": "../hostile/README.md"})))
bad("texture_image_not_png.gltf", "the base colour image is a data URI holding text, not PNG or JPEG",
    "image 0: not a PNG or JPEG image that can be decoded")(
    lambda: modified(textured({"uri": "data:image/png;base64,aGVsbG8gd29ybGQ=", "mimeType": "image/png"})))
bad("texture_no_texcoord.gltf", "a textured floor whose primitive has no TEXCOORD_0",
    "its material has a baseColorTexture but the primitive has no TEXCOORD_0")(
    lambda: modified(textured({"uri": "data:image/png;base64," + TINY_PNG_BASE64, "mimeType": "image/png"})))
bad("texture_texcoord_9.gltf", "a baseColorTexture that uses TEXCOORD_9",
    "its baseColorTexture uses TEXCOORD_9; sets 0 to 7 are read")(
    lambda: modified(lambda d: (textured({"uri": "x.png"})(d),
                                d["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"].update(texCoord=9))))
bad("texture_texcoord_1_absent.gltf", "a baseColorTexture that uses TEXCOORD_1, which the primitive lacks",
    "its material has a baseColorTexture but the primitive has no TEXCOORD_1")(
    lambda: modified(lambda d: (textured({"uri": "data:image/png;base64," + TINY_PNG_BASE64, "mimeType": "image/png"})(d),
                                d["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"].update(texCoord=1))))
def emissive_textured(image, texcoords=None, raw=None):
    """The emitter (material 1, mesh 1) with an emissiveTexture of the given image, and
    TEXCOORD_0 on the light mesh when texcoords is given (raw bytes replace them)."""
    b = base()
    b.doc["materials"][1]["emissiveTexture"] = {"index": 0}
    b.doc["images"] = [image]
    b.doc["textures"] = [{"source": 0}]
    if texcoords is not None:
        packed = raw if raw is not None else b"".join(struct.pack("<2f", *uv) for uv in texcoords)
        b.doc["accessors"].append({"bufferView": b.view(packed), "componentType": FLOAT,
                                   "count": len(texcoords), "type": "VEC2"})
        b.doc["meshes"][1]["primitives"][0]["attributes"]["TEXCOORD_0"] = len(b.doc["accessors"]) - 1
    return b.finish()


TINY_PNG_IMAGE = {"uri": "data:image/png;base64," + TINY_PNG_BASE64, "mimeType": "image/png"}
LIGHT_UVS = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]
bad("emissive_texture_image_missing.gltf", "the emitter's emissiveTexture image is a file that does not exist",
    "image 0 'emissive_does_not_exist.png': no readable file of that name inside the scene's folder")(
    lambda: emissive_textured({"uri": "emissive_does_not_exist.png"}, LIGHT_UVS))
bad("emissive_texture_image_not_png.gltf", "the emissiveTexture image is a data URI holding text, not PNG or JPEG",
    "image 0: not a PNG or JPEG image that can be decoded")(
    lambda: emissive_textured({"uri": "data:image/png;base64,aGVsbG8gd29ybGQ=", "mimeType": "image/png"}, LIGHT_UVS))
bad("emissive_texture_no_texcoord.gltf", "an emitter with an emissiveTexture whose primitive has no TEXCOORD_0",
    "its material has an emissiveTexture but the primitive has no TEXCOORD_0")(
    lambda: emissive_textured(TINY_PNG_IMAGE))
bad("emissive_texture_uv_nan.gltf", "the emitter's TEXCOORD_0 of vertex 1 has u = NaN (raw float bits 0x7fc00000)",
    "TEXCOORD_0 of vertex 1 is not finite")(
    lambda: emissive_textured(TINY_PNG_IMAGE, LIGHT_UVS,
                              raw=struct.pack("<2f", *LIGHT_UVS[0]) + struct.pack("<If", NAN_BITS, 0.0) +
                              b"".join(struct.pack("<2f", *uv) for uv in LIGHT_UVS[2:])))
bad("emissive_texture_texcoord_9.gltf", "an emissiveTexture that uses TEXCOORD_9",
    "its emissiveTexture uses TEXCOORD_9; sets 0 to 7 are read")(
    lambda: modified(lambda d: (d.update(images=[{"uri": "x.png"}], textures=[{"source": 0}]),
                                d["materials"][1].update(emissiveTexture={"index": 0, "texCoord": 9}))))

bad("diffuse_above_one.gltf", "SMALLVCM_material diffuse (1.2, 0.5, 0.5)", "must not exceed 1")(
    lambda: modified(lambda d: d["materials"][0]["extensions"]["SMALLVCM_material"].update(
        diffuse=[1.2, 0.5, 0.5])))
bad("diffuse_plus_phong_above_one.gltf", "SMALLVCM_material diffuse 0.6 + phong 0.6",
    "diffuse + Phong reflectance exceeds 1")(
    lambda: modified(lambda d: d["materials"][0]["extensions"]["SMALLVCM_material"].update(
        diffuse=[0.6, 0.6, 0.6], phong=[0.6, 0.6, 0.6], phongExponent=10)))
bad("emission_negative.gltf", "emissiveFactor (-1, 1, 1)", "the emission must be finite and non-negative")(
    lambda: modified(lambda d: d["materials"][1].update(emissiveFactor=[-1.0, 1.0, 1.0])))
bad("emission_strength_nan.gltf", "emissiveStrength is the string \"NaN\" (JSON has no NaN number)",
    "the emission must be finite and non-negative")(
    lambda: modified(lambda d: d["materials"][1]["extensions"]["KHR_materials_emissive_strength"].update(
        emissiveStrength="NaN")))
def alpha_floor(alpha_mode="MASK", cutoff=None, factor_alpha=None, alphas=(255, 128, 127, 0), extra=None):
    """The small scene with a cut-out floor: a 2 x 2 RGBA base-colour texture (white, the
    alpha bytes `alphas` top left, top right, bottom left, bottom right) mapped upright onto
    the floor seen from above, uv = ((x + 1) / 2, (1 - y) / 2), so texel centres lie at
    x, y = +-0.5."""
    material = {"name": "cut-out floor", "alphaMode": alpha_mode,
                "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.8, 0.8, 1.0 if factor_alpha is None else factor_alpha],
                                         "metallicFactor": 0.0, "roughnessFactor": 1.0,
                                         "baseColorTexture": {"index": 0}}}
    if cutoff is not None:
        material["alphaCutoff"] = cutoff
    material.update(extra or {})
    b = base(floor_material=material)
    uvs = [((x + 1.0) / 2.0, (1.0 - y) / 2.0) for (x, y, _) in FLOOR]
    b.doc["accessors"].append({"bufferView": b.view(b"".join(struct.pack("<2f", *uv) for uv in uvs)),
                               "componentType": FLOAT, "count": len(uvs), "type": "VEC2"})
    b.doc["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_0"] = len(b.doc["accessors"]) - 1
    png = png_bytes(2, 2, [(255, 255, 255, a) for a in alphas])
    b.doc["images"] = [{"uri": "data:image/png;base64," + base64.b64encode(png).decode("ascii")}]
    b.doc["samplers"] = [{"wrapS": 33071, "wrapT": 33071}]
    b.doc["textures"] = [{"source": 0, "sampler": 0}]
    return b.finish()


bad("alpha_cutoff_negative.gltf", "a MASK material with alphaCutoff -0.25",
    "material 0 'cut-out floor': alphaCutoff must be a number >= 0")(lambda: alpha_floor(cutoff=-0.25))
bad("alpha_cutoff_string.gltf", "a MASK material whose alphaCutoff is the string \"0.3\"",
    "material 0 'cut-out floor': alphaCutoff must be a number >= 0")(lambda: alpha_floor(cutoff="0.3"))
bad("alpha_mode_unknown.gltf", "alphaMode \"mask\" (the specification's values are upper case)",
    "material 0 'cut-out floor': alphaMode must be \"OPAQUE\", \"MASK\" or \"BLEND\"")(
    lambda: alpha_floor(alpha_mode="mask"))
bad("alpha_factor_above_one.gltf", "a MASK material whose baseColorFactor alpha is 1.5",
    "material 0 'cut-out floor': the alpha of baseColorFactor must be in [0, 1]")(lambda: alpha_floor(factor_alpha=1.5))
bad("emission_strength_infinite.gltf", "emissiveStrength 1e999 (too large for a double)",
    "1e999")(
    lambda: dumps(scene()).replace('"emissiveStrength": 10.0', '"emissiveStrength": 1e999'))
bad("emission_power_overflow.gltf", "emissiveStrength 1e38: finite, but the light's power overflows "
    "single-precision arithmetic", "emits a power of")(
    lambda: modified(lambda d: d["materials"][1]["extensions"]["KHR_materials_emissive_strength"].update(
        emissiveStrength=1e38)))

# --- media (docs/scene_format.md 4.4) ------------------------------------------
def floor_extension(name, value):
    return lambda: modified(lambda d: d["materials"][0]["extensions"].update({name: value}))


def glass_floor_volume(volume):
    return lambda: scene(floor_material=pbr((1.0, 1.0, 1.0), 0.0, 0.0, extensions={
        "KHR_materials_transmission": {"transmissionFactor": 1.0}, "KHR_materials_volume": volume}))


bad("medium_not_object.gltf", "the floor's SMALLVCM_medium is an array", "material 0 'white Lambert': SMALLVCM_medium must be an object")(
    floor_extension("SMALLVCM_medium", [0.1, 0.1, 0.1]))
bad("medium_sigma_negative.gltf", "SMALLVCM_medium sigmaS (0.1, -0.1, 0)",
    "material 0 'white Lambert': SMALLVCM_medium.sigmaS must be finite and non-negative")(
    floor_extension("SMALLVCM_medium", {"sigmaS": [0.1, -0.1, 0.0]}))
bad("medium_sigma_two_numbers.gltf", "SMALLVCM_medium sigmaA has 2 numbers",
    "material 0 'white Lambert': SMALLVCM_medium: 'sigmaA' must be an array of 3 numbers")(
    floor_extension("SMALLVCM_medium", {"sigmaA": [0.1, 0.1]}))
bad("medium_g_one.gltf", "SMALLVCM_medium g = 1 (Henyey-Greenstein needs -1 < g < 1)",
    "material 0 'white Lambert': SMALLVCM_medium.g must be a number in (-1, 1)")(
    floor_extension("SMALLVCM_medium", {"sigmaS": [1.0, 1.0, 1.0], "g": 1.0}))
bad("medium_unknown_member.gltf", "SMALLVCM_medium has 'sigma_s' (misspelt sigmaS)",
    "SMALLVCM_medium has an unknown member 'sigma_s'")(
    floor_extension("SMALLVCM_medium", {"sigma_s": [1.0, 1.0, 1.0]}))
bad("scene_medium_g_string.gltf", "the scene's SMALLVCM_medium has g \"0.3\" (a string)",
    "scene 0: SMALLVCM_medium.g must be a number in (-1, 1)")(
    lambda: modified(lambda d: d["scenes"][0].update(extensions={"SMALLVCM_medium": {"g": "0.3"}})))
bad("volume_distance_zero.gltf", "glass with KHR_materials_volume attenuationDistance 0",
    "material 0 'floor': KHR_materials_volume.attenuationDistance must be a number > 0")(
    glass_floor_volume({"attenuationDistance": 0.0, "attenuationColor": [0.5, 0.5, 0.5]}))
bad("volume_color_above_one.gltf", "glass with KHR_materials_volume attenuationColor (1.2, 0.5, 0.5)",
    "material 0 'floor': KHR_materials_volume.attenuationColor must be 3 numbers in [0, 1]")(
    glass_floor_volume({"attenuationDistance": 1.0, "attenuationColor": [1.2, 0.5, 0.5]}))

# --- lights -----------------------------------------------------------------
POINT_LIGHT_NODE = {"name": "point light", "translation": [0, 0, 0.5],
                    "extensions": {"KHR_lights_punctual": {"light": 0}}}


def with_punctual(light, node=POINT_LIGHT_NODE):
    def change(d):
        d.setdefault("extensions", {})["KHR_lights_punctual"] = {"lights": [light]}
        d["extensionsUsed"] = sorted(set(d.get("extensionsUsed", [])) | {"KHR_lights_punctual"})
        d["nodes"].append(copy.deepcopy(node))
        d["scenes"][0]["nodes"].append(len(d["nodes"]) - 1)
    return change


SPOT_LIGHT_NODE = {"name": "spot light", "translation": [0, 0, 0.5],
                   "extensions": {"KHR_lights_punctual": {"light": 0}}}


def spot(spot_properties):
    """A spot light (shining down -z of an unrotated node) with these cone properties."""
    return modified(with_punctual({"type": "spot", "name": "lamp", "intensity": 1.0, "spot": spot_properties},
                                  SPOT_LIGHT_NODE))


bad("light_spot_inner_negative.gltf", "a spot light with innerConeAngle -0.1",
    "light 0 'lamp' (spot, innerConeAngle -0.1, outerConeAngle 0.5): innerConeAngle is negative")(
    lambda: spot({"innerConeAngle": -0.1, "outerConeAngle": 0.5}))
bad("light_spot_inner_not_less.gltf", "a spot light with innerConeAngle 0.5 = outerConeAngle",
    "innerConeAngle is not less than outerConeAngle")(
    lambda: spot({"innerConeAngle": 0.5, "outerConeAngle": 0.5}))
bad("light_spot_inner_default_above_outer.gltf", "a spot light with outerConeAngle -0.2 (the inner default 0 "
    "is then not less)", "innerConeAngle is not less than outerConeAngle")(
    lambda: spot({"outerConeAngle": -0.2}))
bad("light_spot_outer_above_half_pi.gltf", "a spot light with outerConeAngle 2 (> pi/2)",
    "outerConeAngle exceeds pi/2")(
    lambda: spot({"innerConeAngle": 0.2, "outerConeAngle": 2.0}))
bad("light_spot_outer_huge.gltf", "a spot light with outerConeAngle 1e300 (infinite in float32)",
    "a cone angle is not finite")(
    lambda: spot({"innerConeAngle": 0.2, "outerConeAngle": 1e300}))
bad("light_spot_outer_tiny.gltf", "a spot light with outerConeAngle 0.001 (below the 0.01 rad single "
    "precision samples accurately)", "outerConeAngle is below 0.01 rad")(
    lambda: spot({"outerConeAngle": 0.001}))
bad("light_spot_angle_string.gltf", "a spot light whose innerConeAngle is the string \"0.1\"",
    "light 0: spot.innerConeAngle must be a number (radians)")(
    lambda: spot({"innerConeAngle": "0.1", "outerConeAngle": 0.5}))
bad("light_range.gltf", "a point light with range 10", "'range' is not supported")(
    lambda: modified(with_punctual({"type": "point", "intensity": 1.0, "range": 10.0})))
bad("light_index_out_of_range.gltf", "a node refers to light 3 (there is 1)",
    "refers to light 3, which does not exist")(
    lambda: modified(with_punctual({"type": "point", "intensity": 1.0},
                                   dict(POINT_LIGHT_NODE, extensions={"KHR_lights_punctual": {"light": 3}}))))
bad("light_negative_intensity.gltf", "a point light with intensity -1", "must be finite and non-negative")(
    lambda: modified(with_punctual({"type": "point", "intensity": -1.0})))

# --- camera -------------------------------------------------------------------
bad("camera_orthographic.gltf", "an orthographic camera", "type 'orthographic' is not supported")(
    lambda: modified(lambda d: d["cameras"][0].update(
        type="orthographic", orthographic={"xmag": 1.0, "ymag": 1.0, "znear": 0.01, "zfar": 100.0})))
bad("camera_yfov_zero.gltf", "perspective camera with yfov 0", "yfov must be in (0, 3.1) radians")(
    lambda: modified(lambda d: d["cameras"][0]["perspective"].update(yfov=0.0)))
bad("camera_out_of_range.gltf", "the camera node refers to camera 2 (there is 1)",
    "refers to camera 2, which does not exist")(
    lambda: modified(lambda d: d["nodes"][0].update(camera=2)))

# --- spheres ------------------------------------------------------------------


def with_sphere(sphere, node_extra=None):
    def change(d):
        node = {"name": "sphere", "translation": [0, 0, 0.3],
                "extensions": {"SMALLVCM_sphere": sphere}}
        node.update(node_extra or {})
        d["nodes"].append(node)
        d["scenes"][0]["nodes"].append(len(d["nodes"]) - 1)
        d["extensionsUsed"] = sorted(set(d.get("extensionsUsed", [])) | {"SMALLVCM_sphere"})
        d["extensionsRequired"] = ["SMALLVCM_sphere"]
    return change


SPHERE_RADIUS = "the sphere radius must be finite and positive"
bad("sphere_radius_zero.gltf", "SMALLVCM_sphere radius 0", SPHERE_RADIUS)(
    lambda: modified(with_sphere({"radius": 0.0, "material": 0})))
bad("sphere_radius_negative.gltf", "SMALLVCM_sphere radius -0.3", SPHERE_RADIUS)(
    lambda: modified(with_sphere({"radius": -0.3, "material": 0})))
bad("sphere_radius_infinite.gltf", "SMALLVCM_sphere radius 1e999 (too large for a double)", "1e999")(
    lambda: dumps(modified(with_sphere({"radius": 12345.0, "material": 0}))).replace("12345.0", "1e999"))
bad("sphere_radius_nan.gltf", "SMALLVCM_sphere radius NaN, written as the bare token NaN (not JSON)",
    "glTF parse error: [json.exception.parse_error")(
    lambda: dumps(modified(with_sphere({"radius": 12345.0, "material": 0}))).replace("12345.0", "NaN"))
bad("sphere_radius_string.gltf", "SMALLVCM_sphere radius is the string \"NaN\"",
    "SMALLVCM_sphere needs a numeric 'radius'")(
    lambda: modified(with_sphere({"radius": "NaN", "material": 0})))
bad("sphere_nonuniform_scale.gltf", "a sphere node with scale (1, 2, 1)", "must have a uniform scale")(
    lambda: modified(with_sphere({"radius": 0.2, "material": 0}, {"scale": [1.0, 2.0, 1.0]})))
bad("sphere_material_out_of_range.gltf", "SMALLVCM_sphere material 7 (there are 2)",
    "refers to material 7, which does not exist")(
    lambda: modified(with_sphere({"radius": 0.2, "material": 7})))
bad("sphere_material_negative.gltf", "SMALLVCM_sphere material -1 (not an index)",
    "material -1")(
    lambda: modified(with_sphere({"radius": 0.2, "material": -1})))
bad("sphere_light_tiny.gltf", "an emissive SMALLVCM_sphere of radius 1e-20: its area pdf overflows single "
    "precision", "has an area of")(
    lambda: modified(with_sphere({"radius": 1e-20, "material": 1})))

# --- extensions and nodes -------------------------------------------------------
bad("extension_required_unknown.gltf", "extensionsRequired names EXT_unknown_feature",
    "required extension 'EXT_unknown_feature' is not supported")(
    lambda: modified(lambda d: (d.update(extensionsRequired=["EXT_unknown_feature"]),
                                d.update(extensionsUsed=sorted(d.get("extensionsUsed", []) +
                                                               ["EXT_unknown_feature"])))))


def draco_compressed(d):
    # As exporters write it: the primitive's attributes point at accessors without
    # bufferViews, and the extension names the compressed bufferView; here that view
    # holds the floor's plain positions, which are no Draco stream.
    floor = d["meshes"][0]["primitives"][0]
    floor["extensions"] = {"KHR_draco_mesh_compression": {"bufferView": 0, "attributes": {"POSITION": 0}}}
    d["extensionsUsed"] = sorted(d.get("extensionsUsed", []) + ["KHR_draco_mesh_compression"])
    d["extensionsRequired"] = ["KHR_draco_mesh_compression"]
    for accessor in (0, 1):
        del d["accessors"][accessor]["bufferView"]


bad("draco_stream_not_draco.gltf", "a Draco-compressed floor whose stream's bufferView holds plain floats, not a "
    "Draco stream", "mesh 0 primitive 0: KHR_draco_mesh_compression: the stream in bufferView 0 does not decode "
    "(libdraco: ")(lambda: modified(draco_compressed))
bad("extension_required_several.gltf", "extensionsRequired names KHR_draco_mesh_compression (read), EXT_unknown_feature "
    "and KHR_texture_basisu: the two not read are named in one line, with the hint for the known one",
    "required extensions 'EXT_unknown_feature' and KHR_texture_basisu are not supported: KHR_texture_basisu: its "
    "textures are KTX2/Basis")(
    lambda: modified(lambda d: (d.update(extensionsRequired=["KHR_draco_mesh_compression", "EXT_unknown_feature",
                                                             "KHR_texture_basisu"]),
                                d.update(extensionsUsed=sorted(d.get("extensionsUsed", []) + d["extensionsRequired"])))))


def meshopt_not_meshopt(d):
    # The floor's buffer views compressed: each reads its bytes from buffer 0 through
    # EXT_meshopt_compression, here the plain bytes, which are no meshopt data, and stands
    # in buffer 1, a fallback buffer without a URI.
    for view, stride, count, mode in ((0, 12, 4, "ATTRIBUTES"), (1, 4, 6, "INDICES")):
        v = d["bufferViews"][view]
        v["extensions"] = {"EXT_meshopt_compression": {
            "buffer": 0, "byteOffset": v["byteOffset"], "byteLength": v["byteLength"], "byteStride": stride,
            "count": count, "mode": mode}}
        v["buffer"] = 1
    d["buffers"].append({"byteLength": d["buffers"][0]["byteLength"],
                         "extensions": {"EXT_meshopt_compression": {"fallback": True}}})
    d["extensionsUsed"] = sorted(d.get("extensionsUsed", []) + ["EXT_meshopt_compression"])


MESHOPT_NOT_MESHOPT = "bufferView 0: EXT_meshopt_compression: its 48 compressed bytes do not decode to 4 x 12 bytes"
bad("meshopt_bytes_not_meshopt.gltf", "the floor's buffer views meshopt-compressed, their compressed bytes the plain "
    "floats, their fallback buffer without a URI", MESHOPT_NOT_MESHOPT)(lambda: modified(meshopt_not_meshopt))
bad("meshopt_bytes_not_meshopt.glb", "the same as a .glb (the fallback buffer without a URI must not be given the "
    "BIN chunk)", MESHOPT_NOT_MESHOPT)(lambda: make_glb(modified(meshopt_not_meshopt)))


# --- compressed geometry, from the files of tests/data/compressed --------------
COMPRESSED = os.path.join(HERE, "compressed")


def read_glb(name):
    data = open(os.path.join(COMPRESSED, name), "rb").read()
    length = struct.unpack("<I", data[12:16])[0]
    binary_start = 20 + length
    return json.loads(data[20:binary_start]), data[binary_start + 8:]


def glb_of(doc, binary):
    text = json.dumps(doc, separators=(",", ":")).encode("ascii")
    text += b" " * (-len(text) % 4)
    body = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(binary), 0x004E4942) + binary
    return struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body


def compressed(name, change):
    def make():
        doc, binary = read_glb(name)
        changed = change(doc, binary)
        binary = changed if isinstance(changed, bytes) else binary
        return glb_of(doc, binary)
    return make


def meshopt_view(doc, mode):
    return next(v["extensions"]["EXT_meshopt_compression"] for v in doc["bufferViews"]
                if v.get("extensions", {}).get("EXT_meshopt_compression", {}).get("mode") == mode)


bad("meshopt_truncated.glb", "the Avocado through gltf-transform meshopt, its index view's compressed bytes cut "
    "to half their length", "EXT_meshopt_compression: its 396 compressed bytes do not decode to 2046 x 2 bytes")(
    compressed("avocado_meshopt.glb", lambda d, b: meshopt_view(d, "TRIANGLES").update(byteLength=396)))
bad("meshopt_count_lies.glb", "the same, its vertex view's count 406 said to be 40600 (the compressed bytes hold "
    "406 vertices)", "compressed bytes do not decode to 40600 x 8 bytes")(
    compressed("avocado_meshopt.glb", lambda d, b: [v["extensions"]["EXT_meshopt_compression"].update(count=40600)
                                                    for v in d["bufferViews"] if v.get("byteStride") == 8]))
bad("meshopt_count_huge.glb", "the same, a view's count 2^30 of 256-byte vertices (256 GiB, more than the "
    "limits: refused before anything is allocated)", "EXT_meshopt_compression: decodes to 262144.0 MiB, more than the loader's limits allow")(
    compressed("avocado_meshopt.glb", lambda d, b: next(e for e in (v["extensions"]["EXT_meshopt_compression"]
                                                                    for v in d["bufferViews"] if "extensions" in v)
                                                        if e["mode"] == "ATTRIBUTES" and "filter" not in e)
               .update(count=2 ** 30, byteStride=256)))
bad("meshopt_filter_stride.glb", "the same, the octahedral filter on a view of 12-byte vertices (it takes 4 or 8)",
    "filter 'OCTAHEDRAL' with mode ATTRIBUTES and byteStride 12")(
    compressed("avocado_meshopt.glb", lambda d, b: next(v for v in (e["extensions"]["EXT_meshopt_compression"]
                                                                    for e in d["bufferViews"] if "extensions" in e)
                                                        if v.get("filter") == "OCTAHEDRAL").update(byteStride=12)))
bad("meshopt_mode_unknown.glb", "the same, the index view's mode \"STRIPS\"", "mode 'STRIPS' (ATTRIBUTES, TRIANGLES or INDICES)")(
    compressed("avocado_meshopt.glb", lambda d, b: meshopt_view(d, "TRIANGLES").update(mode="STRIPS")))


def draco_stream(doc):
    return doc["bufferViews"][doc["meshes"][0]["primitives"][0]["extensions"]["KHR_draco_mesh_compression"]["bufferView"]]


bad("draco_truncated.glb", "the Avocado through gltf-transform draco, its Draco stream cut to half its length",
    "mesh 0 primitive 0: KHR_draco_mesh_compression: the stream in bufferView 2 does not decode (libdraco: ")(
    compressed("avocado_draco.glb", lambda d, b: draco_stream(d).update(byteLength=draco_stream(d)["byteLength"] // 2)))
bad("draco_count_lies.glb", "the same, the POSITION accessor's count 406 said to be 405",
    "the stream holds 406 points, the accessor of POSITION (accessor 4) counts 405")(
    compressed("avocado_draco.glb", lambda d, b: d["accessors"][4].update(count=405)))
bad("draco_indices_count_lies.glb", "the same, the indices accessor's count 2046 said to be 2049",
    "the stream holds 682 triangles, the indices accessor 0 counts 2049 indices")(
    compressed("avocado_draco.glb", lambda d, b: d["accessors"][0].update(count=2049)))
bad("draco_attribute_id_missing.glb", "the same, POSITION mapped to the stream's attribute id 9, which it has not",
    "the stream has no attribute of id 9 (POSITION)")(
    compressed("avocado_draco.glb", lambda d, b: d["meshes"][0]["primitives"][0]["extensions"]
               ["KHR_draco_mesh_compression"]["attributes"].update(POSITION=9)))
bad("draco_bit_flips.glb", "the same, every 7th byte of the Draco stream's second half inverted",
    "KHR_draco_mesh_compression: ")(
    compressed("avocado_draco.glb", lambda d, b: bytes(
        (x ^ 0xFF) if (draco_stream(d)["byteOffset"] + draco_stream(d)["byteLength"] // 2 <= i <
                       draco_stream(d)["byteOffset"] + draco_stream(d)["byteLength"] and i % 7 == 0) else x
        for i, x in enumerate(b))))
bad("quantized_normals_unsigned.glb", "the Avocado through gltf-transform quantize, its NORMAL accessor's component "
    "type changed to unsigned short (KHR_mesh_quantization allows normalised byte or short)",
    "normals must be FLOAT or normalised byte or short (KHR_mesh_quantization)")(
    compressed("avocado_quantized.glb", lambda d, b: d["accessors"][2].update(componentType=USHORT)))


bad("buffer_without_uri.glb", "a .glb whose second buffer has no URI (only the first stands for the BIN chunk; "
    "tinygltf would copy the BIN chunk into it)", "buffer 1 has no URI")(
    lambda: make_glb(modified(lambda d: d["buffers"].append({"byteLength": d["buffers"][0]["byteLength"]}))))
bad("lights_emit_nothing.gltf", "the only light is a point light of intensity 0 (the image would be black)",
    "the scene has no light: the file's 1 light emits nothing")(
    lambda: modified(with_punctual({"type": "point", "intensity": 0.0}), light=False))
bad("no_geometry.gltf", "a camera and a point light, nothing else", "the scene has no geometry")(
    lambda: no_geometry())
bad("node_cycle.gltf", "the floor node is its own child", "cycle")(
    lambda: modified(lambda d: d["nodes"][1].update(children=[1])))
bad("node_out_of_range.gltf", "the scene lists node 9 (there are 3)", "refers to node 9, which does not exist")(
    lambda: modified(lambda d: d["scenes"][0]["nodes"].append(9)))
bad("node_two_parents.gltf", "the floor node is a root and also the light node's child (glTF: "
    "a node has at most one parent); it would be loaded twice", "parent")(
    lambda: modified(lambda d: d["nodes"][2].update(children=[1])))


def no_geometry():
    b = Builder()
    b.camera()
    doc = b.finish()
    doc.pop("buffers")
    with_punctual({"type": "point", "intensity": 1.0})(doc)
    return doc


# ---------------------------------------------------------------------------
# Files with zero-area triangles: they load, the degenerate triangles are skipped
# (file, what, skipped count, triangles kept)
# ---------------------------------------------------------------------------
DEGENERATE_CASES = [
    ("degenerate_repeated_index.gltf",
     "the floor has a third triangle (0, 0, 2) with a repeated index", 1, 4,
     lambda: scene(floor_indices=FLOOR_INDICES + [0, 0, 2])),
    ("degenerate_collinear_and_point.gltf",
     "the floor has two extra vertices, collinear with vertex 0 and 1, and two extra "
     "triangles: (0, 4, 1) on a line and (5, 5, 5) a point", 2, 4,
     lambda: scene(floor_points=FLOOR + [(0.0, -1.0, 0.0), (0.5, 0.5, 0.0)],
                   floor_indices=FLOOR_INDICES + [0, 4, 1, 5, 5, 5])),
]


# ---------------------------------------------------------------------------
# Valid scenes for the mapping and transform tests (tests/data/gltf/)
# ---------------------------------------------------------------------------

def pbr(base_color, metallic, roughness, **extra):
    m = {"name": "floor", "pbrMetallicRoughness": {"baseColorFactor": list(base_color) + [1.0],
                                                   "metallicFactor": metallic,
                                                   "roughnessFactor": roughness}}
    m.update(extra)
    return m


QUARTER_TURN_Z = [0.0, 0.0, 0.7071067811865476, 0.7071067811865476]   # 90 degrees about +z

# metallicRoughnessTexture: a 12 x 12 texture of 3 x 3 cells of 4 x 4 texels, metal (blue)
# 0, 128, 255 from left to right and roughness (green) 0, 128, 255 from top to bottom, on
# the floor (uv (0, 0) at floor corner 0, (1, 1) at corner 2), factors 1 and base colour
# (0.8, 0.5, 0.3). Materials 2 to 10: the factor-only material of each cell (cell i = 3 *
# row + column), metallicFactor and roughnessFactor the cell's bytes / 255, that the
# textured floor must equal at the cell's centre (tests/test_gltf_compressed.cpp).
MR_BYTES = (0, 128, 255)
MR_BASE = (0.8, 0.5, 0.3)


def metal_roughness_texture():
    texels = [(0, MR_BYTES[y // 4], MR_BYTES[x // 4]) for y in range(12) for x in range(12)]
    b = base(floor_material=pbr(MR_BASE, 1.0, 1.0))
    b.doc["materials"][0]["pbrMetallicRoughness"]["metallicRoughnessTexture"] = {"index": 0}
    b.doc["images"] = [{"uri": "data:image/png;base64," + base64.b64encode(png_bytes(12, 12, texels)).decode(),
                        "mimeType": "image/png"}]
    b.doc["textures"] = [{"source": 0}]
    packed = b"".join(struct.pack("<2f", *uv) for uv in [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)])
    b.doc["accessors"].append({"bufferView": b.view(packed), "componentType": FLOAT, "count": 4, "type": "VEC2"})
    b.doc["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_0"] = len(b.doc["accessors"]) - 1
    for row in range(3):
        for column in range(3):
            b.material(pbr(MR_BASE, float(repr(MR_BYTES[column] / 255)), float(repr(MR_BYTES[row] / 255))))
    return b.finish()


GOOD_CASES = {
    "metal_roughness_texture.gltf": metal_roughness_texture,
    # pbrMetallicRoughness mapping (docs/scene_format.md 4.2)
    "material_lambert.gltf": lambda: scene(floor_material=pbr((0.5, 0.25, 1.0), 0.0, 1.0)),
    "material_mirror.gltf": lambda: scene(floor_material=pbr((0.9, 0.8, 0.7), 1.0, 0.0)),
    "material_rough_metal.gltf": lambda: scene(floor_material=pbr((0.9, 0.6, 0.3), 1.0, 0.5)),
    "material_dielectric_glossy.gltf": lambda: scene(floor_material=pbr((0.5, 0.5, 0.5), 0.25, 0.5)),
    "material_glass.gltf": lambda: scene(floor_material=pbr(
        (1.0, 1.0, 1.0), 0.0, 0.0, extensions={"KHR_materials_transmission": {"transmissionFactor": 1.0},
                                               "KHR_materials_ior": {"ior": 1.6}})),
    "material_glass_default_ior.gltf": lambda: scene(floor_material=pbr(
        (1.0, 1.0, 1.0), 0.0, 0.0, extensions={"KHR_materials_transmission": {"transmissionFactor": 1.0}})),
    "material_default.gltf": lambda: scene(floor_material={"name": "all glTF defaults"}),
    # alpha cut-outs (docs/scene_format.md): texture alpha bytes 255, 128, 127, 0
    "alpha_mask_default.gltf": lambda: alpha_floor(),
    "alpha_mask_cutoff.gltf": lambda: alpha_floor(cutoff=0.45, factor_alpha=0.8, alphas=(255, 128, 191, 0)),
    "alpha_blend.gltf": lambda: alpha_floor(alpha_mode="BLEND", cutoff=0.9),
    "material_none.gltf": lambda: modified(lambda d: d["meshes"][0]["primitives"][0].pop("material")),
    "material_double_sided.gltf": lambda: scene(floor_material=pbr((0.5, 0.5, 0.5), 0.0, 1.0,
                                                                   doubleSided=True)),
    "material_override.gltf": lambda: scene(floor_material=pbr(
        (0.9, 0.8, 0.7), 1.0, 0.0, extensions={"SMALLVCM_material": {
            "diffuse": [0.1, 0.2, 0.3], "phong": [0.4, 0.3, 0.2], "phongExponent": 90.0,
            "mirror": [0.0, 0.0, 0.0], "ior": -1.0}})),
    "material_override_glass.gltf": lambda: scene(floor_material=pbr(
        (0.5, 0.5, 0.5), 0.0, 1.0, extensions={"SMALLVCM_material": {"mirror": [1.0, 1.0, 1.0], "ior": 1.6}})),
    "emitter_pbr_white.gltf": lambda: modified(lambda d: d["materials"][1].update(
        pbrMetallicRoughness={"baseColorFactor": [1.0, 1.0, 1.0, 1.0], "metallicFactor": 0.0,
                              "roughnessFactor": 1.0})),
    "emitter_with_reflectance.gltf": lambda: modified(lambda d: d["materials"][1]["extensions"].update(
        SMALLVCM_material={"diffuse": [0.3, 0.3, 0.3]})),
    # Vertex normals: tilted towards +x at x = 1 and -x at x = -1, two of them twice too
    # long (normalised, with a note), under a node that stretches x by 2 (so the world
    # normals follow the inverse transpose: the tilt halves).
    "normals_scaled.gltf": lambda: with_normals(
        [(-0.6, 0.0, 0.8), (1.2, 0.0, 1.6), (0.6, 0.0, 0.8), (-1.2, 0.0, 1.6)], floor_node={"scale": [2.0, 1.0, 1.0]}),
    # Indices: none (vertex order), UNSIGNED_BYTE, UNSIGNED_SHORT.
    "indices_none.gltf": lambda: scene(floor_points=[FLOOR[i] for i in FLOOR_INDICES], floor_indices=None),
    "indices_unsigned_byte.gltf": lambda: scene(floor_component=UBYTE),
    "indices_unsigned_short.gltf": lambda: scene(floor_component=USHORT),
    # Node transforms
    "transform_trs.gltf": lambda: scene(floor_node={"translation": [1.0, 2.0, 3.0],
                                                    "rotation": QUARTER_TURN_Z,
                                                    "scale": [2.0, 0.5, 1.5]}),
    "transform_matrix.gltf": lambda: scene(floor_node={"matrix": [0, 1, 0, 0, -1, 0, 0, 0, 0, 0, 1, 0,
                                                                  1, 2, 3, 1]}),
    "transform_parent_child.gltf": lambda: parent_child(),
    "transform_mirror_x.gltf": lambda: scene(floor_node={"scale": [-1.0, 1.0, 1.0]}),
    "transform_mirror_z.gltf": lambda: scene(floor_node={"scale": [1.0, 1.0, -1.0]}),
    "sphere_scaled.gltf": lambda: modified(with_sphere({"radius": 0.2, "material": 0},
                                                       {"translation": [0.1, 0.2, 0.3], "scale": [1.5, 1.5, 1.5]})),
}


def parent_child():
    """The floor under a parent node: parent translates by (0, 0, 1) and turns 90 degrees
    about +z, child (the floor node) translates by (1, 0, 0)."""
    b = base(floor_node={"translation": [1.0, 0.0, 0.0]})
    doc = b.finish()
    doc["nodes"].append({"name": "parent", "translation": [0.0, 0.0, 1.0], "rotation": QUARTER_TURN_Z,
                         "children": [1]})
    doc["scenes"][0]["nodes"] = [0, 3, 2]
    return doc


# ---------------------------------------------------------------------------
# Hostile inputs (tests/data/hostile/): they crash or hang the loader of this writing,
# so only tests/test_cli.cpp runs them, in a child process under a time limit.
# (file, what is wrong, expected message fragment, content)
# ---------------------------------------------------------------------------
NESTING = 50000


def shared_nodes_dag():
    """40 nodes, each listing the next one twice as its child: a node with two parents,
    2^40 paths from the root to the floor."""
    doc = scene()
    first = len(doc["nodes"])
    for i in range(40):
        doc["nodes"].append({"name": "level %d" % i, "children": [first + i + 1] * 2})
    doc["nodes"].append({"name": "floor again", "mesh": 0})
    doc["scenes"][0]["nodes"].append(first)
    return doc


HOSTILE_CASES = [
    ("deep_nesting.gltf", "asset.extras is an array nested %d deep (recursion in the JSON "
     "to value conversion overflows the stack)" % NESTING, "nest",
     lambda: dumps(scene()).replace('"generator"', '"extras": ' + "[" * NESTING + "]" * NESTING +
                                    ', "generator"', 1)),
    ("shared_nodes_dag.gltf", "40 nodes each listing the next one twice as child: 2^40 paths "
     "to one mesh (the walk never ends)", "parent", shared_nodes_dag),
]


def make_glb(doc):
    """A binary glTF: the JSON chunk with the buffer moved to the BIN chunk."""
    doc = copy.deepcopy(doc)
    uri = doc["buffers"][0].pop("uri")
    binary = base64.b64decode(uri.split(",", 1)[1])
    binary += b"\0" * (-len(binary) % 4)
    text = json.dumps(doc, separators=(",", ":")).encode("ascii")
    text += b" " * (-len(text) % 4)
    body = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(binary), 0x004E4942) + binary
    return struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body


def write(path, content):
    mode = "wb" if isinstance(content, bytes) else "w"
    with open(path, mode, **({} if mode == "wb" else {"encoding": "ascii", "newline": "\n"})) as f:
        f.write(content)


def main():
    for folder in (BAD, GOOD, HOSTILE):
        if os.path.isdir(folder):
            shutil.rmtree(folder)
        os.makedirs(folder)

    rows = []
    for file, what, fragment, make in BAD_CASES:
        path = os.path.join(BAD, file)
        content = make()
        if content is None:     # the directory case
            os.makedirs(path)
            write(os.path.join(path, "README.md"),
                  "A folder named like a scene: the loader must say it is not a readable file.\n")
        else:
            write(path, dumps(content) if isinstance(content, dict) else content)
        assert "`" not in fragment and "|" not in fragment and "|" not in what, file
        rows.append("| `%s` | %s | `%s` |" % (file, what, fragment))
    for file, what, skipped, kept, make in DEGENERATE_CASES:
        write(os.path.join(BAD, file), dumps(make()))
        rows.append("| `%s` | %s | loads: skipped %d, kept %d |" % (file, what, skipped, kept))

    readme = [
        "# tests/data/bad: glTF files the loader must reject",
        "",
        "Written by `tests/data/make_bad_gltf.py` (edit the script, then run",
        "`python3 tests/data/make_bad_gltf.py` and commit its output). Each file starts from",
        "the valid scene of `docs/scene_format.md` section 10 (camera, white floor, emitter)",
        "and breaks one thing.",
        "",
        "`tests/test_gltf.cpp` reads this table: for every row with a message fragment",
        "`LoadGltfScene(\"data/bad/FILE\")` must throw `smallvcm::Error` whose message starts",
        "with `data/bad/FILE: ` and contains the fragment; every `.gltf`/`.glb` in this folder",
        "must have a row. Rows saying \"loads\" are files with zero-area triangles that must",
        "load, with the skipped triangles counted in `GltfLoadReport`.",
        "`tests/test_cli.cpp` runs every rejected file through `build/smallvcm` (exit code 1).",
        "",
        "| file | what is wrong | expected message fragment |",
        "|---|---|---|",
    ] + rows
    write(os.path.join(BAD, "README.md"), "\n".join(readme) + "\n")

    rows = []
    for file, what, fragment, make in HOSTILE_CASES:
        content = make()
        write(os.path.join(HOSTILE, file), dumps(content) if isinstance(content, dict) else content)
        rows.append("| `%s` | %s | `%s` |" % (file, what, fragment))
    readme = [
        "# tests/data/hostile: glTF files that crash or hang the loader",
        "",
        "Written by `tests/data/make_bad_gltf.py`. Loading these in the test process would",
        "take the whole test run down (a stack overflow, an endless walk), so only",
        "`tests/test_cli.cpp` runs them, through `build/smallvcm` under `timeout`: the",
        "expected result is exit code 1 and one line naming the file with the fragment below.",
        "",
        "| file | what is wrong | expected message fragment |",
        "|---|---|---|",
    ] + rows
    write(os.path.join(HOSTILE, "README.md"), "\n".join(readme) + "\n")

    for file, make in GOOD_CASES.items():
        write(os.path.join(GOOD, file), dumps(make()))
    write(os.path.join(GOOD, "minimal.glb"), make_glb(scene()))
    print("wrote %d files to tests/data/bad, %d to tests/data/gltf, %d to tests/data/hostile" %
          (len(BAD_CASES) + len(DEGENERATE_CASES), len(GOOD_CASES) + 1, len(HOSTILE_CASES)))


if __name__ == "__main__":
    main()
