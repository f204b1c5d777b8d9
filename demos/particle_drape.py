"""A square cotton sheet draped over a sphere with the particle (mass-spring) fabric model.

What this script does
---------------------
1. Builds a 0.3 m x 0.3 m sheet of 10 x 10 nine-node cells (the spring network of
   :mod:`clothfem.particle`, crimped cotton, t = 1 mm) 5 mm above a rigid sphere of radius
   0.08 m (a :class:`clothfem.body.Ellipsoid` with equal radii).
2. Drops it under gravity: velocity-Verlet steps at 0.9 x the stable step, forward-increment
   Lagrange-multiplier contact (FILM, clothfem.contact.explicit.film_step) with Coulomb
   friction mu = 0.3, mass-proportional and spring-axis damping, Provot's strain limit 10 %.
3. Prints the energies every 0.1 s, then the contact force on the sheet against its weight
   and the smallest gap; writes ``<out>/particle_drape.png`` (matplotlib, rank 0).

Run: ``.venv/bin/python demos/particle_drape.py --out results/particle`` (the particle model
is held redundantly on every rank: ``mpirun -n 2`` prints the same numbers).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from clothfem import particle as pm
from clothfem.body import Ellipsoid
from clothfem.contact.film import FilmParameters
from clothfem.particle.network import regular_patch
from clothfem.shell import FabricMaterial

RADIUS, SIDE = 0.08, 0.3


def build() -> pm.ParticleModel:
    origin = (-SIDE / 2, -SIDE / 2, RADIUS + 0.005)
    net = regular_patch(length=SIDE, width=SIDE, nx=10, ny=10, origin=origin)
    cotton = FabricMaterial(E1=1.2e6, E2=1.2e6, G12=1.0e5, rho=436.0)
    fab = pm.fabric_from_material(net, material=cotton, thickness=1e-3)
    sphere = Ellipsoid(centre=np.zeros(3), axes=np.eye(3), radii=np.full(3, RADIUS))
    return pm.ParticleModel(
        network=net, fabric=fab, bodies=pm.bodies([sphere]), contact=FilmParameters(mu=0.3),
        damping=pm.Damping(alpha=5.0, beta=1e-4), strain_limit=pm.StrainLimit(max_stretch=0.1),
    )  # fmt: skip


def picture(model: pm.ParticleModel, x: np.ndarray, t: float, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    g = model.network.grid
    quads = [g[:, i : i + 2, j : j + 2] for i in range(2) for j in range(2)]
    faces = np.concatenate([q.reshape(-1, 4)[:, [0, 2, 3, 1]] for q in quads])
    fig = plt.figure(figsize=(6, 5))
    ax = fig.add_subplot(projection="3d")
    z = x[faces, 2].mean(axis=1)
    poly = Poly3DCollection(x[faces], facecolors=plt.cm.viridis((z - z.min()) / np.ptp(z)))
    poly.set_edgecolor("k")
    poly.set_linewidth(0.2)
    ax.add_collection3d(poly)
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 30), np.linspace(0, np.pi, 15))
    r = 0.98 * RADIUS
    ax.plot_wireframe(
        r * np.cos(u) * np.sin(v), r * np.sin(u) * np.sin(v), r * np.cos(v), color="0.6", lw=0.3
    )
    ax.set(xlim=(-0.16, 0.16), ylim=(-0.16, 0.16), zlim=(-0.16, 0.16), box_aspect=(1, 1, 1))
    ax.set_title(f"particle cotton sheet on a sphere, t = {t:.2f} s")
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="results/particle")
    ap.add_argument("--t-end", type=float, default=1.5, help="simulated time [s] (> 0.2)")
    args = ap.parse_args()
    root = MPI.COMM_WORLD.rank == 0
    model = build()
    dt = 0.9 * pm.stable_time_step(model)
    state = pm.ParticleState.at_rest(model)
    weight = model.mass.sum() * 9.81
    t0, every = time.perf_counter(), round(0.1 / dt)
    state, records = pm.integrate(model, state, t_end=args.t_end - 0.1, dt=dt, every=every)
    forces, gaps = [], []  # the last 0.1 s: mean contact force, smallest gap
    for _ in range(every):
        state, info = pm.step_explicit(model, state, dt)
        forces.append(info.contact_force)
        gaps.append(info.min_gap)
    if not root:
        return
    for t, e, info in records:
        print(
            f"t {t:5.2f} s  kinetic {e.kinetic:.3e} J  spring {e.spring:.3e} J  "
            f"gravity {e.gravity:+.3e} J  contact nodes {info.active:3d}  "
            f"F_z/W {info.contact_force[2] / weight:.3f}"
        )
    steps = len(records) * every + every
    print(f"about {steps} steps of {dt:.3e} s in {time.perf_counter() - t0:.1f} s")
    fz = float(np.mean(forces, axis=0)[2])
    print(f"contact force on the sheet over the last 0.1 s F_z = {fz:.5f} N, W = {weight:.5f} N")
    print(f"smallest gap after the correction over the last 0.1 s {min(gaps):.3e} m")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    picture(model, state.x, state.t, out / "particle_drape.png")
    print(f"wrote {out / 'particle_drape.png'}")


if __name__ == "__main__":
    main()
