"""``type = "keyframes"`` body segments: poses at given times, interpolated, checked at
load (one line naming the key) and played by the dynamic runner."""

import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from clothfem import scene as scenes
from clothfem.scene_body import body_motions, keyframe_motion
from clothfem.spec import SegmentSpec, section_from_dict

ROOT = Path(__file__).resolve().parents[2]
CI = ROOT / "demos" / "scenes" / "arm_sleeve_ci.toml"
EXPLICIT = ["solver.integrator=explicit", "solver.settle_time=0.05", "solver.ramp_time=0.05"]
UNSET = ["solver.steps", "contact.increments"]


def _segment(**keys) -> SegmentSpec:
    """A keyframes segment ``keys``, the schema's defaults for the others."""
    seg = {k: key.default for k, key in scenes.SCHEMA["body"].keys.items()}
    seg.update(name="s", type="keyframes", axis=[1.0, 0.0, 0.0], up=[0.0, 0.0, 1.0], turns=None)
    return section_from_dict({**seg, **keys}, section="body")


def test_two_keys_move_at_constant_rates_then_rest():
    """Between two keys the centre moves on the straight line and the axes turn about the
    fixed turn axis at a constant rate (the splines of two points); after the last key the
    segment rests there."""
    turn = [0.0, 0.0, 0.6]
    m = keyframe_motion(
        _segment(times=[0.0, 2.0], centres=[[0, 0, 0], [1.0, 2.0, 0.0]], turns=[[0, 0, 0], turn])
    )
    p = m.pose(0.5)
    assert np.allclose(p.centre, [0.25, 0.5, 0.0], atol=1e-12)
    assert np.allclose(p.velocity, [0.5, 1.0, 0.0], atol=1e-12)
    q0 = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])  # e1 = axis, e2 = up, e3 = e1 x e2
    assert np.allclose(m.pose(0.0).rotation, q0, atol=1e-15)
    assert np.allclose(p.rotation, Rotation.from_rotvec([0, 0, 0.15]).as_matrix() @ q0, atol=1e-12)
    assert np.allclose(p.angular_velocity, [0.0, 0.0, 0.3], atol=1e-12)
    end = m.pose(5.0)
    assert np.allclose(end.centre, [1.0, 2.0, 0.0]) and not end.velocity.any()
    assert not end.angular_velocity.any()


def test_keyframes_sampled_from_a_hinge_follow_it():
    """Keys sampled every 0.5 deg from the arm scene's hinge: between the keys the played
    pose is the hinge's within the cubic splines' error (fourth order in the key spacing:
    below 1e-8 m and 1e-8 rad here)."""
    base = scenes.load(CI)
    hinge = body_motions(base)[1]
    times = np.linspace(0.0, hinge.t_end, 2 * int(round(math.degrees(hinge.angle_max))) + 1)
    m = keyframe_motion(_segment(**_keys(hinge, times)))
    for t in np.linspace(0.0, hinge.t_end, 37):
        a, b = hinge.pose(t), m.pose(t)
        assert np.abs(a.centre - b.centre).max() < 1e-8
        turn = Rotation.from_matrix(a.rotation.T @ b.rotation).magnitude()
        assert turn < 1e-8


def _keys(hinge, times) -> dict:
    poses = [hinge.pose(t) for t in times]
    q0 = poses[0].rotation
    turns = [Rotation.from_matrix(p.rotation @ q0.T).as_rotvec().tolist() for p in poses]
    return dict(times=times.tolist(), centres=[p.centre.tolist() for p in poses], turns=turns)


def _keyframed_ci(sets: list[str], keys: dict) -> dict:
    data = tomllib.loads(CI.read_text())
    data = scenes.apply_overrides(scenes.remove_keys(data, UNSET), sets)
    arm = data["body"][1]
    for k in ("joint", "hinge_axis", "angle_max", "omega", "centre"):
        arm.pop(k, None)
    arm.update(type="keyframes", **keys)
    data["contact"].pop("torque_segment")
    data["contact"].update(aj="all", torque_point=[0.3, 0.0, 0.0])
    return data


@pytest.mark.parametrize(
    "change, message",
    [
        ({"times": [0.1, 1.0]}, "'body[1].times': must start at 0"),
        ({"times": [0.0, 1.0, 1.0]}, "'body[1].times': must start at 0 and increase"),
        ({"centres": [[0.4, 0, 0]]}, "'body[1].centres': must give 2 entries"),
        ({"centres": [[0.4, 0, 0], [0.4, 0]]}, "'body[1].centres': must be a list of 3-number"),
        ({"turns": [[0, 0, 0], [0, 2.0, 0]]}, "'body[1].turns': motion 'forearm': rotation"),
        ({"joint": [0.3, 0, 0]}, "'body[1].joint': is a key of type = 'hinge'"),
    ],
)
def test_bad_keyframes_one_line(change, message):
    keys = {"times": [0.0, 1.0], "centres": [[0.42, 0, 0], [0.42, 0, 0.01]], **change}
    data = _keyframed_ci(EXPLICIT, keys)
    with pytest.raises(scenes.SceneError) as err:
        scenes.validate(data, base=CI.parent)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_keyframes_need_a_dynamic_integrator():
    data = tomllib.loads(CI.read_text())
    data["body"][1] = {
        "name": "forearm", "type": "keyframes", "radii": [0.2, 0.06, 0.06],
        "times": [0.0, 1.0], "centres": [[0.42, 0, 0], [0.42, 0, 0.01]],
    }  # fmt: skip
    data["contact"].pop("torque_segment")
    data["contact"].update(aj="all", torque_point=[0.3, 0.0, 0.0])
    with pytest.raises(scenes.SceneError, match=r"'body\[1\].type': 'keyframes' needs"):
        scenes.validate(data, base=CI.parent)
