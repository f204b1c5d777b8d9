"""Scene key ``repeat`` of mocap segments: the shipped gait recording's right-foot cycle
played three times through the scene layer (validation, body motions, log): each copy is
the first shifted by the stride, the motion lasts three cycles, bad keys are one-line
errors."""

import numpy as np
import pytest
from _gait import WALK, right_leg

from clothfem import scene as scenes
from clothfem.body.gait_repeat import gait_cycle
from clothfem.scene_body import body_motions, contact_log


def _scene(**extra) -> dict:
    start, end = gait_cycle(WALK, foot="Right")
    seg = {
        "type": "mocap",
        "file": str(WALK),
        "window": [start, end],
        "max_gap": 10,
        "repeat": 3,
        "stride_markers": ["LFEP", "RFEP"],
        **extra,
    }
    return {
        "scene": {"name": "walk"},
        "mesh": {"generator": "strip", "length": 0.1, "width": 0.1, "nx": 1, "ny": 1},
        "material": {"preset": "crimped-cotton", "thickness": 1e-3},
        "body": right_leg(seg),
        "contact": {"torque_point": [0.0, 0.0, 0.25], "aj": "all"},
        "solver": {"integrator": "explicit", "settle_time": 0.0},
    }


def test_repeated_cycle_through_the_scene():
    """Each copy is the first one shifted by the stride (0.997 m for this recording, moved
    with the placing transform; away from the 0.05 s seam blends), the motion lasts three
    cycles, and the log says it is a repeated cycle."""
    scene = scenes.validate(_scene())
    start, end = scene.body[0].window
    T = end - start
    thigh, shank = body_motions(scene)
    assert thigh.t_end == pytest.approx(3 * T, abs=0.011)
    for motion in (thigh, shank):
        for t in (0.2, 0.5, 0.8):
            d = motion.pose(T + t).centre - motion.pose(t).centre
            d2 = motion.pose(2 * T + t).centre - motion.pose(T + t).centre
            assert np.linalg.norm(d) == pytest.approx(0.997, abs=0.01)
            assert np.allclose(d2, d, atol=1e-6)  # interpolation between frames: 3e-7
    assert any("a repeated cycle: 3 copies" in line for line in contact_log(scene))


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        ({"stride_markers": None}, r"'body\[0\].stride_markers': required with repeat > 1"),
        ({"repeat_blend": 5.0}, r"'body\[0\].repeat': .*blend"),
        ({"repeat": 1}, r"'body\[0\].stride_markers': is a key of repeat > 1 only"),
    ],
)
def test_repeat_keys_one_line_errors(extra, message):
    data = _scene(**extra)
    if extra.get("stride_markers", 0) is None:
        for seg in data["body"]:
            del seg["stride_markers"]
    with pytest.raises(scenes.SceneError, match=message) as info:
        scenes.validate(data)
    assert "\n" not in str(info.value)
