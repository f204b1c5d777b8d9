"""The arm-sleeve scene with the particle fabric: the elbow torque of Eq. 28 on a mesh ladder.

The scene file (default ``demos/scenes/arm_sleeve.toml``) gives the sleeve mesh, the
material, the arm's ellipsoids and hinge, the contact's mu and the clock (``settle_time``,
then the forearm turns). The fabric is the particle model of :mod:`clothfem.particle` on the
shell mesh's nodes (structural, shear and flexion springs by :class:`SpringRule`, Provot
flexion by default; the nodes of the shoulder ring pinned), integrated explicitly
(velocity Verlet at ``safety`` x :func:`stable_time_step`) with the paper's forward-increment
Lagrange-multiplier contact against the same moving ellipsoids as the shell's explicit
runner. Gravity acts in full from t = 0 (the shell's runner ramps it over ``ramp_time``),
and no damping is added: the shell run is undamped too.

One row per ``output.interval`` (0.01 s): the Eq. 28 torque about the elbow J over the
nodes past the elbow plane (the scene's ``aj = "beyond_joint"``), as the mean over the row's
steps of the per-step FILM forces (the shell runner's rule), its magnitude and component
about the hinge axis, and the contact nodes. Each mesh's rows go to
``OUT/particle_<mesh>.csv`` (readable by :func:`clothfem.report.read_history`), a table of
|tau| at 5 / 10 / 15 / 20 deg to standard output.

    .venv/bin/python -m clothfem.particle.arm --mesh 8x10 16x20 24x30 --angle 20 --out DIR
    .venv/bin/python -m clothfem.particle.arm --mesh 16x20 24x30 --constants-from 8x10 ...

``--constants-from NAxNL`` keeps the spring constants of that mesh (median of each spring
class) instead of the rule's values for each mesh: the paper's "fish-net" question, whether
springs tuned on one mesh hold on another.
"""

from __future__ import annotations

import argparse
import csv
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mpi4py import MPI

from clothfem.scene import SceneError
from clothfem.spec import Scene

__all__ = ["ArmRun", "run_arm"]

ANGLES = (5.0, 10.0, 15.0, 20.0)


@dataclass(frozen=True)
class ArmRun:
    """Rows of one particle arm run (angle [deg], |tau| [N m], tau . axis [N m], contact
    nodes, time [s]) and its cost (steps, step [s], wall [s])."""

    mesh: str
    angle: np.ndarray
    torque_mag: np.ndarray
    torque_flex: np.ndarray
    active: np.ndarray
    time: np.ndarray
    steps: int
    dt: float
    seconds: float


def _scene(path: str, mesh: tuple[int, int], angle: float | None, mu: float | None) -> Scene:
    from clothfem import scene as scenes

    sets = [f"mesh.n_around={mesh[0]}", f"mesh.n_along={mesh[1]}", "output.png=false"]
    if angle is not None:
        sets.append(f"body.1.angle_max={angle:g}")
    if mu is not None:
        sets.append(f"contact.mu={mu:g}")
    return scenes.load(path, sets)


def _model(scene: Scene, fabric_from: tuple[int, int] | None, bending: str, scene_path: str):
    """The particle model of a validated arm-sleeve scene (and its network)."""
    from clothfem import particle as pm
    from clothfem.contact.film import FilmParameters
    from clothfem.run import build_material, build_mesh
    from clothfem.scene_body import body_motions, body_poses

    from .sleeve import _transfer

    mat = scene.material
    rule = pm.SpringRule(bending=bending, warp=tuple(mat.warp))

    def fabric_of(sc: Scene):
        net = pm.network_from_mesh(build_mesh(sc, MPI.COMM_SELF))
        fab = pm.fabric_from_material(
            net, material=build_material(mat), thickness=mat.thickness, rule=rule
        )
        return net, fab

    net, fab = fabric_of(scene)
    if fabric_from is not None:  # the spring constants of another mesh, class by class
        fab = _transfer(fab, net, fabric_of(_scene(scene_path, fabric_from, None, None)))
    (g,) = [ld.acceleration for ld in scene.loads if ld.type == "gravity"]
    bodies_at = body_poses(scene, body_motions(scene))
    params = FilmParameters(mu=scene.contact.mu, kernel=scene.contact.kernel)
    model = pm.ParticleModel(
        network=net,
        fabric=fab,
        fixed=net.nodes(scene.supports[0].where),
        gravity=tuple(g),
        bodies=bodies_at,
        contact=params,
    )
    return model, net


def run_arm(
    *,
    scene_path: str,
    mesh: tuple[int, int],
    angle: float | None = None,
    mu: float | None = None,
    bending: str = "provot",
    constants_from: tuple[int, int] | None = None,
    safety: float = 0.9,
    on_row: Callable[[tuple[float, float, float, float, int]], None] | None = None,
) -> ArmRun:
    """One explicit particle run of the arm-sleeve scene on ``mesh`` (module docstring).
    ``on_row(row)`` is called with every row (time [s], angle [deg], |tau| [N m],
    tau . axis [N m], contact nodes) as it is made."""
    from clothfem import particle as pm
    from clothfem.contact.forces import joint_torque
    from clothfem.scene_body import body_motions, run_plan

    t0 = time.perf_counter()
    scene = _scene(scene_path, mesh, angle, mu)
    model, net = _model(scene, constants_from, bending, scene_path)
    plan = run_plan(scene, body_motions(scene))
    aj = np.asarray(plan.aj(net.x0.T), dtype=bool)
    dt = safety * pm.stable_time_step(model)
    interval = scene.output.interval
    state = pm.ParticleState.at_rest(model)
    rows: list[tuple[float, float, float, float, int]] = []
    acc, k, row_end = np.zeros(3), 0, interval
    steps = 0
    while state.t < plan.t_end - 1e-12:
        state, info = pm.step_explicit(model, state, min(dt, plan.t_end - state.t))
        steps += 1
        on = aj & np.any(info.node_force != 0.0, axis=1)
        if on.any():
            acc += joint_torque(state.x[on], -info.node_force[on], plan.J)
        k += 1
        if state.t >= row_end - 1e-12 or state.t >= plan.t_end - 1e-12:
            tau = acc / k
            row = (
                state.t,
                plan.angle_at(state.t),
                float(np.linalg.norm(tau)),
                float(tau @ plan.hinge_axis),
                info.active,
            )
            rows.append(row)
            if on_row is not None:
                on_row(row)
            acc, k, row_end = np.zeros(3), 0, row_end + interval
        if not np.all(np.isfinite(state.x)):
            raise FloatingPointError(f"particle arm run blew up at t = {state.t:.6g} s")
    r = np.array(rows)
    name = f"{mesh[0]}x{mesh[1]}"
    return ArmRun(
        name, r[:, 1], r[:, 2], r[:, 3], r[:, 4].astype(int), r[:, 0], steps, dt,
        time.perf_counter() - t0,
    )  # fmt: skip


class _RowFile:
    """The CSV of one mesh's rows, written and flushed as they come (a run that stops keeps
    the rows made so far; nothing on ranks other than 0)."""

    def __init__(self, path: Path, t_settle: float) -> None:
        self.t_settle = t_settle
        self.fh = path.open("w", newline="") if MPI.COMM_WORLD.rank == 0 else None
        if self.fh is not None:
            self.writer = csv.writer(self.fh)
            self.writer.writerow(
                ["stage", "time", "angle_deg", "torque_mag", "torque_flex", "n_active"]
            )

    def __call__(self, row: tuple[float, float, float, float, int]) -> None:
        if self.fh is not None:
            stage = "settle" if row[0] <= self.t_settle + 1e-12 else "motion"
            self.writer.writerow([stage, *row])
            self.fh.flush()

    def close(self) -> None:
        if self.fh is not None:
            self.fh.close()


def _mesh_arg(text: str) -> tuple[int, int]:
    """``NAROUNDxNALONG`` as two positive integers (argparse type)."""
    parts = text.split("x")
    if len(parts) != 2 or not all(p.isdigit() and int(p) > 0 for p in parts):
        raise argparse.ArgumentTypeError(f"must be NAROUNDxNALONG, e.g. 16x20, got {text!r}")
    return int(parts[0]), int(parts[1])


def main() -> None:
    from clothfem.report import torque_at

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="demos/scenes/arm_sleeve.toml")
    parser.add_argument(
        "--mesh", nargs="+", type=_mesh_arg, default=[(8, 10), (16, 20)], help="NAROUNDxNALONG"
    )
    parser.add_argument("--angle", type=float, default=20.0, help="flexion [deg]")
    parser.add_argument("--mu", type=float, default=None, help="contact mu (scene's if unset)")
    parser.add_argument("--bending", default="provot", choices=("provot", "choi-ko"))
    parser.add_argument(
        "--constants-from", type=_mesh_arg, default=None, help="NAROUNDxNALONG: keep its k"
    )
    parser.add_argument("--out", default="results/particle-arm")
    args = parser.parse_args()
    out = Path(args.out)
    try:
        settles = [_scene(args.scene, m, args.angle, args.mu).solver.settle_time for m in args.mesh]
    except SceneError as exc:  # before anything is written
        _print(f"clothfem.particle.arm: {exc}")
        raise SystemExit(2) from None
    if MPI.COMM_WORLD.rank == 0:
        out.mkdir(parents=True, exist_ok=True)
    head = " | ".join(f"{a:g} deg" for a in ANGLES)
    _print(f"| mesh | constants | steps | dt [s] | s | \\|tau\\| at {head} [N m] |")
    src = args.constants_from
    const = "rule" if src is None else f"{src[0]}x{src[1]}"
    for mesh, settle in zip(args.mesh, settles, strict=True):
        name = f"{mesh[0]}x{mesh[1]}"
        rows = _RowFile(out / f"particle_{name}.csv", settle)
        try:
            run = run_arm(
                scene_path=args.scene, mesh=mesh, angle=args.angle, mu=args.mu,
                bending=args.bending, constants_from=args.constants_from, on_row=rows,
            )  # fmt: skip
        finally:
            rows.close()
        motion = run.time > settle
        taus = [torque_at(run.angle[motion], run.torque_mag[motion], a) for a in ANGLES]
        cells = " | ".join("-" if t is None else f"{t:.4f}" for t in taus)
        _print(f"| {name} | {const} | {run.steps} | {run.dt:.3e} | {run.seconds:.0f} | {cells} |")


def _print(line: str) -> None:
    if MPI.COMM_WORLD.rank == 0:
        print(line, flush=True)


if __name__ == "__main__":
    main()
