"""Checks a run would otherwise make late, made at `clothfem validate` and before a run
builds or writes anything: boundary names of generated and file meshes, a file mesh that
is a surface, dt_min <= dt. Each one line naming the key, exit status 2."""

from pathlib import Path

import pytest
from mpi4py import MPI

from clothfem import scene as scenes
from clothfem.cli import main

ROOT = Path(__file__).resolve().parents[2]
SLEEVE = ROOT / "demos" / "scenes" / "sleeve_gravity.toml"
CI = ROOT / "demos" / "scenes" / "arm_sleeve_ci.toml"

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial checks (gmsh files)")


def _square(path: Path, *, dim: int = 2, group: str = "left") -> Path:
    """A gmsh file of a unit square (dim 2) or cube (dim 3) with its curve x = 0 named."""
    import gmsh

    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    try:
        if dim == 2:
            gmsh.model.occ.addRectangle(0, 0, 0, 1, 1)
        else:
            gmsh.model.occ.addBox(0, 0, 0, 1, 1, 1)
        gmsh.model.occ.synchronize()
        curves = [c for _, c in gmsh.model.getEntities(1)]
        left = [c for c in curves if abs(gmsh.model.occ.getCenterOfMass(1, c)[0]) < 1e-9]
        gmsh.model.addPhysicalGroup(1, left[:1], 1)
        gmsh.model.setPhysicalName(1, 1, group)
        gmsh.model.addPhysicalGroup(dim, [gmsh.model.getEntities(dim)[0][1]], 2)
        gmsh.model.mesh.generate(dim)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()
    return path


def test_generated_mesh_boundary_must_exist(capsys):
    words = r"'supports\[0\].where': must name a boundary of the cylinder mesh, one of "
    with pytest.raises(scenes.SceneError, match=words + r"\['shoulder', 'cuff'\], got 'elbow'"):
        scenes.load(SLEEVE, ["supports.0.where=elbow"])
    assert main(["validate", str(SLEEVE), "--set", "supports.0.where=elbow"]) == 2
    assert "supports[0].where" in capsys.readouterr().err


def test_run_with_a_bad_boundary_writes_nothing(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", str(SLEEVE), "--out", str(out), "--set", "supports.0.where=elbow"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "supports[0].where" in err and not out.exists()


def test_file_mesh_boundaries_and_dimension(tmp_path, capsys):
    good = _square(tmp_path / "square.msh")
    sets = ["mesh.generator='file'", f"mesh.file='{good}'", "supports.0.where=left"]
    unset = ["mesh.radius", "mesh.length", "mesh.n_around", "mesh.n_along"]
    args = ["validate", str(SLEEVE), *[a for k in unset for a in ("--unset", k)]]
    assert main([*args, *[a for kv in sets for a in ("--set", kv)]]) == 0
    capsys.readouterr()
    bad = [*sets[:2], "supports.0.where=right"]
    assert main([*args, *[a for kv in bad for a in ("--set", kv)]]) == 2
    err = capsys.readouterr().err
    assert (
        "'supports[0].where': must name a boundary of the square.msh mesh, one of ['left']" in err
    )
    mitc9 = [*sets, "element.scheme=mitc9"]  # the square is of 3-node triangles
    assert main([*args, *[a for kv in mitc9 for a in ("--set", kv)]]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "'element.scheme': 'mitc9' needs 9-node quadrilaterals" in err
    cube = _square(tmp_path / "cube.msh", dim=3)
    solid = [f"mesh.file='{cube}'" if s.startswith("mesh.file") else s for s in sets]
    assert main([*args, *[a for kv in solid for a in ("--set", kv)]]) == 2
    assert "must be a surface mesh" in capsys.readouterr().err


def test_dt_min_above_dt_refused():
    sets = ["solver.integrator=newmark", "solver.dt=0.01", "solver.dt_min=0.02"]
    unset = ["solver.steps", "contact.increments"]
    with pytest.raises(scenes.SceneError, match=r"'solver.dt_min': must be <= solver.dt = 0.01 s"):
        scenes.load(CI, sets, unset=unset)


def test_mesh_beyond_the_memory_refused():
    """4000 x 4000 cells (~64 million nodes, ~2.4 TB at the measured 40 kB a node)."""
    with pytest.raises(scenes.SceneError, match=r"'mesh.n_around': about 64,00\d,\d{3} nodes"):
        scenes.load(SLEEVE, ["mesh.n_around=4000", "mesh.n_along=4000"])
    assert scenes.load(SLEEVE, ["mesh.n_around=64", "mesh.n_along=64"])  # 8,256 nodes: fine


def test_run_ending_before_the_body_moves_refused():
    explicit = ["solver.integrator=explicit", "solver.rotary_scale=1000", "solver.duration=0.1"]
    with pytest.raises(scenes.SceneError) as err:
        scenes.load(CI, explicit, unset=["solver.steps", "contact.increments"])
    assert "'solver.duration': must be > solver.settle_time = 0.2 s" in str(err.value)
