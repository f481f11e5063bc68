# Run inside Blender (tests/blender/run.sh): imports the mesh.glb files that `radiosity solve`
# wrote and checks the colours Blender reads back.
#   blender -b --factory-startup --python-exit-code 1 --python import_glb.py -- \
#       FURNACE_GLB CORNELL_GLB
# FURNACE_GLB: scenes/furnace.json solved; every wall has exitance E = 1 and reflectance 0.5, so
#   the radiosity everywhere is B = E / (1 - rho) = 2 (closed form), and every colour Blender reads
#   must be exposure x 2 (exposure from the file's asset.extras).
# CORNELL_GLB: scenes/cornell_box.obj solved; every corner colour Blender reads must be the
#   COLOR_0 written at that corner's vertex (read here from the file itself, position checked
#   through glTF's Y-up to Blender's Z-up), and the red wall must read red.
import json
import struct
import sys

import bpy


def read_glb(path):
    """The JSON chunk, the binary chunk and a reader of float/uint accessors."""
    with open(path, "rb") as f:
        data = f.read()
    magic, version, length = struct.unpack_from("<4sII", data, 0)
    assert magic == b"glTF" and version == 2 and length == len(data), f"{path}: not a glTF 2.0 GLB"
    json_length, json_type = struct.unpack_from("<I4s", data, 12)
    assert json_type == b"JSON"
    doc = json.loads(data[20:20 + json_length])
    bin_length, bin_type = struct.unpack_from("<I4s", data, 20 + json_length)
    assert bin_type == b"BIN\0"
    blob = data[28 + json_length:28 + json_length + bin_length]

    def accessor(i):
        a = doc["accessors"][i]
        view = doc["bufferViews"][a["bufferView"]]
        width = {"SCALAR": 1, "VEC3": 3}[a["type"]]
        code = {5126: "f", 5125: "I"}[a["componentType"]]
        n = a["count"] * width
        flat = struct.unpack_from("<%d%s" % (n, code), blob, view["byteOffset"] + a.get("byteOffset", 0))
        return [flat[k:k + width] for k in range(0, n, width)] if width > 1 else list(flat)

    return doc, accessor


def srgb_step(linear):
    """Half a step of Blender's 8-bit sRGB colour storage at a linear value (8-bit BYTE_COLOR)."""
    s = 12.92 * linear if linear <= 0.0031308 else 1.055 * linear ** (1 / 2.4) - 0.055
    to_linear = lambda v: v / 12.92 if v <= 0.04045 else ((v + 0.055) / 1.055) ** 2.4
    return max(abs(to_linear(min(s + 0.5 / 255, 1.0)) - linear),
               abs(to_linear(max(s - 0.5 / 255, 0.0)) - linear))


def import_mesh(path):
    """Imports the file into an empty scene; returns its one mesh and the colour attribute."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    # Debian bookworm's Blender 3.4 fails in the default shading mode ("NORMALS": np.bool, gone
    # from numpy 1.24); SMOOTH avoids that code and changes no colour.
    bpy.ops.import_scene.gltf(filepath=path, import_shading="SMOOTH")
    meshes = [o for o in bpy.context.scene.objects if o.type == "MESH"]
    assert len(meshes) == 1, f"{path}: {len(meshes)} mesh objects, expected 1"
    mesh = meshes[0].data
    assert len(mesh.color_attributes) >= 1, f"{path}: Blender found no vertex colours"
    colours = mesh.color_attributes[0]
    assert colours.domain == "CORNER", colours.domain
    return mesh, colours


def check_furnace(path):
    doc, _ = read_glb(path)
    exposure = doc["asset"]["extras"]["radiosity_exposure"]
    expected = min(exposure * 2.0, 1.0)
    mesh, colours = import_mesh(path)
    worst = 0.0
    for loop in range(len(mesh.loops)):
        c = colours.data[loop].color
        for channel in range(3):
            worst = max(worst, abs(c[channel] - expected))
    allowed = 0.01 * expected + srgb_step(expected)
    print(f"furnace: {len(mesh.loops)} corners, colour {expected:.4f} (B = 2 x exposure "
          f"{exposure:.4f}), worst difference {worst:.5f}, allowed {allowed:.5f}")
    assert len(mesh.loops) > 0
    assert worst <= allowed, f"furnace: a corner's colour is {worst} from the closed form"


def check_cornell(path):
    doc, accessor = read_glb(path)
    attributes = doc["meshes"][0]["primitives"][0]["attributes"]
    positions = accessor(attributes["POSITION"])
    written = accessor(attributes["COLOR_0"])
    indices = accessor(doc["meshes"][0]["primitives"][0]["indices"])
    mesh, colours = import_mesh(path)
    assert len(mesh.loops) == len(indices), f"{len(mesh.loops)} corners, {len(indices)} indices"
    worst_position = worst_colour = 0.0
    for loop, l in enumerate(mesh.loops):
        v = indices[loop]
        x, y, z = positions[v]
        co = mesh.vertices[l.vertex_index].co
        worst_position = max(worst_position, abs(co.x - x), abs(co.y + z), abs(co.z - y))
        c = colours.data[loop].color
        for channel in range(3):
            diff = abs(c[channel] - written[v][channel])
            worst_colour = max(worst_colour, diff / (srgb_step(written[v][channel]) + 1e-6))
    # The red wall (x = 550..556 mm) reads red: more than twice as much red as green.
    red = [0.0, 0.0]
    for poly in mesh.polygons:
        if all(mesh.vertices[i].co.x > 549.0 for i in poly.vertices):
            for loop in poly.loop_indices:
                red[0] += colours.data[loop].color[0]
                red[1] += colours.data[loop].color[1]
    print(f"cornell: {len(mesh.loops)} corners, worst position {worst_position:.2e}, worst colour "
          f"{worst_colour:.2f} quantisation steps, red wall r/g {red[0] / max(red[1], 1e-9):.2f}")
    assert worst_position <= 1e-3, "a corner is not where the file puts it"
    assert worst_colour <= 1.5, "a corner's colour is not the COLOR_0 written at its vertex"
    assert red[1] > 0 and red[0] > 2 * red[1], f"the red wall does not read red: {red}"


argv = sys.argv[sys.argv.index("--") + 1:]
check_furnace(argv[0])
check_cornell(argv[1])
print("blender: the baked light reads back")
