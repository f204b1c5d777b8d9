"""Post-processing of a run folder: torque-angle plots, a Markdown report, curve errors.

Reads what ``clothfem run`` writes: ``history.csv`` (one row per recorded step) and
``summary.json`` (at the end or when the run stops). Pure numpy/csv/json; matplotlib (Agg) is
imported only to draw, so this module imports fast and needs neither MPI nor dolfinx.
Angles are in degrees, torques in N m, lengths in m, times in s.
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

REQUIRED = ("stage", "angle_deg", "torque_mag")
REPORT_ANGLES = (0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 57.0)
TIMERS = ("t_assembly", "t_solve", "t_contact", "t_io")
_ATOL = 1e-6  # angle tolerance [deg] for "reached" / "covered" (57 deg may come back 56.9999..)


class ReportError(Exception):
    """A run folder that cannot be read (missing file, missing column); one-line message."""


def read_history(path: str | Path) -> dict[str, np.ndarray]:
    """Columns of a ``history.csv`` as arrays: ``stage`` as str, every other column as float.

    Empty cells become nan; an incomplete last line (the file is written as the run goes)
    is dropped. Raises :class:`ReportError` if the file is missing or lacks ``stage``,
    ``angle_deg`` or ``torque_mag``.
    """
    path = Path(path)
    if not path.is_file():
        raise ReportError(f"{path} not found")
    with path.open(newline="") as f:
        reader = csv.reader(f)
        header = next(reader, [])
        rows = [r for r in reader if len(r) == len(header)]
    missing = [c for c in REQUIRED if c not in header]
    if missing:
        word = "column" if len(missing) == 1 else "columns"
        raise ReportError(f"{path}: missing required {word} {', '.join(map(repr, missing))}")
    out: dict[str, np.ndarray] = {}
    for j, name in enumerate(header):
        cells = [r[j] for r in rows]
        if name == "stage":
            out[name] = np.array(cells, dtype=str)
            continue
        try:
            out[name] = np.array([float(c) if c.strip() else math.nan for c in cells])
        except ValueError:
            out[name] = np.array(cells, dtype=str)
            if name in REQUIRED:
                raise ReportError(f"{path}: column {name!r} is not numeric") from None
    return out


def read_summary(run_dir: str | Path) -> dict:
    """``RUN_DIR/summary.json`` as a dict; empty if missing or unreadable."""
    try:
        data = json.loads((Path(run_dir) / "summary.json").read_text())
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def torque_curve(h: dict[str, np.ndarray], y: str = "torque_mag") -> tuple[np.ndarray, np.ndarray]:
    """(angle [deg], column ``y`` [N m]) over the last ``settle`` row and all ``motion`` rows.

    The last settle row is the fully settled state (normally at 0 deg); earlier settle rows
    are partial loads and left out. Rows keep their file order.
    """
    stage = h["stage"]
    keep = stage == "motion"
    settle = np.flatnonzero(stage == "settle")
    if settle.size:
        keep[settle[-1]] = True
    return h["angle_deg"][keep], h[y][keep]


def _sorted(angles: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a, v = np.asarray(angles, float), np.asarray(values, float)
    ok = np.isfinite(a) & np.isfinite(v)
    order = np.argsort(a[ok], kind="stable")
    return a[ok][order], v[ok][order]


def torque_at(angles: np.ndarray, torque: np.ndarray, at: float) -> float | None:
    """Torque [N m] at angle ``at`` [deg], linearly interpolated; None if ``at`` is not reached.

    ``angles`` need not be sorted; "reached" allows a 1e-6 deg round-off at the ends.
    """
    a, t = _sorted(angles, torque)
    if a.size == 0 or not a[0] - _ATOL <= at <= a[-1] + _ATOL:
        return None
    return float(np.interp(at, a, t))


def _check_window(window: float) -> float:
    """``window`` as a float; ValueError unless it is a finite number >= 0."""
    try:
        w = float(window)
    except (TypeError, ValueError):
        w = math.nan
    if not (math.isfinite(w) and w >= 0.0):
        raise ValueError(
            f"window must be a finite number of degrees >= 0 (0 = no smoothing), got {window!r}"
        )
    return w


def moving_average(
    angle: np.ndarray, torque: np.ndarray, window: float, *, at: np.ndarray | None = None
) -> np.ndarray:
    """Centred moving average of a torque-angle curve over ``window`` degrees.

    The curve is the piecewise-linear interpolant of the finite (angle, torque) pairs,
    sorted by angle, on its own range [a0, a1]. Its moving average at an angle a is the
    exact mean of that interpolant over [a - window/2, a + window/2] intersected with
    [a0, a1]: with F the cumulative trapezoid integral of the curve (exact for a
    piecewise-linear function),

        S(a) = (F(r) - F(l)) / (r - l),   l = max(a - window/2, a0), r = min(a + window/2, a1).

    Near the ends the window is truncated (one-sided mean), so a linear function is
    reproduced exactly only where |a - a0| and |a - a1| are >= window/2. Returns S at the
    angles ``at`` (default: ``angle`` itself, in the given order), as a float array: nan
    where the window misses [a0, a1] or the angle is not finite; where it only touches it
    (or the curve is a single point) the curve's end value. ``window = 0`` returns the
    torque values at ``angle`` unchanged (or, with ``at``, the curve linearly interpolated,
    clamped at the ends). Raises ValueError if ``window`` is negative or not finite.
    """
    w = _check_window(window)
    a, t = _sorted(angle, torque)
    x = np.asarray(angle if at is None else at, float)
    if w == 0.0:
        if at is None:
            return np.array(torque, dtype=float)
        return np.interp(x, a, t) if a.size else np.full(x.shape, math.nan)
    out = np.full(x.shape, math.nan)
    if a.size == 0:
        return out
    F = np.concatenate(([0.0], np.cumsum(0.5 * np.diff(a) * (t[1:] + t[:-1]))))

    def integral(y: np.ndarray) -> np.ndarray:  # F(y), exact: trapezoid from the node below y
        k = np.clip(np.searchsorted(a, y, side="right") - 1, 0, a.size - 1)
        return F[k] + 0.5 * (y - a[k]) * (t[k] + np.interp(y, a, t))

    with np.errstate(invalid="ignore"):
        left = np.maximum(x - 0.5 * w, a[0])
        right = np.minimum(x + 0.5 * w, a[-1])
        width = right - left
        inside = width > 0
        touch = width == 0
    out[inside] = (integral(right[inside]) - integral(left[inside])) / width[inside]
    out[touch] = np.interp(left[touch], a, t)
    return out


def curve_error(
    ref_angle: np.ndarray,
    ref_torque: np.ndarray,
    angle: np.ndarray,
    torque: np.ndarray,
    *,
    lo: float,
    hi: float,
    window: float = 0.0,
) -> float:
    """Relative L2 error of a torque-angle curve against a reference over [lo, hi] deg.

    With S_w[tau] the centred ``window``-degree moving average of :func:`moving_average`
    (each curve averaged over its own angle range, so values just outside [lo, hi] enter
    the averages near lo and hi; S_0[tau] = tau, the default):

        e_w = sqrt(int_lo^hi (S_w[tau] - S_w[tau_ref])^2 da / int_lo^hi S_w[tau_ref]^2 da),

    both curves taken as their piecewise-linear interpolants, S_w evaluated exactly at 200
    uniform angles in [lo, hi] (``window = 0``: the curves interpolated there) and both
    integrals by the trapezoidal rule on those angles. ``window > 0`` filters step-to-step
    oscillation of period <= ``window`` (a full period averages to 0) and compares the
    trends. Dimensionless; nan if either curve does not cover [lo, hi] (or if both integrals
    are 0), inf if the (averaged) reference is identically 0 but the curve is not. Raises
    ValueError if lo >= hi or ``window`` is negative or not finite.
    """
    if not hi > lo:
        raise ValueError(f"curve_error: need lo < hi, got lo={lo}, hi={hi}")
    w = _check_window(window)
    grid = np.linspace(lo, hi, 200)
    curves = []
    for a, t in ((ref_angle, ref_torque), (angle, torque)):
        a, t = _sorted(a, t)
        if a.size == 0 or a[0] > lo + _ATOL or a[-1] < hi - _ATOL:
            return math.nan
        curves.append(moving_average(a, t, w, at=grid))  # window 0: interpolated

    def trap(f: np.ndarray) -> float:  # uniform spacing cancels in the ratio
        return float(f.sum() - 0.5 * (f[0] + f[-1]))

    with np.errstate(divide="ignore", invalid="ignore"):
        return float(np.sqrt(np.float64(trap((curves[1] - curves[0]) ** 2)) / trap(curves[0] ** 2)))


def _stopped_note(h: dict[str, np.ndarray], summary: dict) -> str:
    """`` (stopped at X deg)`` if summary.json says the run did not complete, else ''."""
    if summary.get("completed", True) is not False:
        return ""
    angle = summary.get("final_angle_deg")
    if not isinstance(angle, int | float):
        a, _ = torque_curve(h)
        angle = a[-1] if a.size else math.nan
    return f" (stopped at {angle:.1f} deg)"


def plot_runs(
    run_dirs: Sequence[str | Path],
    out: str | Path | None = None,
    *,
    labels: Sequence[str] | None = None,
    y: str = "torque_mag",
    title: str | None = None,
) -> Path:
    """Torque [N m] against angle [deg], one line per run folder; returns the PNG written.

    ``y = "torque_flex"`` plots -tau . hinge axis. Default ``out``: ``RUN_DIR/torque_angle.png``
    for one run, ``./torque_angle_compare.png`` for several.
    """
    if y not in ("torque_mag", "torque_flex"):
        raise ReportError(f"--y must be torque_mag or torque_flex, not {y!r}")
    if labels and len(labels) != len(run_dirs):
        raise ReportError(f"{len(labels)} --label value(s) for {len(run_dirs)} run folder(s)")
    runs = []
    for i, d in enumerate(run_dirs):
        h = read_history(Path(d) / "history.csv")
        if y not in h:
            raise ReportError(f"{Path(d) / 'history.csv'}: missing column {y!r}")
        a, t = torque_curve(h, y)
        name = labels[i] if labels else Path(d).resolve().name
        runs.append((a, -t if y == "torque_flex" else t, name + _stopped_note(h, read_summary(d))))
    if out is None:
        out = Path(run_dirs[0]) / "torque_angle.png" if len(run_dirs) == 1 else None
        out = out or Path("torque_angle_compare.png")
    out = Path(out)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for a, t, name in runs:
        ax.plot(a, t, "o-", ms=3, label=name)
    ax.set_xlabel("flexion angle [deg]")
    ax.set_ylabel("torque -tau . hinge axis [N m]" if y == "torque_flex" else "torque |tau| [N m]")
    ax.set_title(title or (runs[0][2] if len(runs) == 1 else "torque-angle"))
    ax.grid(True)
    ax.legend()
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out


def _fmt(x: float | None, spec: str = ".4g") -> str:
    return "—" if x is None or not math.isfinite(x) else format(x, spec)


def report_markdown(run_dir: str | Path) -> str:
    """A short Markdown report of a run folder (status, torques at fixed angles, cost)."""
    run_dir = Path(run_dir)
    h = read_history(run_dir / "history.csv")
    s = read_summary(run_dir)
    n = h["stage"].size

    def num(key: str, how, column: str | None = None) -> float | None:  # summary, else CSV
        v = s.get(key)
        if isinstance(v, int | float) and not isinstance(v, bool):
            return float(v)
        col = h.get(column or key)
        if col is None or col.dtype.kind != "f" or not np.isfinite(col).any():
            return None
        return float(how(col[np.isfinite(col)]))

    if "completed" not in s:
        status = "unknown (no summary.json: still running or killed)"
    elif s["completed"]:
        status = "completed"
    else:
        status = f"stopped: {s.get('reason') or 'no reason given'}"
    a, tm = torque_curve(h)
    final = num("final_angle_deg", lambda c: c[-1], "angle_deg")
    lines = [
        f"# Run report: {s.get('scene') or run_dir.resolve().name}",
        "",
        f"- folder: `{run_dir}`",
        f"- status: {status}",
        f"- final angle: {_fmt(final, '.2f')} deg",
    ]
    ok = np.isfinite(tm)
    if ok.any():
        k = int(np.argmax(np.where(ok, tm, -np.inf)))
        lines.append(f"- peak torque |tau|: {tm[k]:.4g} N m at {a[k]:.2f} deg")
    steps = s.get("steps")
    n_motion = int(np.count_nonzero(h["stage"] == "motion"))
    steps = steps if isinstance(steps, int) else n
    lines.append(f"- steps: {steps} ({n} rows: {n - n_motion} settle, {n_motion} motion)")
    facts = (
        ("cut-backs", num("cutbacks", np.sum), ".0f", ""),
        ("max penetration", num("max_penetration", np.max), ".3g", " m"),
        ("Newton iterations (total)", num("newton_iterations", np.sum), ".0f", ""),
        ("wall time", num("wall_time", lambda c: c[-1], "elapsed"), ".1f", " s"),
    )
    lines += [f"- {label}: {v:{spec}}{unit}" for label, v, spec, unit in facts if v is not None]
    timers = {k[2:]: float(np.nansum(h[k])) for k in TIMERS if k in h and h[k].dtype.kind == "f"}
    total = sum(timers.values())
    wall = num("wall_time", lambda c: c[-1], "elapsed")
    if timers and total > 0:
        # of the run's wall time when known (the rest, "other", is what no timer covers: the
        # explicit step itself, the CSV, pictures), else of the timed parts
        whole = wall if wall is not None and wall >= total else total
        shares = ", ".join(f"{k} {100 * v / whole:.1f} %" for k, v in timers.items())
        of = "of the timed parts"
        if whole > total:
            shares += f", other {100 * (whole - total) / whole:.1f} %"
            of = "of the wall time"
        lines.append(f"- time shares {of}: {shares}")
    flex = torque_curve(h, "torque_flex") if "torque_flex" in h else None
    head = "| angle [deg] | torque_mag [N m] |" + (" -torque_flex [N m] |" if flex else "")
    lines += ["", head, "|---|---|" + ("---|" if flex else "")]
    for at in REPORT_ANGLES:
        row = f"| {at:g} | {_fmt(torque_at(a, tm, at))} |"
        if flex:
            tf = torque_at(flex[0], flex[1], at)
            row += f" {_fmt(None if tf is None else -tf)} |"
        lines.append(row)
    return "\n".join(lines) + "\n"
