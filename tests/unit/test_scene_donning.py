"""``[initial] don``: the donning as the first stage of a scene, checked at load (one line
naming the key, before anything is built)."""

import tomllib
from pathlib import Path

import pytest

from clothfem import scene as scenes
from clothfem.particle.scene_donning import DIMENSIONS, fit_dimensions

SCENE = Path(__file__).resolve().parents[2] / "demos" / "scenes" / "pants_walk.toml"


def _load(sets=(), unset=()):
    return scenes.load(SCENE, list(sets), unset=list(unset))


def test_dimensions_left_out_are_the_fits():
    """The shipped scene gives the fit's dimensions; without them the scene takes the same
    numbers from the fit (other ease, other dimensions). The same to round-off: the fit's
    last bit follows the machine's BLAS (the scene accepts 1e-9 relative)."""
    given = _load()
    taken = _load(unset=[f"mesh.{k}" for k in DIMENSIONS])
    for k in DIMENSIONS:
        assert getattr(taken.mesh, k) == pytest.approx(getattr(given.mesh, k), rel=1e-14), k
    looser = _load(["donning.ease=0.03"], unset=[f"mesh.{k}" for k in DIMENSIONS])
    assert looser.mesh.leg_radius == pytest.approx(given.mesh.leg_radius + 0.015)
    assert fit_dimensions(looser) == {k: getattr(looser.mesh, k) for k in DIMENSIONS}


@pytest.mark.parametrize(
    "sets, message",
    [
        (["mesh.leg_radius=0.081"], "'mesh.leg_radius': 0.081 is not the donning fit's"),
        (["initial.positions=donned.npz"], "'initial.positions': give either positions or don"),
        (["initial.don=false", "donning.ease=0.02"], "'donning': applies with initial.don"),
        (["body.2.radii=[0.2, 0.07, 0.07]"], "'body[2].radii': the donning dons onto L_shank"),
        (["body.3.window=[0.0, 2.0]"], "'body[3].window': initial.don needs one window"),
    ],
)
def test_bad_donning_one_line(tmp_path, sets, message):
    if any(s.startswith("initial.positions") for s in sets):  # a readable positions file
        import numpy as np

        np.savez(tmp_path / "donned.npz", X=np.zeros((4, 3)), x=np.zeros((4, 3)))
        sets = [f"initial.positions={tmp_path / 'donned.npz'}"]
    with pytest.raises(scenes.SceneError) as err:
        _load(sets)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_don_needs_the_pants_and_a_lower_body():
    data = tomllib.loads((SCENE.parent / "sleeve_mocap.toml").read_text())
    data.setdefault("initial", {})["don"] = True
    with pytest.raises(scenes.SceneError, match="'mesh.generator': initial.don dons the generated"):
        scenes.validate(data, base=SCENE.parent)
