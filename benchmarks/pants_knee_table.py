"""The knee-torque table of docs/results/pants_walk.md from walk run folders: per run, the
time-mean and peak of |tau| and of the resisting flexion component -tau . a over the walk
(the motion rows) and over the right leg's stance (foot strike to foot off) and swing (foot
off to foot strike) phases of the run's events.csv, as a Markdown table.

    .venv/bin/python benchmarks/pants_knee_table.py results/pants-walk-1mm results/pants-walk-2mm
"""

import argparse
import csv
from pathlib import Path

from clothfem.report import ReportError, _phase_stats, read_history


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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path)
    args = parser.parse_args()
    head = ["run", "phase", "s", "mean \\|tau\\| [N m]", "peak \\|tau\\|"]
    head += ["mean -tau.a [N m]", "peak -tau.a"]
    print("| " + " | ".join(head) + " |")
    print("|---|---|---|---|---|---|---|")
    for run in args.runs:
        if not (run / "events.csv").is_file():
            parser.error(f"{run}: no events.csv (not a run of a recorded motion)")
        try:
            h = read_history(run / "history.csv")
        except ReportError as exc:
            parser.error(str(exc))
        on = h["stage"] == "motion"
        t, mag, res = h["time"][on], h["torque_mag"][on], -h["torque_flex"][on]
        phases = [("walk", float(t[0]), float(t[-1])), *_phases(run)]
        for name, a, b in phases:
            sel = (t >= a) & (t <= b)
            (m_peak, m_mean), (r_peak, r_mean) = (_phase_stats(t[sel], y[sel]) for y in (mag, res))
            print(f"| {run.name} | {name} | {a:.2f}-{b:.2f} | {m_mean:.4f} | {m_peak:.4f} | "
                  f"{r_mean:.4f} | {r_peak:.4f} |")  # fmt: skip


if __name__ == "__main__":
    main()
