"""Shared plumbing of the arm-sleeve benchmark drivers (``arm_studies.py``, ``arm_ladder.py``,
``arm_extreme.py``): one case = one ``clothfem run`` subprocess in its own folder.

A case is a name plus a list of ``--set`` overrides of ``demos/scenes/arm_sleeve.toml`` and a
number of MPI ranks (``Case.ranks``, default 1: a plain serial run; N > 1: the same command
under ``mpirun --allow-run-as-root --oversubscribe -n N <python> -m mpi4py``). Its
folder ``OUT/<study>/<case>/`` holds what ``clothfem run`` writes (``history.csv``,
``summary.json``, PNGs, XDMF) and what the driver adds: ``command.txt`` (the exact command),
``stdout.log`` / ``stderr.log`` and ``case.json`` (exit status, wall time measured by the
driver, the overrides, the ranks). A case whose ``summary.json`` says ``completed`` with the
same overrides and ranks is not run again unless ``force`` (so an interrupted study resumes where it
stopped); while ``clothfem run`` does not write ``summary.json`` yet, ``case.json`` with exit
status 0 stands in for it. A case whose physics (the scene after overrides and defaults, but
for its name and output sections) a completed case of another study in the same output
folder already ran is copied from it (:func:`find_twin`; ``case.json`` names it under
``same_as``) instead of being run again.

A scene takes only the keys of its integrator: a case whose overrides switch
``solver.integrator`` runs with ``--unset`` of the scene file's keys that belong to another
integrator (:func:`scene_edits`), and the quasi-static path of a hinge scene gets its
settling in ``solver.steps`` = 2 load steps and the hinge in 1-degree ``contact.increments``
(the scene file's increment size when it has one) unless the overrides give them.

:func:`case_result` reduces a case folder to one flat row (completed, reason, final angle,
steps, cut-backs, max penetration, wall time, torques at given angles, peak torque, NaN/inf
in the output); :class:`RowWriter` writes such rows to a CSV one at a time (flushed), and
:func:`torque_plot` draws torque against angle for several cases (matplotlib Agg).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import shlex
import shutil
import signal
import subprocess
import sys
import time
import tomllib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from clothfem.report import curve_error, moving_average, read_history
from clothfem.report import torque_curve as report_torque_curve
from clothfem.scene import SceneError, apply_overrides, foreign_keys
from clothfem.scene import load as load_scene
from clothfem.spec import to_dict

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "demos" / "scenes" / "arm_sleeve.toml"
HINGE = "body.1"  # the forearm segment of arm_sleeve.toml ([[body]] index 1)
REPORT_ANGLES = (10, 20, 30, 40, 50, 57)  # deg: torque columns of the study tables
# deg: angle bands of the band-mean torque columns (mean of |tau| over the band: robust to
# single-step spikes, which the pointwise columns and the peak are not)
REPORT_BANDS = ((2, 15), (15, 30), (30, 45), (45, 57))
# deg: window of the centred moving average of the smoothed curve errors (curve_error
# window=...); it filters the step-to-step dynamic oscillation of the torque (a few deg)
SMOOTH_DEG = 2.0
STATIC_SETTLE_STEPS = 2  # load steps of the quasi-static settling (solver.steps)

__all__ = [
    "HINGE",
    "ROOT",
    "SCENE",
    "REPORT_ANGLES",
    "REPORT_BANDS",
    "SMOOTH_DEG",
    "Case",
    "RowWriter",
    "MPIRUN",
    "add_common_args",
    "angle_max_sets",
    "band_mean",
    "case_result",
    "command",
    "curve_error",
    "find_twin",
    "fmt",
    "markdown_table",
    "mesh_sets",
    "set_arg",
    "parse_mesh",
    "read_history",
    "result_columns",
    "run_cases",
    "scene_edits",
    "torque_curve",
    "torque_plot",
]


@dataclass
class Case:
    """One run: ``name`` (its folder), ``sets`` (``key.path=value`` overrides, in order),
    ``params`` (columns for the tables, e.g. ``{"mu": 0.5}``), ``ranks`` (MPI ranks: 1 runs
    ``clothfem run`` plainly, N > 1 under ``mpirun -n N``; see :func:`command`)."""

    name: str
    sets: list[str]
    params: dict[str, Any] = field(default_factory=dict)
    scene: Path = SCENE
    ranks: int = 1

    def __post_init__(self) -> None:
        if isinstance(self.ranks, bool) or not isinstance(self.ranks, int) or self.ranks < 1:
            raise ValueError(f"case {self.name}: ranks must be an int >= 1, got {self.ranks!r}")


# ---------------------------------------------------------------------------------------------
# command line


def add_common_args(parser: argparse.ArgumentParser, *, default_out: str) -> None:
    """Options every driver has: --out, --quick, --dry-run, --force, --only, --angle-max,
    --extra-set, --timeout, --scene."""
    parser.add_argument("--out", default=default_out, help="output folder (default %(default)s)")
    parser.add_argument("--quick", action="store_true", help="fewer / coarser cases")
    parser.add_argument(
        "--dry-run", action="store_true", help="print the commands (and which would be skipped)"
    )
    parser.add_argument(
        "--force", action="store_true", help="run again cases whose summary says completed"
    )
    parser.add_argument(
        "--only", nargs="+", default=None, metavar="CASE", help="run only these case names"
    )
    parser.add_argument(
        "--angle-max",
        type=float,
        default=None,
        metavar="DEG",
        help=f"override {HINGE}.angle_max (quick checks); contact.increments is scaled with it",
    )
    parser.add_argument(
        "--extra-set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="extra --set for every case, after the case's own (repeatable), "
        "e.g. solver.integrator=newmark",
    )
    parser.add_argument(
        "--timeout",
        type=float,
        default=None,
        metavar="S",
        help="stop a case (SIGTERM) after S seconds of wall time and record it as not completed",
    )
    parser.add_argument("--scene", type=Path, default=SCENE, help="base scene (arm_sleeve.toml)")


def parse_mesh(text: str) -> tuple[int, int]:
    """``"16x20"`` -> (16, 20) (n_around, n_along)."""
    try:
        a, b = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"mesh must be NAxNL, e.g. 16x20, got {text!r}") from None
    return a, b


def set_arg(key: str, value: Any) -> str:
    """``key=value`` for ``--set`` (value in TOML syntax; strings bare, e.g. newmark)."""
    if isinstance(value, bool):
        text = "true" if value else "false"
    elif isinstance(value, float):
        text = repr(value)
    else:
        text = str(value)
    return f"{key}={text}"


def mesh_sets(mesh: tuple[int, int]) -> list[str]:
    return [set_arg("mesh.n_around", mesh[0]), set_arg("mesh.n_along", mesh[1])]


def angle_max_sets(angle_max: float | None) -> list[str]:
    """Overrides for ``--angle-max``: the hinge's angle_max (the quasi-static path's
    increments follow it, :func:`scene_edits`)."""
    return [] if angle_max is None else [f"{HINGE}.angle_max={angle_max:g}"]


def scene_edits(scene: Path, sets: Sequence[str]) -> tuple[list[str], list[str]]:
    """(keys to ``--unset``, ``--set`` overrides to add) that run ``scene`` with ``sets``:
    the keys of the scene file that do not apply to the integrator ``sets`` select (a key
    ``sets`` give is kept: the run refuses it) and, on the static path, the settling steps
    and hinge increments ``sets`` do not give (:func:`_static_sets`). Nothing when the file
    or the overrides do not read (the run reports it)."""
    try:
        data = tomllib.loads(scene.read_text())
        merged = apply_overrides(data, list(sets))
    except (OSError, tomllib.TOMLDecodeError, SceneError):
        return [], []
    given = {s.split("=", 1)[0].strip() for s in sets}
    unset = [k for k in foreign_keys(merged) if k not in given]
    static = merged.get("solver", {}).get("integrator", "static") == "static"
    return unset, _static_sets(data, merged, given) if static else []


def _static_sets(data: dict[str, Any], merged: dict[str, Any], given: set[str]) -> list[str]:
    """The quasi-static path of the hinge of scene file ``data`` (``merged``: with the
    overrides, whose keys are ``given``): STATIC_SETTLE_STEPS load steps of settling, and
    hinge increments of the file's size (1 deg if it has none) over the angle reached."""
    k = int(HINGE.split(".")[1])
    bodies = data.get("body", [])
    a0 = bodies[k].get("angle_max") if len(bodies) > k else None
    if not a0:
        return []
    add = (
        []
        if "solver.steps" in given or "steps" in data.get("solver", {})
        else [f"solver.steps={STATIC_SETTLE_STEPS}"]
    )
    inc0 = data.get("contact", {}).get("increments")
    angle = merged["body"][k].get("angle_max", a0)
    inc = max(1, math.ceil((inc0 or a0) * angle / a0 - 1e-9))
    if "contact.increments" not in given and inc != inc0:
        add.append(f"contact.increments={inc}")
    return add


# ---------------------------------------------------------------------------------------------
# running a case


MPIRUN = ("mpirun", "--allow-run-as-root", "--oversubscribe")


def command(case: Case, out: Path, extra: Sequence[str] = ()) -> list[str]:
    """The ``clothfem run`` command of a case (``extra``: overrides after the case's own);
    with ``case.ranks`` > 1 under ``mpirun -n ranks <python> -m mpi4py``."""
    cmd = [sys.executable, "-m", "clothfem.cli", "run", str(case.scene), "--out", str(out)]
    if case.ranks > 1:
        cmd = [*MPIRUN, "-n", str(case.ranks), sys.executable, "-m", "mpi4py", *cmd[1:]]
    sets = [*case.sets, *extra]
    unset, add = scene_edits(case.scene, sets)
    for key in unset:
        cmd += ["--unset", key]
    for s in [*sets, *add]:
        cmd += ["--set", s]
    return cmd


def _load_json(path: Path) -> dict[str, Any] | None:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def _done_before(folder: Path, sets: list[str], ranks: int = 1) -> bool:
    """True if the folder holds a completed run with the same overrides (and ranks; a
    case.json without ``ranks`` was a serial run)."""
    rec = _load_json(folder / "case.json")
    if rec is not None and (rec.get("sets") != sets or rec.get("ranks", 1) != ranks):
        return False  # other overrides (e.g. another --angle-max): not the same case
    summary = _load_json(folder / "summary.json")
    if summary is not None:
        return bool(summary.get("completed"))
    return rec is not None and rec.get("returncode") == 0


# sections of a scene that do not change the computed answer (names, output cadence)
_NOT_PHYSICS = ("scene", "output")


def _physics(scene_path: Path | str, sets: Sequence[str]) -> dict[str, Any] | None:
    """The validated scene with overrides as a dict, without the sections that only name it
    or say what to write (None if it does not load)."""
    unset, add = scene_edits(Path(scene_path), sets)
    try:
        data = to_dict(load_scene(scene_path, [*sets, *add], unset=unset))
    except (SceneError, OSError):
        return None
    return {k: v for k, v in data.items() if k not in _NOT_PHYSICS}


def _scene_of_command(path: Path) -> str | None:
    """The scene file of a ``command.txt`` (the word after ``run``; case.json files written
    before it recorded ``scene`` have only this)."""
    try:
        words = shlex.split(path.read_text())
    except (OSError, ValueError):
        return None
    return words[words.index("run") + 1] if "run" in words[:-1] else None


def find_twin(folder: Path, scene: Path, sets: Sequence[str], ranks: int = 1) -> Path | None:
    """A completed case folder of the same driver output (``folder/../../*/*``) that ran the
    same physics: same ranks and, after overrides and defaults, the same scene but for its
    name and output sections (e.g. friction's mu = 0.5 case and fit's R = 0.06 m case).
    None if there is none."""
    mine = _physics(scene, sets)
    if mine is None:
        return None
    for rec_path in sorted(folder.parent.parent.glob("*/*/case.json")):
        other = rec_path.parent
        rec = _load_json(rec_path) or {}
        if other.resolve() == folder.resolve() or "same_as" in rec:
            continue  # itself, or a copy
        their_sets = rec.get("sets")
        their_ranks = rec.get("ranks", 1)
        if their_sets is None or their_ranks != ranks or not _done_before(other, their_sets, ranks):
            continue
        their_scene = rec.get("scene") or _scene_of_command(other / "command.txt")
        if their_scene is not None and _physics(their_scene, their_sets) == mine:
            return other
    return None


def _copy_twin(twin: Path, folder: Path, sets: list[str], ranks: int) -> None:
    """Make ``folder`` a result-only copy of ``twin`` (history, summary, PNGs; not the XDMF,
    logs or checkpoint) whose case.json names the twin."""
    folder.mkdir(parents=True, exist_ok=True)
    for f in [twin / "history.csv", twin / "summary.json", *twin.glob("*.png")]:
        if f.is_file():
            shutil.copy2(f, folder / f.name)
    rec = _load_json(twin / "case.json") or {}
    rec.update(sets=sets, same_as=str(twin))
    if ranks > 1:
        rec["ranks"] = ranks
    (folder / "case.json").write_text(json.dumps(rec, indent=1) + "\n")


def _run(cmd: list[str], folder: Path, timeout: float | None) -> tuple[int, float, bool]:
    """Run ``cmd`` in its own process group, logs to ``folder``; returns (exit status, wall
    time, timed out). On timeout or Ctrl-C the child gets SIGTERM (clothfem closes its files
    and keeps its rows), then SIGKILL after 60 s."""
    t0 = time.perf_counter()
    timed_out = False
    # one BLAS thread per process (as make sets it), and no MPI environment of a driver that
    # was itself started under mpirun (it would break the child's own mpirun)
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "OPAL_"))}
    env.update(PYTHONUNBUFFERED="1", OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    with open(folder / "stdout.log", "w") as so, open(folder / "stderr.log", "w") as se:
        proc = subprocess.Popen(
            cmd, stdout=so, stderr=se, cwd=ROOT, env=env, start_new_session=True
        )

        def stop() -> None:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGTERM)
                try:
                    proc.wait(60)
                except subprocess.TimeoutExpired:
                    os.killpg(proc.pid, signal.SIGKILL)
                    proc.wait()

        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            timed_out = True
            stop()
        except BaseException:  # Ctrl-C of the driver: stop the child cleanly, then re-raise
            stop()
            raise
    return proc.returncode, time.perf_counter() - t0, timed_out


def run_cases(
    cases: Iterable[Case],
    study_dir: Path,
    args: argparse.Namespace,
    *,
    on_result=None,
    settings: Sequence[str] = (),
) -> list[dict[str, Any]]:
    """Run (or skip, or with ``args.dry_run`` print) every case in ``study_dir/<case>/``;
    ``settings`` are overrides common to the study (e.g. the mesh), put before the case's.
    After each case, ``on_result(case, row)`` gets its :func:`case_result` row. Cases left
    out by ``--only`` contribute the rows of their earlier runs, if any. Returns the rows in
    the order of ``cases`` (dry run: empty)."""
    rows = []
    for case in cases:
        case.sets = [*settings, *case.sets]
        if args.scene != SCENE:
            case.scene = args.scene
        folder = study_dir / case.name
        if args.only and case.name not in args.only:
            # not selected: its earlier result (if any) still goes into the tables
            if not args.dry_run and (folder / "case.json").exists():
                row = {"case": case.name, **case.params, **case_result(folder)}
                rows.append(row)
                if on_result is not None:
                    on_result(case, row)
            continue
        cmd = command(case, folder, args.extra_set)
        sets = [*case.sets, *args.extra_set]
        skip = not args.force and _done_before(folder, sets, case.ranks)
        twin = None if skip or args.force else find_twin(folder, case.scene, sets, case.ranks)
        if args.dry_run:
            prefix = "# done, skipped: " if skip else ""
            prefix = f"# same physics as {twin}, copied: " if twin else prefix
            print(prefix + shlex.join(cmd))
            continue
        if skip:
            print(f"[{study_dir.name}/{case.name}] completed before: skipped (--force reruns)")
        elif twin is not None:
            _copy_twin(twin, folder, sets, case.ranks)
            print(f"[{study_dir.name}/{case.name}] same physics as {twin}: copied, not run")
        else:
            folder.mkdir(parents=True, exist_ok=True)
            # a case stopped by --timeout continues from its checkpoint (same overrides)
            before = _load_json(folder / "case.json") or {}
            resume = (
                not args.force
                and before.get("timed_out")
                and before.get("sets") == sets
                and before.get("ranks", 1) == case.ranks
                and (folder / "checkpoint").is_dir()
            )
            if resume:
                cmd = [*cmd, "--resume"]
            else:  # the case folder is this driver's: a new run starts in an empty one
                shutil.rmtree(folder)
                folder.mkdir(parents=True)
            (folder / "command.txt").write_text(shlex.join(cmd) + "\n")
            print(
                f"[{study_dir.name}/{case.name}] {'resuming' if resume else 'running'} ...",
                flush=True,
            )
            code, wall, timed_out = _run(cmd, folder, args.timeout)
            wall += float(before.get("wall_s", 0.0)) if resume else 0.0
            rec = {"sets": sets, "returncode": code, "wall_s": wall, "timed_out": timed_out}
            rec["scene"] = str(case.scene)
            rec["resumed"] = bool(resume)
            if case.ranks > 1:
                rec["ranks"] = case.ranks
            if timed_out:
                rec["timeout_s"] = args.timeout
            (folder / "case.json").write_text(json.dumps(rec, indent=1) + "\n")
        row = {"case": case.name, **case.params, **case_result(folder)}
        print(
            f"[{study_dir.name}/{case.name}] completed {row['completed']}, "
            f"final angle {fmt(row['final_angle_deg'])} deg, wall {fmt(row['wall_s'])} s"
            + ("" if row["completed"] == "yes" else f" ({row['reason']})"),
            flush=True,
        )
        rows.append(row)
        if on_result is not None:
            on_result(case, row)
    return rows


# ---------------------------------------------------------------------------------------------
# reading a case


def _last_stderr_line(folder: Path) -> str:
    try:
        lines = [ln.strip() for ln in (folder / "stderr.log").read_text().splitlines()]
    except OSError:
        return ""
    lines = [ln for ln in lines if ln]
    return lines[-1] if lines else ""


def _nan_in_csv(path: Path) -> bool:
    """Any NaN or inf value in the CSV (any column)."""
    try:
        with path.open(newline="") as f:
            for row in csv.reader(f):
                for v in row:
                    if v.strip().lower().lstrip("+-") in ("nan", "inf", "infinity"):
                        return True
    except OSError:
        return False
    return False


def torque_curve(hist: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """:func:`clothfem.report.torque_curve` (the settled row and the motion rows), finite
    values only, sorted by angle (repeated angles keep their last row); empty if the
    history lacks the columns."""
    if not hist or "angle_deg" not in hist or "torque_mag" not in hist:
        return np.zeros(0), np.zeros(0)
    if "stage" not in hist:
        hist = {**hist, "stage": np.full(len(hist["angle_deg"]), "motion")}
    a, t = report_torque_curve(hist)
    ok = np.isfinite(a) & np.isfinite(t)
    a, t = a[ok], t[ok]
    order = np.argsort(a, kind="stable")
    a, t = a[order], t[order]
    last = np.r_[a[1:] != a[:-1], True] if a.size else np.zeros(0, dtype=bool)
    return a[last], t[last]


def band_mean(angle: np.ndarray, torque: np.ndarray, lo: float, hi: float) -> float:
    """Mean of the piecewise-linear torque curve over [lo, hi] deg (the exact integral over
    the band divided by its width: ``clothfem.report.moving_average`` of window hi - lo at
    the band's middle); nan if the curve does not cover the band."""
    if angle.size == 0 or np.nanmin(angle) > lo + 1e-9 or np.nanmax(angle) < hi - 1e-9:
        return math.nan
    mid = np.array([0.5 * (lo + hi)])
    return float(moving_average(angle, torque, hi - lo, at=mid)[0])


def case_result(folder: Path, angles: Sequence[float] = REPORT_ANGLES) -> dict[str, Any]:
    """One flat row for a case folder: from ``summary.json`` where it exists, else from
    ``history.csv`` and the exit status in ``case.json``."""
    summary = _load_json(folder / "summary.json") or {}
    rec = _load_json(folder / "case.json") or {}
    hist_path = folder / "history.csv"
    hist = {}
    if hist_path.exists():
        try:
            hist = read_history(hist_path)
        except Exception as exc:  # an unreadable CSV is a result too
            hist = {}
            summary.setdefault("reason", f"history.csv unreadable: {exc}")
    a, t = torque_curve(hist)
    code = rec.get("returncode")
    completed = bool(summary["completed"]) if "completed" in summary else code == 0
    if completed:
        status = "yes"
    elif rec.get("timed_out"):
        status = "no"
        summary["reason"] = f"stopped by the driver after --timeout {rec.get('timeout_s', 0):g} s"
    else:
        status = "no"
    reason = summary.get("reason") or ("" if completed else _last_stderr_line(folder))
    if not completed and not reason:
        reason = f"exit status {code}" if code is not None else "not run"

    def col(name: str) -> np.ndarray:
        return np.asarray(hist.get(name, []), dtype=float)

    def pick(key: str, fallback: float) -> float:
        v = summary.get(key)
        return float(v) if isinstance(v, int | float) and v is not None else fallback

    stage = np.asarray(hist.get("stage", [])).astype(str)
    elapsed = col("elapsed")
    cut = col("cutbacks")
    pen = col("max_penetration")
    row: dict[str, Any] = {
        "completed": status,
        "reason": reason.replace("\n", " "),
        "exit_status": code if code is not None else "",
        "final_angle_deg": pick("final_angle_deg", float(a[-1]) if a.size else math.nan),
        "steps": int(pick("steps", float((stage == "motion").sum()))),
        "cutbacks": pick("cutbacks", float(np.nansum(cut)) if cut.size else math.nan),
        "max_penetration_m": pick(
            "max_penetration", float(np.nanmax(pen)) if pen.size else math.nan
        ),
        "wall_s": float(rec["wall_s"])  # a resumed case: both runs, from the driver
        if rec.get("resumed")
        else pick(
            "wall_time",
            float(elapsed[-1]) if elapsed.size else float(rec.get("wall_s", math.nan)),
        ),
        "driver_wall_s": float(rec.get("wall_s", math.nan)),
    }
    for ang in angles:
        covered = a.size and a[0] - 1e-9 <= ang <= a[-1] + 1e-9
        row[f"torque_at_{ang:g}deg"] = float(np.interp(ang, a, t)) if covered else math.nan
    for lo, hi in REPORT_BANDS:
        row[f"mean_torque_{lo:g}_{hi:g}deg"] = band_mean(a, t, lo, hi)
    row["peak_torque"] = float(t.max()) if t.size else math.nan
    row["nan_in_output"] = "yes" if _nan_in_csv(hist_path) else "no"
    return row


# ---------------------------------------------------------------------------------------------
# tables and figures


def fmt(v: Any) -> str:
    """Table cell: 4 significant digits for floats, empty for NaN."""
    if isinstance(v, float | np.floating):
        return "" if math.isnan(v) else f"{v:.4g}"
    return str(v)


class RowWriter:
    """A CSV written one row at a time (flushed). Columns are fixed by ``columns`` (rows may
    lack some: empty cells); :meth:`rewrite` replaces the whole file (e.g. once columns that
    need every case, like an error against the finest mesh, are known)."""

    def __init__(self, path: Path, columns: Sequence[str]) -> None:
        self.path, self.columns = Path(path), list(columns)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._f = self.path.open("w", newline="")
        self._w = csv.DictWriter(self._f, fieldnames=self.columns, extrasaction="ignore")
        self._w.writeheader()
        self._f.flush()

    def write(self, row: dict[str, Any]) -> None:
        self._w.writerow({k: fmt(v) if isinstance(v, float) else v for k, v in row.items()})
        self._f.flush()

    def rewrite(self, rows: Iterable[dict[str, Any]]) -> None:
        self._f.close()
        self._f = self.path.open("w", newline="")
        self._w = csv.DictWriter(self._f, fieldnames=self.columns, extrasaction="ignore")
        self._w.writeheader()
        for row in rows:
            self.write(row)

    def close(self) -> None:
        self._f.close()


def result_columns(angles: Sequence[float] = REPORT_ANGLES) -> list[str]:
    return [
        "completed",
        "reason",
        "exit_status",
        "final_angle_deg",
        *(f"torque_at_{a:g}deg" for a in angles),
        *(f"mean_torque_{lo:g}_{hi:g}deg" for lo, hi in REPORT_BANDS),
        "peak_torque",
        "wall_s",
        "driver_wall_s",
        "steps",
        "cutbacks",
        "max_penetration_m",
        "nan_in_output",
    ]


def torque_plot(
    curves: Sequence[tuple[str, Path]],
    png: Path,
    *,
    title: str,
    logy: bool = False,
) -> None:
    """Torque |tau| against flexion angle, one line per (label, case folder); runs that
    stopped say where in their label. Folders without a history are left out."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    drawn = 0
    for label, folder in curves:
        path = folder / "history.csv"
        if not path.exists():
            continue
        try:
            a, t = torque_curve(read_history(path))
        except Exception:
            continue
        if logy:
            a, t = a[t > 0], t[t > 0]
        summary = _load_json(folder / "summary.json") or {}
        if summary.get("completed") is False and a.size:
            label += f" (stopped at {a[-1]:.3g} deg)"
        if a.size:
            ax.plot(a, t, ".-", label=label)
            drawn += 1
    ax.set_xlabel("flexion angle [deg]")
    ax.set_ylabel("torque about the elbow |tau| [N m]")
    if logy:
        ax.set_yscale("log")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.4)
    if drawn:
        ax.legend(fontsize=8)
    fig.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=120)
    plt.close(fig)


def markdown_table(rows: Sequence[dict[str, Any]], columns: Sequence[str]) -> str:
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    for r in rows:
        lines.append("| " + " | ".join(fmt(r.get(c, "")) for c in columns) + " |")
    return "\n".join(lines) + "\n"
