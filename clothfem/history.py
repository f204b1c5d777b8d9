"""The one history format: the columns of ``history.csv`` with their units.

Every runner (quasi-static with or without a body, Newmark, explicit) writes the same
columns in the same order; a column a runner does not measure is left empty (read back as
nan by :func:`clothfem.report.read_history`). ``history_columns.csv`` beside the history
(written with it) lists each column's unit and meaning: ``column,unit,meaning``.
"""

from __future__ import annotations

import csv
from pathlib import Path

__all__ = ["COLUMNS", "UNITS_FILE", "write_units", "check_row", "yarn_strain_columns"]

UNITS_FILE = "history_columns.csv"

# (name, unit, meaning); "-" for dimensionless numbers and counts
COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("stage", "-", "settle (loads coming on, body at rest), motion, or load (no body)"),
    ("increment", "-", "row number within the run (accepted step, increment or row)"),
    ("time", "s", "time at the end of the row (quasi-static: the motion's time)"),
    ("dt", "s", "step size (explicit: of the row's last step)"),
    ("load_factor", "-", "factor on the loads (gravity ramps to 1)"),
    ("angle_deg", "deg", "angle of the torque segment's hinge"),
    ("torque_x", "N m", "Eq. 28 torque about the joint centre, x"),
    ("torque_y", "N m", "Eq. 28 torque about the joint centre, y"),
    ("torque_z", "N m", "Eq. 28 torque about the joint centre, z"),
    ("torque_mag", "N m", "|tau| of Eq. 28"),
    ("torque_flex", "N m", "tau . hinge axis"),
    (
        "torque_flex_pinched",
        "N m",
        "newmark, two or more segments: the part of torque_flex from fabric nodes pressed "
        "by two segments at once (fabric pinched where the segments meet)",
    ),
    ("resultant_x", "N", "resultant of the contact forces on the body, x"),
    ("resultant_y", "N", "resultant of the contact forces on the body, y"),
    ("resultant_z", "N", "resultant of the contact forces on the body, z"),
    ("n_active", "-", "nodes in contact"),
    ("max_penetration", "m", "largest penetration into the body after the step"),
    ("predictor_penetration", "m", "explicit: largest penetration of the contact-free predictor"),
    (
        "tissue_indentation",
        "m",
        "contact.tissue_stiffness: the largest give of the body's surface under the fabric",
    ),
    ("min_multiplier", "N", "implicit: smallest normal multiplier of the active set"),
    ("complementarity", "N m", "implicit: max |lambda gap| over the nodes"),
    ("sum_lam", "N", "sum of the normal contact forces"),
    ("n_stick", "-", "contact nodes sticking"),
    ("n_slip", "-", "contact nodes slipping"),
    ("substeps", "-", "steps or sub-steps in the row"),
    ("cutbacks", "-", "step cut-backs in the row"),
    ("active_set_iterations", "-", "implicit: active-set passes in the row"),
    ("newton_iterations", "-", "Newton iterations in the row"),
    ("residual", "-", "static without a body: final residual norm of the load step"),
    ("stabilization_force", "N", "quasi-static: force of the viscous stabilization"),
    ("min_yarn_strain", "-", "smallest Green strain along the yarns (-0.5: a crushed fold)"),
    ("max_yarn_strain", "-", "largest Green strain along the yarns"),
    ("kinetic_energy", "J", "kinetic energy of the fabric"),
    ("strain_energy", "J", "strain energy of the fabric (with the stored friction energy)"),
    ("external_work", "J", "explicit: work of the loads (gravity) since the start"),
    ("joint_work", "J", "work of the measured joint against the garment, -int tau_seg . omega"),
    ("dissipation_total", "J", "energy dissipated by contact friction since the start"),
    ("dissipation_material", "J", "energy dissipated by the fabric (yarn friction, viscosity)"),
    (
        "self_pairs",
        "-",
        "self-contact: fabric-fabric pairs in contact, last step (newmark: within the barrier)",
    ),
    (
        "self_min_gap",
        "m",
        "self-contact: smallest pair gap after the corrections (newmark: of the last step)",
    ),
    (
        "self_crossings",
        "-",
        "self-contact: crossing pairs the fail-safe found in the row (newmark: 0, filtered)",
    ),
    ("self_crossings_left", "-", "self-contact: crossing pairs left after the fail-safe"),
    ("self_zone_nodes", "-", "explicit self-contact: nodes moved in impact zones in the row"),
    (
        "self_friction_work",
        "J",
        "self-contact: energy dissipated by the friction between layers since the start",
    ),
    (
        "self_intersections",
        "-",
        "intersecting triangle pairs of the fabric by the independent check, at field frames",
    ),
    ("t_assembly", "s", "wall time of the row's assembly"),
    ("t_contact", "s", "wall time of the row's contact work (body contact)"),
    ("t_self_contact", "s", "wall time of the row's self-contact corrections and checks"),
    ("t_solve", "s", "wall time of the row's linear solves"),
    ("t_io", "s", "wall time of the row's field output"),
    ("wall_time", "s", "wall time of the row"),
    ("elapsed", "s", "wall time since the run started"),
)
NAMES = tuple(name for name, _, _ in COLUMNS)


def check_row(row: dict[str, object]) -> None:
    """Raise ValueError if ``row`` has a column outside :data:`COLUMNS` (a runner's bug)."""
    unknown = [k for k in row if k not in NAMES]
    if unknown:
        raise ValueError(f"history row has unknown column(s) {unknown}; add them to COLUMNS")


def write_units(folder: str | Path) -> Path:
    """Write ``folder/history_columns.csv`` (column, unit, meaning); returns its path."""
    path = Path(folder) / UNITS_FILE
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["column", "unit", "meaning"])
        w.writerows(COLUMNS)
    return path


def yarn_strain_columns(model) -> dict[str, float]:
    """The ``min_yarn_strain`` / ``max_yarn_strain`` columns of a
    :class:`clothfem.shell.ShellModel` at its current state (collective)."""
    lo, hi = model.yarn_strain_range()
    return {"min_yarn_strain": lo, "max_yarn_strain": hi}
