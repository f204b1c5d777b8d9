"""benchmarks/arm_ladder.py: the MPI-rank rungs and the round-off floor.

No simulation runs: synthetic run folders (history.csv, summary.json, case.json) in
``tmp_path`` (one per process, so this also runs under mpirun), with analytic torque curves
whose errors against the reference are computed here independently of the code.
"""

import csv
import json
import math
import re
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

import _arm_common as C  # noqa: E402
import arm_ladder as L  # noqa: E402

HI = 10.0  # deg: the compared range is [L.LO, HI] = [2, 10] (passed as --angle / given A)
AMP = 0.033  # relative amplitude of the floor rung's round-off wiggle


def tau_ref(a):
    return 0.1 + 0.002 * a


def tau_floor(a):
    return tau_ref(a) * (1 + AMP * np.sin(a))


# synthetic ladder: scene keys only matter for the --set list; BASE is empty
REF = {"name": "ref", "reference": True, "mesh.n_around": 16}
RUNGS = [
    {"name": "off4", "mesh.n_around": 8},  # tau_ref * 1.04: error exactly 4 % in both norms
    {"name": "off1.5", "mesh.n_around": 10},  # 1.5 %
    {"name": "off0.5", "mesh.n_around": 12},  # 0.5 %
    REF,
    L.floor_rung(REF),  # ref_np2: tau_floor
]
CURVES = {
    "off4": (lambda a: 1.04 * tau_ref(a), 20.0),  # (torque curve, wall time [s])
    "off1.5": (lambda a: 1.015 * tau_ref(a), 50.0),
    "off0.5": (lambda a: 1.005 * tau_ref(a), 100.0),
    "ref": (tau_ref, 200.0),
    "ref_np2": (tau_floor, 1.0),  # the cheapest of all: must never be chosen
}


def analytic_floor() -> tuple[float, float]:
    """(raw, smoothed) relative L2 error of tau_floor against tau_ref over [2, 10] deg, by
    dense quadrature of closed forms. Smoothed: the centred 2-deg moving average of the
    linear tau_ref is tau_ref itself (the curves span [0, 12], so every window is whole);
    that of the difference d(x) = AMP sin(x) (0.1 + 0.002 x) is (I(a+1) - I(a-1)) / 2 with
    I = AMP (-0.1 cos x + 0.002 (sin x - x cos x)) its antiderivative."""
    x = np.linspace(L.LO, HI, 200_001)

    def integral(f):
        return float(np.sum(0.5 * (f[1:] + f[:-1]) * np.diff(x)))

    def anti(y):
        return AMP * (-0.1 * np.cos(y) + 0.002 * (np.sin(y) - y * np.cos(y)))

    den = integral(tau_ref(x) ** 2)
    raw = math.sqrt(integral((AMP * np.sin(x) * tau_ref(x)) ** 2) / den)
    smooth = math.sqrt(integral((0.5 * (anti(x + 1) - anti(x - 1))) ** 2) / den)
    return raw, smooth


def write_case(folder: Path, curve, wall: float, *, stop_at: float | None = None) -> None:
    """A finished case folder: history.csv (a settle row at 0 deg, motion rows every 0.05 deg
    to 12 deg, or to ``stop_at`` for a run that stopped), summary.json, case.json."""
    folder.mkdir(parents=True, exist_ok=True)
    end = 12.0 if stop_at is None else stop_at
    angles = np.linspace(0.0, end, int(round(end / 0.05)) + 1)
    with (folder / "history.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["stage", "time", "angle_deg", "torque_mag", "elapsed", "cutbacks"])
        w.writerow(["settle", 0.0, 0.0, repr(float(curve(0.0))), 0.0, 0])
        for i, a in enumerate(angles[1:], start=1):
            w.writerow(["motion", a / 10, repr(float(a)), repr(float(curve(a))), wall * i, 0])
    summary = {"completed": stop_at is None, "wall_time": wall}
    if stop_at is not None:
        summary["reason"] = "synthetic stop"
    (folder / "summary.json").write_text(json.dumps(summary))
    rec = {"sets": [], "returncode": 0 if stop_at is None else 1, "wall_s": wall}
    (folder / "case.json").write_text(json.dumps(rec))


def ladder_rows(study_dir: Path, *, floor_stop: float | None = None, floor_run: bool = True):
    """Rows as run_cases makes them for the synthetic ladder (cases, reference, rows)."""
    cases, ref = L.rung_cases({}, RUNGS)
    rows = []
    for case in cases:
        curve, wall = CURVES[case.name]
        if case.name == "ref_np2":
            if not floor_run:
                continue
            write_case(study_dir / case.name, curve, wall, stop_at=floor_stop)
        else:
            write_case(study_dir / case.name, curve, wall)
        rows.append({"case": case.name, **case.params, **C.case_result(study_dir / case.name)})
    return cases, ref, rows


def floor_of(line: str) -> float | None:
    m = re.search(r"below the round-off floor F = ([0-9.]+) %", line)
    return float(m.group(1)) / 100 if m else None


# ---------------------------------------------------------------------------------------------
# (a) ranks / floor keys and the command


def test_rung_keys_not_set_and_mpirun_command(tmp_path):
    cases, ref = L.rung_cases({"solver.dt": 0.01}, RUNGS)
    assert ref == "ref"
    by = {c.name: c for c in cases}
    floor = by["ref_np2"]
    assert floor.ranks == 2 and by["ref"].ranks == 1 and by["off4"].ranks == 1
    assert floor.params["floor"] == "yes" and floor.params["ranks"] == 2
    assert by["ref"].params["floor"] == "" and by["ref"].params["ranks"] == 1
    assert floor.sets == by["ref"].sets == ["solver.dt=0.01", "mesh.n_around=16"]
    for c in cases:
        assert not any(s.split("=")[0] in ("ranks", "floor", "reference") for s in c.sets)

    out, extra = tmp_path / "case", ["contact.mu=0.5"]
    cmd1 = C.command(by["ref"], out, extra)
    sets = ["--set", "solver.dt=0.01", "--set", "mesh.n_around=16", "--set", "contact.mu=0.5"]
    scene = [str(C.SCENE), "--out", str(out)]
    assert cmd1 == [sys.executable, "-m", "clothfem.cli", "run", *scene, *sets]
    cmd2 = C.command(floor, out, extra)
    mpi = ["mpirun", "--allow-run-as-root", "--oversubscribe", "-n", "2"]
    assert cmd2 == [*mpi, sys.executable, "-m", "mpi4py", *cmd1[1:]]


def test_shipped_ladders_end_with_the_floor_rung():
    for base, ladder in ((L.BASE, L.LADDER), (L.QUICK_BASE, L.QUICK_LADDER)):
        cases, ref = L.rung_cases(base, ladder)
        by = {c.name: c for c in cases}
        floor = by[f"{ref}_np2"]
        assert floor.ranks == 2 and floor.params["floor"] == "yes"
        assert floor.sets == by[ref].sets and by[ref].ranks == 1
        assert [c.name for c in cases if c.params["floor"] == "yes"] == [f"{ref}_np2"]
    assert "ranks" in L.COLUMNS and "floor" in L.COLUMNS


def test_bad_ranks_and_done_before(tmp_path):
    for bad in (0, -1, 1.5, True, "2"):
        with pytest.raises(ValueError):
            L.rung_cases({}, [{"name": "x", "ranks": bad}])
    with pytest.raises(ValueError):
        L.rung_cases({}, [{"name": "x", "reference": True, "floor": True}])
    # a completed serial case is not the same case as the same overrides on 2 ranks
    write_case(tmp_path / "c", tau_ref, 1.0)
    assert C._done_before(tmp_path / "c", [], 1)
    assert not C._done_before(tmp_path / "c", [], 2)


# ---------------------------------------------------------------------------------------------
# (b) the round-off floor


def test_floor_errors_and_flags(tmp_path):
    _, ref, rows = ladder_rows(tmp_path)
    angle = L.compare_angle(rows, ref, HI)
    assert angle == HI
    L.add_errors(rows, ref, tmp_path, angle)
    err = {r["case"]: (r["error"], r["error_smooth"]) for r in rows}
    for name, e in (("off4", 0.04), ("off1.5", 0.015), ("off0.5", 0.005)):
        assert err[name] == pytest.approx((e, e), rel=1e-9)  # a constant relative offset

    raw, smooth = analytic_floor()
    assert raw > 0.02 > smooth > 0.01  # the raw floor is above the 2 % threshold, smoothed not
    floor = L.round_off_floor(rows)
    assert floor["error"] == pytest.approx(raw, rel=5e-3)
    assert floor["error_smooth"] == pytest.approx(smooth, rel=5e-3)

    lines = L.cheapest(rows, ref, floor)
    assert lines == L.cheapest(rows, ref)  # the floor defaults to that of the rows
    expect = {  # (threshold, norm): (chosen rung, flagged F or None)
        (5, "raw"): ("off4", None),
        (5, "smooth"): ("off4", None),
        (2, "raw"): ("off1.5", raw),
        (2, "smooth"): ("off1.5", None),
        (1, "raw"): ("off0.5", raw),
        (1, "smooth"): ("off0.5", smooth),
    }
    assert len(lines) == len(expect)
    for line, ((tol, norm), (best, flag)) in zip(lines, expect.items(), strict=True):
        head = f"within {tol} % ({'raw' if norm == 'raw' else '2-deg moving average'}): "
        assert line.startswith(head + best + " ("), line
        assert "ref_np2" not in line
        if flag is None:
            assert floor_of(line) is None, line
        else:
            assert floor_of(line) == pytest.approx(flag, abs=6e-5), line  # printed as x.xx %

    text = L.floor_line(rows, floor)
    assert text.startswith("round-off floor (ref_np2: the reference's settings on 2 MPI ranks")
    assert f"F = {100 * raw:.3g} % (raw)" in text
    assert f"F = {100 * smooth:.3g} % (2-deg moving average)" in text


def test_floor_never_chosen_even_if_alone(tmp_path):
    """Only the floor rung (and the reference) within 3 %: no rung is chosen."""
    _, ref, rows = ladder_rows(tmp_path)
    L.add_errors(rows, ref, tmp_path, L.compare_angle(rows, ref, HI))
    rows = [r for r in rows if r["case"] in ("ref", "ref_np2", "off4")]
    for line in L.cheapest(rows, ref):
        if line.startswith("within 5 %"):
            assert "off4" in line
        else:
            assert "none of the rungs" in line and "ref_np2" not in line


@pytest.mark.parametrize("floor_run", [True, False])
def test_floor_not_measured(tmp_path, floor_run):
    """The floor rung stopped at 5 deg (the others completed at 12: A = 12, not lowered by
    it) or was not run at all: the floor is not measured and nothing is flagged."""
    _, ref, rows = ladder_rows(tmp_path, floor_stop=5.0, floor_run=floor_run)
    angle = L.compare_angle(rows, ref, None)
    assert angle == pytest.approx(12.0)
    L.add_errors(rows, ref, tmp_path, angle)
    floor = L.round_off_floor(rows)
    assert math.isnan(floor["error"]) and math.isnan(floor["error_smooth"])
    text = L.floor_line(rows, floor)
    assert text.startswith("round-off floor: not measured")
    lines = L.cheapest(rows, ref, floor)
    assert not any("round-off floor" in v for v in lines)
    assert lines[0].startswith("within 5 % (raw): off4 (")


def test_floor_counts_in_the_angle_like_any_rung(tmp_path):
    """A completed floor rung that ends first sets A (documented choice)."""
    _, ref, rows = ladder_rows(tmp_path)
    next(r for r in rows if r["case"] == "ref_np2")["final_angle_deg"] = 11.0
    assert L.compare_angle(rows, ref, None) == 11.0


def test_main_writes_floor_to_md_and_png(tmp_path, monkeypatch, capsys):
    """main() on finished folders (``--only`` a name that is no rung: nothing is run, every
    rung contributes its earlier result) writes the floor line and the flags."""
    out = tmp_path / "out"
    ladder_rows(out / "ladder")
    monkeypatch.setattr(L, "QUICK_BASE", {})
    monkeypatch.setattr(L, "QUICK_LADDER", RUNGS)
    argv = ["--quick", "--out", str(out), "--angle", str(HI), "--only", "no-such-rung"]
    assert L.main(argv) == 0
    printed = capsys.readouterr().out
    md = (out / "ladder.md").read_text()
    raw, smooth = analytic_floor()
    assert f"compared over [{L.LO:g}, {HI:g}] deg (A given by --angle)" in md
    for text in (printed, md):
        assert f"F = {100 * raw:.3g} % (raw)" in text
        assert "within 2 % (raw): off1.5" in text
        assert text.count("below the round-off floor") == 3
    assert (out / "ladder.png").stat().st_size > 0
    with (out / "ladder.csv").open(newline="") as f:
        csv_rows = {r["case"]: r for r in csv.DictReader(f)}
    assert csv_rows["ref_np2"]["ranks"] == "2" and csv_rows["ref_np2"]["floor"] == "yes"
    assert csv_rows["ref"]["ranks"] == "1" and csv_rows["ref"]["floor"] == ""
