"""What a run writes and where: results folders are never mixed, a failed start writes
nothing, a killed run leaves readable files, a resumed run repeats the uninterrupted one bit
for bit from any checkpoint and continues its field series, the XDMF series opens in meshio's
and VTK's readers, and the scenes without a hinge (a free drape, a motion-captured arm) run
from their files alone."""

import csv
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from clothfem import scene as scenes
from clothfem import scene_body, simulation
from clothfem.cli import main
from clothfem.history import NAMES as HISTORY_NAMES
from clothfem.history import UNITS_FILE
from clothfem.report import report_markdown
from clothfem.run import RUN_FILES, check_output, clear_output, run_scene
from clothfem.scene import SceneError

COMM = MPI.COMM_WORLD
ROOT = Path(__file__).resolve().parents[2]
CI = ROOT / "demos" / "scenes" / "arm_sleeve_ci.toml"
EXPLICIT = [
    "solver.integrator=explicit",
    "solver.rotary_scale=1000",
    "solver.settle_time=0.05",
    "solver.ramp_time=0.05",
    "body.1.angle_max=3.0",
    "output.interval=0.004",
    "output.checkpoint_every=1",
]
NEWMARK = [
    "solver.integrator=newmark",
    "solver.settle_time=0.05",
    "solver.ramp_time=0.05",
    "solver.dt=0.005",
    "body.1.angle_max=3.0",
    "output.checkpoint_every=1",
]
# the CI scene's keys of the static integrator, removed for the EXPLICIT and NEWMARK runs
UNSET_STATIC = ["solver.steps", "contact.increments"]
TIMING = ("t_assembly", "t_contact", "t_self_contact", "t_solve", "t_io", "wall_time", "elapsed")
# a child process must not inherit this (singleton) MPI process's environment
ENV = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "OPAL_"))}
ENV["OPENBLAS_NUM_THREADS"] = "1"


def _shared(tmp_path: Path) -> Path:
    return Path(COMM.bcast(str(tmp_path) if COMM.rank == 0 else None, root=0))


def _rows(out: Path) -> list[dict[str, str]]:
    """The history's rows; checks on the way that it has the one history format (the
    columns of clothfem.history.COLUMNS in order, their units in history_columns.csv)."""
    with (out / "history.csv").open() as fh:
        reader = csv.DictReader(fh)
        rows = list(reader)
        assert tuple(reader.fieldnames) == HISTORY_NAMES
    with (out / UNITS_FILE).open() as fh:
        units = list(csv.DictReader(fh))
    assert [u["column"] for u in units] == list(HISTORY_NAMES) and all(u["unit"] for u in units)
    return rows


def _series(out: Path) -> tuple[list[float], list[dict[str, np.ndarray]]]:
    """Times and point data of ``out/fabric.xdmf`` through meshio's time-series reader."""
    import meshio

    times, data = [], []
    with meshio.xdmf.TimeSeriesReader(out / "fabric.xdmf") as reader:
        reader.read_points_cells()
        for k in range(reader.num_steps):
            t, point_data, _ = reader.read_data(k)
            times.append(t)
            data.append(point_data)
    return times, data


# ---------------------------------------------------------------- results folders


def test_output_folder_rules(tmp_path):
    """New, empty or holding only files clothfem does not write: fine. A previous run:
    refused, or with overwrite its files are removed; with other files beside it, overwrite
    is refused (they are never deleted). A folder under a file: refused. Every refusal is one
    line naming the folder."""
    base = _shared(tmp_path)
    check_output(base / "new", comm=COMM)
    if COMM.rank == 0:
        (base / "empty").mkdir()
        run = base / "run"
        (run / "checkpoint").mkdir(parents=True)
        for name in ("history.csv", "fabric.xdmf", "fabric.h5", "snapshot_final.png"):
            (run / name).write_text("x")
        (run / "checkpoint" / "rank0-of-1.npz").write_text("x")
        (base / "mixed").mkdir()
        (base / "mixed" / "history.csv").write_text("x")
        (base / "mixed" / "notes.txt").write_text("mine")
        (base / "user").mkdir()
        (base / "user" / "data.csv").write_text("mine")
        (base / "afile").write_text("x")
    COMM.barrier()
    check_output(base / "empty", comm=COMM)
    check_output(base / "user", comm=COMM)
    check_output(base / "user", overwrite=True, comm=COMM)  # nothing of a run to remove
    for folder, kwargs, words in [
        ("run", {}, "holds another run"),
        ("mixed", {}, "holds another run"),
        ("mixed", {"overwrite": True}, "--overwrite refused"),
        ("afile/out", {}, "cannot be created"),
        ("empty", {"resume": True}, "--resume needs"),
    ]:
        with pytest.raises(SceneError) as err:
            check_output(base / folder, comm=COMM, **kwargs)
        msg = str(err.value)
        assert "\n" not in msg and f"'{base / folder}'" in msg and words in msg, msg
    check_output(base / "run", overwrite=True, comm=COMM)
    clear_output(base / "run", comm=COMM)
    assert not any((base / "run").iterdir())
    assert (base / "mixed" / "notes.txt").read_text() == "mine"  # never touched
    assert "history.csv" in RUN_FILES


def test_cli_refuses_a_folder_with_a_run(tmp_path, capsys):
    """`clothfem run` into a folder holding another run: exit 2, one line naming it, nothing
    changed; `--overwrite` replaces the run."""
    out = _shared(tmp_path) / "r"
    args = ["run", str(ROOT / "demos" / "scenes" / "sleeve_gravity.toml"), "--out", str(out)]
    args += ["--set", "mesh.n_around=4", "--set", "mesh.n_along=2", "--set", "output.png=false"]
    assert main(args) == 0
    before = (out / "history.csv").read_bytes()
    capsys.readouterr()
    assert main([*args, "--set", "solver.steps=2"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and str(out) in err and "holds another run" in err
    assert (out / "history.csv").read_bytes() == before
    assert main([*args, "--set", "solver.steps=2", "--overwrite"]) == 0
    assert len(_rows(out)) == 2


def test_failed_start_writes_nothing(tmp_path, capsys):
    """A bad scene, a mesh file that is missing or not a mesh, an output folder that cannot
    be created: exit 2 with one line, and the output folder is not created."""
    base = _shared(tmp_path)
    garbage, scene = base / "garbage.msh", base / "s.toml"
    if COMM.rank == 0:
        garbage.write_text("this is not a gmsh file\n")
        (base / "afile").write_text("x")
        scene.write_text(
            '[scene]\nname = "f"\n[mesh]\ngenerator = "file"\nfile = "MESH"\n[material]\n'
            'preset = "crimped-cotton"\nthickness = 1e-3\n[output]\npng = false\n'
        )
    COMM.barrier()
    sleeve = str(ROOT / "demos" / "scenes" / "sleeve_gravity.toml")
    cases = [
        (["run", sleeve, "--set", "mesh.n_around=5"], "mesh.n_around"),
        (["run", str(scene), "--set", f"mesh.file={base / 'none.msh'}"], "mesh.file"),
        (["run", str(scene), "--set", f"mesh.file={garbage}"], "mesh.file"),
        (
            ["run", sleeve, "--set", "solver.integrator=newmark", "--unset", "solver.steps"],
            "solver.integrator",
        ),
    ]
    for k, (args, key) in enumerate(cases):
        out = base / f"out{k}"
        capsys.readouterr()
        assert main([*args, "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and key in err, err
        assert not out.exists()
    capsys.readouterr()
    assert main(["run", sleeve, "--out", str(base / "afile" / "out")]) == 2
    assert "cannot be created" in capsys.readouterr().err


# ---------------------------------------------------------------- resume and field series


def _run_keeping_checkpoints(scene, out: Path, keep: tuple[int, ...]) -> dict[int, Path]:
    """Run ``scene`` into ``out`` and copy the checkpoint folder after the checkpoints
    number ``keep`` (1-based) to ``out.parent / ck<k>``."""
    original = simulation.save_checkpoint
    count, kept = {"k": 0}, {}

    def checkpoint(folder, comm, data):
        original(folder, comm, data)
        count["k"] += 1
        if count["k"] in keep:
            dest = out.parent / f"ck{count['k']}"
            if comm.rank == 0:
                shutil.copytree(folder / "checkpoint", dest)
            comm.barrier()
            kept[count["k"]] = dest

    simulation.save_checkpoint = checkpoint
    try:
        run_scene(scene, out, comm=COMM)
    finally:
        simulation.save_checkpoint = original
    return kept


def _resume_from(reference: Path, checkpoint: Path, out: Path, scene) -> None:
    """An interrupted run's folder: the reference's history and field files (later steps
    included, as a run killed after its checkpoint leaves them) and ``checkpoint``."""
    if COMM.rank == 0:
        out.mkdir()
        for name in ("history.csv", "fabric.xdmf", "fabric.h5", "torques.csv"):
            if (reference / name).exists():
                shutil.copy(reference / name, out / name)
        shutil.copytree(checkpoint, out / "checkpoint")
    COMM.barrier()
    run_scene(scene, out, comm=COMM, resume=True)


# what a solve cost, not what it found: a state that differs at round-off can meet the
# Newton tolerance one iteration earlier or later
SOLVER_EFFORT = ("newton_iterations", "active_set_iterations")


def _family(column: str) -> str:
    """A vector's columns share a scale: torque_x, _y, _z, _mag, _flex -> torque."""
    for suffix in ("_x", "_y", "_z", "_mag", "_flex"):
        if column.endswith(suffix):
            return column[: -len(suffix)]
    return column


def _same_history(a: list[dict[str, str]], b: list[dict[str, str]], *, rtol: float = 0.0) -> None:
    """The rows agree in every column but the timers: as strings (``rtol`` = 0, bit for
    bit), or with floats within ``rtol`` of their scale (integers and labels still as
    strings; the iteration counts of SOLVER_EFFORT not compared). A column's scale is the
    largest magnitude of its family over the rows of
    ``a``: a vector component that is round-off about zero is measured against the
    vector's size, not against itself; and 1e-15 in SI units (m, N, J) absolute, for the
    quantities that are round-off about zero throughout (a penetration of 1e-17 m)."""
    assert len(a) == len(b)
    scale: dict[str, float] = {}
    if rtol:
        for row in a:
            for k, v in row.items():
                try:
                    mag = abs(float(v))
                except ValueError:
                    continue
                if math.isfinite(mag):
                    scale[_family(k)] = max(scale.get(_family(k), 0.0), mag)
    for ra, rb in zip(a, b, strict=True):
        ca = {k: v for k, v in ra.items() if k not in TIMING}
        cb = {k: v for k, v in rb.items() if k not in TIMING}
        if rtol == 0.0:
            assert ca == cb
            continue
        assert ca.keys() == cb.keys()
        for k, va in ca.items():
            if va == cb[k] or k in SOLVER_EFFORT:
                continue
            x, y = float(va), float(cb[k])  # a differing label or integer fails here
            tol = rtol * max(scale.get(_family(k), 0.0), abs(x), abs(y)) + 1e-15
            assert abs(x - y) <= tol, (ra["increment"], k, va, cb[k])


@pytest.mark.parametrize(
    ("sets", "picks"),
    [
        (EXPLICIT, (5, 17)),
        ([*EXPLICIT, "material.preset=crimped-cotton-hysteretic"], (5, 17)),
        (
            [*EXPLICIT, "material.preset=decrimping-cotton-hysteretic", "element.scheme=mitc9"]
            + [f"material.viscosity{k}=5" for k in ("1", "2", "12")],
            (5, 17),
        ),
        ([*NEWMARK, "body.1.angle_max=1.5"], (4, 11)),
        ([*NEWMARK, "body.1.angle_max=1.5", "material.preset=crimped-cotton-hysteretic"], (4, 11)),
    ],
    ids=[
        "explicit",
        "explicit-yarn-friction",
        "explicit-mitc9-laws",
        "newmark",
        "newmark-yarn-friction",
    ],
)
def test_resume_bit_for_bit_from_two_checkpoints(tmp_path, sets, picks):
    """A short run of the CI scene checkpointing every row (explicit) / step (Newmark),
    resumed from an early and a late checkpoint: every history column (but the timers) is
    the same string as the uninterrupted run's, and the field series holds the same times
    once each with the same displacement. The late Newmark checkpoint is one where the
    bordered contact matrix keeps slots of pairs that left the active set (before they were
    checkpointed, a resume from there differed by 1e-12 and took other Newton counts).

    The Newmark resumes are compared to the contact Newton's tolerance (newton_rtol = 1e-9
    of each column's scale, see _same_history), not bit for bit: run alone this case is bit
    for bit, but after the three other cases in the same process the resume of
    newmark-yarn-friction from step 11 parts at round-off at step 12 (2e-15 in the strain
    energy), and from there each step's solution is fixed only to the Newton tolerance
    (largest difference by the last step 2.5e-12 of the resultant; on 2 ranks one step
    took 15 Newton iterations instead of 14, so the iteration counts are not compared).
    Measured 2026-12-02 serially and on 2 ranks, also with the code of 617d543; MUMPS
    without value-based permutation and scaling and another OpenBLAS kernel set did not
    change it. The explicit resumes are bit for bit, also with MITC9 and every material
    term (decrimping, yarn friction and viscosity, histories at the kernels' points), run
    alone or in the suite's order (the forms' kernels do not depend on the Constants made
    before them: tests/unit/test_form_determinism.py)."""
    base = _shared(tmp_path)
    scene = scenes.load(CI, sets, unset=UNSET_STATIC)
    kept = _run_keeping_checkpoints(scene, base / "reference", picks)
    reference = _rows(base / "reference")
    if any("hysteretic" in s for s in sets):  # the material history is part of the state
        assert float(reference[-1]["dissipation_material"]) > 0.0
    t_ref, f_ref = _series(base / "reference")
    if COMM.size == 1 and "newmark" in sets[0]:
        with np.load(kept[picks[1]] / "rank0-of-1.npz") as z:
            assert len(z["contact_kkt_slots"]) > int(z["contact_active"].sum())
    for k in picks:
        out = base / f"resumed{k}"
        _resume_from(base / "reference", kept[k], out, scene)
        rtol = 1e-9 if "newmark" in sets[0] else 0.0  # the contact Newton's newton_rtol
        _same_history(reference, _rows(out), rtol=rtol)
        times, fields = _series(out)
        assert times == t_ref and len(set(times)) == len(times)
        for a, b in zip(f_ref, fields, strict=True):
            for name in ("displacement", "contact_pressure"):
                scale = rtol * np.abs(a[name]).max(initial=0.0)
                assert np.allclose(a[name], b[name], rtol=0.0, atol=scale), name


def test_resume_refuses_another_scene(tmp_path):
    """A resume whose scene differs from the interrupted run's in a key outside
    RESUME_MAY_CHANGE (here the friction coefficient) is refused with one line naming the
    key and both values, before anything is written: the history stays as it was. Where
    the run ends (the hinge's final angle) and what it writes may change."""
    from clothfem.run_output import resume_problem

    base = _shared(tmp_path)
    scene = scenes.load(CI, [*EXPLICIT, "body.1.angle_max=0.5"], unset=UNSET_STATIC)
    out = base / "run"
    run_scene(scene, out, comm=COMM)
    before = (out / "history.csv").read_bytes()
    other = scenes.load(
        CI, [*EXPLICIT, "body.1.angle_max=0.5", "contact.mu=0.3"], unset=UNSET_STATIC
    )
    with pytest.raises(SceneError) as err:
        run_scene(other, out, comm=COMM, resume=True)
    msg = str(err.value)
    assert "\n" not in msg and "'contact.mu' is 0.3 here but 0.1" in msg, msg
    assert (out / "history.csv").read_bytes() == before
    longer = scenes.load(
        CI, [*EXPLICIT, "body.1.angle_max=0.8", "output.png=false"], unset=UNSET_STATIC
    )
    assert resume_problem(longer, out, ranks=COMM.size) is None


@pytest.mark.slow
def test_resume_bit_for_bit_with_self_contact(tmp_path):
    """The arm-sleeve scene (16x20) with fabric self-contact to 50 deg, resumed from the
    checkpoint at 42.8 deg (row 100), from where fabric-fabric pairs are in contact at every
    row: the resumed run builds a fresh candidate list and repeats the history (but the
    timers). How many pairs touch past the slip moves with round-off (the fewest in a row
    was 16 in one process and above 20 in another, with the same code), so the scenario
    check asks for at least 10."""
    base = _shared(tmp_path)
    sets = ["contact.self_contact=true", "body.1.angle_max=50", "mesh.n_around=16"]
    sets += ["mesh.n_along=20", "output.png=false", "output.checkpoint_every=20"]
    scene = scenes.load(ROOT / "demos" / "scenes" / "arm_sleeve.toml", sets)
    kept = _run_keeping_checkpoints(scene, base / "reference", (5,))
    _resume_from(base / "reference", kept[5], base / "resumed", scene)
    reference = _rows(base / "reference")
    _same_history(reference, _rows(base / "resumed"))
    assert min(int(r["self_pairs"]) for r in reference[100:]) >= 10


def _squashed_tube() -> scenes.Scene:
    """A tube (R = 10 mm, 8 x 2 cells, no support) on a fixed plate, a keyframed plate
    closing on it in 0.1 s to 0.9 d (the fabric thickness) above the first: on the Newmark
    path with fabric self-contact, the tube buckles, its walls pass within d of each other
    and end pressed flat within d over the whole tube (about 1300 pairs)."""
    r, half = 0.01, 0.02  # tube radius, plates' half thickness [m]

    def plate(name: str, z: float) -> dict:
        return {"name": name, "type": "fixed", "radii": [0.2, half, 0.2], "centre": [r, 0.0, z]}

    lid = plate("lid", r + half)
    top, bottom = [r, 0.0, r + half], [r, 0.0, -r + 0.9e-3 + half]
    lid.update(type="keyframes", times=[0.0, 0.1], centres=[top, bottom])
    data = {
        "scene": {"name": "tube-squash", "description": "a tube pressed flat"},
        "mesh": {"generator": "cylinder", "radius": r, "length": 2 * r, "n_around": 8,
                 "n_along": 2},
        "material": {"preset": "crimped-cotton", "thickness": 1e-3},
        "body": [plate("floor", -r - half), lid],
        "contact": {"mu": 0.1, "self_contact": True, "aj": "all", "torque_point": [r, 0.0, 0.0]},
        "solver": {"integrator": "newmark", "dt": 0.01, "gamma": 0.9, "rotary_scale": 100.0,
                   "settle_time": 0.0, "ramp_time": 0.0, "duration": 0.12},
        "output": {"png": False, "checkpoint_every": 1},
    }  # fmt: skip
    return scenes.validate(data, base=ROOT)


def test_resume_newmark_with_self_contact_pairs(tmp_path):
    """The squashed tube on the Newmark path with the self-contact barrier, resumed from the
    first checkpoint at which wall pairs are within the activation distance: every history
    column but the timers is the uninterrupted run's string, through to the pressed end
    (>1000 pairs). The checkpoint holds the barrier's candidate list (build positions and
    skin) and the blocks its Jacobian's pattern took beyond the near pairs; a resume that
    builds a fresh list at the checkpoint's positions instead (the code before they were
    saved) parts from the uninterrupted run at round-off (kinetic energy and yarn strains
    in the last digits). Measured 2026-12-03: resumed from row 29 of 41 serially (32 s for
    the test), from row 24 of 26 on 2 ranks (70 s); bit for bit in both. On 2 ranks the
    fresh list also repeated the two remaining rows: there the test does not tell the two
    apart."""
    base = _shared(tmp_path)
    scene = _squashed_tube()
    kept = _run_keeping_checkpoints(scene, base / "reference", tuple(range(1, 200)))
    reference = _rows(base / "reference")
    pairs = [int(r["self_pairs"]) for r in reference]
    k = next(i + 1 for i, p in enumerate(pairs) if p > 0)
    assert k < len(reference) and pairs[-1] > 1000  # steps with the barrier after it
    with np.load(kept[k] / f"rank{COMM.rank}-of-{COMM.size}.npz") as z:
        assert len(z["barrier_x_build"]) > 0
    _resume_from(base / "reference", kept[k], base / "resumed", scene)
    _same_history(reference, _rows(base / "resumed"))


def test_resume_keeps_the_torque_table(tmp_path):
    """An explicit run with [[torques]] resumed from an early checkpoint: torques.csv (whose
    later rows the interrupted folder holds) ends as the uninterrupted run's, byte for byte,
    one row per history row."""
    base = _shared(tmp_path)
    data = tomllib.loads(CI.read_text())
    data["torques"] = [{"name": "all_about_j", "segment": "forearm", "aj": "all"}]
    data = scenes.apply_overrides(scenes.remove_keys(data, UNSET_STATIC), EXPLICIT)
    scene = scenes.validate(data, base=CI.parent)
    kept = _run_keeping_checkpoints(scene, base / "reference", (5,))
    _resume_from(base / "reference", kept[5], base / "resumed", scene)
    if COMM.rank == 0:
        ref, res = ((p / "torques.csv").read_text() for p in (base / "reference", base / "resumed"))
        assert res == ref and ref.count("\n") == len(_rows(base / "reference")) + 1


@pytest.mark.parametrize("sets", [EXPLICIT, NEWMARK], ids=["explicit", "newmark"])
def test_torque_table_repeats_the_contact_measure(tmp_path, sets):
    """Both integrators measure [[torques]] through the same runner: an entry that repeats
    the scene's [contact] measure (forearm, nodes past the elbow plane) gives, row by row,
    the history's torque columns, and the entry about the same joint over all nodes differs
    from it once the sleeve touches the upper arm."""
    base = _shared(tmp_path)
    data = tomllib.loads(CI.read_text())
    data["torques"] = [
        {"name": "same", "segment": "forearm", "aj": "beyond_joint"},
        {"name": "all_about_j", "segment": "forearm", "aj": "all"},
    ]
    data = scenes.apply_overrides(scenes.remove_keys(data, UNSET_STATIC), sets)
    scene = scenes.validate(data, base=CI.parent)
    assert scene.contact.aj == "beyond_joint" and scene.contact.torque_point is None
    run_scene(scene, base / "run", comm=COMM)
    if COMM.rank == 0:
        rows = _rows(base / "run")
        with (base / "run" / "torques.csv").open(newline="") as fh:
            table = list(csv.DictReader(fh))
        same = [r for r in table if r["name"] == "same"]
        every = [r for r in table if r["name"] == "all_about_j"]
        assert len(same) == len(every) == len(rows)
        for r, m in zip(rows, same, strict=True):
            assert m["time"] == r["time"]
            for col in ("torque_x", "torque_y", "torque_z", "torque_flex"):
                assert float(m[col]) == pytest.approx(float(r[col]), rel=1e-12, abs=1e-15)
        pairs = zip(every, same, strict=True)
        assert any(float(a["torque_mag"]) != float(b["torque_mag"]) for a, b in pairs)


def test_field_series_in_both_readers(tmp_path):
    """The explicit run's fabric.xdmf: meshio's time-series reader and pyvista's XdmfReader
    (VTK, as ParaView) both see displacement and contact pressure at every written time; the
    times are positive and increasing, and the last one is the end of the run."""
    import pyvista as pv

    base = _shared(tmp_path)
    sets = [*EXPLICIT, "output.every=4", "output.checkpoint_every=0"]
    scene = scenes.load(CI, sets, unset=UNSET_STATIC)
    out = run_scene(scene, base / "r", comm=COMM)
    rows = _rows(out)
    times, fields = _series(out)
    assert len(times) == len(rows) // 4 + (len(rows) % 4 != 0)
    assert times[0] > 0 and all(b > a for a, b in zip(times, times[1:], strict=False))
    assert times[-1] == float(rows[-1]["time"])  # the final state is always written
    for f in fields:
        assert f["displacement"].shape[1] == 3 and f["contact_pressure"].ndim == 1
    assert np.max(fields[-1]["contact_pressure"]) > 0
    reader = pv.XdmfReader(str(out / "fabric.xdmf"))
    assert list(reader.time_values) == times
    for t in (times[0], times[-1]):
        reader.set_active_time_value(t)
        grid = reader.read()
        assert {"displacement", "contact_pressure"} <= set(grid.point_data.keys())


def test_quasi_static_body_series_has_no_negative_times(tmp_path):
    """The quasi-static path writes the settled state at t = 0 and the motion after it."""
    base = _shared(tmp_path)
    scene = scenes.load(CI, ["body.1.angle_max=1.0", "contact.increments=2", "solver.steps=1"])
    out = run_scene(scene, base / "s", comm=COMM)
    times, fields = _series(out)
    assert times[0] == 0.0 and all(b > a for a, b in zip(times, times[1:], strict=False))
    assert times[-1] == pytest.approx(float(_rows(out)[-1]["time"]))
    assert all("contact_pressure" in f for f in fields)


# ---------------------------------------------------------------- killed runs, pictures


def _cli(out: Path, scene: Path, *args: str) -> list[str]:
    """`clothfem run` of ``scene`` without the keys UNSET_STATIC, then ``args``."""
    unset = [a for key in UNSET_STATIC for a in ("--unset", key)]
    return [
        sys.executable,
        "-m",
        "clothfem.cli",
        "run",
        str(scene),
        "--out",
        str(out),
        *unset,
        *args,
    ]


def _signal_after_lines(proc: subprocess.Popen, path: Path, lines: int, sig: int) -> None:
    """Send ``sig`` to ``proc`` once ``path`` holds ``lines`` lines (within 300 s)."""
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and proc.poll() is None:
        if path.exists() and path.read_text().count("\n") >= lines:
            proc.send_signal(sig)
            return
        time.sleep(0.02)


@pytest.mark.serial
@pytest.mark.skipif(COMM.size > 1, reason="launches its own process")
def test_sigkill_leaves_readable_files_and_resume_continues(tmp_path):
    """SIGKILL an explicit run once it has written rows and field steps: history.csv and the
    XDMF/HDF5 series read back (meshio) up to the last written step; `--resume` continues the
    same series to the end without a duplicated time. A resume killed in its turn leaves a
    summary that says it did not finish (not a stale earlier status) and lists the first
    segment's end (angle and wall time from the history); the resume after it lists both."""
    out = tmp_path / "killed"
    sets = [a for s in [*EXPLICIT[:-1], "output.checkpoint_every=3"] for a in ("--set", s)]
    proc = subprocess.Popen(
        _cli(out, CI, *sets), env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    _signal_after_lines(proc, out / "history.csv", 10, signal.SIGKILL)
    proc.wait(timeout=60)
    assert proc.returncode == -signal.SIGKILL
    rows = _rows(out)
    assert len(rows) >= 9 and all(r["elapsed"] for r in rows)
    times, fields = _series(out)
    assert len(times) >= 9 and {"displacement", "contact_pressure"} <= set(fields[-1])
    assert times == sorted(set(times))
    assert not (out / "summary.json").exists()
    proc = subprocess.Popen(
        [*_cli(out, CI, *sets), "--resume"], env=ENV, stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )  # fmt: skip
    _signal_after_lines(proc, out / "history.csv", 17, signal.SIGKILL)
    proc.wait(timeout=60)
    assert proc.returncode == -signal.SIGKILL
    killed = json.loads((out / "summary.json").read_text())
    assert killed["running"] is True and killed["completed"] is False
    assert "wall_time" not in killed
    (first,) = killed["earlier"]  # the first segment, killed: its end from the history
    assert first["reason"] == "no end recorded: killed while running"
    assert first["wall_time"] == float(rows[-1]["elapsed"]) > 0
    assert first["final_angle_deg"] == float(rows[-1]["angle_deg"])
    assert "status: not finished" in report_markdown(out)
    res = subprocess.run(
        [*_cli(out, CI, *sets), "--resume"], env=ENV, capture_output=True, text=True, timeout=600
    )
    assert res.returncode == 0, res.stderr[-2000:]
    done = json.loads((out / "summary.json").read_text())
    assert done["completed"] is True and "running" not in done
    assert [e["reason"] for e in done["earlier"]] == ["no end recorded: killed while running"] * 2
    assert done["earlier"][0] == first and done["earlier"][1]["wall_time"] > 0
    rows = _rows(out)
    times, _ = _series(out)
    assert times == sorted(set(times)) and len(times) == len(rows)
    assert times[-1] == float(rows[-1]["time"])
    assert float(rows[-1]["angle_deg"]) == pytest.approx(3.0)


@pytest.mark.serial
@pytest.mark.skipif(COMM.size > 1, reason="launches its own process")
def test_sigterm_writes_the_state_it_stops_at(tmp_path):
    """Fields every 100 rows, stopped by SIGTERM after a few rows: exit 130 and the field
    series holds the state of the last history row."""
    out = tmp_path / "stopped"
    sets = [*EXPLICIT[:-1], "output.every=100", "output.checkpoint_every=0"]
    args = [a for s in sets for a in ("--set", s)]
    proc = subprocess.Popen(
        _cli(out, CI, *args), env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
    )
    _signal_after_lines(proc, out / "history.csv", 4, signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err.decode()[-2000:]
    times, fields = _series(out)
    assert times == [float(_rows(out)[-1]["time"])]
    assert "contact_pressure" in fields[0]


@pytest.mark.serial
@pytest.mark.skipif(COMM.size > 1, reason="launches its own process")
def test_pictures_animation_and_progress(tmp_path):
    """A run with pictures off a terminal: plain progress lines with an ETA, no VTK X-server
    warning; snapshots (coloured by contact pressure, with a colour bar) and animation.gif
    with one frame per written field step."""
    from PIL import Image

    out = tmp_path / "pics"
    sets = [*EXPLICIT[:-1], "output.png=true", "output.every=5", "output.checkpoint_every=0"]
    args = [a for s in sets for a in ("--set", s)]
    res = subprocess.run(_cli(out, CI, *args), env=ENV, capture_output=True, text=True)
    assert res.returncode == 0, res.stderr[-2000:]
    assert "ETA" in res.stdout and "X server" not in res.stderr
    for name in ("snapshot_settled.png", "snapshot_final.png", "torque_angle.png"):
        assert (out / name).stat().st_size > 0
    times, _ = _series(out)
    with Image.open(out / "animation.gif") as gif:
        assert gif.n_frames == len(times) >= 2


# ---------------------------------------------------------------- scenes from files alone


def test_free_drape_scene(tmp_path):
    """demos/scenes/drape_free.toml (no body, explicit) for 0.02 s: the cloth falls."""
    base = _shared(tmp_path)
    scene = scenes.load(ROOT / "demos" / "scenes" / "drape_free.toml", ["solver.duration=0.02"])
    out = run_scene(scene, base / "drape", comm=COMM)
    rows = _rows(out)
    assert len(rows) == 2 and float(rows[-1]["time"]) == pytest.approx(0.02)
    assert float(rows[-1]["kinetic_energy"]) > 0 and int(rows[-1]["n_active"]) == 0
    times, fields = _series(out)
    uz = fields[-1]["displacement"][:, 2]
    assert times[-1] == pytest.approx(0.02) and uz.min() < -1e-3  # ~ g t^2 / 2 = 2 mm


def test_pants_hang_scene(tmp_path):
    """demos/scenes/pants_hang.toml (the pants mesh generator, hung from the waist, explicit)
    for 0.02 s: the waist stays put (clamped) and the legs start to fall, the same mesh and
    rows on any number of ranks."""
    base = _shared(tmp_path)
    sets = ["solver.duration=0.02", "output.png=false"]
    scene = scenes.load(ROOT / "demos" / "scenes" / "pants_hang.toml", sets)
    out = run_scene(scene, base / "pants", comm=COMM)
    rows = _rows(out)
    assert len(rows) == 2 and float(rows[-1]["kinetic_energy"]) > 0
    times, fields = _series(out)
    uz = fields[-1]["displacement"][:, 2]
    # gravity ramped over 0.1 s: g t^3 / (6 * 0.1 s) = 0.13 mm at 0.02 s for a free fall
    assert times[-1] == pytest.approx(0.02) and -2e-4 < uz.min() < -5e-5


@pytest.mark.parametrize(
    ("name", "sets", "column"),
    [
        ("sleeve_gravity", [], "residual"),
        ("drape_free", ["solver.duration=0.02"], "time"),
    ],
)
def test_hysteretic_preset_in_scenes_without_a_body(tmp_path, name, sets, column):
    """The decrimping + yarn-friction preset in the static and the explicit runner without a
    body: the history's material dissipation starts >= 0 and never decreases, and is > 0."""
    base = _shared(tmp_path)
    extra = ["material.preset=decrimping-cotton-hysteretic", "output.png=false"]
    scene = scenes.load(ROOT / "demos" / "scenes" / f"{name}.toml", [*sets, *extra])
    rows = _rows(run_scene(scene, base / name, comm=COMM))
    d = np.array([float(r["dissipation_material"]) for r in rows])
    assert len(rows) >= 2 and column in rows[0]
    assert d[0] >= 0.0 and np.all(np.diff(d) >= 0.0) and d[-1] > 0.0


def test_mocap_scene(tmp_path):
    """demos/scenes/sleeve_mocap.toml (an arm moved by the C3D file) past the settling into
    the recording: the forearm follows the recorded elbow flexion, the run writes its rows."""
    base = _shared(tmp_path)
    sets = ["solver.settle_time=0.01", "solver.ramp_time=0.01", "solver.duration=0.03"]
    sets += ["mesh.n_around=8", "mesh.n_along=4", "output.png=false"]
    scene = scenes.load(ROOT / "demos" / "scenes" / "sleeve_mocap.toml", sets)
    motions = scene_body.body_motions(scene)
    e1 = [motions[1].pose(t).rotation[:, 0] for t in (0.0, 0.8)]
    assert np.degrees(np.arccos(np.clip(e1[0] @ e1[1], -1, 1))) > 60  # 27 -> 114 deg flexion
    out = run_scene(scene, base / "mocap", comm=COMM)
    rows = _rows(out)
    assert len(rows) == 3 and rows[-1]["stage"] == "motion"
    assert all(np.isfinite(float(r["torque_mag"])) for r in rows)


DRAPE = ROOT / "demos" / "scenes" / "drape_free.toml"
NEWMARK_FREE = ["solver.integrator=newmark", "solver.dt=0.01", "solver.gamma=0.5"]
NEWMARK_FREE += ["solver.duration=0.1", "output.png=false", "output.checkpoint_every=3"]


def test_newmark_free_drape_runs_the_verified_integrator(tmp_path):
    """A free drape (no body) on the implicit path: the scene runner's history is, step by
    step and bit for bit, the energies of clothfem.dynamics.integrate_implicit (verified
    against closed-form oscillators and the cantilever benchmarks) on the same model,
    scheme, steps and load."""
    from clothfem.dynamics import ImplicitScheme, ShellSystem, TimeStepping, integrate_implicit
    from clothfem.run import build_model

    base = _shared(tmp_path)
    scene = scenes.load(DRAPE, NEWMARK_FREE, unset=["solver.rotary_scale", "output.interval"])
    rows = _rows(run_scene(scene, base / "run", comm=COMM))
    model, _ = build_model(scene, COMM)
    records = integrate_implicit(
        ShellSystem(model, rotary_scale=scene.solver.rotary_scale),
        stepping=TimeStepping(dt=0.01, t_end=0.1, dt_min=scene.solver.dt_min),
        scheme=ImplicitScheme.newmark(beta=0.25, gamma=0.5),
        load=lambda t: 1.0,
    )
    assert len(rows) == len(records) == 10
    for row, rec in zip(rows, records, strict=True):
        assert float(row["time"]) == rec.time
        assert float(row["kinetic_energy"]) == rec.kinetic > 0.0
        assert float(row["strain_energy"]) == rec.strain
        assert int(row["newton_iterations"]) == rec.newton_iterations


def test_newmark_free_drape_resumes_bit_for_bit(tmp_path):
    """The same free drape checkpointing every 3 steps, resumed from the second checkpoint
    (step 6): every history column but the timers is the uninterrupted run's."""
    base = _shared(tmp_path)
    scene = scenes.load(DRAPE, NEWMARK_FREE, unset=["solver.rotary_scale", "output.interval"])
    kept = _run_keeping_checkpoints(scene, base / "reference", (2,))
    _resume_from(base / "reference", kept[2], base / "resumed", scene)
    _same_history(_rows(base / "reference"), _rows(base / "resumed"))


def test_soft_tissue_tends_to_the_rigid_body(tmp_path):
    """contact.tissue_stiffness: the Newmark arm's torque tends to the rigid body's as
    k_w grows, as 1 / k_w (the give lam / (k_w A) is the only change to the constraints);
    the history reports the give and the log says the body is soft."""
    base = _shared(tmp_path)
    data = scenes.apply_overrides(
        scenes.remove_keys(tomllib.loads(CI.read_text()), UNSET_STATIC), NEWMARK
    )
    runs = {}
    for kw in (None, 1e7, 1e8):
        sets = [] if kw is None else [f"contact.tissue_stiffness={kw:g}"]
        scene = scenes.validate(scenes.apply_overrides(data, sets), base=CI.parent)
        out = base / f"kw{kw}"
        run_scene(scene, out, comm=COMM)
        if COMM.rank == 0:
            built = json.loads((out / "summary.json").read_text())["built"]
            assert any("soft tissue" in line for line in built) == (kw is not None)
            runs[kw] = _rows(out)
    if COMM.rank == 0:
        rigid = np.array([float(r["torque_flex"]) for r in runs[None]])
        assert all(r["tissue_indentation"] == "" for r in runs[None])
        diff = {}
        for kw in (1e7, 1e8):
            give = np.array([float(r["tissue_indentation"]) for r in runs[kw]])
            assert give.max() > 0 and np.all(give >= 0)
            tau = np.array([float(r["torque_flex"]) for r in runs[kw]])
            diff[kw] = np.max(np.abs(tau - rigid)) / np.max(np.abs(rigid))
        assert 0 < diff[1e8] < 1e-2
        assert diff[1e7] / diff[1e8] == pytest.approx(10.0, rel=0.3)  # first order in 1 / k_w
