"""Results as they are produced: an XDMF field series, a CSV step history, PNG snapshots,
an animation and a progress display.

:class:`ResultWriter` is a context manager. Every row of ``history.csv`` is flushed when it
is written; every field step of ``<name>.xdmf`` / ``<name>.h5`` (:class:`FieldSeries`) is
written with the HDF5 file closed afterwards and the XDMF file replaced atomically, so a run
killed at any moment (even by SIGKILL) leaves readable files that end at the last written
step. Pictures are drawn on rank 0 from data gathered over the communicator.

The XDMF file is one temporal collection whose grids each carry the mesh (linear cells: a
nine-node quadrilateral is drawn as its four sub-quadrilaterals, a six-node triangle as four
triangles, so no node is lost) and every field of that time: ParaView (and pyvista's
``XdmfReader``) and ``meshio.xdmf.TimeSeriesReader`` read it.
"""

from __future__ import annotations

import csv
import os
import sys
import time as _time
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from mpi4py import MPI

from .history import NAMES as HISTORY_NAMES
from .history import check_row, write_units

__all__ = [
    "FieldSeries",
    "Progress",
    "ResultWriter",
    "animate_series",
    "rank0_print",
    "read_series",
    "snapshot_png",
]

# sub-cells of a VTK cell: (VTK type, XDMF topology of the pieces, local node lists)
_SPLIT = {
    9: ("Quadrilateral", [[0, 1, 2, 3]]),  # VTK_QUAD
    5: ("Triangle", [[0, 1, 2]]),  # VTK_TRIANGLE
    28: (  # VTK_BIQUADRATIC_QUAD: corners, edge midpoints (01, 12, 23, 30), centre
        "Quadrilateral",
        [[0, 4, 8, 7], [4, 1, 5, 8], [8, 5, 2, 6], [7, 8, 6, 3]],
    ),
    22: ("Triangle", [[0, 3, 5], [3, 1, 4], [5, 4, 2], [3, 4, 5]]),  # VTK_QUADRATIC_TRIANGLE
}
_SPLIT[70] = _SPLIT[28]  # VTK_LAGRANGE_QUADRILATERAL of degree 2: the same node order
_SPLIT[69] = _SPLIT[22]  # VTK_LAGRANGE_TRIANGLE of degree 2


def _use_offscreen_gl() -> None:
    """Without an X display, render with EGL (VTK otherwise warns 'bad X server connection'
    before it falls back); set before VTK creates its first window."""
    if not os.environ.get("DISPLAY"):
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")


class _Layout:
    """The global node numbering of the model's node space, gathered once (collective):
    owned nodes' global ids and reference positions, and the linear sub-cells on rank 0."""

    def __init__(self, model) -> None:
        import dolfinx.plot

        self.comm = model.comm
        V = model.V
        im = V.dofmap.index_map
        self.n_owned = im.size_local
        gids = im.local_to_global(np.arange(im.size_local + im.num_ghosts, dtype=np.int32))
        self.gids = np.asarray(gids[: self.n_owned], dtype=np.int64)
        topology, cell_types, x = dolfinx.plot.create_vtk_mesh(V)
        n_cells = model.mesh.topology.index_map(2).size_local
        vtk_type = int(cell_types[0]) if len(cell_types) else -1
        kinds = self.comm.allgather(vtk_type)
        vtk_type = max(kinds)
        if vtk_type not in _SPLIT:
            raise ValueError(f"cell type VTK {vtk_type} is not supported by the field writer")
        self.cell_type, pieces = _SPLIT[vtk_type]
        nper = topology[0] if len(topology) else 0
        cells = topology.reshape(-1, nper + 1)[:n_cells, 1:] if n_cells else np.zeros((0, 1))
        sub = np.concatenate([cells[:, p] for p in pieces], axis=0) if n_cells else cells
        sub_global = np.asarray(gids, dtype=np.int64)[sub.astype(np.int64)] if n_cells else sub
        gathered = self.comm.gather((self.gids, x[: self.n_owned], sub_global), root=0)
        self.n_global = im.size_global
        self.points = self.cells = None
        if self.comm.rank == 0:
            self.points = np.zeros((self.n_global, 3))
            for g, p, _ in gathered:
                self.points[g] = p
            self.cells = np.vstack([c for _, _, c in gathered if len(c)]).astype(np.int64)

    def gather(self, values: np.ndarray) -> np.ndarray | None:
        """Owned nodal values (n_owned, k) of every rank as (n_global, k) on rank 0."""
        parts = self.comm.gather((self.gids, values), root=0)
        if self.comm.rank != 0:
            return None
        out = np.zeros((self.n_global, values.shape[1]))
        for g, v in parts:
            out[g] = v
        return out


def _nodal(f, n_owned: int) -> np.ndarray:
    """A function's owned nodal values (n_owned, block size)."""
    bs = f.function_space.dofmap.index_map_bs
    return np.asarray(f.x.array[: n_owned * bs]).reshape(n_owned, bs)


class FieldSeries:
    """``<out>/<name>.xdmf`` + ``<name>.h5``: the displacement and other nodal fields over time.

    ``resume_after`` [s]: continue the series of an interrupted run: steps later than that
    time (written after the checkpoint the run resumes from) are dropped, and the next steps
    are appended to the same files. Times written must increase; a time not later than the
    last one written is skipped, so the series never holds a time twice.
    """

    def __init__(
        self, out: str | Path, model, *, name: str = "fabric", resume_after: float | None = None
    ) -> None:
        self.layout = _Layout(model)
        self.comm = model.comm
        self.xdmf = Path(out) / f"{name}.xdmf"
        self.h5 = Path(out) / f"{name}.h5"
        self.steps: list[tuple[str, float, list[tuple[str, int]]]] = []  # group, time, fields
        if self.comm.rank == 0:
            self._open(resume_after)
        last = self.steps[-1][1] if self.steps else -np.inf
        self.last_time: float = self.comm.bcast(last, root=0)

    def _open(self, resume_after: float | None) -> None:
        import h5py

        lay = self.layout
        if resume_after is None or not self.h5.exists():
            with h5py.File(self.h5, "w") as f:
                f["mesh/geometry"] = lay.points
                f["mesh/topology"] = lay.cells
                f.attrs["cell_type"] = lay.cell_type
        else:
            with h5py.File(self.h5, "a") as f:
                for group in sorted(k for k in f if k.startswith("step")):
                    t = float(f[group].attrs["time"])
                    if t > resume_after * (1 + 1e-12) + 1e-15:
                        del f[group]
                        continue
                    fields = [(k, int(np.prod(f[group][k].shape[1:]))) for k in f[group]]
                    self.steps.append((group, t, fields))
        self._write_xml()

    def write(self, time: float, fields: Sequence) -> None:
        """Write the functions ``fields`` (on the model's node layout; each named by its
        ``name``) at ``time`` [s or load factor]; collective."""
        if not time > self.last_time:
            return
        values = [(f.name, self.layout.gather(_nodal(f, self.layout.n_owned))) for f in fields]
        self.last_time = float(time)
        if self.comm.rank != 0:
            return
        import h5py

        index = int(self.steps[-1][0][4:]) + 1 if self.steps else 0
        group = f"step{index:06d}"
        with h5py.File(self.h5, "a") as f:  # closed after every step: readable if killed
            g = f.create_group(group)
            g.attrs["time"] = float(time)
            for name, v in values:
                g[name] = v[:, 0] if v.shape[1] == 1 else v  # scalars as 1-D data
            f.flush()
        self.steps.append((group, float(time), [(n, v.shape[1]) for n, v in values]))
        self._write_xml()

    def _write_xml(self) -> None:
        lay, h5 = self.layout, self.h5.name
        root = ET.Element("Xdmf", Version="3.0")
        dom = ET.SubElement(root, "Domain")
        coll = ET.SubElement(
            dom, "Grid", Name="fabric", GridType="Collection", CollectionType="Temporal"
        )

        def item(parent, path: str, dims: tuple[int, ...], kind: str = "Float") -> None:
            d = ET.SubElement(
                parent,
                "DataItem",
                DataType=kind,
                Dimensions=" ".join(str(n) for n in dims),
                Format="HDF",
                Precision="8",
            )
            d.text = f"{h5}:/{path}"

        n_pts, (n_cells, n_per) = len(lay.points), lay.cells.shape
        for group, t, fields in self.steps:
            g = ET.SubElement(coll, "Grid", Name=group, GridType="Uniform")
            topo = ET.SubElement(
                g, "Topology", TopologyType=lay.cell_type, NumberOfElements=str(n_cells)
            )
            item(topo, "mesh/topology", (n_cells, n_per), "Int")
            item(ET.SubElement(g, "Geometry", GeometryType="XYZ"), "mesh/geometry", (n_pts, 3))
            ET.SubElement(g, "Time", Value=repr(t))
            for name, k in fields:
                a = ET.SubElement(
                    g,
                    "Attribute",
                    Name=name,
                    AttributeType="Vector" if k == 3 else "Scalar",
                    Center="Node",
                )
                item(a, f"{group}/{name}", (n_pts, k) if k > 1 else (n_pts,))
        tmp = self.xdmf.with_suffix(".xdmf.tmp")
        ET.ElementTree(root).write(tmp, xml_declaration=True, encoding="utf-8")
        os.replace(tmp, self.xdmf)  # a killed run keeps the previous complete file


def read_series(h5: str | Path) -> tuple[np.ndarray, np.ndarray, list[tuple[float, dict]]]:
    """Reference points, linear cells and ``[(time, {field: values})]`` of a field series."""
    import h5py

    with h5py.File(h5, "r") as f:
        points, cells = f["mesh/geometry"][...], f["mesh/topology"][...]
        steps = [
            (float(f[g].attrs["time"]), {k: f[g][k][...] for k in f[g]})
            for g in sorted(k for k in f if k.startswith("step"))
        ]
    return points, cells, steps


class ResultWriter:
    """The field series (:class:`FieldSeries`) plus the CSV history, in ``out``."""

    def __init__(
        self,
        out: str | Path,
        model,
        *,
        name: str = "fabric",
        keep_rows: int | None = None,
        resume_after: float | None = None,
        columns: Sequence[str] | None = None,
    ) -> None:
        """``keep_rows``: continue an existing ``history.csv`` after its first ``keep_rows``
        rows (later rows are dropped: a resumed run rewrites them); None starts a new one.
        ``resume_after``: continue the field series after that time (:class:`FieldSeries`).
        ``columns``: the history's columns; None: the runners' one format
        (:data:`clothfem.history.COLUMNS`, with its units file ``history_columns.csv``)."""
        self.columns = tuple(HISTORY_NAMES if columns is None else columns)
        self._standard = columns is None
        self.out = Path(out)
        self.comm = model.comm
        if self.comm.rank == 0:
            self.out.mkdir(parents=True, exist_ok=True)
        self.comm.barrier()
        self.model = model
        self.series = FieldSeries(self.out, model, name=name, resume_after=resume_after)
        self.csv_path = self.out / "history.csv"
        self._csv = None
        self._writer = None
        if keep_rows is not None and self.comm.rank == 0:
            with open(self.csv_path, newline="") as fh:
                reader = csv.DictReader(fh)
                fields, rows = list(reader.fieldnames or ()), list(reader)[:keep_rows]
            if self._standard:  # today's columns (a history written before a column was
                # added gets it, empty in its old rows), and any old column kept
                fields = [*self.columns, *(f for f in fields if f not in self.columns)]
            self._csv = open(self.csv_path, "w", newline="")  # noqa: SIM115
            self._writer = csv.DictWriter(self._csv, fieldnames=fields)
            self._writer.writeheader()
            self._writer.writerows(rows)
            self._csv.flush()
            if self._standard:
                write_units(self.out)

    @property
    def last_time(self) -> float:
        """Time of the last field step written (-inf before the first)."""
        return self.series.last_time

    def write_fields(self, time: float, fields=()) -> None:
        """Write the displacement (and ``fields``) at ``time`` to the field series."""
        self.model.u.name = "displacement"
        self.series.write(time, [self.model.u, *fields])

    def write(self, time: float, row: dict[str, float], fields=()) -> None:
        """Write the state at ``time`` and append ``row`` to the CSV history (flushed)."""
        self.write_fields(time, fields)
        self.append_row(row)

    def append_row(self, row: dict[str, float]) -> None:
        """Append ``row`` to the CSV history (flushed at once) without writing fields. The
        history has the writer's ``columns``, in that order (those ``row`` lacks are left
        empty); with the standard columns the first row also writes their units beside it."""
        if self._standard:
            check_row(row)
        elif set(row) - set(self.columns):
            raise ValueError(f"history row has columns outside {self.columns}: {sorted(row)}")
        if self.comm.rank == 0:
            if self._writer is None:
                self._csv = open(self.csv_path, "w", newline="")  # noqa: SIM115
                self._writer = csv.DictWriter(self._csv, fieldnames=list(self.columns))
                self._writer.writeheader()
                if self._standard:
                    write_units(self.out)
            self._writer.writerow(row)
            self._csv.flush()
            os.fsync(self._csv.fileno())

    def close(self) -> None:
        if self._csv is not None:
            self._csv.close()
            self._csv = None

    def __enter__(self) -> ResultWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _surface(points: np.ndarray, cells: np.ndarray):
    import pyvista as pv

    faces = np.hstack([np.full((len(cells), 1), cells.shape[1]), cells]).ravel()
    return pv.PolyData(points, faces)


CMAP = "viridis"


def _render(
    plotter,
    points: np.ndarray,
    cells: np.ndarray,
    *,
    scalars: np.ndarray,
    clim: tuple[float, float],
    extra_meshes: Iterable = (),
) -> None:
    surf = _surface(points, cells)
    surf.point_data["value"] = scalars
    plotter.add_mesh(
        surf,
        scalars="value",
        cmap=CMAP,
        clim=clim,
        smooth_shading=True,
        show_edges=False,
        show_scalar_bar=False,  # VTK's bar crashes once dolfinx is loaded: matplotlib draws it
    )
    for m in extra_meshes:  # the body, opaque
        plotter.add_mesh(m, color="#d9b38c", opacity=1.0, smooth_shading=True)


def _pyplot():
    """matplotlib.pyplot with the non-interactive Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _clim(scalars: np.ndarray, *, robust: bool = False) -> tuple[float, float]:
    """The colour range: min to max, or (``robust``, for contact pressures that peak at a few
    nodes) 0 to the 95th percentile of the positive values."""
    lo, hi = float(np.min(scalars)), float(np.max(scalars))
    if robust:
        pos = scalars[scalars > 0]
        lo, hi = 0.0, float(np.percentile(pos, 95)) if len(pos) else 0.0
    return (lo, hi) if hi > lo else (lo, lo + 1.0)


def _with_colour_bar(
    image: np.ndarray, *, clim: tuple[float, float], label: str, title: str, extend: str
):
    """A matplotlib figure of a rendered ``image`` with a colour bar of ``clim`` (the caller
    saves and closes it)."""
    plt = _pyplot()
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    h, w = image.shape[:2]
    fig, ax = plt.subplots(figsize=(w / 100 + 1.6, h / 100), dpi=100)
    ax.imshow(image)
    ax.set_axis_off()
    if title:
        ax.set_title(title, fontsize=10)
    bar = ScalarMappable(norm=Normalize(*clim), cmap=CMAP)
    fig.colorbar(bar, ax=ax, fraction=0.04, pad=0.02, label=label, extend=extend)
    fig.tight_layout()
    return fig


def _figure_array(fig) -> np.ndarray:
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()


def _camera(plotter, view: str) -> None:
    if view == "xz":
        plotter.view_xz()
        plotter.camera.elevation = 15.0
        plotter.camera.azimuth = 20.0
    else:
        plotter.view_isometric()


def snapshot_png(
    model,
    path: str | Path,
    *,
    title: str = "",
    extra_meshes=(),
    view: str = "iso",
    pressure=None,
) -> None:
    """Draw the deformed fabric to a PNG, coloured by the contact pressure [Pa] (``pressure``,
    a nodal function) or else by the displacement magnitude [m], with a colour bar; optional
    pyvista meshes (e.g. the body's ellipsoids) are drawn opaque. Every node of a second-order
    cell is drawn (four sub-cells, smooth shading). ``view``: "iso" or "xz" (side view along y).
    Collective; rank 0 draws."""
    layout = _Layout(model)
    u = layout.gather(_nodal(model.u, layout.n_owned))
    p = layout.gather(_nodal(pressure, layout.n_owned)) if pressure is not None else None
    if model.comm.rank != 0:
        return
    _use_offscreen_gl()
    import pyvista as pv

    plt = _pyplot()
    plotter = pv.Plotter(off_screen=True, window_size=(1000, 700))
    if p is not None:
        scalars, label = p[:, 0], "contact pressure [Pa]"
    else:
        scalars, label = np.linalg.norm(u, axis=1), "|u| [m]"
    clim = _clim(scalars, robust=p is not None)
    _render(
        plotter,
        layout.points + u,
        layout.cells,
        scalars=scalars,
        clim=clim,
        extra_meshes=extra_meshes,
    )
    _camera(plotter, view)
    image = plotter.screenshot(return_img=True)
    plotter.close()
    extend = "max" if p is not None else "neither"
    fig = _with_colour_bar(image, clim=clim, label=label, title=title, extend=extend)
    fig.savefig(path)
    plt.close(fig)


def _colour_bar_panel(
    *, height: int, clim: tuple[float, float], label: str, extend: str
) -> np.ndarray:
    """An RGB image (height x ~1.6 in) of a vertical colour bar of ``clim``."""
    plt = _pyplot()
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    fig = plt.figure(figsize=(1.6, height / 100), dpi=100)
    ax = fig.add_axes((0.08, 0.08, 0.18, 0.84))
    bar = ScalarMappable(norm=Normalize(*clim), cmap=CMAP)
    fig.colorbar(bar, cax=ax, label=label, extend=extend)
    image = _figure_array(fig)
    plt.close(fig)
    return image[:height]


def animate_series(
    h5: str | Path,
    gif: str | Path,
    *,
    bodies_at: Callable[[float], list] | None = None,
    title: str = "",
    view: str = "iso",
    max_frames: int = 60,
    frame_ms: int = 100,
) -> Path | None:
    """A GIF of a field series (rank 0 only, no MPI): the deformed fabric at up to
    ``max_frames`` written times, coloured by the contact pressure when the series has it
    (one colour scale for the whole run), with the pyvista meshes ``bodies_at(t)`` (the body)
    drawn opaque; the camera is fixed by the first frame. None when the series has < 2 steps.
    One render window for all frames (the meshes are updated in place)."""
    _use_offscreen_gl()
    import pyvista as pv
    from PIL import Image

    points, cells, steps = read_series(h5)
    if len(steps) < 2:
        return None
    pick = np.unique(np.linspace(0, len(steps) - 1, min(max_frames, len(steps))).round())
    steps = [steps[int(i)] for i in pick]
    has_p = all("contact_pressure" in f for _, f in steps)
    if has_p:
        every = np.concatenate([f["contact_pressure"] for _, f in steps])
        clim, label = _clim(every, robust=True), "contact pressure [Pa]"
    else:
        hi = max(float(np.linalg.norm(f["displacement"], axis=1).max()) for _, f in steps)
        clim, label = (0.0, hi if hi > 0 else 1.0), "|u| [m]"

    def values(f) -> np.ndarray:
        return f["contact_pressure"] if has_p else np.linalg.norm(f["displacement"], axis=1)

    size = (720, 504)
    plotter = pv.Plotter(off_screen=True, window_size=size)
    t0, f0 = steps[0]
    surf = _surface(points + f0["displacement"], cells)
    surf.point_data["value"] = values(f0)
    actor = plotter.add_mesh(
        surf,
        scalars="value",
        cmap=CMAP,
        clim=clim,
        smooth_shading=True,
        show_scalar_bar=False,
    )
    surf = actor.mapper.dataset  # the mesh drawn (add_mesh may copy it)
    bodies = []
    for m in bodies_at(t0) if bodies_at is not None else []:
        a = plotter.add_mesh(m, color="#d9b38c", opacity=1.0, smooth_shading=True)
        bodies.append(a.mapper.dataset)
    _camera(plotter, view)
    plotter.reset_camera()
    bar = _colour_bar_panel(
        height=size[1], clim=clim, label=label, extend="max" if has_p else "neither"
    )
    frames = []
    for t, f in steps:
        surf.points = points + f["displacement"]
        surf.point_data["value"] = values(f)
        if bodies_at is not None:
            for m, new in zip(bodies, bodies_at(t), strict=True):
                m.points = new.points
        surf.compute_normals(inplace=True)  # smooth shading of the moved surface
        plotter.add_text(f"{title}  t = {t:.4g}", font_size=10, name="title", render=False)
        plotter.render()
        image = plotter.screenshot(return_img=True)
        frames.append(Image.fromarray(np.hstack([image[:, :, :3], bar[: image.shape[0]]])))
    plotter.close()
    gif = Path(gif)
    frames[0].save(
        gif, save_all=True, append_images=frames[1:], duration=frame_ms, loop=0, optimize=False
    )
    return gif


class Progress:
    """Progress of a run on rank 0: a bar with the elapsed time and an ETA (``rich``) on a
    terminal, plain lines (with the ETA) otherwise and under ``mpirun`` (Open MPI and MPICH
    give a rank's stdout a pseudo-terminal even when the output goes to a file, where a bar
    would write every redraw); nothing on the other ranks."""

    def __init__(self, *, label: str, comm: MPI.Comm = MPI.COMM_WORLD, start: float = 0.0):
        self.on = comm.rank == 0
        self.t0, self.f0 = _time.perf_counter(), start
        self._bar = None
        launched = any(k in os.environ for k in ("OMPI_COMM_WORLD_SIZE", "PMI_SIZE"))
        if self.on and sys.stdout.isatty() and not launched:
            try:
                from rich.progress import (
                    BarColumn,
                    TaskProgressColumn,
                    TextColumn,
                    TimeElapsedColumn,
                    TimeRemainingColumn,
                )
                from rich.progress import Progress as _Bar
            except ImportError:
                return
            from rich.table import Column

            self._bar = _Bar(
                TextColumn("{task.description}", table_column=Column(no_wrap=True)),
                BarColumn(bar_width=24),
                TaskProgressColumn(),
                TimeElapsedColumn(),
                TextColumn("ETA"),
                TimeRemainingColumn(),
                TextColumn(
                    "{task.fields[info]}",
                    table_column=Column(no_wrap=True, overflow="ellipsis", ratio=1),
                ),
                expand=True,
            )
            self._task = self._bar.add_task(label, total=1.0, completed=start, info="")
            self._bar.start()

    def eta(self, frac: float) -> float | None:
        """Seconds left at ``frac`` done, from the mean rate since the start (None early)."""
        done = frac - self.f0
        if done <= 1e-9:
            return None
        return (_time.perf_counter() - self.t0) * (1.0 - frac) / done

    def update(self, frac: float, line: str) -> None:
        """Report ``frac`` (0..1) done and the detail ``line``."""
        if not self.on:
            return
        frac = min(max(frac, 0.0), 1.0)
        if self._bar is not None:
            self._bar.update(self._task, completed=frac, info=line)
            return
        eta = self.eta(frac)
        left = "ETA --" if eta is None else f"ETA {eta:.0f} s"
        print(f"  [{'#' * int(20 * frac):<20}] {100 * frac:3.0f} %  {left}  {line}", flush=True)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.stop()
            self._bar = None


def rank0_print(*args: Any, comm: MPI.Comm = MPI.COMM_WORLD) -> None:
    """print() on rank 0 only."""
    if comm.rank == 0:
        print(*args, flush=True)
