"""What every runner writes besides the history rows: snapshots and their schedule, the
torque-angle plot, the animation, restart checkpoints, and the closing of a run on every
rank (a stop with the fields written, the barrier that aborts the MPI job when one rank
fails alone)."""

from __future__ import annotations

import csv
import fnmatch
import json
import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from dolfinx import fem
from mpi4py import MPI

from .contact.lagrange import ContactDivergence
from .io import ResultWriter, animate_series, snapshot_png
from .report import mark_events
from .scene import SceneError
from .scene_body import RunPlan
from .shell import ShellModel
from .spec import SECTIONS, Scene
from .static import SolverDivergence

__all__ = [
    "end_together",
    "load_checkpoint",
    "plot_torque_angle",
    "progress_snapshots",
    "resume_problem",
    "save_checkpoint",
    "scene_record",
    "stop_with_fields",
    "torque_columns",
    "write_animation",
    "write_snapshot",
]


def torque_columns(tau: np.ndarray, res: np.ndarray, flex: float) -> dict:
    """CSV columns of the Eq. 28 torque [N m], its component ``flex`` about the flexion axis
    [N m] and the resultant on the body [N]."""
    return {
        "torque_x": tau[0],
        "torque_y": tau[1],
        "torque_z": tau[2],
        "torque_mag": float(np.linalg.norm(tau)),
        "torque_flex": flex,
        "resultant_x": res[0],
        "resultant_y": res[1],
        "resultant_z": res[2],
    }


def ellipsoid_meshes(bodies, *, scale: float = 0.985) -> list:
    """pyvista surfaces of ellipsoids given as (centre, axes as columns, radii), drawn with
    the radii x ``scale``: contact holds the fabric's nodes on the surface and the flat facets
    of the drawn fabric between them would otherwise cut into the body."""
    import pyvista as pv

    meshes = []
    for c, Q, r in bodies:
        e = pv.ParametricEllipsoid(*(scale * np.asarray(r)), u_res=60, v_res=30, w_res=10)
        e.points = np.asarray(e.points) @ Q.T + c
        meshes.append(e)
    return meshes


def plot_torque_angle(
    csv_path: Path, png: Path, title: str, events: Sequence[tuple[float, str, str]] = ()
) -> None:
    """|tau| and the flexion component against the hinge angle, or against time (a recorded
    motion) with the gait ``events`` (time [s], context, label) marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [  # the settled state (full load) and the motion; not the partial-load rows
        r
        for r in csv.DictReader(csv_path.open())
        if r["stage"] == "motion" or float(r["load_factor"]) == 1.0
    ]
    if not rows:
        return
    a = [float(r["angle_deg"]) for r in rows]
    hinged = max(a) > min(a)  # else (no hinge: a recorded motion) against time
    x = a if hinged else [float(r["time"]) for r in rows]
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(
        x, [float(r["torque_mag"]) for r in rows], "o-", color="C0", ms=4, label="|tau| (Eq. 28)"
    )
    tf = [-float(r["torque_flex"]) for r in rows]
    if any(tf):
        label = "-tau . hinge axis" if hinged else "-tau . flexion axis"
        ax.plot(x, tf, "s--", color="C1", ms=4, mfc="none", label=label)
    if not hinged:
        mark_events(ax, events)
    ax.set_xlabel("flexion angle [deg]" if hinged else "time [s]")
    ax.set_ylabel("torque about the joint [N m]")
    ax.set_title(title)
    ax.grid(True)
    ax.legend()
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)


def write_animation(scene: Scene, out: Path, bodies_at: Callable[[float], list]) -> None:
    """``out/animation.gif`` from the field series (rank 0; scenes with PNG output)."""
    if not scene.output.png or not (out / "fabric.h5").exists():
        return
    animate_series(
        out / "fabric.h5",
        out / "animation.gif",
        bodies_at=lambda t: ellipsoid_meshes(bodies_at(t)),
        title=scene.scene.name,
        view="xz",
        max_frames=scene.output.frames,
    )


def stop_with_fields(
    check_stop: Callable[[str], None], where: str, writer: ResultWriter, t: float, fields
) -> None:
    """``check_stop(where)``; when it stops the run, the fields at ``t`` (``fields()``: the
    functions to write besides the displacement) are written first unless they were."""
    from .errors import RunStopped

    try:
        check_stop(where)
    except RunStopped:
        if writer.last_time < t:  # the same on every rank
            writer.write_fields(t, fields())
        raise


def end_together(comm: MPI.Comm) -> None:
    """The runners' ``finally``: wait for every rank before the closing writes, unless this
    rank is leaving with an error the other ranks do not share. The solver stops and the
    signal stop are decided on reduced values, so every rank raises them at the same point;
    any other error (a bug, an I/O error, Ctrl-C) may be this rank's alone, and the others
    would wait in their next collective call forever: under MPI it aborts the job instead
    (the history rows already written are kept)."""
    from .dynamics import DynamicsDivergence
    from .errors import RunStopped

    exc = sys.exc_info()[1]
    shared = (SolverDivergence, ContactDivergence, DynamicsDivergence, RunStopped, SceneError)
    if comm.size > 1 and exc is not None and not isinstance(exc, shared):
        sys.stderr.write(
            f"clothfem: rank {comm.rank} stopped alone ({type(exc).__name__}: {exc}); "
            "aborting the MPI job (rows written so far are kept)\n"
        )
        sys.stderr.flush()
        comm.Abort(1)
    comm.barrier()


def save_checkpoint(out: Path, comm: MPI.Comm, data: dict[str, Any]) -> None:
    """Write this rank's restart file atomically (``out/checkpoint/rank<r>-of-<n>.npz``)."""
    folder = out / "checkpoint"
    if comm.rank == 0:
        folder.mkdir(parents=True, exist_ok=True)
    comm.barrier()
    path = folder / f"rank{comm.rank}-of-{comm.size}.npz"
    tmp = path.with_suffix(".tmp")
    with open(tmp, "wb") as fh:
        np.savez(fh, **data)
    os.replace(tmp, path)  # a run killed while writing keeps the previous checkpoint
    comm.barrier()


#: The scene keys a resumed run may set otherwise than the interrupted one: where the run
#: ends, the smallest time step and what it writes. Any other difference would continue one
#: run's history with another's physics.
RESUME_MAY_CHANGE = (
    "scene.description", "solver.duration", "solver.dt_min", "body.*.angle_max",
    "output.every", "output.png", "output.frames", "output.checkpoint_every",
)  # fmt: skip
#: The checkpoint's entry holding :func:`scene_record` (JSON).
SCENE_RECORD = "scene_record"


def scene_record(scene: Scene) -> dict[str, Any]:
    """Every key of ``scene`` as ``section.key`` (``section.<i>.key`` for the i-th table of
    a list such as ``body``, as ``--set`` names them), values as JSON gives them back."""
    flat: dict[str, Any] = {}
    for name in SECTIONS:
        value = getattr(scene, name)
        tables = enumerate(value) if isinstance(value, tuple) else [(None, value)]
        for i, table in tables:
            head = name if i is None else f"{name}.{i}"
            for key, v in vars(table).items():
                flat[f"{head}.{key}"] = v
    return json.loads(json.dumps(flat, default=str))


def resume_problem(scene: Scene, out: Path, *, ranks: int) -> str | None:
    """Why ``scene`` may not resume the interrupted run in ``out`` (one line: the first key
    it sets otherwise, outside :data:`RESUME_MAY_CHANGE`), or None; None too when the
    checkpoint of ``ranks`` ranks is missing (:func:`load_checkpoint` says so) or holds no
    scene record."""
    path = out / "checkpoint" / f"rank0-of-{ranks}.npz"
    if not path.is_file():
        return None
    with np.load(path) as z:
        if SCENE_RECORD not in z.files:
            return None
        old = json.loads(str(z[SCENE_RECORD]))
    new = scene_record(scene)
    for key in [*new, *(k for k in old if k not in new)]:
        if new.get(key) == old.get(key) or _may_change(key):
            continue
        return (
            f"--resume: scene key '{key}' is {new.get(key)!r} here but {old.get(key)!r} in "
            f"the interrupted run in '{out}'; a resume may change only "
            f"{', '.join(RESUME_MAY_CHANGE)} (start a new run for another scene)"
        )
    return None


def _may_change(key: str) -> bool:
    return any(fnmatch.fnmatchcase(key, pat) for pat in RESUME_MAY_CHANGE)


def load_checkpoint(out: Path, comm: MPI.Comm) -> dict[str, np.ndarray]:
    path = out / "checkpoint" / f"rank{comm.rank}-of-{comm.size}.npz"
    ok = comm.allreduce(path.exists(), op=MPI.LAND)
    if not ok:
        raise SceneError(
            f"--resume: no checkpoint for {comm.size} rank(s) in {out / 'checkpoint'} "
            "(resume with the same number of ranks as the interrupted run)"
        )
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


def write_snapshot(
    scene: Scene,
    model: ShellModel,
    out: Path,
    comm: MPI.Comm,
    tag: str,
    bodies,
    *,
    pressure: fem.Function | None = None,
) -> None:
    """``out/snapshot_<tag>.png`` of the fabric, coloured by the contact ``pressure`` (else
    by |u|), with the ellipsoids ``bodies`` opaque (if PNGs)."""
    if scene.output.png:
        snapshot_png(
            model,
            out / f"snapshot_{tag}.png",
            title=f"{scene.scene.name} {tag}",
            extra_meshes=ellipsoid_meshes(bodies) if comm.rank == 0 and bodies else (),
            view="xz",
            pressure=pressure,
        )


def progress_snapshots(
    plan: RunPlan, taken: int, stage: str, angle: float, snap, *, t: float = 0.0
) -> int:
    """``snap("settled")`` when the motion starts, then ``snap(<angle>deg)`` at each quarter of
    the hinge motion (without a hinge: ``snap(t<time>s)`` at each quarter of the time after
    the settling); ``taken``: the snapshots taken so far (checkpointed); returns the new
    count."""
    if stage == "motion" and taken == 0:
        taken = 1
        snap("settled")
    if not plan.hinged:
        span = plan.t_end - plan.t_settle
        while 1 <= taken <= 3 and t >= plan.t_settle + span * taken / 4 - 1e-12:
            snap(f"t{plan.t_settle + span * taken / 4:.3f}s")
            taken += 1
        return taken
    quarters = plan.quarters()
    while taken <= 3 and angle >= quarters[taken - 1] - 1e-9:
        snap(f"{quarters[taken - 1]:04.1f}deg")
        taken += 1
    return taken
