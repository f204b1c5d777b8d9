"""Segment motions: Eq. 27 poses from markers, interpolated in time, and analytic motions.

Eq. 27 (Man & Swan 2007) builds a segment frame from two joint centres ``J1``, ``J2`` and an
auxiliary marker ``M``::

    x^c = (J1 + J2) / 2
    e1  = (J2 - J1) / |J2 - J1|
    e2  = Gram-Schmidt of (M - x^c) against e1, normalised
    e3  = e1 x e2

Marker-driven motions (:class:`InterpolatedMotion`) interpolate the per-frame poses:

* centre: **cubic** spline (scipy ``CubicSpline``, not-a-knot), velocity = its derivative;
* rotation: scipy ``RotationSpline`` (C2 cubic in the rotation vectors of successive
  *relative* rotations, hence always the short arc between frames: no quaternion-sign flips);
  angular velocity = its first derivative mapped to the global frame.  Successive frames
  rotating by more than 90 degrees are refused as ambiguous.

Analytic motions: :class:`FixedMotion` and :class:`HingeMotion` (rotation about a fixed joint
axis at constant rate up to a maximum angle: the paper's Sec. 4.1 elbow flexion);
:func:`arm_flexion_body` composes them into a two-segment arm.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation, RotationSpline

from clothfem.body.ellipsoid import Body, Segment, check_radii
from clothfem.body.mocap import MarkerRef, MarkerSet, validate_marker_map
from clothfem.body.pose import Motion, Pose, _vec3, check_rotation

__all__ = [
    "FixedMotion",
    "HingeMotion",
    "InterpolatedMotion",
    "SegmentFrames",
    "arm_flexion_body",
    "body_from_markers",
    "eq27_frames",
    "joint_angle",
    "segment_frames",
    "segment_markers",
]

_MAX_STEP_ROTATION = np.pi / 2  # rad between consecutive frames


def eq27_frames(
    *, j1: ArrayLike, j2: ArrayLike, m: ArrayLike, tol: float = 1e-9
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Centroids and rotations of Eq. 27 from ``J1, J2, M`` (each (3,) or (F, 3), in m).

    Returns ``(centres, rotations)`` of shapes (F, 3) and (F, 3, 3) (or (3,), (3, 3) for
    single points); rotation columns are ``e1, e2, e3``.  Raises ``ValueError`` if
    ``|J2 - J1| <= tol`` m or ``M`` lies within ``tol`` m of the ``J1``-``J2`` line.
    """
    a, b, c = (np.asarray(v, dtype=float) for v in (j1, j2, m))
    single = a.ndim == 1
    a, b, c = (np.atleast_2d(v) for v in (a, b, c))
    if not (a.shape == b.shape == c.shape and a.shape[-1] == 3):
        raise ValueError(
            f"j1, j2, m must have equal shapes (F, 3), got {a.shape}, {b.shape}, {c.shape}"
        )
    xc = 0.5 * (a + b)
    d = b - a
    length = np.linalg.norm(d, axis=1)
    bad = np.flatnonzero(~(length > tol))
    if bad.size:
        raise ValueError(
            f"|J2 - J1| must be > {tol:g} m, got {length[bad[0]]:.3g} m "
            f"at frames {bad[:5].tolist()}"
        )
    e1 = d / length[:, None]
    w = c - xc
    w = w - np.sum(w * e1, axis=1)[:, None] * e1
    wn = np.linalg.norm(w, axis=1)
    bad = np.flatnonzero(~(wn > tol))
    if bad.size:
        raise ValueError(
            f"M must lie > {tol:g} m off the J1-J2 axis, got {wn[bad[0]]:.3g} m "
            f"at frames {bad[:5].tolist()}"
        )
    e2 = w / wn[:, None]
    e3 = np.cross(e1, e2)
    rot = np.stack([e1, e2, e3], axis=-1)
    if single:
        return xc[0], rot[0]
    return xc, rot


@dataclass(frozen=True, eq=False, kw_only=True)
class SegmentFrames:
    """Per-frame Eq. 27 result for one segment.

    Attributes
    ----------
    name : str
        Segment name.
    times : (F,) array
        Frame times in s.
    j1, j2 : (F, 3) arrays
        Joint centre trajectories in m.
    centres : (F, 3) array
        Centroids ``(J1 + J2) / 2`` in m.
    rotations : (F, 3, 3) array
        Columns ``e1, e2, e3``.
    """

    name: str
    times: NDArray[np.float64]
    j1: NDArray[np.float64]
    j2: NDArray[np.float64]
    centres: NDArray[np.float64]
    rotations: NDArray[np.float64]

    @property
    def lengths(self) -> NDArray[np.float64]:
        """Segment length ``|J2 - J1|`` per frame in m."""
        return np.linalg.norm(self.j2 - self.j1, axis=1)


def segment_frames(
    markers: MarkerSet,
    *,
    marker_map: Mapping[str, Mapping[str, MarkerRef]],
    max_gap: int = 10,
) -> dict[str, SegmentFrames]:
    """Eq. 27 frames of every segment of ``marker_map`` at every frame of ``markers``.

    Marker gaps up to ``max_gap`` frames are filled (see :meth:`MarkerSet.trajectory`).
    """
    validate_marker_map(marker_map)
    out: dict[str, SegmentFrames] = {}
    for name, spec in marker_map.items():
        j1 = markers.resolve(spec["j1"], max_gap=max_gap)
        j2 = markers.resolve(spec["j2"], max_gap=max_gap)
        m = markers.resolve(spec["m"], max_gap=max_gap)
        try:
            centres, rots = eq27_frames(j1=j1, j2=j2, m=m)
        except ValueError as err:
            raise ValueError(f"{markers.source}: segment {name!r}: {err}") from None
        out[name] = SegmentFrames(
            name=name, times=markers.times, j1=j1, j2=j2, centres=centres, rotations=rots
        )
    return out


def joint_angle(*, proximal: ArrayLike, distal: ArrayLike) -> NDArray[np.float64]:
    """Angle in rad between the ``e1`` axes of two segments' rotations ((F, 3, 3) or (3, 3)).

    With ``e1`` running proximal -> distal joint (Eq. 27), this is the flexion angle: 0 for a
    straight limb (elbow flexion from upper arm + forearm, knee flexion from thigh + shank).
    """
    a = np.asarray(proximal, dtype=float)[..., :, 0]
    b = np.asarray(distal, dtype=float)[..., :, 0]
    cross = np.linalg.norm(np.cross(a, b), axis=-1)
    return np.arctan2(cross, np.sum(a * b, axis=-1))


@dataclass(frozen=True, eq=False, kw_only=True)
class FixedMotion:
    """A segment at rest: centre ``centre`` (m), rotation ``rotation`` (columns e1, e2, e3)."""

    centre: NDArray[np.float64]
    rotation: NDArray[np.float64]

    def __post_init__(self) -> None:
        object.__setattr__(self, "centre", _vec3(self.centre, what="FixedMotion centre"))
        object.__setattr__(
            self, "rotation", check_rotation(self.rotation, what="FixedMotion rotation")
        )

    def pose(self, t: float) -> Pose:
        """The constant pose, zero velocities."""
        return Pose(
            time=t,
            centre=self.centre,
            rotation=self.rotation,
            velocity=np.zeros(3),
            angular_velocity=np.zeros(3),
        )


def _cross3(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """``a x b`` of two 3-vectors (np.cross's arithmetic, without its per-call overhead)."""
    (a0, a1, a2), (b0, b1, b2) = a.tolist(), b.tolist()
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


def _axis_rotation(axis: NDArray[np.float64], angle: float) -> NDArray[np.float64]:
    return Rotation.from_rotvec(angle * axis).as_matrix()


def _ramp_root(a: float) -> float:
    """The x in (0, 1] with x^3 - x^4 / 2 = a, for 0 < a <= 1/2 (the left side rises
    monotonically from 0 to 1/2 on [0, 1]); bisection to the last bit."""
    lo, hi = 0.0, 1.0
    while True:
        mid = 0.5 * (lo + hi)
        if mid in (lo, hi):
            return hi
        if mid**3 * (1.0 - 0.5 * mid) < a:
            lo = mid
        else:
            hi = mid


@dataclass(frozen=True, eq=False, kw_only=True)
class HingeMotion:
    """Rotation about a fixed joint axis at constant rate, stopping at ``angle_max``.

    The segment starts (for ``t <= t_start``) at ``centre0`` / ``rotation0`` and rotates about
    the line through ``joint`` along unit vector ``axis`` (right-hand rule) by
    ``theta(t) = omega * clip(t - t_start, 0, angle_max / omega)``; afterwards it rests.

    ``t_ramp`` > 0 starts the motion smoothly: the rate rises from 0 to ``omega`` over
    ``t_ramp`` seconds as ``omega (3 x^2 - 2 x^3)``, x = (t - t_start) / t_ramp (continuous
    angular acceleration, 0 at both ends of the ramp), so ``theta = omega t_ramp (x^3 - x^4 / 2)``
    in the ramp and ``omega (t - t_start - t_ramp / 2)`` after it: the angle lags the constant
    rate by ``omega t_ramp / 2`` and ``angle_max`` is reached ``t_ramp / 2`` later. An
    ``angle_max`` below ``omega t_ramp / 2`` is reached inside the ramp, at the root x of
    ``omega t_ramp (x^3 - x^4 / 2) = angle_max`` in (0, 1]. The stop at ``angle_max`` stays
    abrupt.

    Attributes
    ----------
    joint : (3,) array
        Joint centre in m (e.g. the elbow).
    axis : (3,) array
        Rotation axis (normalised on construction).
    omega : float
        Angular speed in rad/s, > 0.
    angle_max : float
        Final angle in rad, > 0 (the paper's elbow example: 57 degrees).
    centre0 : (3,) array
        Centre at ``theta = 0`` in m.
    rotation0 : (3, 3) array
        Rotation at ``theta = 0`` (columns e1, e2, e3).
    t_start : float
        Start of the rotation in s.
    t_ramp : float
        Duration of the smooth start in s (0: the rate jumps to ``omega`` at ``t_start``).
    """

    joint: NDArray[np.float64]
    axis: NDArray[np.float64]
    omega: float
    angle_max: float
    centre0: NDArray[np.float64]
    rotation0: NDArray[np.float64]
    t_start: float = 0.0
    t_ramp: float = 0.0
    _t_end: float = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "joint", _vec3(self.joint, what="HingeMotion joint"))
        ax = _vec3(self.axis, what="HingeMotion axis")
        n = float(np.linalg.norm(ax))
        if not n > 0.0:
            raise ValueError("HingeMotion axis: must be a non-zero vector, got (0, 0, 0)")
        object.__setattr__(self, "axis", ax / n)
        for fname in ("omega", "angle_max"):
            v = float(getattr(self, fname))
            if not (np.isfinite(v) and v > 0.0):
                unit = "rad/s" if fname == "omega" else "rad"
                raise ValueError(f"HingeMotion {fname}: must be finite and > 0 {unit}, got {v}")
            object.__setattr__(self, fname, v)
        object.__setattr__(self, "centre0", _vec3(self.centre0, what="HingeMotion centre0"))
        object.__setattr__(
            self, "rotation0", check_rotation(self.rotation0, what="HingeMotion rotation0")
        )
        object.__setattr__(self, "t_start", float(self.t_start))
        tr = float(self.t_ramp)
        if not (np.isfinite(tr) and tr >= 0.0):
            raise ValueError(f"HingeMotion t_ramp: must be finite and >= 0 s, got {tr}")
        object.__setattr__(self, "t_ramp", tr)
        if 0.5 * self.omega * tr >= self.angle_max:  # reached inside the ramp (or at its end)
            t_end = self.t_start + tr * _ramp_root(self.angle_max / (self.omega * tr))
        else:
            t_end = self.t_start + self.angle_max / self.omega + 0.5 * tr
        object.__setattr__(self, "_t_end", t_end)

    @property
    def t_end(self) -> float:
        """Time in s at which ``angle_max`` is reached."""
        return self._t_end

    def angle(self, t: float) -> float:
        """Hinge angle ``theta(t)`` in rad."""
        if self.t_ramp == 0.0:  # (the constant rate's expression, bit for bit)
            return self.omega * min(max(float(t) - self.t_start, 0.0), self.angle_max / self.omega)
        s = min(max(float(t) - self.t_start, 0.0), self.t_end - self.t_start)
        if s < self.t_ramp:
            x = s / self.t_ramp
            return min(self.omega * self.t_ramp * x**3 * (1.0 - 0.5 * x), self.angle_max)
        return min(self.omega * (s - 0.5 * self.t_ramp), self.angle_max)

    def rate(self, t: float) -> float:
        """Angular speed ``d theta / dt`` at ``t`` in rad/s (0 before the start and from
        ``t_end`` on)."""
        if not self.t_start <= t < self.t_end:
            return 0.0
        s = float(t) - self.t_start
        if s < self.t_ramp:
            x = s / self.t_ramp
            return self.omega * x * x * (3.0 - 2.0 * x)
        return self.omega

    def pose(self, t: float) -> Pose:
        """Pose at ``t`` (s); angular velocity ``rate(t) * axis`` (``omega * axis`` for
        ``t_start + t_ramp <= t < t_end``)."""
        r = _axis_rotation(self.axis, self.angle(t))
        centre = self.joint + r @ (self.centre0 - self.joint)
        rate = self.rate(t)
        w = rate * self.axis if rate else np.zeros(3)
        return Pose(
            time=t,
            centre=centre,
            rotation=r @ self.rotation0,
            velocity=_cross3(w, centre - self.joint),
            angular_velocity=w,
        )


@dataclass(frozen=True, eq=False, kw_only=True)
class InterpolatedMotion:
    """Motion interpolated through sampled poses (e.g. Eq. 27 frames from motion capture).

    Centre: cubic spline; rotation: ``RotationSpline`` (see module docstring).  Poses are
    available for ``times[0] <= t <= times[-1]`` only.

    Attributes
    ----------
    times : (F,) array
        Sample times in s, strictly increasing, F >= 2.
    centres : (F, 3) array
        Centres in m.
    rotations : (F, 3, 3) array
        Rotations (columns e1, e2, e3); consecutive ones must differ by < 90 degrees.
    name : str
        Label for error messages.
    """

    times: NDArray[np.float64]
    centres: NDArray[np.float64]
    rotations: NDArray[np.float64]
    name: str = "segment"
    _centre_spline: CubicSpline = field(init=False, repr=False, compare=False)
    _rotation_spline: RotationSpline = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        who = f"motion '{self.name}'"
        t = np.asarray(self.times, dtype=float)
        c = np.asarray(self.centres, dtype=float)
        q = np.asarray(self.rotations, dtype=float)
        if t.ndim != 1 or t.size < 2:
            raise ValueError(f"{who}: times must be 1-D with >= 2 samples, got shape {t.shape}")
        if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0.0):
            raise ValueError(f"{who}: times must be finite and strictly increasing (s)")
        if c.shape != (t.size, 3) or q.shape != (t.size, 3, 3):
            raise ValueError(
                f"{who}: centres/rotations must have shapes ({t.size}, 3)/({t.size}, 3, 3), "
                f"got {c.shape}/{q.shape}"
            )
        if not (np.all(np.isfinite(c)) and np.all(np.isfinite(q))):
            raise ValueError(f"{who}: centres and rotations must be finite (fill marker gaps)")
        for i in range(t.size):
            check_rotation(q[i], what=f"{who}: rotations[{i}]")
        rot = Rotation.from_matrix(q)
        step = (rot[:-1].inv() * rot[1:]).magnitude()
        worst = int(np.argmax(step))
        if step[worst] > _MAX_STEP_ROTATION:
            raise ValueError(
                f"{who}: rotation between samples {worst} and {worst + 1} is "
                f"{np.degrees(step[worst]):.1f} deg, must be <= 90 deg (sample more densely)"
            )
        object.__setattr__(self, "times", t)
        object.__setattr__(self, "centres", c)
        object.__setattr__(self, "rotations", q)
        object.__setattr__(self, "_centre_spline", CubicSpline(t, c, axis=0))
        object.__setattr__(self, "_rotation_spline", RotationSpline(t, rot))

    @classmethod
    def from_frames(cls, frames: SegmentFrames) -> InterpolatedMotion:
        """Interpolated motion through the Eq. 27 frames of one segment."""
        return cls(
            times=frames.times, centres=frames.centres, rotations=frames.rotations, name=frames.name
        )

    def pose(self, t: float) -> Pose:
        """Interpolated pose at ``t`` in s (``ValueError`` outside the sampled time range)."""
        t0, t1 = float(self.times[0]), float(self.times[-1])
        if not t0 <= t <= t1:
            raise ValueError(
                f"motion '{self.name}': time must be within [{t0:.6g}, {t1:.6g}] s, got {t}"
            )
        q = self._rotation_spline(t).as_matrix()
        w_body = self._rotation_spline(t, 1)
        return Pose(
            time=t,
            centre=self._centre_spline(t),
            rotation=q,
            velocity=self._centre_spline(t, 1),
            angular_velocity=q @ w_body,
        )


def segment_markers(
    motion: Motion, *, times: ArrayLike, length: float, roll_offset: float = 0.05
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Synthetic ``J1, J2, M`` trajectories (F, 3) in m carried by ``motion`` at ``times`` (s).

    ``J1, J2`` sit at ``-/+ length/2`` along ``e1`` from the centre, ``M`` at ``roll_offset``
    (m) along ``e2``, so that :func:`eq27_frames` recovers the motion's poses exactly.
    """
    poses = [motion.pose(float(t)) for t in np.asarray(times, dtype=float)]
    local = np.array([[-0.5 * length, 0.0, 0.0], [0.5 * length, 0.0, 0.0], [0.0, roll_offset, 0.0]])
    pts = np.array([p.to_global(local) for p in poses])  # (F, 3, 3)
    return pts[:, 0], pts[:, 1], pts[:, 2]


def body_from_markers(
    markers: MarkerSet,
    *,
    marker_map: Mapping[str, Mapping[str, MarkerRef]],
    radii: Mapping[str, ArrayLike],
    max_gap: int = 10,
) -> Body:
    """A :class:`Body` whose segments follow ``marker_map`` through ``markers`` (Eq. 27).

    ``radii`` gives ``(r1, r2, r3)`` in m for every segment of ``marker_map`` (``r1`` along the
    limb).
    """
    frames = segment_frames(markers, marker_map=marker_map, max_gap=max_gap)
    missing = [s for s in frames if s not in radii]
    if missing:
        raise ValueError(f"radii: must give (r1, r2, r3) in m for every segment, missing {missing}")
    return Body(
        segments=tuple(
            Segment(name=n, radii=radii[n], motion=InterpolatedMotion.from_frames(f))
            for n, f in frames.items()
        )
    )


def arm_flexion_body(
    *,
    elbow: ArrayLike = (0.0, 0.0, 0.0),
    upper_arm_radii: ArrayLike = (0.15, 0.06, 0.06),
    forearm_radii: ArrayLike = (0.20, 0.06, 0.06),
    omega: float = 1.0,
    angle_max: float = float(np.radians(57.0)),
    t_start: float = 0.0,
) -> Body:
    """The paper's Sec. 4.1 arm: fixed upper arm, forearm flexing about the elbow.

    Both segments start collinear along +X (upper arm from the shoulder at
    ``elbow - 2 r1_upper e_x`` to the elbow, forearm from the elbow to the wrist at
    ``elbow + 2 r1_fore e_x``), with ``e2 = +Z`` and ``e3 = e1 x e2 = -Y``.  The forearm rotates
    about the elbow around ``-Y`` (the wrist rises towards +Z) at ``omega`` rad/s until
    ``angle_max`` rad (default 57 degrees).  Radii in m, ``r1`` along the limb (the paper's
    ``r3``).  Segment names: ``"upper_arm"``, ``"forearm"``.
    """
    e = _vec3(elbow, what="arm_flexion_body elbow")
    ru = check_radii(upper_arm_radii, owner="segment 'upper_arm'")
    rf = check_radii(forearm_radii, owner="segment 'forearm'")
    q0 = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]).T  # columns x, z, -y
    upper = Segment(
        name="upper_arm",
        radii=ru,
        motion=FixedMotion(centre=e - np.array([ru[0], 0.0, 0.0]), rotation=q0),
    )
    fore = Segment(
        name="forearm",
        radii=rf,
        motion=HingeMotion(
            joint=e,
            axis=(0.0, -1.0, 0.0),
            omega=omega,
            angle_max=angle_max,
            centre0=e + np.array([rf[0], 0.0, 0.0]),
            rotation0=q0,
            t_start=t_start,
        ),
    )
    return Body(segments=(upper, fore))
