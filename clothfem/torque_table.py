"""More Eq. 28 joint torques per run: the ``[[torques]]`` measures of a scene (e.g. the left
knee and both hips of the pants walk, besides the right knee of ``[contact]``).

Each entry is a :class:`clothfem.torque_measure.TorqueMeasure` built from the scene with the
entry's Eq. 28 keys in place of those of ``[contact]`` (:func:`clothfem.scene.torque_entry`),
evaluated on the same contact forces in every step. Rows go to ``torques.csv`` (one per
measure and history row: the means over the row's steps, as the history's torque), written
on rank 0 and flushed as they come; a resumed run first drops the rows after its checkpoint.
"""

from __future__ import annotations

import csv
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mpi4py import MPI
from numpy.typing import NDArray

from .scene import torque_entry
from .spec import Scene
from .torque_measure import TorqueMeasure, torque_measure

__all__ = ["COLUMNS", "FILE", "TorqueTable", "append", "keep_rows", "plot", "torque_stats"]

FILE = "torques.csv"
COLUMNS = (
    "increment",
    "time",
    "name",
    "torque_x",
    "torque_y",
    "torque_z",
    "torque_mag",
    "torque_flex",
)


@dataclass(frozen=True)
class _Entry:
    name: str
    measure: TorqueMeasure
    fixed: NDArray[np.bool_] | None  # the fixed AJ of a hinge beyond_joint (this rank's nodes)


class TorqueTable:
    """The ``[[torques]]`` measures of ``scene`` on this rank's nodes of reference positions
    ``X`` (N, 3) [m]; ``aj_mask(scene, J)`` gives a hinge's reference ``beyond_joint``
    selector and ``centre(scene)`` its fixed J (None for a recorded segment)."""

    def __init__(
        self,
        scene: Scene,
        motions: list,
        X: NDArray[np.float64],
        *,
        aj_mask: Callable,
        centre: Callable,
    ) -> None:
        self.entries: list[_Entry] = []
        for spec in scene.torques:
            s = torque_entry(scene, spec)
            J = centre(s)
            m = torque_measure(s, motions, reference_mask=aj_mask(s, J) if J is not None else None)
            self.entries.append(_Entry(spec.name, m, m.fixed_mask(X)))
        self.sums = np.zeros((len(self.entries), 4))  # tau (3) and flex, summed over steps

    def __len__(self) -> int:
        return len(self.entries)

    def add(self, *, t: float, x, force_on_body, body, nodes=None) -> None:
        """Add this step's torques of this rank's points (positions ``x`` [m], forces on the
        body [N], touching segment per point, -1 none; ``nodes``: their owned node indices,
        None: the points are the owned nodes) to the row's sums."""
        for k, e in enumerate(self.entries):
            fixed = e.fixed if e.fixed is None or nodes is None else e.fixed[nodes]
            tau, flex = e.measure.local(
                t=t, x=x, force_on_body=force_on_body, body=body, fixed=fixed
            )
            self.sums[k, :3] += tau
            self.sums[k, 3] += flex

    def rows(self, *, comm: MPI.Comm, steps: int, increment: int, time: float) -> list[dict]:
        """The row's means over ranks and ``steps`` (collective); resets the sums."""
        total = np.empty_like(self.sums)
        comm.Allreduce(self.sums, total, op=MPI.SUM)
        self.sums[:] = 0.0
        total /= max(steps, 1)
        return [
            {
                "increment": increment,
                "time": time,
                "name": e.name,
                "torque_x": tau[0],
                "torque_y": tau[1],
                "torque_z": tau[2],
                "torque_mag": float(np.linalg.norm(tau[:3])),
                "torque_flex": tau[3],
            }
            for e, tau in zip(self.entries, total, strict=True)
        ]


def append(out: Path, rows: list[dict], comm: MPI.Comm) -> None:
    """Append ``rows`` to ``out/torques.csv`` (rank 0; header first; flushed to disk)."""
    if comm.rank != 0 or not rows:
        return
    path = Path(out) / FILE
    new = not path.exists()
    with path.open("a", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=COLUMNS)
        if new:
            w.writeheader()
        w.writerows(rows)
        fh.flush()
        os.fsync(fh.fileno())


def keep_rows(out: Path, last: int, comm: MPI.Comm) -> None:
    """Drop the rows of ``out/torques.csv`` after history row ``last`` (a resumed run)."""
    path = Path(out) / FILE
    if comm.rank != 0 or not path.exists():
        return
    with path.open(newline="") as fh:
        kept = [r for r in csv.DictReader(fh) if int(r["increment"]) <= last]
    path.unlink()
    append(out, kept, comm)


def torque_stats(path: str | Path, *, t_from: float = 0.0) -> dict[str, dict[str, float]]:
    """Per measure of a ``torques.csv``: mean, smallest and largest ``torque_flex`` and the
    mean ``torque_mag`` [N m] over the rows after ``t_from`` [s] (e.g. the settling's end);
    empty without the file."""
    path = Path(path)
    if not path.exists():
        return {}
    with path.open(newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if float(r["time"]) > t_from]
    out: dict[str, dict[str, float]] = {}
    for name in dict.fromkeys(r["name"] for r in rows):
        flex = np.array([float(r["torque_flex"]) for r in rows if r["name"] == name])
        mag = np.array([float(r["torque_mag"]) for r in rows if r["name"] == name])
        out[name] = {
            "mean_flex": float(flex.mean()),
            "min_flex": float(flex.min()),
            "max_flex": float(flex.max()),
            "mean_mag": float(mag.mean()),
        }
    return out


def plot(
    run_dir: str | Path,
    png: str | Path,
    *,
    primary: str,
    title: str,
    events=(),
) -> None:
    """``png``: -torque_flex [N m] against time of the history's measure (labelled
    ``primary``) and of every measure of ``torques.csv`` after the settling, gait ``events``
    (time [s], context, label) marked (rank 0; nothing without the table)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .report import mark_events, read_history

    run_dir = Path(run_dir)
    if not (run_dir / FILE).exists():
        return
    h = read_history(run_dir / "history.csv")
    motion = h["stage"] == "motion"
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(h["time"][motion], -h["torque_flex"][motion], lw=1.5, label=primary)
    with (run_dir / FILE).open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    t0 = float(h["time"][motion][0]) if motion.any() else 0.0
    for name in dict.fromkeys(r["name"] for r in rows):
        mine = [r for r in rows if r["name"] == name and float(r["time"]) >= t0]
        t = [float(r["time"]) for r in mine]
        ax.plot(t, [-float(r["torque_flex"]) for r in mine], lw=1.0, label=name)
    mark_events(ax, events)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("-torque . flexion axis [N m] (> 0: resists flexion)")
    ax.set_title(title)
    ax.grid(True)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)
