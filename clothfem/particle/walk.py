"""The pants walk with the particle fabric: the knee torque of Eq. 28 about the moving knee.

The scene file (default ``demos/scenes/pants_walk.toml``) gives the pants mesh, the
material, the recorded lower body, the contact's mu, the Eq. 28 measure (torque segment,
node set, flexion frame) and the clock; ``--donned`` is the ``donned.npz`` of
:mod:`clothfem.particle.donning` the fabric starts from (nodes matched by their pattern
positions, as the shell's ``[initial] positions``). The fabric is the particle model of
:mod:`clothfem.particle` on the mesh's nodes with the donning's isotropic Provot constants
(:func:`clothfem.particle.donning.simple_fabric`, E = sqrt(E1 E2), G = G12: the pants'
skewed crotch squares defeat :class:`SpringRule`; no supports: the belt-tight waist rests
on the pelvis), integrated
explicitly (velocity Verlet at ``safety`` x :func:`stable_time_step`) with the paper's
forward-increment Lagrange-multiplier contact against the same moving ellipsoids as the
shell's explicit runner. Gravity acts in full from t = 0; mass damping ``solver.
settle_damping`` acts during the settling only, as in the shell's runner.

One row per ``output.interval``: the torque about the moving knee J(t) over the scene's
node set (:class:`clothfem.torque_measure.TorqueMeasure`), the mean over the row's steps
of the per-step FILM forces (the shell runner's rule), its magnitude and flexion component,
and the contact nodes, to ``OUT/history.csv`` (readable by :func:`clothfem.report.
read_history`; ``clothfem plot --x time``), flushed as it is made; the gait events to
``OUT/events.csv``.

    .venv/bin/python -m clothfem.particle.walk --donned results/pants-donned/donned.npz \\
        --out results/pants-walk-particle [--set key=value ...]
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

from clothfem.spec import Scene

__all__ = ["main"]

COLUMNS = ["stage", "time", "angle_deg", "torque_mag", "torque_flex", "n_active", "elapsed"]


def _model(scene: Scene, motions: list):
    """The particle model of a validated walk scene, and its network."""
    from mpi4py import MPI

    from clothfem import particle as pm
    from clothfem.contact.film import FilmParameters
    from clothfem.run import build_mesh
    from clothfem.scene_body import body_poses

    from .donning import simple_fabric

    mat = scene.material
    net = pm.network_from_mesh(build_mesh(scene, MPI.COMM_SELF))
    fab = simple_fabric(
        network=net,
        E=float(np.sqrt(mat.E1 * mat.E2)),
        G=mat.G12,
        rho=mat.rho,
        thickness=mat.thickness,
    )
    (g,) = [ld.acceleration for ld in scene.loads if ld.type == "gravity"]
    model = pm.ParticleModel(
        network=net,
        fabric=fab,
        gravity=tuple(g),
        damping=pm.Damping(alpha=scene.solver.settle_damping),
        bodies=body_poses(scene, motions),
        contact=FilmParameters(mu=scene.contact.mu, kernel=scene.contact.kernel),
    )
    return model, net


def _start(scene: Scene, net, model):
    """The state at the donned positions, at rest."""
    from clothfem import particle as pm
    from clothfem.initial_state import displacement_at_nodes, read_positions

    X, x = read_positions(Path(scene.initial.positions))
    u = displacement_at_nodes(nodes=net.x0, X=X, x=x)
    rest = pm.ParticleState.at_rest(model)
    return dataclasses.replace(rest, x=net.x0 + u)


def walk(scene: Scene, out: Path, *, safety: float = 0.9) -> dict:
    """Run the walk of a validated scene, writing the rows to ``out`` (module docstring);
    returns the cost (steps, dt [s], seconds)."""
    from clothfem import particle as pm
    from clothfem.scene_body import body_motions, recorded_events, run_plan

    t0 = time.perf_counter()
    motions = body_motions(scene)
    model, net = _model(scene, motions)
    plan = run_plan(scene, motions)
    measure = plan.measure
    fixed = measure.fixed_mask(net.x0)  # a hinge's beyond_joint set (else None)
    state = _start(scene, net, model)
    undamped = dataclasses.replace(model, damping=pm.Damping())
    dt = safety * pm.stable_time_step(model)
    interval, t_settle = scene.output.interval, plan.t_settle
    with (out / "events.csv").open("w", newline="") as fh:
        csv.writer(fh).writerows([("time_s", "context", "label"), *recorded_events(scene)])
    steps, acc, k, row_end = 0, np.zeros(4), 0, interval
    with (out / "history.csv").open("w", newline="") as fh:
        rows = csv.writer(fh)
        rows.writerow(COLUMNS)
        while state.t < plan.t_end - 1e-12:
            m = model if state.t + dt <= t_settle + 1e-12 else undamped
            state, info = pm.step_explicit(m, state, min(dt, plan.t_end - state.t))
            steps += 1
            tau, flex = measure.local(
                t=state.t, x=state.x, force_on_body=-info.node_force, body=info.node_body,
                fixed=fixed,
            )  # fmt: skip
            acc += np.append(tau, flex)
            k += 1
            if not np.all(np.isfinite(state.x)):
                raise FloatingPointError(f"particle walk blew up at t = {state.t:.6g} s")
            if state.t >= row_end - 1e-12 or state.t >= plan.t_end - 1e-12:
                mean = acc / k
                stage = "settle" if state.t <= t_settle + 1e-12 else "motion"
                rows.writerow([stage, state.t, 0.0, float(np.linalg.norm(mean[:3])), mean[3],
                               info.active, time.perf_counter() - t0])  # fmt: skip
                fh.flush()
                acc, k, row_end = np.zeros(4), 0, row_end + interval
    return {"steps": steps, "dt": dt, "seconds": time.perf_counter() - t0}


def main(argv: list[str] | None = None) -> int:
    """Command line (module docstring); exit 2 on bad arguments, before anything is written."""
    from clothfem import scene as scenes

    parser = argparse.ArgumentParser(
        prog="clothfem.particle.walk", description=__doc__.splitlines()[0]
    )
    parser.add_argument("--scene", default="demos/scenes/pants_walk.toml")
    parser.add_argument("--donned", required=True, help="donned.npz of clothfem.particle.donning")
    parser.add_argument("--out", required=True, help="output folder (must be new or empty)")
    parser.add_argument("--overwrite", action="store_true", help="write into a non-empty --out")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    args = parser.parse_args(argv)
    out = Path(args.out)
    try:
        sets = [*args.set, "initial.don=false", f"initial.positions='{args.donned}'"]
        scene = scenes.load(Path(args.scene), sets)
        if out.exists() and any(out.iterdir()) and not args.overwrite:
            raise scenes.SceneError(f"--out {out} is not empty (--overwrite to write into it)")
    except (scenes.SceneError, OSError) as exc:
        print(f"clothfem.particle.walk: {exc}", file=sys.stderr)
        return 2
    out.mkdir(parents=True, exist_ok=True)
    cost = walk(scene, out)
    print(
        f"{cost['steps']} steps (dt {cost['dt']:.3e} s), {cost['seconds']:.1f} s; "
        f"wrote {out / 'history.csv'}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
