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
TIMERS = ("t_assembly", "t_solve", "t_contact", "t_self_contact", "t_io")
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


def roughness(angle: np.ndarray, torque: np.ndarray, *, lo: float = 2.0, hi: float = 20.0) -> float:
    """Row-to-row roughness of a torque-angle history over [lo, hi] deg (dimensionless).

    With tau_1..tau_m the torques of the rows whose angle lies in [lo, hi] (file order,
    non-finite pairs dropped),

        roughness = sqrt(mean_k (tau_k+1 - tau_k)^2) / mean_k tau_k,

    the rms of the differences of consecutive rows over their mean. A smooth curve still has
    a floor: a trend of slope s [N m/deg] sampled every da degrees contributes s da / mean.
    nan with fewer than two rows in the range or a zero mean.
    """
    a, t = np.asarray(angle, float), np.asarray(torque, float)
    ok = np.isfinite(a) & np.isfinite(t) & (a >= lo - _ATOL) & (a <= hi + _ATOL)
    t = t[ok]
    if t.size < 2 or t.mean() == 0.0:
        return math.nan
    return float(np.sqrt(np.mean(np.diff(t) ** 2)) / t.mean())


def roughness_split(
    angle: np.ndarray,
    torque: np.ndarray,
    *,
    window: float = 2.0,
    lo: float = 2.0,
    hi: float = 20.0,
) -> tuple[float, float]:
    """The roughness of a history split into the curve's own changes and the oscillation
    about it, over [lo, hi] deg: (the :func:`roughness` of the centred :func:`moving_average`
    over ``window`` deg, sampled at the rows; the rms of the rows about that average / the
    mean torque). A curve with physical events (a slip, a wrap) has the first; ringing,
    impacts and row sampling give the second. nan as for :func:`roughness`."""
    a, t = np.asarray(angle, float), np.asarray(torque, float)
    ok = np.isfinite(a) & np.isfinite(t)
    a, t = a[ok], t[ok]
    if a.size < 2:
        return math.nan, math.nan
    smooth = moving_average(a, t, window)
    sel = (a >= lo - _ATOL) & (a <= hi + _ATOL)
    if sel.sum() < 2 or t[sel].mean() == 0.0:
        return math.nan, math.nan
    osc = float(np.sqrt(np.mean((t[sel] - smooth[sel]) ** 2)) / t[sel].mean())
    return roughness(a, smooth, lo=lo, hi=hi) * float(smooth[sel].mean() / t[sel].mean()), osc


def roughness_trend(
    angle: np.ndarray, torque: np.ndarray, *, lo: float = 2.0, hi: float = 20.0
) -> float:
    """The part of :func:`roughness` a straight trend explains: the roughness of the least-
    squares line through the same rows (|slope| x the rms angle step / the mean). A curve
    without any oscillation still has this much; nan as for :func:`roughness`."""
    a, t = np.asarray(angle, float), np.asarray(torque, float)
    ok = np.isfinite(a) & np.isfinite(t) & (a >= lo - _ATOL) & (a <= hi + _ATOL)
    if np.count_nonzero(ok) < 2 or np.ptp(a[ok]) == 0.0:
        return math.nan
    line = np.polyval(np.polyfit(a[ok], t[ok], 1), a[ok])
    return roughness(a[ok], line, lo=lo, hi=hi) * float(line.mean()) / float(t[ok].mean())


def timer_shares(
    h: dict[str, np.ndarray], edges: Sequence[float], *, timer: str = "t_self_contact"
) -> list[tuple[float, float, int, float, float]]:
    """Per angle bin ``[edges[k], edges[k+1])`` [deg] of the rows of the history ``h`` (the
    last bin closed): (low edge, high edge, rows, seconds in ``timer``, row wall seconds).
    A row counts in the bin of its angle; ``wall_time`` is each row's own wall time."""
    a, t, wall = h["angle_deg"], h[timer], h["wall_time"]
    out = []
    for k, (lo, hi) in enumerate(zip(edges[:-1], edges[1:], strict=True)):
        last = k == len(edges) - 2
        m = (a >= lo) & ((a <= hi) if last else (a < hi))
        out.append((lo, hi, int(m.sum()), float(np.nansum(t[m])), float(np.nansum(wall[m]))))
    return out


def joint_power(torque: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """Power [W] a joint spends against the garment: ``-tau . omega``, with ``tau`` [N m] the
    torque the garment exerts on the segment about its joint and ``omega`` [rad/s] the
    segment's angular velocity (vectors in the last axis, or scalars about the hinge axis)."""
    tau, om = np.asarray(torque, float), np.asarray(omega, float)
    if tau.ndim and tau.shape[-1] == 3 and om.ndim and om.shape[-1] == 3:
        return -np.einsum("...i,...i->...", tau, om)
    return -tau * om


def joint_work(
    t: np.ndarray, torque: np.ndarray, omega: np.ndarray, *, rule: str = "trapezoid"
) -> np.ndarray:
    """Cumulative work [J] a joint does against the garment at the samples ``t`` [s]:

        W(t_k) = -int_{t_0}^{t_k} tau . omega dt,     W(t_0) = 0,

    ``tau`` [N m] the torque the garment exerts on the segment about the joint, ``omega``
    [rad/s] the segment's angular velocity ((n, 3) arrays, or (n,) components about the hinge
    axis). Positive when the joint drives the garment (the arm works against the sleeve);
    negative when the garment drives the joint. Rules: ``"trapezoid"`` (samples are states:
    quasi-static increments, implicit steps), ``"impulse"`` (sample k is the mean over the
    interval (t_k-1, t_k]: the explicit FILM forces, W_k = W_k-1 - tau_k . omega_k
    (t_k - t_k-1)). Any monotone parameter can stand for t when omega is d(angle)/d(it):
    ``joint_work(theta, tau_axis, 1.0)`` is the work over the hinge angle theta [rad].
    """
    s = np.asarray(t, float)
    p = np.broadcast_to(joint_power(torque, omega), s.shape)
    if rule == "trapezoid":
        inc = 0.5 * (p[1:] + p[:-1]) * np.diff(s)
    elif rule == "impulse":
        inc = p[1:] * np.diff(s)
    else:
        raise ValueError(f"joint_work: rule must be 'trapezoid' or 'impulse', got {rule!r}")
    return np.concatenate(([0.0], np.cumsum(inc))) if s.size else np.zeros(0)


PHASES = (("settle", "settle"), ("flexion", "motion"))  # (name in the measures, CSV stage)
MATERIAL_NOTE = "elastic (St. Venant-Kirchhoff): no material dissipation"


def _phase_stats(t: np.ndarray, y: np.ndarray) -> tuple[float | None, float | None]:
    """(peak, mean) of y over a phase's rows: the mean is the time average (trapezoid over
    the row times) when the rows span some time, else the plain mean of the rows."""
    ok = np.isfinite(y)
    if not ok.any():
        return None, None
    t, y = t[ok], y[ok]
    peak = float(np.max(y))
    if t.size > 1 and np.all(np.isfinite(t)) and t[-1] > t[0]:
        return peak, float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(t)) / (t[-1] - t[0]))
    return peak, float(np.mean(y))


def resistance_measures(h: dict[str, np.ndarray], *, joint: str = "joint") -> dict:
    """The run's clothing-resistance measures from its history columns (JSON-ready dict).

    - ``joints[joint]``: ``work`` [J] of the measured joint against the garment (the last
      ``joint_work``; see :func:`joint_work`) and its part in the flexion phase
      (``work_flexion``);
    - ``dissipation`` [J]: ``friction`` (the body contact's ``dissipation_total``),
      ``self_friction`` (the friction between fabric layers, ``self_friction_work``; None
      without self-contact), ``material`` (``dissipation_material``, 0 for the elastic
      fabric, ``material_note`` says so) and ``total`` = their sum;
    - ``torque``: per phase (``settle``: the body at rest while the loads come on;
      ``flexion``: the motion rows), ``peak`` / ``mean`` of |tau| (``torque_mag``) and of
      -tau . hinge axis (``flex``) over the history rows [N m] (rows of an explicit run are
      means over their steps), the mean time-averaged; ``roughness`` of the flexion's
      |tau| over 2-20 deg (:func:`roughness`) and the part a straight trend gives
      (``roughness_trend``, :func:`roughness_trend`); the same split into the 2-deg averaged
      curve's own changes (``roughness_smoothed``) and the oscillation about it
      (``oscillation``, :func:`roughness_split`).
    Missing columns give None.
    """

    def last(col: str) -> float | None:
        c = h.get(col)
        if c is None or c.dtype.kind != "f" or not np.isfinite(c).any():
            return None
        return float(c[np.isfinite(c)][-1])

    stage = h["stage"]
    t = h.get("time", np.arange(stage.size, dtype=float))
    work = last("joint_work")
    motion = np.flatnonzero(stage == "motion")
    work_flex = None
    if work is not None and "joint_work" in h:
        before = np.flatnonzero(stage != "motion")
        w = h["joint_work"]
        start = float(w[before[before < motion[0]][-1]]) if motion.size and before.size else 0.0
        work_flex = work - start if motion.size else 0.0
    friction = last("dissipation_total")
    layers = last("self_friction_work")
    material = last("dissipation_material")
    if material is None and friction is not None:
        material = 0.0  # histories without the column: elastic fabric
    torque = {}
    for name, st in PHASES:
        rows = stage == st
        entry: dict[str, float | None] = {"rows": int(rows.sum())}
        for key, col, sign in (("", "torque_mag", 1.0), ("_flex", "torque_flex", -1.0)):
            peak, mean = (None, None)
            if col in h and rows.any():
                peak, mean = _phase_stats(t[rows], sign * h[col][rows])
            entry["peak" + key], entry["mean" + key] = peak, mean
        torque[name] = entry
    on = stage == "motion"
    r = roughness(h["angle_deg"][on], h["torque_mag"][on]) if on.any() else math.nan
    rt = roughness_trend(h["angle_deg"][on], h["torque_mag"][on]) if on.any() else math.nan
    torque["flexion"]["roughness"] = r if math.isfinite(r) else None
    torque["flexion"]["roughness_trend"] = rt if math.isfinite(rt) else None
    rs, osc = (
        roughness_split(h["angle_deg"][on], h["torque_mag"][on]) if on.any() else (math.nan,) * 2
    )
    torque["flexion"]["roughness_smoothed"] = rs if math.isfinite(rs) else None
    torque["flexion"]["oscillation"] = osc if math.isfinite(osc) else None
    return {
        "joints": {joint: {"work": work, "work_flexion": work_flex}},
        "dissipation": {
            "friction": friction,
            "self_friction": layers,
            "material": material,
            "material_note": MATERIAL_NOTE if material == 0.0 else None,
            "total": None if friction is None else friction + (layers or 0.0) + (material or 0.0),
        },
        "torque": torque,
    }


def _stopped_note(h: dict[str, np.ndarray], summary: dict) -> str:
    """`` (stopped at X deg)`` if summary.json says the run did not complete, else ''."""
    if summary.get("completed", True) is not False:
        return ""
    if summary.get("running"):
        a, _ = torque_curve(h)
        return f" (not finished: {a[-1]:.1f} deg so far)" if a.size else " (not finished)"
    angle = summary.get("final_angle_deg")
    if not isinstance(angle, int | float):
        a, _ = torque_curve(h)
        angle = a[-1] if a.size else math.nan
    return f" (stopped at {angle:.1f} deg)"


# --y of plot_runs: the history columns (the first, minus the others) and the axis label
PLOT_Y: dict[str, tuple[tuple[str, ...], str]] = {
    "torque_mag": (("torque_mag",), "torque |tau| [N m]"),
    "torque_flex": (("torque_flex",), "torque -tau . flexion axis [N m]"),
    "torque_flex_unpinched": (
        ("torque_flex", "torque_flex_pinched"),
        "torque -tau . flexion axis without the pinched fabric [N m]",
    ),
}


def plotted(h: dict[str, np.ndarray], *, y: str, x: str) -> tuple[np.ndarray, np.ndarray]:
    """The (x, y) points :func:`plot_runs` draws of a history: angle [deg] or time [s]
    against the torque of ``y`` (a key of :data:`PLOT_Y`) [N m]."""
    columns = [torque_curve(h, col)[1] for col in PLOT_Y[y][0]]
    t = columns[0] if y == "torque_mag" else -(columns[0] - sum(columns[1:]))
    angle, time_s = torque_curve(h, "time")
    return (time_s if x == "time" else angle), t


def plot_runs(
    run_dirs: Sequence[str | Path],
    out: str | Path | None = None,
    *,
    labels: Sequence[str] | None = None,
    y: str = "torque_mag",
    x: str = "angle",
    title: str | None = None,
) -> Path:
    """Torque [N m] against angle [deg] (``x = "time"``: against time [s], a recorded motion,
    with the first run's gait events of ``events.csv`` marked), one line per run folder;
    returns the PNG written.

    ``y = "torque_flex"`` plots -tau . flexion axis; ``"torque_flex_unpinched"`` the same
    without the part of the fabric pinched between two segments (``torque_flex_pinched``).
    Default ``out``: ``RUN_DIR/torque_angle.png`` for one run,
    ``./torque_angle_compare.png`` for several.
    """
    if y not in PLOT_Y:
        raise ReportError(f"--y must be one of {', '.join(PLOT_Y)}, not {y!r}")
    if x not in ("angle", "time"):
        raise ReportError(f"--x must be angle or time, not {x!r}")
    if labels and len(labels) != len(run_dirs):
        raise ReportError(f"{len(labels)} --label value(s) for {len(run_dirs)} run folder(s)")
    runs = []
    for i, d in enumerate(run_dirs):
        h = read_history(Path(d) / "history.csv")
        for col in PLOT_Y[y][0]:
            if col not in h or not np.isfinite(h[col]).any():
                why = "missing column" if col not in h else "no values in column"
                raise ReportError(f"{Path(d) / 'history.csv'}: {why} {col!r}")
        a, t = plotted(h, y=y, x=x)
        name = labels[i] if labels else Path(d).resolve().name
        runs.append((a, t, name + _stopped_note(h, read_summary(d))))
    if out is None:
        out = Path(run_dirs[0]) / "torque_angle.png" if len(run_dirs) == 1 else None
        out = out or Path("torque_angle_compare.png")
    out = Path(out)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for a, t, name in runs:
        ax.plot(a, t, "o-" if x == "angle" else "-", ms=3, label=name)
    if x == "time":
        mark_events(ax, _events(run_dirs[0]))
    ax.set_xlabel("flexion angle [deg]" if x == "angle" else "time [s]")
    ax.set_ylabel(PLOT_Y[y][1])
    ax.set_title(title or (runs[0][2] if len(runs) == 1 else f"torque-{x}"))
    ax.grid(True)
    ax.legend()
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out


def mark_events(ax, events: Sequence[tuple[float, str, str]]) -> None:
    """Dotted vertical lines on the matplotlib axes ``ax`` at the gait ``events`` (time [s],
    context, label), labelled e.g. "RFS" (Right Foot Strike)."""
    for t_event, context, label in events:
        ax.axvline(t_event, color="0.6", lw=0.8, ls=":")
        short = context[:1] + "".join(w[0] for w in label.split())
        ax.text(t_event, 0.98, f" {short}", transform=ax.get_xaxis_transform(), va="top",
                fontsize=7, color="0.4")  # fmt: skip


def _events(run_dir: str | Path) -> list[tuple[float, str, str]]:
    """``RUN_DIR/events.csv`` as (time [s], context, label); empty if there is none."""
    path = Path(run_dir) / "events.csv"
    if not path.is_file():
        return []
    with path.open() as fh:
        return [(float(r["time_s"]), r["context"], r["label"]) for r in csv.DictReader(fh)]


def _fmt(x: float | None, spec: str = ".4g") -> str:
    return "—" if x is None or not math.isfinite(x) else format(x, spec)


def _measures_lines(h: dict[str, np.ndarray], s: dict) -> list[str]:
    """The report's resistance-measure lines (:func:`resistance_measures` of the history)."""
    joint = s.get("measures", {}).get("joint") if isinstance(s.get("measures"), dict) else None
    m = resistance_measures(h, joint=joint or "joint")
    lines = []
    for name, j in m["joints"].items():
        if j["work"] is not None:
            lines.append(
                f"- work of the {'measured' if name == 'joint' else name} joint against the "
                f"garment: {j['work']:.4g} J "
                f"(flexion {_fmt(j['work_flexion'])} J)"
            )
    d = m["dissipation"]
    if d["total"] is not None:
        note = f": {d['material_note']}" if d["material_note"] else ""
        layers = (
            "" if d["self_friction"] is None else f" + between layers {d['self_friction']:.4g} J"
        )
        lines.append(
            f"- energy dissipated by the clothing: {d['total']:.4g} J = friction "
            f"{d['friction']:.4g} J{layers} + material {d['material']:.4g} J{note}"
        )
    for name, e in m["torque"].items():
        if e["peak"] is None:
            continue
        text = f"- {name} torque |tau|: peak {e['peak']:.4g} N m, mean {e['mean']:.4g} N m"
        if e["peak_flex"] is not None:
            text += f"; -tau . axis: peak {e['peak_flex']:.4g} N m, mean {e['mean_flex']:.4g} N m"
        lines.append(text)
    r = m["torque"]["flexion"].get("roughness")
    if r is not None:
        rt = m["torque"]["flexion"].get("roughness_trend")
        lines.append(
            f"- torque roughness over 2-20 deg (rms row-to-row / mean): {100 * r:.1f} %"
            + (f" (a straight trend alone: {100 * rt:.1f} %)" if rt is not None else "")
        )
        rs = m["torque"]["flexion"].get("roughness_smoothed")
        osc = m["torque"]["flexion"].get("oscillation")
        if rs is not None and osc is not None:
            lines.append(
                f"- split: roughness of the 2-deg averaged curve {100 * rs:.1f} %, "
                f"oscillation about it (rms / mean) {100 * osc:.1f} %"
            )
    return lines


CRUSHED = -0.2  # yarn Green strain (stretch 0.77) below which the report warns


def _element(s: dict) -> str | None:
    """The element line of a run's build log (``summary.json`` "built"), if any."""
    built = s.get("built")
    lines = [b for b in built if isinstance(b, str)] if isinstance(built, list) else []
    return next((b[len("element: ") :] for b in lines if b.startswith("element: ")), None)


def _crush_lines(h: dict[str, np.ndarray], *, element: str | None = None) -> list[str]:
    """The yarn strain range of the run and, when some yarn was compressed below
    :data:`CRUSHED`, a warning with the first angle where it happened; ``element``: the
    build log's element line (the warning names the causes that apply to it)."""
    lo, hi = h.get("min_yarn_strain"), h.get("max_yarn_strain")
    if lo is None or hi is None or lo.dtype.kind != "f" or not np.isfinite(lo).any():
        return []
    lines = [f"- yarn Green strain range: {np.nanmin(lo):.3g} to {np.nanmax(hi):.3g}"]
    bad = np.flatnonzero(lo < CRUSHED)
    if bad.size:
        where = f"row {bad[0] + 1}"
        if "time" in h:
            where = f"t = {h['time'][bad[0]]:.3f} s"
        if "angle_deg" in h and np.ptp(h["angle_deg"]) > 0:
            where = f"{h['angle_deg'][bad[0]]:.1f} deg"
        cause = (
            "a fold the mesh does not resolve (MITC9 has no spurious membrane mode)"
            if element is not None and element.startswith("MITC9")
            else "a fold the mesh does not resolve, or the membrane mode of the partial "
            "selective element (element.scheme = 'psri'; MITC9 has none: "
            "docs/shell_element.md)"
        )
        lines.append(
            f"- warning: a yarn is compressed below E = {CRUSHED} (stretch < 0.77) at some "
            f"integration point from {where} on: {cause}; results past there carry it"
        )
    return lines


def _intersection_lines(h: dict[str, np.ndarray]) -> list[str]:
    """The independent self-intersection check of a run with self-contact (at its field
    frames): the frames checked and, where the fabric passes through itself, a warning."""
    col = h.get("self_intersections")
    if col is None or col.dtype.kind != "f" or not np.isfinite(col).any():
        return []
    checked = np.flatnonzero(np.isfinite(col))
    lines = [f"- fabric self-intersections (independent check, {checked.size} frames): "
             f"{int(np.nanmax(col))} at most"]  # fmt: skip
    bad = checked[col[checked] > 0]
    if bad.size:
        lines.append(
            f"- warning: the fabric passes through itself ({int(col[bad[0]])} intersecting "
            f"triangle pairs at t = {h['time'][bad[0]]:.3f} s, the first checked frame with "
            "any): self-contact cannot undo crossings a run starts with or is handed"
        )
    return lines


def _where(h: dict[str, np.ndarray], i: int, *, by_time: bool) -> str:
    """Row ``i`` as an angle (hinge runs) or a time."""
    if not by_time and "angle_deg" in h:
        return f"{h['angle_deg'][i]:.1f} deg"
    return f"t = {h['time'][i]:.3f} s" if "time" in h else f"row {i + 1}"


def _failsafe_lines(h: dict[str, np.ndarray], *, by_time: bool) -> list[str]:
    """The self-contact fail-safe's work: rows where the proximity response let layers
    cross (crossings found and undone by impact zones) and any crossing left."""
    found, left = h.get("self_crossings"), h.get("self_crossings_left")
    if found is None or found.dtype.kind != "f" or not np.isfinite(found).any():
        return []
    rows = np.flatnonzero(found > 0)
    if rows.size == 0:
        return ["- fabric crossings found by the self-contact fail-safe: none"]
    lines = [
        f"- fabric crossings found and undone by the self-contact fail-safe (the proximity "
        f"response let layers cross): {int(np.nansum(found))} in {rows.size} of {found.size} "
        f"rows, at most {int(np.nanmax(found))} in one, the first at "
        f"{_where(h, int(rows[0]), by_time=by_time)}"
    ]
    if left is not None and left.dtype.kind == "f" and np.nanmax(left, initial=0.0) > 0:
        bad = int(np.flatnonzero(left > 0)[0])
        lines.append(
            f"- warning: crossings left after the fail-safe from "
            f"{_where(h, bad, by_time=by_time)} on: the fabric passes through itself there"
        )
    return lines


KE_JUMP = 20.0  # kinetic energy / median over the motion before it that the report flags
KE_BASE_ROWS = 10  # motion rows the median needs before a jump is judged


def _energy_lines(h: dict[str, np.ndarray]) -> list[str]:
    """A hinge run's first motion row whose fabric kinetic energy exceeds :data:`KE_JUMP`
    times the median of the motion rows before it (at least :data:`KE_BASE_ROWS` of them):
    a dynamic event the prescribed motion does not explain."""
    ke, stage = h.get("kinetic_energy"), h.get("stage")
    if ke is None or stage is None or ke.dtype.kind != "f":
        return []
    rows = np.flatnonzero((stage == "motion") & np.isfinite(ke))
    for k in range(KE_BASE_ROWS, rows.size):
        base = float(np.median(ke[rows[:k]]))
        if base > 0 and ke[rows[k]] > KE_JUMP * base:
            return [
                f"- warning: the fabric's kinetic energy jumps to {ke[rows[k]]:.3g} J at "
                f"{_where(h, int(rows[k]), by_time=False)}, {ke[rows[k]] / base:.0f} x the "
                f"median of the motion before ({base:.3g} J): a snap or a breakdown of the "
                "contact or the element, not the steady resistance; read the torque past "
                "there with it"
            ]
    return []


def _torques_lines(s: dict) -> list[str]:
    """The ``[[torques]]`` measures of ``summary.json`` after the settling, one table row each."""
    table = s.get("torques") or {}
    if not table:
        return []
    lines = ["", "| further torque | mean torque_flex | min | max | mean abs(tau) |"]
    lines.append("|---|---|---|---|---|")
    for name, v in table.items():
        cells = [_fmt(v.get(k)) for k in ("mean_flex", "min_flex", "max_flex", "mean_mag")]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return lines + ["", "(N m, after the settling; torques.csv has the rows)"]


def earlier_segments(s: dict) -> list[dict]:
    """The segments before the last resume of a run, as its summary ``s`` lists them
    (``summary.json``'s ``earlier``; entries that are not objects are skipped)."""
    e = s.get("earlier")
    return [x for x in e if isinstance(x, dict)] if isinstance(e, list) else []


def _earlier_wall(s: dict) -> float:
    """The wall time [s] of the segments before the last resume (those where it is known)."""
    w = [x.get("wall_time") for x in earlier_segments(s)]
    return float(sum(v for v in w if isinstance(v, int | float)))


def _segments_note(s: dict) -> str:
    """`` (N segments; ...)`` for a resumed run: how the earlier ones ended."""
    earlier = earlier_segments(s)
    if not earlier:
        return ""
    ends = []
    for e in earlier:
        a = e.get("final_angle_deg")
        at = f" at {a:.2f} deg" if isinstance(a, int | float) else ""
        w = "" if isinstance(e.get("wall_time"), int | float) else ", its wall time not known"
        ends.append(f"{e.get('reason') or 'ended'}{at}{w}")
    n = len(earlier) + 1
    return f" ({n} segments, resumed after: {'; '.join(ends)})"


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
    elif s.get("running"):
        status = "not finished (a resumed run still running or killed; no end recorded)"
    elif s["completed"]:
        status = "completed"
    else:
        status = f"stopped: {s.get('reason') or 'no reason given'}"
    a, tm = torque_curve(h)
    recorded = a.size > 0 and not a.max() > a.min() and "time" in h  # no hinge angle
    if recorded:  # a recorded motion: against time
        a = torque_curve(h, "time")[1]
    final = num("final_angle_deg", lambda c: c[-1], "angle_deg")
    lines = [
        f"# Run report: {s.get('scene') or run_dir.resolve().name}",
        "",
        f"- folder: `{run_dir}`",
        f"- status: {status}",
    ]
    if not recorded:
        lines.append(f"- final angle: {_fmt(final, '.2f')} deg")
    ok = np.isfinite(tm)
    if ok.any():
        k = int(np.argmax(np.where(ok, tm, -np.inf)))
        where = f"t = {a[k]:.3f} s" if recorded else f"{a[k]:.2f} deg"
        lines.append(f"- peak torque |tau|: {tm[k]:.4g} N m at {where}")
    steps = s.get("steps")
    n_motion = int(np.count_nonzero(h["stage"] == "motion"))
    steps = steps if isinstance(steps, int) else n
    lines.append(f"- steps: {steps} ({n} rows: {n - n_motion} settle, {n_motion} motion)")
    facts = (
        ("cut-backs", num("cutbacks", np.sum), ".0f", ""),
        ("max penetration", num("max_penetration", np.max), ".3g", " m"),
        ("Newton iterations (total)", num("newton_iterations", np.sum), ".0f", ""),
    )
    lines += [f"- {label}: {v:{spec}}{unit}" for label, v, spec, unit in facts if v is not None]
    wall = num("wall_time", lambda c: c[-1], "elapsed")
    wall = wall if wall is None else wall + _earlier_wall(s)
    if wall is not None:
        lines.append(f"- wall time: {wall:.1f} s{_segments_note(s)}")
    timers = {k[2:]: float(np.nansum(h[k])) for k in TIMERS if k in h and h[k].dtype.kind == "f"}
    total = sum(timers.values())
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
    lines += _measures_lines(h, s)
    lines += _torques_lines(s)
    lines += _intersection_lines(h)
    lines += _failsafe_lines(h, by_time=recorded)
    lines += _crush_lines(h, element=_element(s))
    lines += [] if recorded else _energy_lines(h)
    flex = torque_curve(h, "torque_flex")[1] if "torque_flex" in h else None
    if recorded:  # at the gait events (else every 0.25 s)
        events = [(t, f"{c} {lb}") for t, c, lb in _events(run_dir) if a[0] <= t <= a[-1]]
        ats = events or [(t, "") for t in np.arange(0.0, a[-1] + 1e-9, 0.25) if t >= a[0]]
        head = "| time [s] | event | torque_mag [N m] |"
    else:
        ats, head = [(at, None) for at in REPORT_ANGLES], "| angle [deg] | torque_mag [N m] |"
    head += " -torque_flex [N m] |" if flex is not None else ""
    lines += ["", head, "|---" * head.count(" | ") + "|---|"]
    for at, label in ats:
        row = f"| {at:g} |" + ("" if label is None else f" {label} |")
        row += f" {_fmt(torque_at(a, tm, at))} |"
        if flex is not None:
            tf = torque_at(a, flex, at)
            row += f" {_fmt(None if tf is None else -tf)} |"
        lines.append(row)
    return "\n".join(lines) + "\n"
