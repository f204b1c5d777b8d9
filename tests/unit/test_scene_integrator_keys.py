"""Keys of one integrator (or element scheme) are refused in a scene of another, `--unset`
removes keys before validation, and the shipped scenes and the command lines in their
comments validate."""

import shlex
from pathlib import Path

import pytest
from mpi4py import MPI

from clothfem import scene as scenes
from clothfem.cli import main

ROOT = Path(__file__).resolve().parents[2]
SCENES = ROOT / "demos" / "scenes"
ARM = SCENES / "arm_sleeve.toml"
CI = SCENES / "arm_sleeve_ci.toml"
MINIMAL = {
    "scene": {"name": "t"},
    "mesh": {"generator": "strip", "length": 1.0, "width": 0.1, "nx": 2, "ny": 1},
    "material": {"preset": "crimped-cotton", "thickness": 1e-3},
}


def _scene(path: str, value, actual: str) -> dict:
    """MINIMAL with ``path`` = ``value`` and the integrator (the scheme for an element key)
    ``actual``."""
    table, key = path.split(".")
    selector = ("element", "scheme") if table == "element" else ("solver", "integrator")
    data = {**MINIMAL, selector[0]: {selector[1]: actual}}
    data[table] = {**data.get(table, {}), key: value}
    return data


def _message(path: str, allowed: str, actual: str) -> str:
    return f"scene: {path} applies to {allowed}, not '{actual}' (remove it or --unset {path})"


DYNAMIC = "integrators 'newmark', 'explicit'"


@pytest.mark.parametrize(
    ("path", "value", "actual", "allowed"),
    [
        ("solver.dt", 0.01, "explicit", "integrator 'newmark'"),
        ("solver.gamma", 0.6, "static", "integrator 'newmark'"),
        ("solver.steps", 2, "newmark", "integrator 'static'"),
        ("solver.rotary_scale", 10.0, "static", DYNAMIC),
        ("solver.safety", 0.5, "newmark", "integrator 'explicit'"),
        ("solver.settle_damping", 10.0, "newmark", "integrator 'explicit'"),
        ("contact.increments", 4, "explicit", "integrator 'static'"),
        ("contact.settle", True, "newmark", "integrator 'static'"),
        ("contact.self_mu", 0.2, "static", DYNAMIC),
        ("contact.self_pressure", 2e3, "explicit", "integrator 'newmark'"),
        ("contact.kernel", "numpy", "static", "integrator 'explicit'"),
        ("contact.semismooth_passes", 2, "explicit", "integrator 'newmark'"),
        ("output.interval", 0.01, "newmark", "integrator 'explicit'"),
        ("output.checkpoint_every", 2, "static", DYNAMIC),
        ("material.viscosity1", 1.0, "static", DYNAMIC),
        ("element.stabilization", 0.1, "psri", "scheme 'sri'"),
        ("element.psri_factor", 2.0, "sri", "scheme 'psri'"),
    ],
)
def test_a_key_of_another_integrator_is_refused(path, value, actual, allowed):
    """The message is one line naming the key, the scene's integrator (or scheme) and the
    ones the key belongs to."""
    with pytest.raises(scenes.SceneError) as info:
        scenes.validate(_scene(path, value, actual))
    assert str(info.value) == _message(path, allowed, actual)


def test_every_tagged_key_names_values_of_its_selector():
    """Each key's ``when`` names a choice key and some of its choices."""
    tagged = 0
    for section in scenes.SCHEMA.values():
        for key in section.keys.values():
            if key.when is None:
                continue
            table, name = key.when.selector.split(".")
            selector = scenes.SCHEMA[table].keys[name]
            assert selector.kind == "choice" and set(key.when.values) < set(selector.choices)
            tagged += 1
    assert tagged >= 20


def test_schema_names_the_integrator_of_a_key():
    text = scenes.schema_markdown()
    assert "| `dt` | a number in (0, 1] | 0.01 | newmark: time step [s] |" in text
    assert "| newmark, explicit: time [s] with the body at rest" in text
    assert "| static: equal recorded increments of the hinge motion" in text
    assert "| sri: alpha x the fully integrated membrane energy" in text


def test_cli_refuses_a_foreign_key_before_writing(tmp_path, capsys):
    """`clothfem run` and `validate`: exit 2, the one line on stderr, no output folder."""
    out = tmp_path / "out"
    line = "clothfem: " + _message("solver.dt", "integrator 'newmark'", "explicit") + "\n"
    for command in (["run", str(ARM), "--out", str(out)], ["validate", str(ARM)]):
        capsys.readouterr()
        assert main([*command, "--set", "solver.dt=0.005"]) == 2
        assert capsys.readouterr().err == line
    assert not out.exists()


def test_unset_removes_a_key(capsys):
    """--unset drops a key of the file before --set and validation: the CI scene (static)
    switches to the explicit integrator once its static keys are removed; a key --unset
    and --set takes the --set value; a key the scene does not set is left alone."""
    switch = ["--set", "solver.integrator=explicit"]
    capsys.readouterr()
    assert main(["validate", str(CI), *switch]) == 2
    assert "solver.steps applies to integrator 'static'" in capsys.readouterr().err
    unset = ["--unset", "solver.steps", "--unset", "contact.increments"]
    assert main(["validate", str(CI), *switch, *unset]) == 0
    s = scenes.load(CI, unset=["solver.steps", "solver.dt"])
    assert s.solver.steps == scenes.SCHEMA["solver"].keys["steps"].default
    assert scenes.load(CI, ["solver.steps=3"], unset=["solver.steps"]).solver.steps == 3
    s = scenes.load(ARM, unset=["body.1.omega"])
    assert s.body[1].omega == scenes.SCHEMA["body"].keys["omega"].default


@pytest.mark.parametrize(
    ("key", "words"),
    [
        ("solver.foo", "--unset solver.foo: unknown key; allowed: integrator, safety"),
        ("nosuch.key", "--unset nosuch.key: unknown table; allowed: scene, mesh"),
        ("solver", "--unset solver: expected solver.key"),
        ("body.omega", "--unset body.omega: expected body.N.key"),
        ("body.7.omega", "--unset body.7.omega: no element '7'"),
    ],
)
def test_unset_of_an_unknown_key_is_refused(key, words, capsys):
    capsys.readouterr()
    assert main(["validate", str(ARM), "--unset", key]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and words in err, err


def _commented_commands(path: Path) -> list[list[str]]:
    """The `clothfem run` command lines in a scene file's comments (continued on the comment
    lines below that start with an option), without --out."""
    lines = [ln.lstrip("#").strip() for ln in path.read_text().splitlines() if ln.startswith("#")]
    commands = []
    for i, ln in enumerate(lines):
        if not ln.startswith("clothfem run "):
            continue
        words = shlex.split(ln)
        for more in lines[i + 1 :]:
            if not more.startswith("--"):
                break
            words += shlex.split(more)
        if "--out" in words:
            k = words.index("--out")
            del words[k : k + 2]
        commands.append(words[2:])
    return commands


@pytest.mark.parametrize("path", sorted(SCENES.glob("*.toml")), ids=lambda p: p.stem)
def test_shipped_scenes_and_their_commands_validate(path, capsys):
    """Every shipped scene validates as it is and with the command lines of its comments
    (e.g. the switch of arm_sleeve.toml to another integrator)."""
    if MPI.COMM_WORLD.rank != 0:
        return
    assert main(["validate", str(path)]) == 0, capsys.readouterr().err
    for words in _commented_commands(path):
        scene, *options = words
        assert (ROOT / scene).resolve() == path
        assert main(["validate", str(path), *options]) == 0, capsys.readouterr().err
