#!/usr/bin/env python3
"""The 1990 global-illumination test room (scenes/make_test_room.py) at its calculation points,
and the image method as a check of specular transport (docs/guide/specular.md,
bench/REPORT.md "The 1990 test room").

Usage: python3 bench/test_room.py [--radiosity build/bin/radiosity] [--out bench/results]
           [-- EXTRA SOLVE FLAGS]

Solves every variant at the defaults with `--sensors scenes/test_room_points.txt` and writes:
  OUT/test_room.txt         per variant: solve time, floor and ceiling irradiance at the points
                            (mean, min, max), and the image-method check below
  OUT/test_room_points.csv  variant, grid, x, y, irradiance (green channel; the room is grey)

The image-method check: the room with its wall y = 0 an ideal mirror of reflectance 1 (no
absorption there) gives, at every point, the irradiance of the room mirrored about y = 0 (10 x 12,
two sources) without the mirror. Both are solved at the defaults; the report gives the relative
difference per point (worst and RMS) against the doubled room solved with 16 x the rays. The same
per element (radiosity of every element of the room's surfaces, both rooms meshed with
--element-size 0.25 so that their elements coincide), for the mirror room's default direct step
(computed, with the source's image in the mirror) and for --direct shot.
"""

import argparse
import csv
import importlib.util
import json
import math
import os
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def load_generator():
    spec = importlib.util.spec_from_file_location(
        "make_test_room", os.path.join(ROOT, "scenes", "make_test_room.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def doubled_room(gen):
    """The test room mirrored about y = 0: 10 x 12 (y -6..6), two sources, no wall at y = 0."""
    x, y, z = (0.0, gen.SIZE_X), (-gen.SIZE_Y, gen.SIZE_Y), (0.0, gen.HEIGHT)
    mirrored_y = (-gen.SOURCE_Y[1], -gen.SOURCE_Y[0])
    return {
        "name": "test_room_doubled",
        "materials": [
            {"name": "floor", "reflectance": gen.grey(0.3)},
            {"name": "ceiling", "reflectance": gen.grey(0.7)},
            {"name": "wall", "reflectance": gen.grey(0.5)},
            {"name": "source", "reflectance": gen.grey(0), "emission": gen.grey(gen.EMISSION)},
        ],
        "surfaces": [
            gen.surface("floor", "floor", [gen.rect(2, 0.0, x, y, +1)]),
            gen.surface("ceiling", "ceiling", [gen.rect(2, gen.HEIGHT, x, y, -1)]),
            gen.surface("wall_x0", "wall", [gen.rect(0, 0.0, y, z, +1)]),
            gen.surface("wall_x10", "wall", [gen.rect(0, gen.SIZE_X, y, z, -1)]),
            gen.surface("wall_y_6", "wall", [gen.rect(1, -gen.SIZE_Y, x, z, +1)]),
            gen.surface("wall_y6", "wall", [gen.rect(1, gen.SIZE_Y, x, z, -1)]),
            gen.surface("source", "source", [gen.rect(2, gen.SOURCE_Z, gen.SOURCE_X, gen.SOURCE_Y,
                                                      -1)]),
            gen.surface("source_image", "source",
                        [gen.rect(2, gen.SOURCE_Z, gen.SOURCE_X, mirrored_y, -1)]),
        ],
    }


def solve(radiosity, scene, points, out, extra):
    start = time.monotonic()
    subprocess.run([radiosity, "solve", scene, "--sensors", points, "--out", out, "--quiet"] +
                   extra, check=True, stdout=subprocess.DEVNULL)
    seconds = time.monotonic() - start
    summary = json.load(open(os.path.join(out, "summary.json")))
    rows = list(csv.DictReader(open(os.path.join(out, "sensors.csv"))))
    values = {(r["grid"], round(float(r["x"]), 3), round(float(r["y"]), 3)): float(r["g"])
              for r in rows}
    return seconds, summary, values


def element_values(out):
    """Per element: (rounded centroid) -> radiosity (green), the sources left out."""
    values = {}
    for r in csv.DictReader(open(os.path.join(out, "elements.csv"))):
        if r["surface"].startswith("source"):
            continue
        key = tuple(round(float(r[c]), 3) for c in ("cx", "cy", "cz"))
        values[key] = float(r["g"])
    return values


def error_line(label, seconds, values, reference, unit):
    # Left out: what the reference hardly lights (the ceiling elements that the source, hung
    # just under them, covers: below 1/20 of the median).
    floor = 0.05 * sorted(reference.values())[len(reference) // 2]
    errors = [values[k] / reference[k] - 1 for k in values if reference.get(k, 0) > floor]
    rms = math.sqrt(sum(e * e for e in errors) / len(errors))
    return "  %s: %.2f s, RMS %.2f %%, worst %.2f %% (%d %s)" % (
        label, seconds, 100 * rms, 100 * max(abs(e) for e in errors), len(errors), unit)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--radiosity", default=os.path.join(ROOT, "build", "bin", "radiosity"))
    parser.add_argument("--out", default=os.path.join(ROOT, "bench", "results"))
    parser.add_argument("extra", nargs="*")
    args = parser.parse_args()
    gen = load_generator()
    points = os.path.join(ROOT, "scenes", "test_room_points.txt")
    lines = []
    table = []
    with tempfile.TemporaryDirectory() as tmp:
        variants = ["test_room", "test_room_partitions", "test_room_mirror_y0",
                    "test_room_mirror_y0_x0", "test_room_mirror_y0_y6"]
        lines.append("variant | solve s (wall) | method | rays | floor mean / min / max | "
                     "ceiling mean / min / max  (irradiance W/m^2 at the calculation points)")
        for v in variants:
            seconds, summary, values = solve(args.radiosity, os.path.join(ROOT, "scenes", v + ".json"),
                                             points, os.path.join(tmp, v), args.extra)
            stats = []
            for grid in ("floor", "ceiling"):
                vals = [val for (g, _, _), val in values.items() if g == grid]
                stats.append("%.4f / %.4f / %.4f" % (sum(vals) / len(vals), min(vals), max(vals)))
                table += [(v, g, x, y, val) for (g, x, y), val in sorted(values.items())
                          if g == grid]
            lines.append("%s | %.2f | %s | %s | %s | %s" % (
                v, seconds, summary.get("method"), summary.get("rays"), stats[0], stats[1]))

        # The image-method check.
        ideal = gen.room("test_room_ideal_mirror_y0", mirror_walls=("wall_y0",))
        for m in ideal["materials"]:
            if m["name"] == "mirror_wall":
                m["mirror"] = gen.grey(1.0)
        ideal_path = os.path.join(tmp, "ideal.json")
        open(ideal_path, "w").write(gen.to_json(ideal))
        doubled_path = os.path.join(tmp, "doubled.json")
        open(doubled_path, "w").write(gen.to_json(doubled_room(gen)))
        s_mirror, _, mirror = solve(args.radiosity, ideal_path, points,
                                    os.path.join(tmp, "ideal"), args.extra)
        s_doubled, _, doubled = solve(args.radiosity, doubled_path, points,
                                      os.path.join(tmp, "doubled"), args.extra)
        s_ref, _, reference = solve(args.radiosity, doubled_path, points,
                                    os.path.join(tmp, "reference"),
                                    args.extra + ["--rays-per-element", "16000",
                                                  "--sensor-samples", "65536"])
        lines.append("")
        lines.append("image method (wall y=0 a mirror of reflectance 1 against the room mirrored "
                     "about y=0), irradiance at the 480 points against the doubled room at 16x rays "
                     "(%.1f s):" % s_ref)
        for label, seconds, values in (("mirror room, defaults", s_mirror, mirror),
                                       ("doubled room, defaults", s_doubled, doubled)):
            lines.append(error_line(label, seconds, values, reference, "points"))

        # The same per element, on one grid.
        grid = ["--element-size", "0.25"]
        runs = []
        for label, path, flags in (
                ("mirror room, defaults", ideal_path, []),
                ("mirror room, --direct shot", ideal_path, ["--direct", "shot"]),
                ("doubled room, defaults", doubled_path, []),
                ("reference", doubled_path, ["--rays-per-element", "16000"])):
            out = os.path.join(tmp, "el_" + str(len(runs)))
            seconds, _, _ = solve(args.radiosity, path, points, out, args.extra + grid + flags)
            runs.append((label, seconds, element_values(out)))
        reference = runs[-1][2]
        lines.append("")
        lines.append("the same per element (radiosity, --element-size 0.25), against the doubled "
                     "room at 16x rays (%.1f s):" % runs[-1][1])
        for label, seconds, values in runs[:-1]:
            lines.append(error_line(label, seconds, values, reference, "elements"))
    os.makedirs(args.out, exist_ok=True)
    text = "\n".join(lines) + "\n"
    open(os.path.join(args.out, "test_room.txt"), "w").write(text)
    with open(os.path.join(args.out, "test_room_points.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["variant", "grid", "x", "y", "irradiance"])
        for row in table:
            w.writerow([row[0], row[1], row[2], row[3], "%.5g" % row[4]])
    sys.stdout.write(text)


if __name__ == "__main__":
    main()
