"""The self-contact share of a run's time per flexion-angle bin (docs/results/self_contact.md):
for each run folder, the rows' ``t_self_contact`` over their own wall time in each bin of
``--edges`` [deg] and over the whole run, as a Markdown table (the history's timers, so the
same split the run measured; a resumed run's rows count once, as its history holds them).

    .venv/bin/python benchmarks/self_contact_share.py RUN [RUN ...] [--edges 0 45 60 90 120]
"""

import argparse
from pathlib import Path

from clothfem.report import ReportError, read_history, timer_shares


def _share(t: float, wall: float) -> str:
    return f"{100 * t / wall:.1f} %" if wall > 0 else "-"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument(
        "--edges", nargs="+", type=float, default=[0, 45, 60, 75, 90, 105, 120],
        help="angle bin edges [deg], increasing",
    )  # fmt: skip
    args = parser.parse_args()
    edges = args.edges
    if len(edges) < 2 or any(b <= a for a, b in zip(edges, edges[1:], strict=False)):
        parser.error(f"--edges: at least two increasing angles, got {edges}")
    bins = [f"{lo:g}-{hi:g} deg" for lo, hi in zip(edges, edges[1:], strict=False)]
    print("| run | whole run | " + " | ".join(bins) + " |")
    print("|---|---|" + "---|" * len(bins))
    for run in args.runs:
        try:
            h = read_history(run / "history.csv")
        except ReportError as err:
            parser.error(str(err))
        if "t_self_contact" not in h:
            parser.error(f"{run}: the history has no t_self_contact column")
        rows = timer_shares(h, edges)
        (whole,) = timer_shares(h, [min(edges[0], h["angle_deg"].min()), h["angle_deg"].max()])
        cells = [f"{_share(t, w)} ({t:.0f} / {w:.0f} s, {n} rows)" for _, _, n, t, w in rows]
        head = f"{_share(whole[3], whole[4])} ({whole[3]:.0f} / {whole[4]:.0f} s)"
        print(f"| {run.name} | {head} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
