"""Static sag of the arm-sleeve tube under gravity: particle model against the shell.

The sleeve of demos/scenes/arm_sleeve.toml (R = 0.06 m, L = 0.5 m, crimped cotton, t = 1 mm)
without the arm, held at the shoulder ring, hangs under gravity. The shell is clamped at the
shoulder (ShellModel + clothfem.static.solve_static); the particle model has its shoulder
nodes pinned (a ring of pins also stops the tube's rotation as a beam) and is brought to
equilibrium by :func:`clothfem.particle.solve_static`. Both use the same mesh and material.

    .venv/bin/python -m clothfem.particle.sleeve --mesh 8x10 16x20 [--shell]

prints one table row per mesh and model (docs/results/particle.md); ``--settle T`` instead
runs damped explicit dynamics of the particle sleeve to T s and prints the cuff's sag.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass, replace

import numpy as np
from mpi4py import MPI

__all__ = ["SagResult", "particle_sag", "particle_settle", "shell_sag"]

RADIUS, LENGTH, THICKNESS = 0.06, 0.5, 1e-3
MATERIALS = {  # clothfem.scene presets
    "crimped-cotton": dict(E1=1.2e6, E2=1.2e6, G12=1.0e5, rho=436.0),
    "decrimped-cotton": dict(E1=350e6, E2=350e6, G12=350e6 / 200, rho=436.0),
}


@dataclass(frozen=True)
class SagResult:
    """Vertical displacements [m] at the cuff (x = L): mean over the cuff ring, its top
    (z = +R) and bottom (z = -R) nodes; the cuff's change of vertical diameter [m]
    (ovalisation); nodes; wall time [s]; the largest out-of-balance nodal force of the
    particle solution over the largest nodal weight (NaN for the shell, converged by SNES).
    :meth:`row` prints the displacements in micrometres."""

    model: str
    mesh: str
    mean: float
    top: float
    bottom: float
    ovalisation: float
    nodes: int
    seconds: float
    imbalance: float = float("nan")

    def row(self) -> str:
        um = [f"{1e6 * v:.1f}" for v in (self.mean, self.top, self.bottom, self.ovalisation)]
        tail = f"{self.seconds:.1f} | {self.imbalance:.1e}"
        return f"| {self.model} | {self.mesh} | {self.nodes} | {' | '.join(um)} | {tail} |"


def _material(name: str):
    from clothfem.shell import FabricMaterial

    if name not in MATERIALS:
        raise ValueError(f"material must be one of {sorted(MATERIALS)}, got {name!r}")
    return FabricMaterial(**MATERIALS[name])


def _surface(n_around: int, n_along: int):
    from clothfem.mesh import cylinder

    return cylinder(
        MPI.COMM_WORLD, radius=RADIUS, length=LENGTH, n_around=n_around, n_along=n_along
    )


def _cuff(x0: np.ndarray, uz: np.ndarray, name: str, mesh: str, nodes: int, sec: float):
    cuff = np.flatnonzero(np.abs(x0[:, 0] - LENGTH) < 1e-9)
    top = cuff[np.argmax(x0[cuff, 2])]
    bot = cuff[np.argmin(x0[cuff, 2])]
    return SagResult(
        name, mesh, float(uz[cuff].mean()), float(uz[top]), float(uz[bot]),
        float(uz[top] - uz[bot]), nodes, sec,
    )  # fmt: skip


def _classes(net) -> np.ndarray:
    """Spring class: 3 x kind + (0 along the axis, 1 around, 2 oblique)."""
    d = net.x0[net.pairs[:, 1]] - net.x0[net.pairs[:, 0]]
    c = np.abs(d[:, 0]) / np.linalg.norm(d, axis=1)
    orient = np.where(c > 0.9, 0, np.where(c < 0.1, 1, 2))
    return 3 * net.kind + orient


def _fabric(n_around: int, n_along: int, material: str, bending: str):
    from clothfem import particle as pm

    net = pm.network_from_mesh(_surface(n_around, n_along))
    rule = pm.SpringRule(bending=bending)
    mat = _material(material)
    return net, pm.fabric_from_material(net, material=mat, thickness=THICKNESS, rule=rule)


def _transfer(fab, net, src) -> object:
    """``fab`` with each spring class's stiffness replaced by the median of that class on
    the network and fabric ``src`` (springs kept from another mesh, masses by area)."""
    snet, sfab = src
    k = fab.stiffness.copy()
    cls, scls = _classes(net), _classes(snet)
    for c in np.unique(cls):
        k[cls == c] = np.median(sfab.stiffness[scls == c])
    return replace(fab, stiffness=k)


def particle_sag(
    *,
    n_around: int,
    n_along: int,
    material: str,
    bending: str = "provot",
    constants_from: tuple[int, int] | None = None,
    load: float = 1.0,
) -> SagResult:
    """Static sag of the particle sleeve (every rank computes the whole network).
    ``constants_from``: (n_around, n_along) of a mesh whose spring constants (median of each
    kind and orientation) are kept instead of the rule's values for this mesh; ``load``:
    fraction of gravity."""
    from clothfem import particle as pm

    t0 = time.perf_counter()
    net, fab = _fabric(n_around, n_along, material, bending)
    name = f"particle ({bending})"
    if constants_from is not None:
        fab = _transfer(fab, net, _fabric(*constants_from, material, bending))
        name = f"particle ({bending}, k of {constants_from[0]}x{constants_from[1]})"
    g = (0.0, 0.0, -9.81 * load)
    model = pm.ParticleModel(network=net, fabric=fab, fixed=net.nodes("shoulder"), gravity=g)
    state, _ = pm.solve_static(model)
    uz = state.x[:, 2] - net.x0[:, 2]
    res = _cuff(net.x0, uz, name, f"{n_around}x{n_along}", net.n_nodes, time.perf_counter() - t0)
    imbalance = np.abs(state.a * fab.mass[:, None]).max() / (fab.mass.max() * 9.81 * load)
    return replace(res, imbalance=float(imbalance))


def particle_settle(
    *,
    n_around: int,
    n_along: int,
    material: str,
    load: float = 1.0,
    t_end: float = 1.5,
    alpha: float = 30.0,
    every: float = 0.25,
) -> list[tuple[float, float, float]]:
    """Damped explicit dynamics of the particle sleeve from the round tube at rest
    (Provot springs, mass-proportional damping ``alpha`` [1/s], 0.9 x the stable step):
    ``(t [s], mean cuff sag [m], kinetic energy [J])`` every ``every`` s up to ``t_end``.
    Tells a stable static solution (the sag settles there) from an unstable one."""
    from clothfem import particle as pm

    net, fab = _fabric(n_around, n_along, material, "provot")
    model = pm.ParticleModel(
        network=net, fabric=fab, fixed=net.nodes("shoulder"), gravity=(0.0, 0.0, -9.81 * load),
        damping=pm.Damping(alpha=alpha),
    )  # fmt: skip
    dt = 0.9 * pm.stable_time_step(model)
    cuff = np.flatnonzero(np.abs(net.x0[:, 0] - LENGTH) < 1e-9)
    state, out = pm.ParticleState.at_rest(model), []
    while state.t < t_end - 1e-9:
        state, _ = pm.integrate(model, state, t_end=min(state.t + every, t_end), dt=dt)
        sag = float(np.mean(state.x[cuff, 2] - net.x0[cuff, 2]))
        out.append((state.t, sag, pm.energies(model, state).kinetic))
    return out


def shell_sag(*, n_around: int, n_along: int, material: str, load: float = 1.0) -> SagResult:
    """Static sag of the shell sleeve, clamped at the shoulder, at the load factor ``load``
    of gravity (collective)."""
    from clothfem.shell import ShellModel
    from clothfem.shell.conditions import Clamp, Gravity
    from clothfem.static import solve_static

    t0 = time.perf_counter()
    model = ShellModel(
        _surface(n_around, n_along), material=_material(material), thickness=THICKNESS,
        loads=[Gravity()], supports=[Clamp("shoulder")],
    )  # fmt: skip
    solve_static(model, targets=np.array([load]))
    comm = model.comm
    n = model.n_owned
    x0 = np.concatenate(comm.allgather(model.x_nodes[:n]))
    uz = np.concatenate(comm.allgather(model.u.x.array[: 3 * n].reshape(n, 3)[:, 2]))
    return _cuff(x0, uz, "shell", f"{n_around}x{n_along}", len(x0), time.perf_counter() - t0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh", nargs="+", default=["8x10", "16x20"], help="NAROUNDxNALONG")
    parser.add_argument("--shell", action="store_true", help="also solve the shell")
    parser.add_argument("--bending", nargs="+", default=["provot", "choi-ko"])
    parser.add_argument("--constants-from", default=None, help="NAROUNDxNALONG: keep its k")
    parser.add_argument("--settle", type=float, default=0.0, help="damped dynamics to T [s]")
    parser.add_argument("--load", type=float, default=1.0, help="fraction of gravity")
    parser.add_argument("--material", default="decrimped-cotton", choices=sorted(MATERIALS))
    args = parser.parse_args()
    rows = []
    for m in args.mesh:
        na, nl = (int(v) for v in m.split("x"))
        if args.settle > 0.0:
            hist = particle_settle(
                n_around=na, n_along=nl, material=args.material, load=args.load,
                t_end=args.settle,
            )  # fmt: skip
            for t, sag, ke in hist:
                _print(f"| {m} | {t:.2f} | {1e6 * sag:.1f} | {ke:.2e} |")
            continue
        for b in args.bending:
            src = args.constants_from
            src = None if src is None else tuple(int(v) for v in src.split("x"))
            rows.append(
                particle_sag(
                    n_around=na,
                    n_along=nl,
                    material=args.material,
                    bending=b,
                    constants_from=src,
                    load=args.load,
                )  # fmt: skip
            )
            _print(rows[-1].row())
        if args.shell:
            rows.append(shell_sag(n_around=na, n_along=nl, material=args.material, load=args.load))
            _print(rows[-1].row())


def _print(line: str) -> None:
    if MPI.COMM_WORLD.rank == 0:
        print(line, flush=True)


if __name__ == "__main__":
    main()
