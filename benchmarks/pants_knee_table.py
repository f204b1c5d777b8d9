"""The knee-torque table of docs/results/pants_walk.md from walk run folders: per run, the
time-mean and peak of |tau| and of the resisting flexion component -tau . a over the walk
(the motion rows) and over the right leg's stance (foot strike to foot off) and swing (foot
off to foot strike) phases of the run's events.csv, as a Markdown table.

    .venv/bin/python benchmarks/pants_knee_table.py results/pants-walk-1mm results/pants-walk-2mm
"""

import argparse
import csv
from pathlib import Path

import numpy as np

from clothfem.report import read_history


def _phases(run: Path) -> list[tuple[str, float, float]]:
    """(name, start, end) [s] of the right leg's stance and swing phases in events.csv."""
    with (run / "events.csv").open() as fh:
        ev = [
            (float(r["time_s"]), r["label"]) for r in csv.DictReader(fh) if r["context"] == "Right"
        ]
    out = []
    for (t0, a), (t1, _) in zip(ev, ev[1:], strict=False):
        out.append(("stance" if a == "Foot Strike" else "swing", t0, t1))
    return out


def _stats(t: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """(time mean by the trapezoid rule, peak) of y over the rows t."""
    if len(t) < 2:
        return float("nan"), float("nan")
    area = float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(t)))
    return area / float(t[-1] - t[0]), float(np.max(y))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path)
    args = parser.parse_args()
    head = ["run", "phase", "s", "mean \\|tau\\| [N m]", "peak \\|tau\\|"]
    head += ["mean -tau.a [N m]", "peak -tau.a"]
    print("| " + " | ".join(head) + " |")
    print("|---|---|---|---|---|---|---|")
    for run in args.runs:
        h = read_history(run / "history.csv")
        on = h["stage"] == "motion"
        t, mag, res = h["time"][on], h["torque_mag"][on], -h["torque_flex"][on]
        phases = [("walk", float(t[0]), float(t[-1])), *_phases(run)]
        for name, a, b in phases:
            sel = (t >= a) & (t <= b)
            m = _stats(t[sel], mag[sel])
            r = _stats(t[sel], res[sel])
            print(f"| {run.name} | {name} | {a:.2f}-{b:.2f} | {m[0]:.4f} | {m[1]:.4f} | "
                  f"{r[0]:.4f} | {r[1]:.4f} |")  # fmt: skip


if __name__ == "__main__":
    main()
