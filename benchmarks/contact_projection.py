"""Micro-benchmark: closest-point projection of fabric nodes onto ellipsoids (not a test).

Usage::

    .venv/bin/python benchmarks/contact_projection.py [--sizes 10000 100000] [--repeat 5]

Times the exact projection (``closest_point_ellipsoid``), the cheap radial / gradient
approximations, a two-ellipsoid union and one FILM step, on points scattered inside and outside
(radial fraction 0-2) of a forearm-like ellipsoid (0.20, 0.06, 0.06) m and a 1:20 one.
Prints the best of ``--repeat`` wall-clock times in ms and the points per second.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from clothfem.contact import (
    closest_point_ellipsoid,
    closest_point_union,
    film_step,
    gradient_projection,
    radial_projection,
)


def _best_ms(fn, repeat: int) -> float:
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return 1e3 * best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000])
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()

    rng = np.random.default_rng(0)
    th = np.radians(57.0)
    fa = np.array([np.sin(th), 0.0, -np.cos(th)])
    Qf = np.column_stack([fa, np.cross([0, 1.0, 0], fa), [0, 1.0, 0]])
    shapes = {
        "forearm (0.20,0.06,0.06)": (np.zeros(3), Qf, np.array([0.20, 0.06, 0.06])),
        "1:20 (0.20,0.01,0.05)": (np.zeros(3), Qf, np.array([0.20, 0.01, 0.05])),
    }
    upper = (
        np.array([0, 0, 0.13]),
        np.column_stack([[0, 0, 1.0], [1.0, 0, 0], [0, 1.0, 0]]),
        np.array([0.15, 0.06, 0.06]),
    )
    arm = [upper, (0.18 * fa, Qf, np.array([0.20, 0.06, 0.06]))]

    print(f"numpy {np.__version__}; best of {args.repeat}; times in ms")
    print(f"{'case':44s} {'N':>8s} {'ms':>9s} {'Mpts/s':>8s}")
    for n in args.sizes:
        u = rng.normal(size=(n, 3))
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        frac = rng.uniform(0.0, 2.0, (n, 1))
        for name, (c, Q, r) in shapes.items():
            x = c + (u * r * frac) @ Q.T
            cases = {
                f"exact     {name}": lambda x=x, c=c, Q=Q, r=r: closest_point_ellipsoid(x, c, Q, r),
                f"radial    {name}": lambda x=x, c=c, Q=Q, r=r: radial_projection(x, c, Q, r),
                f"gradient  {name}": lambda x=x, c=c, Q=Q, r=r: gradient_projection(x, c, Q, r),
            }
            for label, fn in cases.items():
                ms = _best_ms(fn, args.repeat)
                print(f"{label:44s} {n:8d} {ms:9.2f} {n / ms / 1e3:8.2f}")
        x = rng.normal(scale=0.08, size=(n, 3))
        ms = _best_ms(lambda x=x: closest_point_union(x, arm), args.repeat)
        print(f"{'union of 2 (arm at 57 deg)':44s} {n:8d} {ms:9.2f} {n / ms / 1e3:8.2f}")
        v = np.zeros_like(x)
        ms = _best_ms(lambda x=x, v=v: film_step(x, v, 1e-4, 1e-4, arm, mu=0.3), args.repeat)
        print(f"{'film_step, union of 2, mu=0.3':44s} {n:8d} {ms:9.2f} {n / ms / 1e3:8.2f}")


if __name__ == "__main__":
    main()
