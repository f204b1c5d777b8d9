"""A run that starts from given positions (``[initial] positions``, ShellModel.start_at):
rigid motions start with zero strain energy and the rotated directors, a uniform stretch
with the closed-form membrane energy, nodes matched in any order, one-line errors."""

import math

import numpy as np
import pytest
from mpi4py import MPI

from clothfem import mesh as meshes
from clothfem import scene as scenes
from clothfem.initial_state import displacement_at_nodes, read_positions
from clothfem.run import build_model
from clothfem.shell import FabricMaterial, ShellModel
from clothfem.shell import rotation as R

COMM = MPI.COMM_WORLD
MAT = FabricMaterial(E1=1.0e6, E2=0.6e6, G12=0.2e6, nu12=0.0, rho=500.0)


@pytest.fixture(scope="module")
def panel():
    return meshes.cylinder_panel(
        COMM, radius=1.0, length=1.5, angle=math.radians(50), n_around=4, n_along=3
    )


def test_rigid_start_has_zero_energy_and_rotated_directors(panel):
    """u = (Q - I) X + c: the directors are Q D (the best-fit rotation of every node's
    neighbourhood is Q), the rotations 0, the strain energy 0 to round-off (against a 1e-3
    stretch's)."""
    model = ShellModel(panel, material=MAT, thickness=0.01)
    axis = np.array([1.0, 2.0, 3.0]) / math.sqrt(14.0)
    Q = R.rotation_matrix(0.5 * math.pi * axis[None, :])[0]
    X = model.x_nodes
    model.start_at(X @ Q.T - X + np.array([0.3, -0.2, 0.5]))
    D = model.D.x.array.reshape(-1, 3)
    assert np.allclose(model.d.x.array.reshape(-1, 3), D @ Q.T, atol=1e-12)
    assert not model.theta.x.array.any()
    rigid = model.strain_energy()
    model.start_at(1e-3 * X)
    stretch = model.strain_energy()
    assert stretch > 0 and abs(rigid) < 1e-20 * stretch / 1e-6


def test_stretched_start_has_the_membrane_energy():
    """A flat strip stretched by 1.1 along the warp: Green strain E11 = (1.1^2 - 1)/2,
    nu12 = 0, so W = E1 t A E11^2 / 2 exactly (the directors stay normal)."""
    strip = meshes.strip(COMM, length=0.4, width=0.2, nx=2, ny=2)
    model = ShellModel(strip, material=MAT, thickness=1e-3)
    X = model.x_nodes
    u = np.zeros_like(X)
    u[:, 0] = 0.1 * X[:, 0]
    model.start_at(u)
    E11 = (1.1**2 - 1.0) / 2
    expected = 0.5 * MAT.E1 * 1e-3 * (0.4 * 0.2) * E11**2
    assert model.strain_energy() == pytest.approx(expected, rel=1e-10)
    assert np.allclose(np.abs(model.d.x.array.reshape(-1, 3)[:, 2]), 1.0)


def test_nodes_matched_by_reference_position_in_any_order():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(40, 3))
    x = X + rng.normal(size=(40, 3))
    order = rng.permutation(40)
    u = displacement_at_nodes(nodes=X[order], X=X, x=x)
    assert np.array_equal(u, (x - X)[order])
    with pytest.raises(ValueError, match=r"^1 mesh node\(s\) are not in the file") as info:
        displacement_at_nodes(nodes=np.vstack([X, [[9.0, 9.0, 9.0]]]), X=X, x=x)
    assert "\n" not in str(info.value)


def _scene(tmp_path, X, x, **extra) -> dict:
    np.savez(tmp_path / "start.npz", X=X, x=x)
    return {
        "scene": {"name": "start"},
        "mesh": {"generator": "strip", "length": 0.4, "width": 0.2, "nx": 2, "ny": 2},
        "material": {
            "E1": 1.0e6,
            "E2": 0.6e6,
            "G12": 0.2e6,
            "nu12": 0.0,
            "rho": 500.0,
            "thickness": 1e-3,
        },  # fmt: skip
        "initial": {"positions": str(tmp_path / "start.npz")},
        **extra,
    }


def test_scene_starts_from_the_file(tmp_path):
    """build_model applies initial.positions: the displacement of the file at every node
    (the file's nodes shuffled) and a log line that says so."""
    strip = meshes.strip(COMM, length=0.4, width=0.2, nx=2, ny=2)
    X = ShellModel(strip, material=MAT, thickness=1e-3).x_nodes
    X = COMM.allgather(X)
    X = np.unique(np.vstack(X).round(12), axis=0)[::-1]
    x = X + np.array([0.0, 0.0, 0.25])
    model, log = build_model(scenes.validate(_scene(tmp_path, X, x)), COMM)
    assert np.allclose(model.u.x.array.reshape(-1, 3), [0.0, 0.0, 0.25])
    assert any(line.startswith("initial state: the positions of start.npz") for line in log)


@pytest.mark.parametrize(
    ("change", "words"),
    [
        ({"x": np.zeros((3, 2))}, "X and x must both be (N, 3)"),
        ({"X": np.full((3, 3), np.nan)}, "X and x must be finite"),
        ({"supports": [{"type": "clamp", "where": "root"}]}, "takes no [[supports]]"),
    ],
)
def test_bad_initial_positions_one_line_errors(tmp_path, change, words):
    X = np.zeros((3, 3))
    data = _scene(tmp_path, change.get("X", X), change.get("x", X))
    if "supports" in change:
        data["supports"] = change["supports"]
    with pytest.raises(scenes.SceneError) as info:
        scenes.validate(data)
    msg = str(info.value)
    assert "'initial.positions'" in msg and words in msg and "\n" not in msg


def test_missing_file_and_missing_array(tmp_path):
    with pytest.raises(scenes.SceneError, match="does not exist"):
        scenes.validate({**_scene(tmp_path, np.zeros((2, 3)), np.zeros((2, 3))),
                         "initial": {"positions": "nowhere.npz"}})  # fmt: skip
    np.savez(tmp_path / "only_X.npz", X=np.zeros((2, 3)))
    with pytest.raises(ValueError, match="has no array 'x'"):
        read_positions(tmp_path / "only_X.npz")
