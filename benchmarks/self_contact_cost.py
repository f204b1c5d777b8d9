"""Cost of the explicit self-contact correction on the sleeve (docs/results/self_contact.md).

For each sleeve mesh (cylinder radius 0.06 m, length 0.5 m) two configurations: straight,
and elbow-like (the tube flattened over 0.16 m about x = 0.3 until the walls are 1.02 d
apart, then bent by 120 degrees about the y axis through that region, the walls pressed
together by the predictor at 0.05 m/s). Times (median of ``--repeat``):

* broad phase: the candidate list (``build_candidates``: a uniform grid with the exclusion
  and distances in compiled loops) and by brute force (all node-centroid distances in
  blocks, then the exact distances), at the folded configuration, and whether both give
  the same node-triangle pairs;
* one correction with the candidate list reused (the steady step: 5 warm-up steps from the
  configuration, then a list built at that state) and with a rebuild;
* the life of a candidate list while the part past the elbow turns rigidly at 57 deg/s
  (steps of 1.1e-4 s, the arm scene's explicit step on 24x30), and the cost per step with
  the rebuilds spread over that life.

Run: ``.venv/bin/python benchmarks/self_contact_cost.py [--meshes 16x20 24x30 32x40]``.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
from mpi4py import MPI

from clothfem import mesh as meshes
from clothfem.contact.intersections import check_surface
from clothfem.contact.self_contact import (
    SelfContactParameters,
    build_candidates,
    closest_point_triangle,
    fabric_surface,
    mesh_nodes,
    near_pairs,
    self_contact_step,
)

D, RADIUS, LENGTH, XJ = 1e-3, 0.06, 0.5, 0.3
DT, SPEED, MASS = 1.1e-4, 0.05, 1e-4  # step [s], pressing speed [m/s], nodal mass [kg]
WARMUP = 5  # steps before the timed one


def elbow(X: np.ndarray, *, angle_deg: float = 120.0, half: float = 0.08) -> np.ndarray:
    """The sleeve flattened about x = XJ (walls 1.02 D apart at the centre) and bent."""
    s = X[:, 0] - XJ
    f = np.exp(-0.5 * (s / (0.5 * half)) ** 2)
    z = X[:, 2] * (1 - (1 - 0.51 * D / RADIUS) * f)
    y = X[:, 1]
    theta = np.deg2rad(angle_deg)
    rho = 2 * half / theta
    psi = np.clip(s, -half, half) / rho
    rest = s - np.clip(s, -half, half)
    # bend the axis in the x-y plane (across the flattened walls' normal z)
    xb = XJ + (rho - y) * np.sin(psi) + rest * np.cos(psi)
    yb = rho - (rho - y) * np.cos(psi) + rest * np.sin(psi)
    return np.column_stack([xb, yb, z])


def brute_force_candidates(x, surf, reach):
    """The node-triangle pairs of build_candidates by blocks of all node-centroid distances,
    the neighbour exclusion and the exact distances: nodes and triangles, sorted."""
    tri = surf.triangles
    xt = x[tri]
    cen = xt.mean(axis=1)
    rad = float(np.max(np.linalg.norm(xt - cen[:, None], axis=2)))
    rows, cols = [], []
    for i in range(0, len(x), 512):
        d2 = ((x[i : i + 512, None, :] - cen[None, :, :]) ** 2).sum(-1)
        r, c = np.nonzero(d2 <= (reach + rad) ** 2)
        rows.append(r + i)
        cols.append(c)
    node, t = np.concatenate(rows), np.concatenate(cols)
    far = ~np.any([near_pairs(surf, node, tri[t, k]) for k in range(3)], axis=0)
    node, t = node[far], t[far]
    q, _ = closest_point_triangle(x[node], *(x[tri[t, k]] for k in range(3)))
    close = np.linalg.norm(x[node] - q, axis=1) < reach
    order = np.lexsort((t[close], node[close]))
    return node[close][order], t[close][order]


def list_life(x0: np.ndarray, c, *, omega: float = np.deg2rad(57.0), limit: int = 5000) -> int:
    """Steps of DT the candidate list stays valid while the part past the elbow (x > XJ at
    the build) turns rigidly about the y axis through (XJ, 0, 0) at ``omega`` [rad/s] (the
    arm scene's forearm speed)."""
    fore = x0[:, 0] > XJ
    for k in range(1, limit + 1):
        a = omega * DT * k
        rot = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
        x = x0.copy()
        x[fore] = (x0[fore] - [XJ, 0, 0]) @ rot.T + [XJ, 0, 0]
        if not c.valid(x):
            return k - 1
    return limit


def timed(fn, repeat: int) -> tuple[float, object]:
    """Median CPU time [s] of ``repeat`` calls (process time: the machine is shared, wall
    time includes waiting for a core) and the last result."""
    times, out = [], None
    for _ in range(repeat):
        t0 = time.process_time()
        out = fn()
        times.append(time.process_time() - t0)
    return statistics.median(times), out


def case(na: int, nl: int, repeat: int, edges: bool, skin: float | None) -> dict:
    sm = meshes.cylinder(MPI.COMM_SELF, radius=RADIUS, length=LENGTH, n_around=na, n_along=nl)
    X, cells = mesh_nodes(sm.mesh)
    surf = fabric_surface(cells, n_nodes=len(X))
    p = SelfContactParameters(distance=D, mu=0.3, edge_proximity=edges, skin=skin)
    m = np.full(len(X), MASS)
    reach, skin = p.distance + p.skin_length, p.skin_length
    row = {"mesh": f"{na}x{nl}", "nodes": len(X), "triangles": len(surf.triangles)}
    for name, x0 in (("straight", X), ("elbow", elbow(X))):
        v = np.zeros_like(x0)
        flat = np.abs(x0[:, 2]) < 2 * D
        v[flat, 2] = -SPEED * np.sign(x0[flat, 2])
        t_tree, c = timed(
            lambda x0=x0: build_candidates(x0, surf, distance=D, skin=skin, edges=edges), repeat
        )
        t_bf, bf = timed(lambda x0=x0, r=reach: brute_force_candidates(x0, surf, r), repeat)
        same = np.array_equal(bf[0], c.pt_node) and np.array_equal(bf[1], c.pt_tri)
        for _ in range(WARMUP):  # to the steady state: the walls pressed, the list settled
            r = self_contact_step(x0, x0 + DT * v, v, m, DT, surf, params=p, candidates=c)
            x0, c = r.x, r.candidates
        c = build_candidates(x0, surf, distance=D, skin=skin, edges=edges)  # at the state timed
        xs = x0 + DT * v
        t_step, r = timed(
            lambda x0=x0, xs=xs, v=v, c=c: self_contact_step(
                x0, xs, v, m, DT, surf, params=p, candidates=c
            ),
            repeat,
        )
        t_rebuild, _ = timed(
            lambda x0=x0, xs=xs, v=v: self_contact_step(x0, xs, v, m, DT, surf, params=p), repeat
        )
        life = list_life(x0, build_candidates(x0, surf, distance=D, skin=skin, edges=edges))
        chk = check_surface(r.x, surf.triangles, radius=4 * D)
        row[name] = {
            "tree_ms": 1e3 * t_tree,
            "same": same,
            "brute_ms": 1e3 * t_bf,
            "step_ms": 1e3 * t_step,
            "rebuild_step_ms": 1e3 * t_rebuild,
            "listed": len(c.pt_node) + len(c.ee),
            "life": life,
            "amortised_ms": 1e3 * (t_step + t_rebuild / max(life, 1)),
            "contacts": len(r.jn),
            "intersections": chk.intersections,
            "min_distance_mm": 1e3 * chk.min_distance,
        }
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--meshes", nargs="+", default=["16x20", "24x30", "32x40"])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--skin", type=float, default=None, help="list skin [m] (default d / 2)")
    ap.add_argument("--no-edge-proximity", action="store_true", help="node-triangle pairs only")
    args = ap.parse_args()
    print(
        "| mesh | nodes | config | listed pairs | contacts | list build ms | brute force ms "
        "| same pairs "
        "| step ms (list kept) | step ms (rebuilt) | list life (steps) | ms per step "
        "| intersections | min distance mm |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for spec in args.meshes:
        na, nl = (int(k) for k in spec.split("x"))
        row = case(na, nl, args.repeat, not args.no_edge_proximity, args.skin)
        for name in ("straight", "elbow"):
            r = row[name]
            print(
                f"| {row['mesh']} | {row['nodes']} | {name} | {r['listed']} | {r['contacts']} "
                f"| {r['tree_ms']:.2f} | {r['brute_ms']:.1f} | {'yes' if r['same'] else 'NO'} "
                f"| {r['step_ms']:.2f} "
                f"| {r['rebuild_step_ms']:.2f} | {r['life']} | {r['amortised_ms']:.2f} "
                f"| {r['intersections']} "
                f"| {r['min_distance_mm']:.3f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
