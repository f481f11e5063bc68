#!/usr/bin/env python3
"""A closed room with furniture (or a street canyon) as an OBJ in which every facet is its own
surface (`g f<k>`): the view-factor scaling scenes of docs/guide/view-factors.md.

  python3 bench/make_facets.py room N > room.obj      # about N facets: a closed 6 x 4 x 3 m
                                                      # room, a table top, a cabinet and a box
                                                      # (raised off the floor), every side cut
                                                      # into squares of one size
  python3 bench/make_facets.py canyon N > canyon.obj  # a street between two rows of buildings
                                                      # (open to the sky)
"""
import math
import sys


def boxes(kind):
    """(x0, y0, z0, x1, y1, z1, inward) boxes: the room faces in, furniture out."""
    if kind == "room":
        return [(0, 0, 0, 6, 4, 3, True),          # the room
                (1, 1, 0.4, 2.6, 2, 0.75, False),  # a table top (as a slab)
                (4.5, 0.2, 0.1, 5.9, 0.8, 2, False),  # a cabinet on feet near a wall
                (3, 2.5, 0.1, 3.6, 3.1, 0.5, False)]  # a box on feet
    # A street 10 m wide, 60 m long, buildings 4 deep and 8 to 16 high on both sides, the ground.
    out = []
    for side in (0, 1):
        for k in range(6):
            h = 8 + 8 * ((k * 7 + side * 3) % 5) / 4
            y0 = -4 if side == 0 else 10
            out.append((k * 10, y0, 0, k * 10 + 9, y0 + 4, h, False))
    return out


def main():
    kind = sys.argv[1] if len(sys.argv) > 1 else "room"
    target = int(sys.argv[2]) if len(sys.argv) > 2 else 10000
    bs = boxes(kind)
    area = sum(2 * ((b[3] - b[0]) * (b[4] - b[1]) + (b[3] - b[0]) * (b[5] - b[2]) +
                    (b[4] - b[1]) * (b[5] - b[2])) for b in bs)
    if kind == "canyon":
        area += 60 * 10  # the street
    size = math.sqrt(area / target)
    verts, faces = [], []

    def rect(c, u, v, flip):
        nu = max(1, round(math.sqrt(sum(x * x for x in u)) / size))
        nv = max(1, round(math.sqrt(sum(x * x for x in v)) / size))
        for i in range(nu):
            for j in range(nv):
                p = [[c[k] + u[k] * (i + a) / nu + v[k] * (j + b) / nv for k in range(3)]
                     for a, b in ((0, 0), (1, 0), (1, 1), (0, 1))]
                if flip:
                    p.reverse()
                base = len(verts)
                verts.extend(p)
                faces.append([base + 1, base + 2, base + 3, base + 4])

    for (x0, y0, z0, x1, y1, z1, inward) in bs:
        dx, dy, dz = x1 - x0, y1 - y0, z1 - z0
        # Counter-clockwise seen from outside (front outward); flipped for the room.
        sides = [((x0, y0, z0), (0, 0, dz), (0, dy, 0)),   # x0 side, normal -x
                 ((x1, y0, z0), (0, dy, 0), (0, 0, dz)),   # x1, +x
                 ((x0, y0, z0), (dx, 0, 0), (0, 0, dz)),   # y0, -y
                 ((x0, y1, z0), (0, 0, dz), (dx, 0, 0)),   # y1, +y
                 ((x0, y0, z0), (0, dy, 0), (dx, 0, 0)),   # z0, -z
                 ((x0, y0, z1), (dx, 0, 0), (0, dy, 0))]   # z1, +z
        for k, (c, u, v) in enumerate(sides):
            if not inward and k == 4 and z0 == 0:
                continue  # Buildings stand on the ground: no bottom.
            rect(c, u, v, inward)
    if kind == "canyon":
        rect((0, 0, 0), (60, 0, 0), (0, 10, 0), False)  # The street, facing up.
    out = sys.stdout
    for p in verts:
        out.write("v %.6g %.6g %.6g\n" % tuple(p))
    for k, f in enumerate(faces):
        out.write("g f%d\nf %d %d %d %d\n" % (k, *f))


if __name__ == "__main__":
    main()
