"""Scene files: validation messages, defaults, overrides, docs, and runs through the CLI."""

import csv
import math
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from clothfem import scene as scenes
from clothfem import verification as V
from clothfem.cli import main

COMM = MPI.COMM_WORLD
ROOT = Path(__file__).resolve().parents[2]

MINIMAL = {
    "scene": {"name": "t"},
    "mesh": {"generator": "strip", "length": 10.0, "width": 1.0, "nx": 10, "ny": 1},
    "material": {"E1": 1.2e6, "E2": 1.2e6, "G12": 6e5, "thickness": 0.1},
}


def _with(path: str, value):
    data = scenes.apply_overrides(MINIMAL, [])
    node = data
    parts = path.split(".")
    for p in parts[:-1]:
        node = node.setdefault(p, {})
    node[parts[-1]] = value
    return data


def test_defaults_filled():
    s = scenes.validate(MINIMAL)
    assert s.solver.integrator == "static" and s.material.nu12 == 0.0
    assert s.supports == () and s.mesh.order == 2


@pytest.mark.parametrize(
    "data, message",
    [
        (_with("extra.x", 1), "scene key 'extra': unknown table; allowed: scene, mesh"),
        (_with("mesh.nxx", 3), "scene key 'mesh.nxx': unknown key; allowed: generator"),
        (
            _with("material.thickness", -1e-3),
            r"'material.thickness': must be a number in \(0, inf\]",
        ),
        (_with("material.E1", "soft"), r"'material.E1': must be a number in \(0, inf\]"),
        (_with("material.nu12", 1.5), r"'material.nu12': must be in \(-1, 1\)"),
        (_with("mesh.generator", "sphere"), "'mesh.generator': must be one of 'strip', 'cylinder'"),
        (_with("mesh.nx", 2.5), r"'mesh.nx': must be an integer in \[1, inf\]"),
        (_with("material.warp", [1, 0]), "'material.warp': must be 3 finite numbers"),
        (
            _with("supports", [{"type": "symmetry", "where": "root"}]),
            r"'supports\[0\].axis': required",
        ),
        (_with("loads", [{"type": "pressure"}]), r"'loads\[0\].value': required for 'pressure'"),
        ({k: v for k, v in MINIMAL.items() if k != "mesh"}, "scene key 'mesh': required table"),
        (
            _with(
                "mesh",
                {
                    "generator": "cylinder",
                    "radius": 0.06,
                    "length": 0.5,
                    "n_around": 6,
                    "n_along": 2,
                },
            ),
            "'mesh.n_around': must be a multiple of 4",
        ),
        (
            _with("mesh", {"generator": "pants", "n_around": 16, "n_along": 4, "leg_spacing": 0.1}),
            r"'mesh.leg_spacing': must be >= 2.2 leg_radius = 0.198 m",
        ),
        (
            _with("mesh", {"generator": "pants", "n_around": 6, "n_along": 4}),
            "'mesh.n_around': must be a multiple of 4 for a pants",
        ),
        (_with("solver.integrator", "euler"), "'solver.integrator': must be one of 'static'"),
        (
            _with("contact.newton_stall_limit", 0),
            r"'contact.newton_stall_limit': must be an integer in \[1, inf\]",
        ),
        (_with("contact.kernel", "cuda"), "'contact.kernel': must be one of 'compiled', 'numpy'"),
        (
            _with("material.friction_stiffness1", 1e6),
            "'material.friction_stiffness2': required with the other material.friction_",
        ),
        (
            {**_with("material.viscosity12", 40.0), "solver": {"integrator": "explicit"}},
            "'material.viscosity1': required with the other material.viscosity",
        ),
        (
            _with("material.friction_stress2", -1.0),
            r"'material.friction_stress2': must be a number in \(0, inf\]",
        ),
    ],
)
def test_bad_scenes_one_line_errors(data, message):
    with pytest.raises(scenes.SceneError, match=message) as info:
        scenes.validate(data)
    assert "\n" not in str(info.value)


def test_overrides_and_preset():
    data = dict(MINIMAL, material={"preset": "kevlar", "thickness": 1e-3})
    s = scenes.validate(scenes.apply_overrides(data, ["mesh.nx=4", "material.E2=1e9"]))
    assert s.mesh.nx == 4 and s.material.E1 == 7.2e9 and s.material.E2 == 1e9
    assert s.material.G12 == 7.2e9 / 200 and s.material.rho == 700.0
    with pytest.raises(scenes.SceneError, match="expected key.path=value"):
        scenes.apply_overrides(MINIMAL, ["mesh.nx"])


def test_hysteretic_preset_builds_yarn_friction():
    from clothfem.run import build_material
    from clothfem.shell.hysteresis import COTTON_FRICTION

    data = dict(MINIMAL, material={"preset": "decrimping-cotton-hysteretic", "thickness": 1e-3})
    mat = build_material(scenes.validate(data).material)
    assert mat.friction == COTTON_FRICTION and mat.E1_decrimped == 350e6
    assert build_material(scenes.validate(MINIMAL).material).friction is None


def test_docs_match_schema():
    text = (ROOT / "docs" / "scene.md").read_text()
    assert scenes.schema_markdown() in text, "regenerate docs/scene.md with `clothfem schema`"


def test_example_scenes_are_valid():
    """Every demo scene validates as shipped (the pants walk dons its pants itself)."""
    for path in sorted((ROOT / "demos" / "scenes").glob("*.toml")):
        scenes.load(path, [])


def _shared_dir(tmp_path):
    return Path(COMM.bcast(str(tmp_path) if COMM.rank == 0 else None, root=0))


def test_scene_run_matches_elastica(tmp_path):
    """A strip scene under a dead end shear PL^2/EI = 1 through the CLI: tip vs the elastica."""
    out = _shared_dir(tmp_path)
    L, b, t, E = 10.0, 1.0, 0.1, 1.2e6
    P = 1.0 * E * b * t**3 / 12 / L**2
    scene = out / "s.toml"
    if COMM.rank == 0:
        scene.write_text(
            '[scene]\nname = "elastica"\n[mesh]\ngenerator = "strip"\nlength = 10.0\nwidth = 1.0\n'
            "nx = 10\nny = 1\n[material]\nE1 = 1.2e6\nE2 = 1.2e6\nG12 = 6e5\nthickness = 0.1\n"
            '[[supports]]\ntype = "clamp"\nwhere = "root"\n'
            f'[[loads]]\ntype = "edge_traction"\nwhere = "tip"\ntraction = [0.0, 0.0, {P / b!r}]\n'
            "[solver]\nsteps = 2\n[output]\npng = false\n"
        )
    COMM.barrier()
    assert main(["run", str(scene), "--out", str(out / "r")]) == 0
    rows = list(csv.DictReader((out / "r" / "history.csv").open()))
    assert float(rows[-1]["load_factor"]) == 1.0
    # the tip displacement of the model the runner builds from the same scene
    from clothfem.run import build_model

    model, log = build_model(scenes.load(scene), COMM)
    assert any("contact: not built" in line for line in log)
    assert any(line.startswith("element: partial selective") for line in log)  # the default
    from clothfem.static import LoadStepping, solve_static

    solve_static(model, stepping=LoadStepping(initial_increment=0.5, max_increment=0.5))
    tip = model.displacement_at((L, 0.0, 0.0))
    u_ex, w_ex = V.elastica_tip(1.0)
    assert math.isclose(tip[2] / L, w_ex, rel_tol=5e-3) and math.isclose(
        -tip[0] / L, u_ex, rel_tol=5e-3
    )


def test_failed_run_keeps_written_steps(tmp_path, capsys):
    """Gravity across a soft sleeve wrinkles it; the quasi-static path stops with a clear
    message (exit status 3) and the steps already written stay in history.csv."""
    out = _shared_dir(tmp_path) / "fail"
    code = main(
        [
            "run",
            str(ROOT / "demos" / "scenes" / "sleeve_gravity.toml"),
            "--out",
            str(out),
            "--set",
            "loads.0.acceleration=[0,0,-9.81]",
            "--set",
            "mesh.n_around=8",
            "--set",
            "mesh.n_along=6",
            "--set",
            "solver.min_increment=0.01",
            "--set",
            "output.png=false",
        ]
    )
    assert code == 3
    assert "Newton failed at load factor" in capsys.readouterr().err
    rows = list(csv.DictReader((out / "history.csv").open()))
    assert len(rows) >= 2 and all(0 < float(r["load_factor"]) < 1 for r in rows)


MOCAP = ROOT / "demos" / "scenes" / "sleeve_mocap.toml"


@pytest.mark.parametrize(
    "override, key, words",
    [
        ("body.0.file=nowhere.c3d", "body[0].file", "does not exist"),
        ("body.1.m=LARM_ANT", "body[1].m", "'LARM_ANT' is not in the file"),
        ("body.0.j1={midpoint=['EPICl','NOPE']}", "body[0].j1", "'NOPE' is not in the file"),
        ("body.0.window=[0.0,9.0]", "body[0].window", "within the recording [0, 5.79] s"),
        ("body.0.window=[0.5,0.2]", "body[0].window", "start < end"),
        ("body.1.placed_by='torso'", "body[1].placed_by", "must name a mocap segment"),
        ("body.0.hinge_axis=[0,1,0]", "body[0].hinge_axis", "type = 'hinge' segments only"),
        ("body.0.max_gap=-1", "body[0].max_gap", "must be an integer in [0, inf]"),
    ],
)
def test_mocap_segments_checked_at_load(override, key, words, capsys):
    """A mocap segment's file, markers, window and placing segment are checked when the scene
    is loaded: one line naming the key; `clothfem validate` exits with 2."""
    with pytest.raises(scenes.SceneError) as info:
        scenes.load(MOCAP, [override])
    msg = str(info.value)
    assert "\n" not in msg and f"'{key}'" in msg and words in msg, msg
    assert main(["validate", str(MOCAP), "--set", override]) == 2
    assert capsys.readouterr().err.count("\n") == 1


def test_mocap_needs_a_dynamic_integrator(capsys):
    """A mocap segment in a static scene (its dynamic keys removed): one line, exit 2."""
    dynamic = ["solver.rotary_scale", "solver.settle_time", "solver.ramp_time"]
    dynamic += ["output.interval", "output.checkpoint_every"]
    with pytest.raises(scenes.SceneError, match=r"'body\[0\].type': 'mocap' needs solver.integ"):
        scenes.load(MOCAP, ["solver.integrator='static'"], unset=dynamic)
    unset = [a for k in dynamic for a in ("--unset", k)]
    assert main(["validate", str(MOCAP), "--set", "solver.integrator=static", *unset]) == 2
    assert capsys.readouterr().err.count("\n") == 1


def test_mocap_file_relative_to_the_scene():
    """The scene's relative recording path resolves from the scene file's folder."""
    s = scenes.load(MOCAP)
    assert Path(s.body[0].file).is_file() and s.body[1].placed_by == "upper_arm"


def test_dynamic_scene_without_a_moving_body_needs_a_duration():
    data = _with("solver.integrator", "explicit")
    data["material"]["rho"] = 400.0
    with pytest.raises(scenes.SceneError, match=r"'solver.duration': required"):
        scenes.validate(data)
    data["solver"]["duration"] = 0.1
    assert scenes.validate(data).solver.duration == 0.1


def test_pants_hip_radius_reaches_the_mesh():
    """mesh.hip_radius of a pants scene builds the pants of pants_lattice(hip_radius=...):
    the same node coordinates (the hip ellipse's perimeter is 2 pi hip_radius)."""
    from clothfem.pants_mesh import pants_lattice
    from clothfem.run import build_mesh

    keys = {"generator": "pants", "n_around": 8, "n_along": 4, "hip_radius": 0.2}
    data = {"scene": {"name": "p"}, "mesh": keys}
    data["material"] = {"preset": "crimped-cotton", "thickness": 1e-3}
    sm = build_mesh(scenes.validate(data), MPI.COMM_SELF)
    lat = pants_lattice(hip_radius=0.2, n_around=8, n_along=4)
    got = np.unique(sm.mesh.geometry.x.round(9), axis=0)
    assert np.array_equal(got, np.unique(lat.x.round(9), axis=0))
    a, b = lat.hip_semi_axes
    h = ((a - b) / (a + b)) ** 2
    perimeter = math.pi * (a + b) * (1 + 3 * h / (10 + math.sqrt(4 - 3 * h)))
    assert perimeter == pytest.approx(2 * math.pi * 0.2, rel=1e-9)


def test_settle_damping_is_an_explicit_key():
    data = _with("solver.integrator", "newmark")
    data["solver"].update(settle_damping=10.0, duration=0.1)
    with pytest.raises(scenes.SceneError, match=r"solver.settle_damping applies to integrator 'e"):
        scenes.validate(data)
