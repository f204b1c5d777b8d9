"""The [[torques]] measures of a scene: checked at load as the [contact] Eq. 28 keys are,
one line naming the key, before anything is built."""

import tomllib
from pathlib import Path

import pytest

from clothfem import scene as scenes

SCENE = Path(__file__).resolve().parents[2] / "demos" / "scenes" / "pants_walk.toml"


def _validate(torques: list[dict], **solver):
    data = tomllib.loads(SCENE.read_text())
    data["torques"] = torques
    data["solver"].update(solver)
    data["initial"] = {}  # the donned file is not needed to check the measures
    return scenes.validate(data, base=SCENE.parent)


def test_shipped_pants_walk_lists_left_knee_and_hips():
    names = [t["name"] for t in tomllib.loads(SCENE.read_text())["torques"]]
    assert names == ["left_knee", "right_hip", "left_hip"]


def test_entry_replaces_the_contact_keys():
    s = _validate([{"name": "lk", "segment": "L_shank", "torque_with": ["L_foot"]}])
    c = scenes.torque_entry(s, s.torques[0]).contact
    assert c.torque_segment == "L_shank" and c.torque_with == ("L_foot",)
    assert c.aj == "touching" and c.flexion_axis == "e3" and c.mu == s.contact.mu


@pytest.mark.parametrize(
    "torques, solver, message",
    [
        ([{"name": "a b", "segment": "L_shank"}], {}, "'torques[0].name': must be letters"),
        (
            [{"name": "k", "segment": "L_shank"}, {"name": "k", "segment": "R_shank"}],
            {},
            "'torques[0].name': must be unique",
        ),
        (
            [{"name": "k", "segment": "knee"}],
            {},
            "'torques[0].segment': must name a hinge or mocap",
        ),
        (
            [{"name": "k", "segment": "L_shank", "torque_with": ["L_foot"], "aj": "all"}],
            {},
            "'torques[0].torque_with': counts with aj = 'touching' only",
        ),
        (
            [{"name": "k", "segment": "L_shank", "flexion_frame": "thigh"}],
            {},
            "'torques[0].flexion_frame': must name a mocap segment",
        ),
        ([{"name": "k"}], {}, "'torques[0].segment': required"),
    ],
)
def test_bad_torques_one_line(torques, solver, message):
    with pytest.raises(scenes.SceneError) as err:
        _validate(torques, **solver)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_torques_need_a_dynamic_integrator():
    """The quasi-static runner measures only the [contact] torque: [[torques]] in a static
    scene is refused at load."""
    ci = SCENE.parent / "arm_sleeve_ci.toml"
    data = tomllib.loads(ci.read_text())
    assert data["solver"]["integrator"] == "static"
    data["torques"] = [{"name": "k", "segment": "forearm"}]
    with pytest.raises(scenes.SceneError, match=r"'torques\[0\]': is measured by .* not 'static'"):
        scenes.validate(data, base=ci.parent)


def test_build_log_names_the_measures():
    from clothfem.scene_body import contact_log

    s = _validate([{"name": "lk", "segment": "L_shank"}, {"name": "rh", "segment": "R_thigh"}])
    assert "torques: lk about L_shank, rh about R_thigh" in contact_log(s)
    s = _validate([])
    assert not any(line.startswith("torques:") for line in contact_log(s))
