#!/usr/bin/env python3
"""Solves a scene on a radiosity server, watches it converge and plots the unshot fraction
against time (docs/service/python.md).

    PYTHONPATH=build/python python3 client/python/examples/convergence.py \
        --server 127.0.0.1:50051 --out convergence.png scenes/cornell_box.obj
"""

import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import radiosity  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene", help="scene file (.obj with its .mtl, .json, .gltf, ...)")
    parser.add_argument("--server", help="HOST:PORT (default: $RADIOSITY_SERVER)")
    parser.add_argument("--out", default="convergence.png", help="PNG of the plot")
    parser.add_argument("--max-seconds", type=float, default=60)
    args = parser.parse_args()

    with radiosity.connect(args.server) as client:
        scene = client.upload(args.scene)
        job = client.solve(scene, max_seconds=args.max_seconds, snapshot_interval=0.2)
        seconds, unshot = [], []
        for snap in client.watch(job, progress_only=True):
            seconds.append(snap.progress.elapsed_seconds)
            unshot.append(max(snap.progress.unshot_fraction, 1e-12))
            print(f"{snap.sequence:5d} {snap.state_name:20s} {snap.progress.rays:12d} rays "
                  f"unshot {snap.progress.unshot_fraction:.3%}")
        ended = client.job(job)
        print(f"{ended.name} {radiosity.pb.JobState.Name(ended.state)} ({ended.stop_reason})")

    plt.semilogy(seconds, unshot, marker=".")
    plt.xlabel("seconds")
    plt.ylabel("unshot fraction of the emitted power")
    plt.title(f"{args.scene}: {ended.method}")
    plt.grid(True, which="both", alpha=0.3)
    plt.savefig(args.out, dpi=100)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
