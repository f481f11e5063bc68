#!/usr/bin/env python3
"""A generated open-plan office of about 10^6 triangles, tessellated as CAD exports are (every
box a grid of small triangles, every leg a fine cylinder): rows of workstations (desk, chair,
monitor), shelves along the walls, and a ceiling light panel over each desk. For the issue-14
target "a generated office of about 10^6 triangles loads, meshes and solves within 8 GiB"
(docs/guide/scenes.md).

    python3 bench/make_office.py OUT.obj [--rows 10] [--cols 12] [--detail 16]

writes OUT.obj and office.mtl beside it, and prints the triangle count. Units: metres; y up.
"""
import argparse
import math
import os

ap = argparse.ArgumentParser()
ap.add_argument('out')
ap.add_argument('--rows', type=int, default=10)
ap.add_argument('--cols', type=int, default=12)
ap.add_argument('--detail', type=int, default=16, help='grid cells along a desk top edge')
a = ap.parse_args()

out = open(a.out, 'w')
out.write('# generated office: bench/make_office.py %s\nmtllib office.mtl\n'
          % ' '.join('--%s %s' % kv for kv in vars(a).items() if kv[0] != 'out'))
nv = 0
triangles = 0
current = None


def use(name, material):
    global current
    if current != (name, material):
        out.write('o %s\nusemtl %s\n' % (name, material))
        current = (name, material)


def grid(name, material, origin, u, v, n, m):
    """A parallelogram origin + s u + t v as n x m cells of two triangles, front along u x v."""
    global nv, triangles
    use(name, material)
    lines = []
    for j in range(m + 1):
        for i in range(n + 1):
            p = [origin[k] + u[k] * i / n + v[k] * j / m for k in range(3)]
            lines.append('v %.5f %.5f %.5f\n' % tuple(p))
    out.write(''.join(lines))
    base = nv + 1
    idx = lambda i, j: base + j * (n + 1) + i
    faces = []
    for j in range(m):
        for i in range(n):
            faces.append('f %d %d %d\nf %d %d %d\n' % (idx(i, j), idx(i + 1, j), idx(i + 1, j + 1),
                                                       idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)))
    out.write(''.join(faces))
    nv += (n + 1) * (m + 1)
    triangles += 2 * n * m


def box(name, material, lo, hi, n):
    """An axis-aligned box facing outward, each side an n x n grid."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    dx, dy, dz = x1 - x0, y1 - y0, z1 - z0
    grid(name, material, (x0, y1, z0), (0, 0, dz), (dx, 0, 0), n, n)   # top, +y
    grid(name, material, (x0, y0, z0), (dx, 0, 0), (0, 0, dz), n, n)   # bottom, -y
    grid(name, material, (x0, y0, z0), (0, dy, 0), (dx, 0, 0), n, n)   # -z
    grid(name, material, (x0, y0, z1), (dx, 0, 0), (0, dy, 0), n, n)   # +z
    grid(name, material, (x0, y0, z0), (0, 0, dz), (0, dy, 0), n, n)   # -x
    grid(name, material, (x1, y0, z0), (0, dy, 0), (0, 0, dz), n, n)   # +x


def cylinder(name, material, base, radius, height, segments, rings):
    """A vertical cylinder facing outward, with a top cap (it stands on something)."""
    global nv, triangles
    use(name, material)
    cx, cy, cz = base
    lines = []
    for r in range(rings + 1):
        y = cy + height * r / rings
        for s in range(segments):
            t = 2 * math.pi * s / segments
            lines.append('v %.5f %.5f %.5f\n' % (cx + radius * math.cos(t), y, cz + radius * math.sin(t)))
    lines.append('v %.5f %.5f %.5f\n' % (cx, cy + height, cz))
    out.write(''.join(lines))
    base_i = nv + 1
    idx = lambda r, s: base_i + r * segments + s % segments
    centre = base_i + (rings + 1) * segments
    faces = []
    for r in range(rings):
        for s in range(segments):
            # Counter-clockwise seen from outside.
            faces.append('f %d %d %d\nf %d %d %d\n' % (idx(r, s), idx(r + 1, s), idx(r + 1, s + 1),
                                                       idx(r, s), idx(r + 1, s + 1), idx(r, s + 1)))
    for s in range(segments):
        faces.append('f %d %d %d\n' % (centre, idx(rings, s + 1), idx(rings, s)))
    out.write(''.join(faces))
    nv += (rings + 1) * segments + 1
    triangles += 2 * rings * segments + segments


d = a.detail
pitch_x, pitch_z = 2.4, 3.0
width = a.cols * pitch_x + 4
depth = a.rows * pitch_z + 4
height = 3.0
# The room, facing inward (one quad per side: large faces are meshed as before).
grid('floor', 'carpet', (0, 0, 0), (0, 0, depth), (width, 0, 0), 1, 1)
grid('ceiling', 'ceiling', (0, height, 0), (width, 0, 0), (0, 0, depth), 1, 1)
grid('walls', 'wall', (0, 0, 0), (width, 0, 0), (0, height, 0), 1, 1)
grid('walls', 'wall', (0, 0, depth), (0, height, 0), (width, 0, 0), 1, 1)
grid('walls', 'wall', (0, 0, 0), (0, height, 0), (0, 0, depth), 1, 1)
grid('walls', 'wall', (width, 0, 0), (0, 0, depth), (0, height, 0), 1, 1)
for row in range(a.rows):
    for col in range(a.cols):
        x = 2 + col * pitch_x + 0.4
        z = 2 + row * pitch_z + 0.5
        box('desks', 'wood', (x, 0.72, z), (x + 1.6, 0.75, z + 0.8), d)
        for lx, lz in ((0.05, 0.05), (1.55, 0.05), (0.05, 0.75), (1.55, 0.75)):
            cylinder('desks', 'metal', (x + lx, 0, z + lz), 0.025, 0.72, 2 * d, d // 4)
        box('monitors', 'plastic', (x + 0.5, 0.75, z + 0.1), (x + 1.1, 1.1, z + 0.14), d // 2)
        cx, cz = x + 0.8, z + 1.2
        box('chairs', 'fabric', (cx - 0.25, 0.45, cz - 0.25), (cx + 0.25, 0.5, cz + 0.25), d // 2)
        box('chairs', 'fabric', (cx - 0.25, 0.5, cz + 0.2), (cx + 0.25, 1.0, cz + 0.25), d // 2)
        cylinder('chairs', 'metal', (cx, 0.05, cz), 0.03, 0.4, 2 * d, d // 4)
        for k in range(5):
            t = 2 * math.pi * k / 5
            cylinder('chairs', 'metal', (cx + 0.2 * math.cos(t), 0, cz + 0.2 * math.sin(t)), 0.02,
                     0.05, d, 1)
        # A ceiling panel over the desk, facing down.
        grid('lamps', 'lamp', (x + 0.5, height - 0.01, z + 0.1), (0.6, 0, 0), (0, 0, 0.6), 1, 1)
# Shelves along the two long walls.
for side, zs in ((0, 0.05), (1, depth - 0.45)):
    for k in range(int(width // 2)):
        x = 0.5 + 2 * k
        for b in range(5):
            y = 0.1 + 0.45 * b
            box('shelves', 'wood', (x, y, zs), (x + 1.8, y + 0.03, zs + 0.4), d // 2)
out.close()
with open(os.path.join(os.path.dirname(os.path.abspath(a.out)), 'office.mtl'), 'w') as m:
    m.write('newmtl carpet\nKd 0.2 0.2 0.25\nnewmtl ceiling\nKd 0.8 0.8 0.8\n'
            'newmtl wall\nKd 0.7 0.7 0.65\nnewmtl wood\nKd 0.5 0.35 0.2\n'
            'newmtl metal\nKd 0.6 0.6 0.6\nnewmtl plastic\nKd 0.1 0.1 0.1\n'
            'newmtl fabric\nKd 0.2 0.25 0.5\nnewmtl lamp\nKd 0.8 0.8 0.8\nKe 200 200 200\n')
print('triangles=%d vertices=%d' % (triangles, nv))
