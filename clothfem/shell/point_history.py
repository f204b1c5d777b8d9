"""Material history at quadrature points: the part yarn friction and membrane viscosity share.

A subclass calls :meth:`PointHistory._build` in its constructor (the history of ``dim``
values and the cumulated dissipation density [J/m^3] at the points of the reduced membrane
rule, the strains it follows, the dissipated-energy form), uses
:meth:`PointHistory._point_strains` in its update, and sets the class attribute ``PREFIX``
that names its arrays in checkpoints.
"""

from __future__ import annotations

from collections.abc import Callable

import dolfinx
import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI

__all__ = ["PointHistory"]


class PointHistory:
    """Checkpoint arrays and the dissipated energy of a quadrature-point history."""

    PREFIX = "history"
    mesh: object
    history: fem.Function
    dissipation: fem.Function
    _dissipated_form: fem.FormMetaClass

    def _build(
        self,
        mesh: dolfinx.mesh.Mesh,
        *,
        degree: int,
        dim: int,
        strains: ufl.core.expr.Expr,
        t: fem.Constant,
        dx: ufl.Measure,
        names: tuple[str, str],
        point_strains: Callable[[], np.ndarray] | None = None,
    ) -> None:
        """The Quadrature functions ``history`` (``dim`` values a point) and ``dissipation``
        named ``names`` at the points of the rule of ``degree``, the expression of
        ``strains`` at those points and the form of t D dx. ``point_strains``, if given,
        gives the strains instead (the assumed strains of the MITC9 kernels): (owned cells,
        points, components) in the rule's point order; the history of ghost cells then
        stays as it is (assembly and the dissipated energy read owned cells only)."""
        from ffcx.element_interface import create_quadrature

        cell = mesh.ufl_cell()
        He = ufl.VectorElement("Quadrature", cell, degree, dim=dim, quad_scheme="default")
        De = ufl.FiniteElement("Quadrature", cell, degree, quad_scheme="default")
        self.mesh = mesh
        self.history = fem.Function(fem.FunctionSpace(mesh, He), name=names[0])
        self.dissipation = fem.Function(fem.FunctionSpace(mesh, De), name=names[1])
        points, _ = create_quadrature(cell.cellname(), degree, "default")
        self._source = point_strains
        self._strain = fem.Expression(strains, points) if point_strains is None else None
        self._nq = len(points)
        self._dissipated_form = fem.form(t * self.dissipation * dx)

    def _point_strains(self) -> tuple[np.ndarray, np.ndarray]:
        """The strains at the points of every local cell (owned and ghost; owned only from
        ``point_strains``), shape (cells, points, components), and the dofs of those points
        in ``history`` / ``dissipation`` (cells, points); no collective call."""
        imap = self.mesh.topology.index_map(2)
        n_cells = imap.size_local + imap.num_ghosts
        dofs = self.dissipation.function_space.dofmap.list.array.reshape(-1, self._nq)
        if self._source is not None:
            e = self._source()
            return e, dofs[: e.shape[0]]
        e = self._strain.eval(np.arange(n_cells, dtype=np.int32)).reshape(n_cells, self._nq, -1)
        return e, dofs[:n_cells]

    def state_arrays(self) -> dict[str, np.ndarray]:
        """The history and the cumulated dissipation (local arrays, for a checkpoint)."""
        return {
            f"{self.PREFIX}_history": self.history.x.array.copy(),
            f"{self.PREFIX}_dissipation": self.dissipation.x.array.copy(),
        }

    def restore_arrays(self, data: dict[str, np.ndarray]) -> None:
        """Restore :meth:`state_arrays` of the same model and partition, before the model
        assembles at a new state (it caches its residual by state, e.g. restore on the
        freshly built model of a resumed run)."""
        for name, f in (
            (f"{self.PREFIX}_history", self.history),
            (f"{self.PREFIX}_dissipation", self.dissipation),
        ):
            if data[name].shape != f.x.array.shape:
                raise ValueError(
                    f"{name} must have shape {f.x.array.shape} (same model and partition), "
                    f"got {data[name].shape}"
                )
            f.x.array[:] = data[name]

    def dissipated(self) -> float:
        """Energy [J] dissipated since the start (collective)."""
        return self.mesh.comm.allreduce(fem.assemble_scalar(self._dissipated_form), op=MPI.SUM)
