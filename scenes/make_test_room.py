#!/usr/bin/env python3
"""Writes the 1990 global-illumination test room scenes (radiosity.v1 Scene JSON) and its points.

The room of the 1990 "globillum" comparison (Ward, Rushmeier and others; the Radiance
distribution's tests/empty/*/grey and tests/obstructed/*/grey): a 10 (x) by 6 (y) by 3 (z, up)
box, floor reflectance 0.3, ceiling 0.7, walls 0.5, and a 0.5 x 0.5 source at the centre of the
ceiling (x 4.75..5.25, y 2.75..3.25) emitting 31.416 W/m^2 (10 pi, a radiance of 10 W/m^2/sr)
with reflectance 0.

Usage: python3 scenes/make_test_room.py OUTDIR

Writes to OUTDIR (standard library only, byte-for-byte the same on every run):

  test_room.json               the empty diffuse room
  test_room_partitions.json    plus two full-height partitions 0.1 thick (reflectance 0.5):
                               partition_a x 2.95..3.05, y 3..6; partition_b x 6.95..7.05, y 0..3
  test_room_mirror_y0.json     the empty room, wall y=0 an ideal mirror (0.75)
  test_room_mirror_y0_x0.json  walls y=0 and x=0 mirrors (0.75), at right angles
  test_room_mirror_y0_y6.json  walls y=0 and y=6 mirrors (0.75), facing each other
  test_room_points.txt         the calculation points for `radiosity solve --sensors`: every 0.5
                               from 0.25 (x 0.25..9.75, y 0.25..5.75) on the floor (z 0, normal
                               up, grid "floor") and on the ceiling (z 3, normal down, grid
                               "ceiling"), 240 points each; no point lies inside a partition, so
                               the one file serves every variant

Modelling choices (the Scene message has no comment field, so they are recorded here):

- The source is a separate one-sided surface "source" placed 0.001 below the intact ceiling
  (z = 2.999), facing down; the ceiling is one whole quad with no hole cut for it. The ceiling's
  0.25 m^2 above the source then sees only the source's non-emitting black back.
- Every big surface is ONE quad face (the solver meshes it); fronts (counter-clockwise by the
  right-hand rule) face into the room.
- Each partition is a box of its faces that can see the room: its two large sides (x = const)
  and its free end (y = 3). The end against the wall and the faces against the floor and the
  ceiling are left out (covered); the floor, ceiling and wall under/over/behind a partition stay
  whole, so those parts of them receive no light.
- A mirror wall's material has diffuse reflectance 0 and "mirror" (ideal specular reflectance)
  0.75 per channel.
"""

import json
import os
import sys

SIZE_X, SIZE_Y, HEIGHT = 10.0, 6.0, 3.0
SOURCE_Z = 2.999
SOURCE_X = (4.75, 5.25)
SOURCE_Y = (2.75, 3.25)
EMISSION = 31.416
MIRROR = 0.75
PARTITION_A = ((2.95, 3.05), (3.0, 6.0))  # x range, y range; end face at y = 3 (faces -y)
PARTITION_B = ((6.95, 7.05), (0.0, 3.0))  # end face at y = 3 (faces +y)


def grey(v):
    return {"r": v, "g": v, "b": v}


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def rect(axis, value, range_u, range_v, normal_sign):
    """An axis-aligned rectangle in the plane coordinate[axis] = value, as 4 corners
    counter-clockwise seen from its front, whose normal points along normal_sign * axis."""
    u_axis, v_axis = [a for a in range(3) if a != axis]
    corners = []
    for (iu, iv) in ((0, 0), (1, 0), (1, 1), (0, 1)):
        p = [0.0, 0.0, 0.0]
        p[axis] = value
        p[u_axis] = range_u[iu]
        p[v_axis] = range_v[iv]
        corners.append(tuple(p))
    e1 = tuple(corners[1][i] - corners[0][i] for i in range(3))
    e2 = tuple(corners[3][i] - corners[0][i] for i in range(3))
    if cross(e1, e2)[axis] * normal_sign < 0:
        corners = [corners[0], corners[3], corners[2], corners[1]]
    # Check: the front normal (right-hand rule) points the way asked.
    e1 = tuple(corners[1][i] - corners[0][i] for i in range(3))
    e2 = tuple(corners[3][i] - corners[0][i] for i in range(3))
    n = cross(e1, e2)
    assert n[axis] * normal_sign > 0 and all(n[i] == 0 for i in range(3) if i != axis)
    return corners


def surface(name, material, quads):
    vertices = [c for quad in quads for c in quad]
    faces = [list(range(4 * i, 4 * i + 4)) for i in range(len(quads))]
    return {"name": name, "material": material, "vertices": vertices, "faces": faces}


def partition(name, x_range, y_range, end_y, end_sign):
    z = (0.0, HEIGHT)
    return surface(name, "wall", [
        rect(0, x_range[0], y_range, z, -1),  # side facing -x
        rect(0, x_range[1], y_range, z, +1),  # side facing +x
        rect(1, end_y, x_range, z, end_sign),  # free end
    ])


def room(name, mirror_walls=(), partitions=False):
    materials = [
        {"name": "floor", "reflectance": grey(0.3)},
        {"name": "ceiling", "reflectance": grey(0.7)},
        {"name": "wall", "reflectance": grey(0.5)},
    ]
    if mirror_walls:
        materials.append({"name": "mirror_wall", "reflectance": grey(0), "mirror": grey(MIRROR)})
    materials.append({"name": "source", "reflectance": grey(0), "emission": grey(EMISSION)})

    def wall_material(wall):
        return "mirror_wall" if wall in mirror_walls else "wall"

    x, y, z = (0.0, SIZE_X), (0.0, SIZE_Y), (0.0, HEIGHT)
    surfaces = [
        surface("floor", "floor", [rect(2, 0.0, x, y, +1)]),
        surface("ceiling", "ceiling", [rect(2, HEIGHT, x, y, -1)]),
        surface("wall_x0", wall_material("wall_x0"), [rect(0, 0.0, y, z, +1)]),
        surface("wall_x10", wall_material("wall_x10"), [rect(0, SIZE_X, y, z, -1)]),
        surface("wall_y0", wall_material("wall_y0"), [rect(1, 0.0, x, z, +1)]),
        surface("wall_y6", wall_material("wall_y6"), [rect(1, SIZE_Y, x, z, -1)]),
        surface("source", "source", [rect(2, SOURCE_Z, SOURCE_X, SOURCE_Y, -1)]),
    ]
    if partitions:
        surfaces.append(partition("partition_a", *PARTITION_A, end_y=PARTITION_A[1][0], end_sign=-1))
        surfaces.append(partition("partition_b", *PARTITION_B, end_y=PARTITION_B[1][1], end_sign=+1))
    return {"name": name, "materials": materials, "surfaces": surfaces}


def num(v):
    """A coordinate or value as the shortest exact text: 0, 2.95, 31.416 (never 3.0500000000000003)."""
    v = round(float(v), 9)
    if v == int(v):
        return str(int(v))
    return repr(v)


def color(c):
    return "{" + ", ".join('"%s": %s' % (k, num(c[k])) for k in ("r", "g", "b")) + "}"


def to_json(scene):
    """The scene in the layout of scenes/furnace.json: 2-space indent, a block per material and
    surface, colours and vertex lists inline (vertex triples separated by two spaces)."""
    out = ["{", '  "name": %s,' % json.dumps(scene["name"]), '  "materials": [']
    blocks = []
    for m in scene["materials"]:
        lines = ['      "name": %s' % json.dumps(m["name"])]
        for key in ("reflectance", "emission", "mirror"):
            if key in m:
                lines.append('      "%s": %s' % (key, color(m[key])))
        blocks.append("    {\n" + ",\n".join(lines) + "\n    }")
    out.append(",\n".join(blocks))
    out.append("  ],")
    out.append('  "surfaces": [')
    blocks = []
    for s in scene["surfaces"]:
        triples = [", ".join(num(c) for c in p) for p in s["vertices"]]
        faces = ", ".join('{"indices": [%s]}' % ", ".join(str(i) for i in f) for f in s["faces"])
        lines = [
            '      "name": %s' % json.dumps(s["name"]),
            '      "material": %s' % json.dumps(s["material"]),
            '      "vertices": [%s]' % ",  ".join(triples),
            '      "faces": [%s]' % faces,
        ]
        blocks.append("    {\n" + ",\n".join(lines) + "\n    }")
    out.append(",\n".join(blocks))
    out.append("  ]")
    out.append("}")
    text = "\n".join(out) + "\n"
    json.loads(text)  # must stay valid JSON
    return text


def points():
    xs = [0.25 + 0.5 * i for i in range(int(SIZE_X / 0.5))]
    ys = [0.25 + 0.5 * j for j in range(int(SIZE_Y / 0.5))]
    lines = [
        "# test_room*.json: the calculation points of the 1990 test room (x y z nx ny nz, as rtrace",
        "# reads them): every 0.5 from 0.25, on the floor facing up and on the ceiling facing down",
    ]
    for grid, z, nz in (("floor", 0.0, 1), ("ceiling", HEIGHT, -1)):
        lines.append("# grid: %s" % grid)
        for x in xs:
            for y in ys:
                lines.append("%s %s %s 0 0 %d" % (num(x), num(y), num(z), nz))
    return "\n".join(lines) + "\n"


VARIANTS = [
    ("test_room", dict()),
    ("test_room_partitions", dict(partitions=True)),
    ("test_room_mirror_y0", dict(mirror_walls=("wall_y0",))),
    ("test_room_mirror_y0_x0", dict(mirror_walls=("wall_y0", "wall_x0"))),
    ("test_room_mirror_y0_y6", dict(mirror_walls=("wall_y0", "wall_y6"))),
]


def main(argv):
    if len(argv) != 2:
        sys.stderr.write("usage: %s OUTDIR\n" % argv[0])
        return 2
    outdir = argv[1]
    os.makedirs(outdir, exist_ok=True)
    for name, options in VARIANTS:
        path = os.path.join(outdir, name + ".json")
        with open(path, "w", encoding="utf-8", newline="\n") as f:
            f.write(to_json(room(name, **options)))
        print(path)
    path = os.path.join(outdir, "test_room_points.txt")
    with open(path, "w", encoding="utf-8", newline="\n") as f:
        f.write(points())
    print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
