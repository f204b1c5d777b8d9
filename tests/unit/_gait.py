"""The right thigh and shank of the shipped gait recording as scene [[body]] tables (shared
by the scene tests of recorded segments)."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
WALK = ROOT / "data" / "mocap" / "walk_cgm_lowerlimb.c3d"


def right_leg(seg: dict) -> list[dict]:
    """[thigh, shank]: Eq. 27 markers, radii [m], the thigh placed along -z from (0, 0, 0.7)
    m; ``seg`` (type, file, window, repeat keys) is shared by both."""
    thigh = {
        "name": "R_thigh", "j1": "RFEP", "j2": "RFEO", "m": "RFEA",
        "radii": [0.23, 0.066, 0.066], "centre": [0.0, 0.0, 0.7],
        "axis": [0.0, 0.0, -1.0], "up": [0.0, 1.0, 0.0], **seg,
    }  # fmt: skip
    shank = {
        "name": "R_shank", "j1": "RFEO", "j2": "RTIO", "m": "RTIA",
        "radii": [0.24, 0.063, 0.063], "placed_by": "R_thigh", **seg,
    }  # fmt: skip
    return [thigh, shank]
