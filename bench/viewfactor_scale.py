#!/usr/bin/env python3
"""View factors at scale (docs/guide/view-factors.md): time, peak memory and error against N.

  python3 bench/viewfactor_scale.py [--quick]     # writes bench/results/viewfactor_scale.txt

Scenes from bench/make_facets.py (every facet its own surface): a closed furnished room of about
600, 1 500 and 10 000 facets and a street canyon of about 93 000. Errors are against the dense
analytic matrix where that is affordable (600 facets, --tolerance 1e-5), and otherwise against
exact rows of 4 facets (`--method analytic --from`, spread over the model), and a second run with
another seed (the difference of two independent estimates, divided by sqrt 2).
Runs one `radiosity viewfactor` at a time (the machine's 2 cores each); nothing else should run.
"""
import math
import os
import resource
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CLI = os.path.join(ROOT, "build", "bin", "radiosity")


def load_mtx(path):
    m, n = {}, 0
    with open(path) as f:
        header = None
        for line in f:
            if line.startswith("%"):
                continue
            if header is None:
                header = line.split()
                n = int(header[0])
                continue
            i, j, v = line.split()
            m[(int(i) - 1, int(j) - 1)] = float(v)
    return n, m


def run(scene, out, args):
    cmd = ["/usr/bin/time", "-f", "%e %M", CLI, "viewfactor", scene, "--out", out, "--check"] + args
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit("failed: %s\n%s" % (" ".join(cmd), p.stderr[-2000:]))
    seconds, kb = p.stderr.strip().splitlines()[-1].split()
    return float(seconds), int(kb) / 1024.0


def compare(ref, m, n):
    keys = set(ref) | set(m)
    worst, s2, count, rows = 0.0, 0.0, 0, [0.0] * n
    for k in keys:
        d = m.get(k, 0.0) - ref.get(k, 0.0)
        worst = max(worst, abs(d))
        rows[k[0]] += d
        s2 += d * d
        count += 1
    return worst, math.sqrt(s2 / max(count, 1)), max(abs(r) for r in rows)


def compare_rows(exact, m, rows, rays):
    """Errors of m's rows `rows` against their exact values: max |dF|, RMS dF, max row-sum
    difference, and the mean of (dF / sigma)^2 over the exact nonzeros, sigma = sqrt(F (1 - F) /
    rays) the stated standard error of a ray estimate (near pairs, exact in both, count too)."""
    sub = {k: v for k, v in m.items() if k[0] in rows}
    worst, rms, row = compare(exact, sub, max(rows) + 1)
    z2 = [(sub.get(k, 0.0) - f) ** 2 / (f * (1 - f) / rays) for k, f in exact.items() if 0 < f < 1]
    return worst, rms, row, sum(z2) / max(len(z2), 1)


def main():
    quick = "--quick" in sys.argv
    tmp = tempfile.mkdtemp(prefix="vf-scale-")
    lines = []

    def say(text):
        print(text, flush=True)
        lines.append(text)

    def scene(kind, n):
        path = os.path.join(tmp, "%s%d.obj" % (kind, n))
        with open(path, "w") as f:
            subprocess.run([sys.executable, os.path.join(ROOT, "bench", "make_facets.py"), kind,
                            str(n)], stdout=f, check=True)
        faces = sum(1 for line in open(path) if line.startswith("f "))
        return path, faces

    say("# radiosity viewfactor at scale (2 cores); seconds and peak MiB of the whole process")
    # 1. Against the dense analytic matrix.
    path, faces = scene("room", 600)
    ref_out = os.path.join(tmp, "ref.mtx")
    t, mib = run(path, ref_out, ["--tolerance", "1e-5"])
    n, ref = load_mtx(ref_out)
    say("room %d facets, analytic --tolerance 1e-5 (the reference): %.1f s, %.0f MiB" %
        (faces, t, mib))
    for rays in (10000, 100000):
        for near in (0, 1, 2):
            out = os.path.join(tmp, "mc.mtx")
            t, mib = run(path, out, ["--method", "montecarlo", "--rays-per-surface", str(rays),
                                     "--near", str(near)])
            worst, rms, row = compare(ref, load_mtx(out)[1], n)
            say("  montecarlo %6d rays/facet --near %d: %6.1f s %5.0f MiB  max |dF| %.2e  rms dF "
                "%.2e  max row-sum diff %.2e" % (rays, near, t, mib, worst, rms, row))
    # 2. Time and memory against N; error from two seeds.
    sizes = [("room", 1500, 10000), ("room", 10000, 10000)]
    if not quick:
        sizes.append(("canyon", 100000, 1000))
    for kind, target, rays in sizes:
        path, faces = scene(kind, target)
        # Exact rows of a subset, spread evenly (facet k is the surface f<k>).
        subset = sorted({(2 * k + 1) * faces // 8 for k in range(4)})
        exact_out = os.path.join(tmp, "exact.mtx")
        t, mib = run(path, exact_out, ["--from", ",".join("f%d" % k for k in subset)])
        exact = load_mtx(exact_out)[1]
        sums = [sum(f for (i, _), f in exact.items() if i == r) for r in subset]
        say("%s %d facets: exact rows of %d facets (analytic --from, tolerance 1e-6): %.1f s, "
            "%.0f MiB, row sums %s" % (kind, faces, len(subset), t, mib,
                                      " ".join("%.9f" % x for x in sums)))
        for near in (0, 2):
            a, b = os.path.join(tmp, "a.mtx"), os.path.join(tmp, "b.mtx")
            args = ["--method", "montecarlo", "--rays-per-surface", str(rays), "--near", str(near)]
            t, mib = run(path, a, args)
            size = os.path.getsize(a) / 2**20
            n, ma = load_mtx(a)
            worst, rms, row, z2 = compare_rows(exact, ma, set(subset), rays)
            say("%s %d facets, %d rays/facet --near %d: %.1f s, %.0f MiB, Matrix Market %.0f MiB; "
                "against the exact rows: max |dF| %.2e, rms %.2e, row sums %.2e, mean (dF / "
                "sigma)^2 %.2f" % (kind, faces, rays, near, t, mib, size, worst, rms, row, z2))
            run(path, b, args + ["--seed", "2"])
            worst, rms, row = compare(ma, load_mtx(b)[1], n)
            say("%s %d facets, %d rays/facet --near %d: %.1f s, %.0f MiB, %d nonzeros; seed to "
                "seed / sqrt 2: max |dF| %.2e, rms %.2e, row sums %.2e" %
                (kind, faces, rays, near, t, mib, len(ma), worst / math.sqrt(2),
                 rms / math.sqrt(2), row / math.sqrt(2)))
    out = os.path.join(ROOT, "bench", "results", "viewfactor_scale.txt")
    if not quick:
        with open(out, "w") as f:
            f.write("\n".join(lines) + "\n")
        print("wrote", out)


if __name__ == "__main__":
    main()
