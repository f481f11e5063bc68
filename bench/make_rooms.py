#!/usr/bin/env python3
"""Rooms for the progressive bench (bench/REPORT.md "Progressive on every scene"), as OBJ + MTL.

  python3 bench/make_rooms.py emitting OUT.obj  # a closed 6 x 4 x 3 m room in which every face
                                                # emits (E = 1, rho = 0.5: B = 2 everywhere, a
                                                # furnace), two blocks resting on the floor and a
                                                # slab leaning on a wall, none of them cut into
                                                # the floor: contact edges cross elements
  python3 bench/make_rooms.py lamps OUT.obj     # a 10 x 8 x 3 m room lit by 80 square ceiling
                                                # lamps (10 x 8), 1 cm below the ceiling

Writes OUT.obj and OUT.mtl (the .obj's name with .mtl). z is up; metres.
"""
import math
import os
import sys


def box(x0, y0, z0, x1, y1, z1):
    """The 6 quads of an axis-aligned box, counter-clockwise seen from outside."""
    v = [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0),
         (x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)]
    quads = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
    return [[v[i] for i in q] for q in quads]


def inward(quads):
    return [list(reversed(q)) for q in quads]


def slab_leaning(x_wall, y0, y1, height, thickness, angle_deg):
    """A slab whose lowest edge rests on the floor (z = 0) and whose top edge touches the wall
    x = x_wall, tilted angle_deg from the vertical towards the wall."""
    a = math.radians(angle_deg)
    d = (math.sin(a), math.cos(a))    # up the slab, in (x, z)
    n = (math.cos(a), -math.sin(a))   # across it, towards the wall and down
    # Corners of the cross-section: p0, p0 + n t, p0 + d h, p0 + d h + n t; p0 + n t on the floor
    # and p0 + d h + n t on the wall.
    p0x = x_wall - height * d[0] - thickness * n[0]
    p0z = thickness * math.sin(a)
    sec = [(p0x, p0z), (p0x + thickness * n[0], p0z + thickness * n[1]),
           (p0x + thickness * n[0] + height * d[0], p0z + thickness * n[1] + height * d[1]),
           (p0x + height * d[0], p0z + height * d[1])]
    # The section's corners run clockwise seen from +y; a quad per side, outward.
    quads = []
    for k in range(4):
        (ax, az), (bx, bz) = sec[k], sec[(k + 1) % 4]
        quads.append([(ax, y0, az), (bx, y0, bz), (bx, y1, bz), (ax, y1, az)])
    quads.append([(x, y0, z) for x, z in reversed(sec)])
    quads.append([(x, y1, z) for x, z in sec])
    return quads


def orient_outward(quads, centre):
    """Reverses each quad whose normal points towards `centre` (a convex solid's inside)."""
    out = []
    for q in quads:
        e1 = [q[1][i] - q[0][i] for i in range(3)]
        e2 = [q[2][i] - q[0][i] for i in range(3)]
        nrm = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
               e1[0] * e2[1] - e1[1] * e2[0]]
        c = [sum(p[i] for p in q) / len(q) for i in range(3)]
        if sum(nrm[i] * (c[i] - centre[i]) for i in range(3)) < 0:
            q = list(reversed(q))
        out.append(q)
    return out


def write(path, objects, materials):
    mtl = os.path.splitext(path)[0] + '.mtl'
    with open(mtl, 'w') as m:
        for name, (kd, ke) in materials.items():
            m.write('newmtl %s\nKd %g %g %g\nKe %g %g %g\n' % ((name,) + kd + ke))
    with open(path, 'w') as o:
        o.write('mtllib %s\n' % os.path.basename(mtl))
        index = 1
        for name, material, quads in objects:
            o.write('o %s\nusemtl %s\n' % (name, material))
            for q in quads:
                for p in q:
                    o.write('v %.9g %.9g %.9g\n' % p)
                o.write('f %s\n' % ' '.join(str(index + k) for k in range(len(q))))
                index += len(q)


def emitting(path):
    objects = [('room', 'furnace', inward(box(0, 0, 0, 6, 4, 3))),
               ('block_a', 'furnace', box(1, 1, 0, 2, 2, 1)),
               ('block_b', 'furnace', box(3.2, 2.1, 0, 4.0, 3.3, 0.6))]
    slab = slab_leaning(6, 0.8, 2.4, 1.6, 0.2, 25)
    cx = sum(p[0] for q in slab for p in q) / 24
    cz = sum(p[2] for q in slab for p in q) / 24
    objects.append(('slab', 'furnace', orient_outward(slab, (cx, 1.6, cz))))
    write(path, objects, {'furnace': ((0.5, 0.5, 0.5), (1, 1, 1))})


def lamps(path):
    room = inward(box(0, 0, 0, 10, 8, 3))
    objects = [('floor', 'floor', [room[0]]), ('ceiling', 'ceiling', [room[1]]),
               ('walls', 'wall', room[2:])]
    lamp_quads = []
    for i in range(10):
        for j in range(8):
            x, y, s = 0.5 + i, 0.5 + j, 0.3
            lamp_quads.append([(x - s, y - s, 2.99), (x - s, y + s, 2.99), (x + s, y + s, 2.99),
                               (x + s, y - s, 2.99)])
    objects.append(('lamps', 'lamp', lamp_quads))
    write(path, objects, {'floor': ((0.3, 0.3, 0.3), (0, 0, 0)),
                          'wall': ((0.6, 0.6, 0.6), (0, 0, 0)),
                          'ceiling': ((0.8, 0.8, 0.8), (0, 0, 0)),
                          'lamp': ((0, 0, 0), (50, 50, 50))})


def main():
    if len(sys.argv) != 3 or sys.argv[1] not in ('emitting', 'lamps'):
        sys.exit(__doc__)
    {'emitting': emitting, 'lamps': lamps}[sys.argv[1]](sys.argv[2])


if __name__ == '__main__':
    main()
