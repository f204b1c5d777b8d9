"""Results as they are produced: XDMF fields, a CSV step history, PNG snapshots.

:class:`ResultWriter` is a context manager: every step is flushed to disk when written, and
the files are closed cleanly if the run stops with an exception, so a run that dies keeps
what it wrote. Pictures are drawn on rank 0 from data gathered over the communicator.
"""

from __future__ import annotations

import csv
from pathlib import Path

import dolfinx
import numpy as np
from dolfinx import io
from mpi4py import MPI

__all__ = ["ResultWriter", "snapshot_png"]


class ResultWriter:
    """XDMF file of the displacement (and extra fields) plus a CSV history, in ``out``."""

    def __init__(
        self, out: str | Path, model, *, name: str = "fabric", keep_rows: int | None = None
    ) -> None:
        """``keep_rows``: continue an existing ``history.csv`` after its first ``keep_rows``
        rows (later rows are dropped: a resumed run rewrites them); None starts a new one."""
        self.out = Path(out)
        self.comm = model.comm
        if self.comm.rank == 0:
            self.out.mkdir(parents=True, exist_ok=True)
        self.comm.barrier()
        self.model = model
        self.xdmf = io.XDMFFile(self.comm, str(self.out / f"{name}.xdmf"), "w")
        self.xdmf.write_mesh(model.mesh)
        self.csv_path = self.out / "history.csv"
        self._csv = None
        self._writer = None
        if keep_rows is not None and self.comm.rank == 0:
            with open(self.csv_path, newline="") as fh:
                reader = csv.DictReader(fh)
                fields, rows = reader.fieldnames, list(reader)[:keep_rows]
            self._csv = open(self.csv_path, "w", newline="")  # noqa: SIM115
            self._writer = csv.DictWriter(self._csv, fieldnames=fields)
            self._writer.writeheader()
            self._writer.writerows(rows)
            self._csv.flush()

    def write_fields(self, time: float, fields=()) -> None:
        """Write the displacement (and ``fields``) at ``time`` to the XDMF file."""
        self.xdmf.write_function(self.model.u, time)
        for f in fields:
            self.xdmf.write_function(f, time)

    def write(self, time: float, row: dict[str, float], fields=()) -> None:
        """Write the state at ``time`` and append ``row`` to the CSV history (flushed)."""
        self.write_fields(time, fields)
        self.append_row(row)

    def append_row(self, row: dict[str, float]) -> None:
        """Append ``row`` to the CSV history (flushed at once) without writing fields."""
        if self.comm.rank == 0:
            if self._writer is None:
                self._csv = open(self.csv_path, "w", newline="")  # noqa: SIM115
                self._writer = csv.DictWriter(self._csv, fieldnames=list(row))
                self._writer.writeheader()
            self._writer.writerow(row)
            self._csv.flush()

    def close(self) -> None:
        self.xdmf.close()
        if self._csv is not None:
            self._csv.close()

    def __enter__(self) -> ResultWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _gather_surface(model):
    """Deformed quadrilateral/triangle faces (split from the quadratic cells) on rank 0."""
    V = model.V
    topology, cell_types, x = dolfinx.plot.create_vtk_mesh(V)
    n_cells = model.mesh.topology.index_map(2).size_local
    u = model.u.x.array.reshape(-1, 3)
    points = x + u
    nper = topology[0]
    cells = topology.reshape(-1, nper + 1)[:n_cells, 1:]
    gathered = model.comm.gather((points, cells), root=0)
    if model.comm.rank != 0:
        return None, None
    pts, cls, off = [], [], 0
    for p, c in gathered:
        pts.append(p)
        cls.append(c + off)
        off += len(p)
    return np.vstack(pts), np.vstack(cls)


def snapshot_png(
    model, path: str | Path, *, title: str = "", extra_meshes=(), view: str = "iso"
) -> None:
    """Draw the deformed fabric (and optional pyvista meshes, e.g. ellipsoids) to a PNG;
    ``view``: "iso" (isometric) or "xz" (side view along y)."""
    points, cells = _gather_surface(model)
    if model.comm.rank != 0:
        return
    import pyvista as pv

    pv.OFF_SCREEN = True
    nper = cells.shape[1]
    corners = 4 if nper in (4, 9) else 3
    faces = np.hstack([np.full((len(cells), 1), corners), cells[:, :corners]]).ravel()
    surf = pv.PolyData(points, faces)
    plotter = pv.Plotter(off_screen=True, window_size=(1000, 700))
    plotter.add_mesh(surf, color="#4a7bd0", show_edges=True, edge_color="#1c2c4c")
    for m in extra_meshes:
        plotter.add_mesh(m, color="#e0b090", opacity=0.5)
    if title:
        plotter.add_text(title, font_size=12)
    if view == "xz":
        plotter.view_xz()
        plotter.camera.elevation = 15.0
        plotter.camera.azimuth = 20.0
    else:
        plotter.view_isometric()
    plotter.screenshot(str(path))
    plotter.close()


def rank0_print(*args, comm: MPI.Comm = MPI.COMM_WORLD) -> None:
    """print() on rank 0 only."""
    if comm.rank == 0:
        print(*args, flush=True)
