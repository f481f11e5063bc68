#!/usr/bin/env python3
"""An integrating sphere of unit radius tessellated as an icosphere (20 x 4^S triangles, facing
inward): a cap about +z of exitance M = 1 W/m^2 and reflectance 0 (the lamp), the rest of
reflectance RHO (the coating). The closed form (docs/guide/scenes.md): the irradiance is the same everywhere, H = M f / (1 - RHO (1 - f)), f the lamp's
share of the area, printed here from the triangles written (so the tessellation is exact).

    python3 bench/make_sphere.py OUT.obj [--subdivisions 5] [--rho 0.8] [--cap 0.05]

writes OUT.obj and sphere.mtl beside it, and prints `f=... H=...` on stdout.
"""
import argparse
import math
import os

ap = argparse.ArgumentParser()
ap.add_argument('out')
ap.add_argument('--subdivisions', type=int, default=5)
ap.add_argument('--rho', type=float, default=0.8)
ap.add_argument('--cap', type=float, default=0.05,
                help='target lamp share of the area (a cap z > 1 - 2 cap)')
a = ap.parse_args()

t = (1 + 5 ** 0.5) / 2
verts = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t),
         (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
verts = [tuple(c / math.sqrt(sum(x * x for x in v)) for c in v) for v in verts]
faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
         (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
         (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
for _ in range(a.subdivisions):
    cache = {}

    def mid(i, j):
        key = (min(i, j), max(i, j))
        if key not in cache:
            m = [(p + q) / 2 for p, q in zip(verts[i], verts[j])]
            n = math.sqrt(sum(x * x for x in m))
            verts.append(tuple(x / n for x in m))
            cache[key] = len(verts) - 1
        return cache[key]

    nf = []
    for i, j, k in faces:
        ij, jk, ki = mid(i, j), mid(j, k), mid(k, i)
        nf += [(i, ij, ki), (j, jk, ij), (k, ki, jk), (ij, jk, ki)]
    faces = nf


def sub(p, q):
    return [x - y for x, y in zip(p, q)]


def cross(p, q):
    return [p[1] * q[2] - p[2] * q[1], p[2] * q[0] - p[0] * q[2], p[0] * q[1] - p[1] * q[0]]


lamp, coat = [], []
area_lamp = area_all = 0.0
for f in faces:
    p = [verts[i] for i in f]
    n = cross(sub(p[1], p[0]), sub(p[2], p[0]))
    c = [sum(x) / 3 for x in zip(*p)]
    if sum(x * y for x, y in zip(n, c)) > 0:  # outward: reverse so the front faces the centre
        f = (f[0], f[2], f[1])
    area = 0.5 * math.sqrt(sum(x * x for x in n))
    area_all += area
    if c[2] > 1 - 2 * a.cap:
        lamp.append(f)
        area_lamp += area
    else:
        coat.append(f)
frac = area_lamp / area_all
h = frac / (1 - a.rho * (1 - frac))
with open(a.out, 'w') as out:
    out.write('# integrating sphere: %d triangles, f=%.9f rho=%g H=%.9f\n'
              % (len(faces), frac, a.rho, h))
    out.write('mtllib sphere.mtl\n')
    for v in verts:
        out.write('v %.12g %.12g %.12g\n' % v)
    for name, group in (('lamp', lamp), ('coating', coat)):
        out.write('o %s\nusemtl %s\n' % (name, name))
        for f in group:
            out.write('f %d %d %d\n' % (f[0] + 1, f[1] + 1, f[2] + 1))
with open(os.path.join(os.path.dirname(os.path.abspath(a.out)), 'sphere.mtl'), 'w') as out:
    out.write('newmtl lamp\nKd 0 0 0\nKe 1 1 1\nnewmtl coating\nKd %g %g %g\n' % ((a.rho,) * 3))
print('f=%.9f H=%.9f triangles=%d' % (frac, h, len(faces)))
