"""Fabric-body contact as a pipeline, in pure NumPy (no FEM imports).

detect candidates -> gaps and normals -> multipliers / forces -> friction -> diagnostics

Sign conventions used throughout:

* ``gap = (x - p) . n`` is the signed distance of a fabric node ``x`` to the body surface
  (``p`` exact closest point, ``n`` outward unit normal); ``gap < 0`` is penetration.  The paper's
  Eq. 15 ``g`` equals ``-gap``.
* ``lam_n >= 0`` (N) is the compressive normal force magnitude; the force on the fabric is
  ``+lam_n n``, on the body ``-lam_n n``.  Friction forces are forces on the fabric.
* :func:`joint_torque` (Eq. 28) takes forces **on the body**.

The FEM-coupled implicit solver (Lagrange multipliers with active-set iterations, Coulomb
friction) is :mod:`clothfem.contact.lagrange`; import it explicitly (it needs dolfinx), so that
``import clothfem.contact`` stays FEM-free.

Fabric self-contact for the explicit integrator (proximity corrections and a crossing
fail-safe on the triangulated fabric surface) is :mod:`clothfem.contact.self_contact`; the
independent intersection checker is :mod:`clothfem.contact.intersections`.

Ellipsoids are plain ``(c, Q, r)`` triples: centre (3,) m, axes as the columns of ``Q`` (local
coordinates ``y = Q^T (x - c)``), radii (3,) m.
"""

from clothfem.contact.explicit import FilmResult, film_step
from clothfem.contact.forces import (
    ContactDiagnostics,
    contact_forces,
    contact_pressure,
    diagnostics,
    joint_torque,
    node_selection,
    resultant_force,
)
from clothfem.contact.friction import (
    FrictionResult,
    body_point_velocity,
    coulomb_return_map,
    coulomb_slip_update,
    relative_tangential_velocity,
    tangential_part,
)
from clothfem.contact.geometry import (
    EllipsoidData,
    Projection,
    UnionProjection,
    candidates,
    check_ellipsoid,
    check_points,
    closest_point_ellipsoid,
    closest_point_union,
    closest_points,
    gap_lower_bound,
    gradient_projection,
    implicit_value,
    radial_projection,
)
from clothfem.contact.intersections import (
    SurfaceCheck,
    check_surface,
    intersecting_pairs,
    layer_distance,
)
from clothfem.contact.self_contact import (
    FabricSurface,
    SelfContact,
    SelfContactParameters,
    SelfContactResult,
    fabric_surface,
    self_contact_step,
    triangulate_q9,
)

__all__ = [
    "ContactDiagnostics",
    "FabricSurface",
    "SelfContact",
    "SelfContactParameters",
    "SelfContactResult",
    "SurfaceCheck",
    "check_surface",
    "fabric_surface",
    "intersecting_pairs",
    "layer_distance",
    "self_contact_step",
    "triangulate_q9",
    "EllipsoidData",
    "FilmResult",
    "FrictionResult",
    "Projection",
    "UnionProjection",
    "body_point_velocity",
    "candidates",
    "check_ellipsoid",
    "check_points",
    "closest_point_ellipsoid",
    "closest_point_union",
    "closest_points",
    "gap_lower_bound",
    "contact_forces",
    "contact_pressure",
    "coulomb_return_map",
    "coulomb_slip_update",
    "diagnostics",
    "film_step",
    "gradient_projection",
    "implicit_value",
    "joint_torque",
    "node_selection",
    "radial_projection",
    "relative_tangential_velocity",
    "resultant_force",
    "tangential_part",
]
