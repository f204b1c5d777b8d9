"""Material history at quadrature points: the part yarn friction and membrane viscosity share.

A subclass sets ``self.mesh``, ``self.history`` (the committed state at the points of the
reduced membrane rule), ``self.dissipation`` (the cumulated dissipation density [J/m^3] at
the same points) and ``self._dissipated_form`` (``t D dx``), and the class attribute
``PREFIX`` that names its arrays in checkpoints.
"""

from __future__ import annotations

import numpy as np
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
