#!/usr/bin/env python3
"""Answers before convergence and hard cases, through the CLI at its defaults (bench/REPORT.md
"Progressive on every scene"). Each row is one solve; errors are against closed forms:

  emitting  bench/make_rooms.py emitting, 10 k elements: B = E / (1 - rho) = 2 on every element
            light reaches; an element a block's footprint covers by a fraction c has the mean
            2 - c (reported apart)
  lamps     bench/make_rooms.py lamps, 10 k elements: the floor's mean against the converged
            solve's
  sphere    bench/make_sphere.py --cap 0.03 (20 480 triangles, 604 of them the lamp): coating
            B = rho H, H its closed form
  hemicube  scenes/furnace.json with hemicube rows: B = 2
  corner    scenes/corner_block_furnace.json, hierarchical: B = 2
  rho       scenes/furnace.json at reflectance 0.99999, defaults: B = 1 / (1 - rho)

    /usr/bin/python3 bench/anytime.py [--bin build/bin/radiosity] [--only NAME,...] [--work DIR]

Prints one line per solve: seconds (the job's own clock), the first snapshot with values, and
the error. Times are this machine's; run with nothing else heavy running.
"""
import argparse
import csv
import json
import math
import os
import re
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)


def solve(args, scene, out, *flags):
    """Runs `radiosity --json solve`; returns (summary, first seconds with values, rows)."""
    cmd = [args.bin, '--json', 'solve', scene, '--out', out] + [str(f) for f in flags]
    run = subprocess.run(cmd, capture_output=True, text=True)
    if run.returncode != 0:
        sys.exit('failed: %s\n%s' % (' '.join(cmd), run.stderr[-2000:]))
    first = None
    for line in run.stdout.splitlines():
        ev = json.loads(line)
        if ev.get('event') == 'snapshot' and ev.get('elements', 0) > 0 and first is None:
            first = ev.get('elapsed_seconds', 0.0)
    with open(os.path.join(out, 'summary.json')) as f:
        summary = json.load(f)
    with open(os.path.join(out, 'elements.csv')) as f:
        rows = list(csv.DictReader(f))
    return summary, first, rows


def lum(r):
    return (float(r['r']) + float(r['g']) + float(r['b'])) / 3


def stats(errs):
    if not errs:
        return 'n=0'
    rms = math.sqrt(sum(e * e for e in errs) / len(errs))
    return 'rms %.2f %%, worst %.2f %% (n=%d)' % (100 * rms, 100 * max(map(abs, errs)), len(errs))


def report(name, summary, first, text):
    print('%-9s %-28s %6.2f s  first values %s  %s  [%s, %d elements]' % (
        name, summary.get('label', ''), summary['seconds'],
        '%.2f s' % first if first is not None else '-', text, summary['method'],
        summary['elements']), flush=True)


# The footprints of bench/make_rooms.py's blocks resting on the emitting room's floor (x0 y0 x1
# y1), and the slab's contact line x = 6 - 1.2 sin 25 deg - 0.2 cos 25 deg .. along y.
FOOT = [(1, 1, 2, 2), (3.2, 2.1, 4.0, 3.3)]


def covered(x, y, h):
    """Covered fraction of the square floor element of half-size h centred at (x, y)."""
    a = 0.0
    for x0, y0, x1, y1 in FOOT:
        a += max(0, min(x + h, x1) - max(x - h, x0)) * max(0, min(y + h, y1) - max(y - h, y0))
    return a / (4 * h * h)


def emitting(args, work):
    scene = os.path.join(work, 'emit.obj')
    subprocess.run([sys.executable, os.path.join(HERE, 'make_rooms.py'), 'emitting', scene],
                   check=True)
    for seconds in (0.5, 2, 0):
        flags = ['--max-elements', 10000] + (['--max-seconds', seconds] if seconds else [])
        summary, first, rows = solve(args, scene, os.path.join(work, 'emit_%s' % seconds), *flags)
        open_errs, straddle = [], []
        for r in rows:
            c = 0.0
            if abs(float(r['cz'])) < 1e-6 and r['surface'] == 'room':
                c = covered(float(r['cx']), float(r['cy']), math.sqrt(float(r['area'])) / 2)
            if c >= 1 or (abs(float(r['cz'])) < 1e-6 and r['surface'] != 'room'):
                continue  # Under a block, or a block's underside.
            # A straddling element's mean: E = 1 everywhere, the reflected 1 on its open part.
            (straddle if c > 0 else open_errs).append(lum(r) / (2 - c) - 1)
        summary['label'] = 'deadline %s s' % seconds if seconds else 'converged'
        report('emitting', summary, first,
               'open: %s; straddling: %s' % (stats(open_errs), stats(straddle)))


def floor_mean(rows):
    num = den = 0.0
    for r in rows:
        if abs(float(r['cz'])) < 1e-6 and r['surface'] == 'floor':
            num += lum(r) * float(r['area'])
            den += float(r['area'])
    return num / den


def lamps(args, work):
    scene = os.path.join(work, 'lamps.obj')
    subprocess.run([sys.executable, os.path.join(HERE, 'make_rooms.py'), 'lamps', scene],
                   check=True)
    summary, first, rows = solve(args, scene, os.path.join(work, 'lamps_conv'),
                                 '--max-elements', 10000)
    converged = floor_mean(rows)
    summary['label'] = 'converged'
    report('lamps', summary, first, 'floor %.4f' % converged)
    for seconds in (1, 2):
        summary, first, rows = solve(args, scene, os.path.join(work, 'lamps_%s' % seconds),
                                     '--max-elements', 10000, '--max-seconds', seconds)
        summary['label'] = 'deadline %s s' % seconds
        m = floor_mean(rows)
        report('lamps', summary, first, 'floor %.4f (%+.2f %% of converged)' % (
            m, 100 * (m / converged - 1)))


def sphere(args, work):
    scene = os.path.join(work, 'sphere.obj')
    # --cap 0.03: 604 of the 20 480 triangles are the lamp.
    out = subprocess.run([sys.executable, os.path.join(HERE, 'make_sphere.py'), scene, '--cap',
                          '0.03'],
                         check=True, capture_output=True, text=True).stdout
    h = float(re.search(r'H=([0-9.eE+-]+)', out).group(1))
    for seconds in (3, 0):
        flags = ['--max-seconds', seconds] if seconds else []
        summary, first, rows = solve(args, scene, os.path.join(work, 'sphere_%s' % seconds),
                                     *flags)
        errs = [lum(r) / (0.8 * h) - 1 for r in rows if r['surface'] != 'lamp']
        summary['label'] = 'deadline %s s' % seconds if seconds else 'converged'
        report('sphere', summary, first, 'coating: %s' % stats(errs))


def furnace_like(args, work, name, scene, truth, *flags):
    summary, first, rows = solve(args, scene, os.path.join(work, name), *flags)
    summary['label'] = ' '.join(str(f) for f in flags)[:28]
    report(name.split('_')[0], summary, first,
           'all: %s' % stats([lum(r) / truth - 1 for r in rows]))


def hemicube(args, work):
    scene = os.path.join(ROOT, 'scenes', 'furnace.json')
    for method in ('progressive', 'gauss-seidel'):
        furnace_like(args, work, 'hemicube_' + method, scene, 2.0, '--method', method,
                     '--formfactor', 'hemicube')


def corner(args, work):
    furnace_like(args, work, 'corner_hierarchical',
                 os.path.join(ROOT, 'scenes', 'corner_block_furnace.json'), 2.0,
                 '--max-elements', 10000, '--method', 'hierarchical')


def rho(args, work):
    with open(os.path.join(ROOT, 'scenes', 'furnace.json')) as f:
        scene = json.load(f)
    for value in (0.99999, 0.999999):
        scene['materials'][0]['reflectance'] = {'r': value, 'g': value, 'b': value}
        path = os.path.join(work, 'rho_%s.json' % value)
        with open(path, 'w') as f:
            json.dump(scene, f)
        furnace_like(args, work, 'rho_%s' % value, path, 1 / (1 - value))


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--bin', default=os.path.join(ROOT, 'build', 'bin', 'radiosity'))
    ap.add_argument('--only', default='emitting,lamps,sphere,hemicube,corner,rho')
    ap.add_argument('--work', default=None, help='keep outputs here (default: a temp dir)')
    args = ap.parse_args()
    work = args.work or tempfile.mkdtemp(prefix='anytime-')
    os.makedirs(work, exist_ok=True)
    for name in args.only.split(','):
        globals()[name](args, work)


if __name__ == '__main__':
    main()
