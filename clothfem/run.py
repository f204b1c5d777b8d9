"""Run a validated scene: build only what it needs, solve, write results as they come.

The log says what was built (and what was left out because the scene does not need it).
Dynamic scenes run through :func:`clothfem.simulation.run_dynamic`, quasi-static scenes
with ``[[body]]`` segments through :func:`clothfem.runners.run_contact_scene`; a scene with
``[initial] don`` dons its pants first (:mod:`clothfem.particle.scene_donning`). A
quasi-static scene without a body is solved here; its results go to ``out``:
``fabric.xdmf`` (ParaView, meshio), ``history.csv`` (one row per accepted step, flushed at
once), ``final.png``. SIGTERM and Ctrl-C stop the run cleanly:
files are closed and every step already written is kept; a run killed outright leaves
readable files up to its last written step.

Results folders are never mixed (:func:`check_output`): a run refuses a folder that holds
another run's files unless asked to overwrite it, and never deletes a file it did not
write. Everything a run checks before it starts (the scene, the mesh file, the folder)
fails before anything is written.
"""

from __future__ import annotations

import fnmatch
import json
import math
import os
import signal
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from mpi4py import MPI

from . import mesh as meshes
from .errors import RunStopped
from .history import yarn_strain_columns
from .io import Progress, ResultWriter, rank0_print, snapshot_png
from .petsc_options import describe_direct_lu
from .run_output import resume_problem
from .runners import run_contact_scene
from .scene import DECRIMPING_KEYS, SceneError, mesh_file_problem
from .scene_body import contact_log
from .shell import (
    Clamp,
    DahlFriction,
    DecrimpingFabric,
    EdgeMoment,
    EdgeTraction,
    FabricMaterial,
    FabricViscosity,
    Gravity,
    Pin,
    PointForce,
    Prescribed,
    Pressure,
    Quadrature,
    ShellModel,
    Symmetry,
)
from .simulation import run_dynamic
from .spec import ElementSpec, MaterialSpec, Scene, SolverSpec
from .static import LoadStepping, SolverDivergence, solve_static
from .torque_measure import torque_segment_index
from .torque_table import FILE as TORQUE_FILE
from .torque_table import torque_stats

__all__ = [
    "RUN_FILES",
    "RunStopped",
    "build_material",
    "build_mesh",
    "build_model",
    "check_output",
    "clear_output",
    "run_scene",
]

# what a run writes into its folder (file name patterns; checkpoint/ holds rank files)
RUN_FILES = (
    "history.csv",
    "history_columns.csv",
    "summary.json",
    "summary.json.tmp",
    "fabric.xdmf",
    "fabric.h5",
    "fabric.xdmf.tmp",
    "fabric_resumed_*.xdmf",
    "fabric_resumed_*.h5",
    "snapshot_*.png",
    "torque_angle.png",
    "final.png",
    "animation.gif",
    "events.csv",
    "torques.csv",
    "torques.png",
    "donned.npz",
    "donning_log.txt",
)
DONNED = "donned.npz"
CHECKPOINT_FILES = ("rank*-of-*.npz", "rank*-of-*.tmp")


def _split_folder(out: Path) -> tuple[list[str], list[str]]:
    """(entries a run writes, other entries) directly in ``out``."""
    ours, others = [], []
    for p in sorted(out.iterdir()):
        if p.is_dir() and p.name == "checkpoint":  # ours if it holds rank files only
            mine = all(
                q.is_file() and any(fnmatch.fnmatch(q.name, pat) for pat in CHECKPOINT_FILES)
                for q in p.iterdir()
            )
            (ours if mine else others).append("checkpoint/")
        elif p.is_file() and any(fnmatch.fnmatch(p.name, pat) for pat in RUN_FILES):
            ours.append(p.name)
        else:
            others.append(p.name + ("/" if p.is_dir() else ""))
    return ours, others


def _names(items: list[str], k: int = 3) -> str:
    return ", ".join(items[:k]) + (f" and {len(items) - k} more" if len(items) > k else "")


def _output_problem(out: Path, *, overwrite: bool, resume: bool) -> str | None:
    """Why a run cannot write to ``out`` (one line), or None."""
    where = f"output folder '{out}'"
    if overwrite and resume:
        return f"{where}: --overwrite and --resume exclude each other"
    if out.exists() and not out.is_dir():
        return f"{where}: exists and is not a folder"
    base = out
    while not base.exists():
        base = base.parent
    if not base.is_dir():
        return f"{where}: cannot be created ('{base}' is a file)"
    if not os.access(base, os.W_OK | os.X_OK):
        return f"{where}: not writable"
    if resume:
        if not (out / "checkpoint").is_dir():
            return f"{where}: --resume needs an interrupted run's checkpoint/ there, found none"
        return None
    if not out.exists():
        return None
    ours, others = _split_folder(out)
    if others and ours and overwrite:
        return (
            f"{where}: --overwrite refused: it holds files clothfem does not write "
            f"({_names(others)}); remove the old run yourself or choose another --out"
        )
    if ours and not overwrite:
        extra = f" and other files ({_names(others)})" if others else ""
        return (
            f"{where}: holds another run ({_names(ours)}){extra}; choose another --out, "
            "or --overwrite to replace it"
        )
    return None


def check_output(
    out: str | Path, *, overwrite: bool = False, resume: bool = False, comm: MPI.Comm
) -> None:
    """Raise :class:`SceneError` (one line naming the folder) unless a run may write to
    ``out``: it holds no other run's files (it may hold files clothfem does not write); or
    it holds a previous run's files only and ``overwrite`` (:func:`clear_output` removes them
    once the model is built; with other files there, ``overwrite`` is refused: they are never
    deleted); or ``resume`` and it holds an interrupted run's checkpoint. Collective; writes
    nothing."""
    msg = None
    if comm.rank == 0:
        msg = _output_problem(Path(out), overwrite=overwrite, resume=resume)
    msg = comm.bcast(msg, root=0)
    if msg:
        raise SceneError(msg)


def clear_output(out: str | Path, *, comm: MPI.Comm) -> None:
    """Remove the files a previous run wrote to ``out`` (only those: :data:`RUN_FILES` and
    the rank files of ``checkpoint/``); collective."""
    out = Path(out)
    if comm.rank == 0 and out.is_dir():
        ours, _ = _split_folder(out)
        for name in ours:
            path = out / name.rstrip("/")
            if path.is_dir():
                for q in path.iterdir():
                    q.unlink()
                path.rmdir()
            else:
                path.unlink()
    comm.barrier()


def _check_mesh_file(scene: Scene, comm: MPI.Comm) -> None:
    """A ``generator = "file"`` mesh must be usable (:func:`clothfem.scene.mesh_file_problem`,
    checked on rank 0, the decision shared)."""
    if scene.mesh.generator != "file":
        return
    msg = mesh_file_problem(scene) if comm.rank == 0 else None
    msg = comm.bcast(msg, root=0)
    if msg:
        raise SceneError(msg)


def build_mesh(scene: Scene, comm: MPI.Comm) -> meshes.SurfaceMesh:
    m = scene.mesh
    gen, common = m.generator, dict(cell=m.cell, order=m.order)
    if gen == "strip":
        sm = meshes.strip(comm, length=m.length, width=m.width, nx=m.nx, ny=m.ny, **common)
    elif gen == "cylinder":
        sm = meshes.cylinder(
            comm,
            radius=m.radius,
            length=m.length,
            n_around=m.n_around,
            n_along=m.n_along,
            **common,
        )
    elif gen == "panel":
        sm = meshes.cylinder_panel(
            comm,
            radius=m.radius,
            length=m.length,
            angle=math.radians(m.angle),
            n_around=m.n_around,
            n_along=m.n_along,
            **common,
        )
    elif gen == "pants":
        from .pants_mesh import pants

        dims = ("waist_radius", "hip_radius", "leg_radius", "leg_length", "crotch_depth")
        dims += ("leg_spacing",)
        try:
            sm = pants(
                comm,
                n_around=m.n_around,
                n_along=m.n_along,
                **{k: getattr(m, k) for k in dims if getattr(m, k) is not None},
                **common,
            )
        except ValueError as exc:
            raise SceneError(f"scene key 'mesh': {exc}") from None
    else:
        try:
            sm = meshes.load_msh(m.file, comm)
        except ValueError as exc:
            raise SceneError(f"scene key 'mesh.file': {exc}") from None
    if m.translate is not None:
        sm.mesh.geometry.x[:] += np.asarray(m.translate)
    return sm


def _supports(scene: Scene) -> list:
    out = []
    for s in scene.supports:
        kind = s.type
        if kind == "clamp":
            out.append(Clamp(s.where))
        elif kind == "pin":
            out.append(Pin(s.where))
        elif kind == "symmetry":
            out.append(Symmetry(s.where, s.axis))
        else:
            comps = tuple(int(c) for c in s.components)
            out.append(
                Prescribed(
                    s.where,
                    displacement=s.displacement,
                    components=comps,
                    rotation=s.rotation,
                )
            )
    return out


def _loads(scene: Scene) -> list:
    out = []
    for ld in scene.loads:
        kind = ld.type
        if kind == "gravity":
            out.append(Gravity(ld.acceleration))
        elif kind == "pressure":
            out.append(Pressure(ld.value, follower=ld.follower))
        elif kind == "edge_traction":
            out.append(EdgeTraction(ld.where, ld.traction))
        elif kind == "edge_moment":
            out.append(EdgeMoment(ld.where, ld.moment))
        else:
            out.append(PointForce(ld.point, ld.force))
    return out


def build_material(mat: MaterialSpec) -> FabricMaterial:
    """The material of a validated scene's ``[material]`` table."""
    common = dict(E1=mat.E1, E2=mat.E2, G12=mat.G12, nu12=mat.nu12, rho=mat.rho)
    if mat.friction_stiffness1 is not None:  # all four (scene validation)
        common["friction"] = DahlFriction(
            stiffness1=mat.friction_stiffness1,
            stiffness2=mat.friction_stiffness2,
            stress1=mat.friction_stress1,
            stress2=mat.friction_stress2,
        )
    if mat.viscosity1 is not None:  # all three (scene validation)
        common["viscosity"] = FabricViscosity(
            eta1=mat.viscosity1, eta2=mat.viscosity2, eta12=mat.viscosity12
        )
    if mat.law == "decrimping":
        return DecrimpingFabric(**common, **{k: getattr(mat, k) for k in DECRIMPING_KEYS})
    return FabricMaterial(**common)


def _material_line(mat: MaterialSpec) -> str:
    line = (
        f"E1 {mat.E1:.4g} Pa, E2 {mat.E2:.4g} Pa, G12 {mat.G12:.4g} Pa, "
        f"nu12 {mat.nu12:g}, rho {mat.rho:g} kg/m^3, t {mat.thickness:g} m"
    )
    if mat.law == "decrimping":
        line = (
            f"decrimping, crimped {line}; de-crimped E1 {mat.E1_decrimped:.4g} Pa, "
            f"E2 {mat.E2_decrimped:.4g} Pa above yarn strains "
            f"{mat.transition1 + mat.width1:.4g} / {mat.transition2 + mat.width2:.4g}"
            " (the explicit stable step shrinks as the yarns de-crimp: solver.recheck_every)"
        )
    if mat.viscosity1 is not None:
        line += (
            f"; membrane viscosity {mat.viscosity1:.4g} / {mat.viscosity2:.4g} / "
            f"{mat.viscosity12:.4g} Pa s"
        )
    if mat.friction_stiffness1 is not None:
        line += (
            f"; yarn friction (Dahl) k {mat.friction_stiffness1:.4g} / "
            f"{mat.friction_stiffness2:.4g} Pa, S {mat.friction_stress1:.4g} / "
            f"{mat.friction_stress2:.4g} Pa"
        )
    return line


def _initial_state(
    scene: Scene, model: ShellModel, start: tuple[np.ndarray, np.ndarray, str] | None
) -> str:
    """Start ``model`` from ``start`` (X, x, what) or ``initial.positions`` (collective); the
    log line."""
    from .initial_state import displacement_at_nodes, read_positions

    path = scene.initial.positions
    if start is None and path is None:
        return "initial state: the mesh at rest"
    X, x, what = start if start is not None else (*read_positions(Path(path)), Path(path).name)
    key = "initial.don" if start is not None else "initial.positions"
    try:
        u = displacement_at_nodes(nodes=model.x_nodes, X=X, x=x)
        model.start_at(u)
    except ValueError as exc:
        raise SceneError(f"scene key '{key}': {exc}") from None
    umax = model.comm.allreduce(float(np.abs(u).max(initial=0.0)), op=MPI.MAX)
    lo, hi = model.yarn_strain_range()
    return (
        f"initial state: the positions of {what} (reference: the mesh; max "
        f"displacement component {umax:.4g} m; directors turned with their neighbourhoods; "
        f"yarn Green strains {lo:.3g} .. {hi:.3g} at the start)"
    )


def build_model(
    scene: Scene,
    comm: MPI.Comm = MPI.COMM_WORLD,
    *,
    start: tuple[np.ndarray, np.ndarray, str] | None = None,
) -> tuple[ShellModel, list[str]]:
    """The shell model of a scene and a log of what was built and left out; ``start``:
    (X, x, what) node positions to start from instead of ``initial.positions`` (the
    donning's)."""
    sm = build_mesh(scene, comm)
    mat = scene.material
    material = build_material(mat)
    model = ShellModel(
        sm,
        material=material,
        thickness=mat.thickness,
        loads=_loads(scene),
        supports=_supports(scene),
        warp=mat.warp,
        degree=scene.element.degree,
        quadrature=Quadrature(
            reduced=scene.element.reduced_quadrature,
            scheme=scene.element.scheme,
            psri_factor=scene.element.psri_factor,
            stabilization=scene.element.stabilization,
        ),
    )
    n_nodes = comm.allreduce(model.n_owned, op=MPI.SUM)
    n_cells = comm.allreduce(sm.mesh.topology.index_map(2).size_local, op=MPI.SUM)
    started = _initial_state(scene, model, start)
    log = [
        f"mesh: {scene.mesh.generator}, {n_cells} {scene.mesh.cell} cells "
        f"(order {scene.mesh.order}, u and theta of degree {scene.element.degree}), "
        f"{n_nodes} nodes, {5 * n_nodes} unknowns (u: 3, theta: 2 per node), {comm.size} rank(s)",
        f"material: {_material_line(mat)}",
        f"element: {_element_line(scene.element)}",
        "supports: " + (", ".join(f"{s.type} on {s.where}" for s in scene.supports) or "none"),
        "loads: " + (", ".join(ld.type for ld in scene.loads) or "none"),
        started,
        _inertia_log(scene.solver),
        (
            "linear solves: none (explicit: lumped mass)"
            if scene.solver.integrator == "explicit"
            else f"linear solves: {describe_direct_lu(comm)}"
        ),
    ]
    if scene.body:
        log += contact_log(scene)
    else:
        log += ["contact: not built (no body in the scene)", "friction: not built (no contact)"]
    return model, log


def _element_line(el: ElementSpec) -> str:
    """How the scene's membrane and shear are integrated, for the build log."""
    if el.scheme == "mitc9":
        return "MITC9 (assumed membrane and shear strains, 3 x 3 points; docs/shell_element.md)"
    if el.scheme == "psri":
        return (
            f"partial selective reduced integration (alpha = min(1, {el.psri_factor:g} "
            "t^2/h^2) of membrane and shear fully integrated; docs/shell_element.md)"
        )
    return f"selective reduced integration (stabilization {el.stabilization:g}; for comparison)"


def _inertia_log(sv: SolverSpec) -> str:
    if sv.integrator == "static":
        return "inertia: not built (static integrator)"
    if sv.integrator == "explicit":
        return (
            f"inertia: lumped mass, central difference, dt = {sv.safety:g} x dt_crit"
            + (
                f" (re-estimated every {sv.recheck_every} steps)"
                if sv.recheck_every
                else " (at t = 0)"
            )
            + f", rotary inertia x {sv.rotary_scale:g}"
            + (
                f", mass damping {sv.settle_damping:g} 1/s until {sv.settle_time:g} s "
                "(settling only)"
                if sv.settle_damping > 0
                else ""
            )
        )
    return (
        f"inertia: consistent mass, Newmark gamma {sv.gamma:g}, dt {sv.dt:g} s, "
        f"rotary inertia x {sv.rotary_scale:g}"
    )


@dataclass(frozen=True)
class _Donned:
    """The donning stage's result: ``start`` (X, x, what) for :func:`build_model`, its
    checks (:func:`clothfem.particle.donning.summary`; None when a resumed run reads its
    donned.npz) and ``write()`` (collective: donned.npz and donning_log.txt into the run's
    folder, once it is cleared)."""

    start: tuple[np.ndarray, np.ndarray, str]
    summary: dict[str, Any] | None
    write: Callable[[], None]


def _don(scene: Scene, out: Path, comm: MPI.Comm, *, resume: bool) -> _Donned:
    """The donning of ``initial.don`` (rank 0 computes, every rank gets the positions); a
    resumed run reads the donned.npz it wrote."""
    from .initial_state import read_positions
    from .particle import donning
    from .particle.scene_donning import don_scene

    path = out / DONNED
    if resume and comm.bcast(path.is_file() if comm.rank == 0 else None, root=0):
        X, x = read_positions(path)
        return _Donned((X, x, f"{DONNED} of this run"), None, lambda: None)
    rank0_print("donning (particle model, docs/donning.md)")
    progress, d, error = Progress(label="donning", comm=comm), None, None
    try:
        d = don_scene(scene, comm=comm, progress=progress)
    except (FloatingPointError, ValueError) as exc:  # rank 0's: every rank stops below
        error = f"{type(exc).__name__}: {exc}"
    finally:
        progress.close()
    error = comm.bcast(error, root=0)
    if error is not None:
        raise SolverDivergence(f"the donning stopped: {error}")
    summ = donning.summary(d, tol=1e-6) if d is not None else None
    X, x, summ = comm.bcast((d.network.x0, d.result.x, summ) if d is not None else None, root=0)
    rank0_print(
        f"  donned: {summ['nodes']} nodes, {summ['steps']} steps, {summ['wall_seconds']:.1f} s; "
        f"min gap {1e3 * summ['min_gap']:.3f} mm ({summ['inside_end']} nodes inside, "
        f"{summ['pushed_out_nodes']} pushed out); structural strain "
        f"{summ['strain_min_structural']:.3f} .. {summ['strain_max_structural']:.3f}; "
        f"{summ['self_intersections']} intersecting triangle pairs"
    )

    def write() -> None:
        if comm.rank == 0:
            donning.write_donned(out, d, summ, {"scene": scene.scene.name})
        comm.barrier()

    return _Donned((X, x, "the donning"), summ, write)


def _write_summary(out: Path, summary: dict[str, Any], comm: MPI.Comm) -> None:
    """``out/summary.json`` (rank 0): completed, reason, final angle, steps, wall time...
    Written whole (a temporary file renamed over it) and on disk when any rank returns:
    collective."""
    if comm.rank == 0:
        out.mkdir(parents=True, exist_ok=True)
        tmp = out / "summary.json.tmp"
        tmp.write_text(json.dumps(summary, indent=1, default=float) + "\n")
        os.replace(tmp, out / "summary.json")
    comm.barrier()


def _earlier_segments(out: Path, comm: MPI.Comm) -> list[dict[str, Any]]:
    """The segments of an interrupted run before this resume (rank 0 reads, all ranks
    return): those its ``summary.json`` lists, then how the last one ended (reason, final
    angle, steps, wall time [s]). A segment killed while running (its summary says
    ``running``, or there is none) ends at the history's last row: its angle and
    ``elapsed``, read before the resume cuts the history back to the checkpoint."""
    from .report import ReportError, earlier_segments, read_history, read_summary

    earlier: list[dict[str, Any]] = []
    if comm.rank == 0:
        s = read_summary(out)
        earlier = earlier_segments(s)
        last = {k: s.get(k) for k in ("final_angle_deg", "steps", "wall_time")}
        last["reason"] = s.get("reason")
        if not s or s.get("running"):
            last["reason"] = "no end recorded: killed while running"
            try:
                h = read_history(out / "history.csv")
            except ReportError:
                h = {}
            if "elapsed" in h and h["elapsed"].size:
                last["final_angle_deg"] = float(h["angle_deg"][-1])
                last["wall_time"] = float(h["elapsed"][-1])
        earlier.append(last)
    return comm.bcast(earlier, root=0)


def _started(out: Path, comm: MPI.Comm) -> bool:
    """Whether the run has written its first results to ``out`` (rank 0 decides)."""
    ok = (out / "history.csv").exists() or (out / "fabric.h5").exists()
    return bool(comm.bcast(ok if comm.rank == 0 else None, root=0))


def _measures(scene: Scene, out: Path) -> dict[str, Any] | None:
    """The resistance measures of a body scene's history (:func:`report.resistance_measures`),
    keyed by the measured joint (the torque segment); None without a readable history."""
    from .report import ReportError, read_history, resistance_measures

    k = torque_segment_index(scene)
    joint = scene.body[k].name if k is not None else "joint"
    try:
        h = read_history(out / "history.csv")
    except ReportError:
        return None
    return {"joint": joint, **resistance_measures(h, joint=joint)}


def run_scene(
    scene: Scene,
    out: str | Path,
    *,
    comm: MPI.Comm = MPI.COMM_WORLD,
    resume: bool = False,
    overwrite: bool = False,
) -> Path:
    """Run ``scene`` and write its results to ``out``; returns the output folder.

    ``out`` must be new or empty (:func:`check_output`); ``overwrite``: it may hold a previous
    run's files, which are removed once the model is built; ``resume``: continue a dynamic
    run from the last checkpoint in ``out/checkpoint``. Nothing is written (or removed)
    before the scene, the mesh file and the folder have passed their checks.
    ``out/summary.json`` says at the end whether the run completed (and why not).
    """
    out = Path(out)
    if scene.solver.integrator != "static" and scene.material.rho <= 0:
        raise SceneError(
            f"scene key 'material.rho': the {scene.solver.integrator} integrator needs a "
            "density > 0 kg/m^3"
        )
    if resume and scene.solver.integrator == "static":
        raise SceneError(
            "--resume needs solver.integrator = 'newmark' or 'explicit' (static runs write no "
            "checkpoints)"
        )
    check_output(out, overwrite=overwrite, resume=resume, comm=comm)
    if resume:
        msg = resume_problem(scene, out, ranks=comm.size) if comm.rank == 0 else None
        msg = comm.bcast(msg, root=0)
        if msg:
            raise SceneError(msg)
    _check_mesh_file(scene, comm)
    t0 = time.perf_counter()
    donned = _don(scene, out, comm, resume=resume) if scene.initial.don else None
    model, log = build_model(scene, comm, start=donned.start if donned else None)
    if overwrite:
        clear_output(out, comm=comm)
    if donned is not None:
        donned.write()
    rank0_print(f"scene {scene.scene.name!r}")
    for line in log:
        rank0_print("  built " + line if "not built" not in line else "  " + line)
    s = scene.solver
    inc = 1.0 / s.steps
    stepping = LoadStepping(
        initial_increment=inc,
        max_increment=max(inc, s.max_increment),
        min_increment=min(inc, s.min_increment),
    )
    stop = {"signal": None}

    def handler(signum, frame):
        stop["signal"] = signum

    old = signal.signal(signal.SIGTERM, handler)
    if scene.body or s.integrator != "static":

        def check_stop(where: str) -> None:
            if comm.allreduce(stop["signal"] is not None, op=MPI.LOR):
                raise RunStopped(f"stopped by signal after {where}; results kept in {out}")

        summary: dict[str, Any] = {"scene": scene.scene.name, "completed": False}
        summary["built"] = log  # what the run built and left out (e.g. a repeated gait cycle)
        if donned is not None:
            summary["donning"] = donned.summary
        if resume:  # the earlier stop's summary is replaced at once: no stale status
            summary["earlier"] = _earlier_segments(out, comm)
            summary["running"] = True
            _write_summary(out, summary, comm)
        try:
            if s.integrator == "static":
                run_contact_scene(
                    scene, out, model=model, comm=comm, t0=t0, check_stop=check_stop,
                    summary=summary,
                )  # fmt: skip
            else:
                run_dynamic(
                    scene, out, model=model, comm=comm, t0=t0, check_stop=check_stop,
                    resume=resume, summary=summary,
                )  # fmt: skip
            summary["completed"] = True
        except BaseException as exc:
            summary["reason"] = f"{type(exc).__name__}: {exc}"
            raise
        finally:
            signal.signal(signal.SIGTERM, old)
            summary.pop("running", None)
            summary["wall_time"] = time.perf_counter() - t0
            if comm.rank == 0 and scene.body:
                summary["measures"] = _measures(scene, out)
            if comm.rank == 0 and scene.torques:
                t_from = scene.solver.settle_time
                summary["torques"] = torque_stats(out / TORQUE_FILE, t_from=t_from)
            if _started(out, comm):  # a failed start writes nothing
                _write_summary(out, summary, comm)
        rank0_print(f"done in {time.perf_counter() - t0:.1f} s; results in {out}/")
        return out
    progress = Progress(label=scene.scene.name, comm=comm)
    clock = {"row": time.perf_counter()}
    try:
        with ResultWriter(out, model) as writer:

            def on_step(rec):
                model.commit_material()  # a converged load step: material history to it
                now = time.perf_counter()
                writer.write(
                    rec.load_factor,
                    {
                        "stage": "load",
                        "increment": rec.step,
                        "load_factor": rec.load_factor,
                        "substeps": 1,
                        "cutbacks": rec.cutbacks,
                        "newton_iterations": rec.newton_iterations,
                        "residual": rec.residual_final,
                        **yarn_strain_columns(model),
                        "strain_energy": model.strain_energy(),
                        "dissipation_material": model.dissipated_material(),
                        "wall_time": now - clock["row"],
                        "elapsed": now - t0,
                    },
                )
                clock["row"] = now
                progress.update(rec.load_factor, rec.line())
                if comm.allreduce(stop["signal"] is not None, op=MPI.LOR):
                    raise RunStopped(
                        f"stopped by signal after step {rec.step}; results kept in {out}"
                    )

            solve_static(model, stepping=stepping, on_step=on_step)
    finally:
        progress.close()
        signal.signal(signal.SIGTERM, old)
    if scene.output.png:
        snapshot_png(model, out / "final.png", title=scene.scene.name)
    rank0_print(f"done in {time.perf_counter() - t0:.1f} s; results in {out}/")
    return out
