"""Donning pants onto the lower body with the particle fabric (clothfem.particle.donning).

Analytic checks of the skinning (rigid motions are exact), the growing colliders (a tube
around a growing ellipsoid ends outside it; a tube that already fits is left unchanged),
the spring constants on a square grid, the fitted pattern's skeleton (hip and knee land on
the body's joint centres) and one coarse end-to-end donning on the recording's first frame
through the command line, whose layers never intersect. Serial (the driver is serial).
"""

from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI
from scipy.spatial import cKDTree

from clothfem import particle as pm
from clothfem.body import Ellipsoid
from clothfem.body.lower_body import lower_body_from_c3d
from clothfem.contact.intersections import intersecting_pairs
from clothfem.contact.self_contact import mesh_nodes, triangulate_q9
from clothfem.mesh import cylinder
from clothfem.pants_mesh import pants as pants_mesh
from clothfem.pants_mesh import pants_lattice
from clothfem.particle import donning as dn

pytestmark = pytest.mark.serial

WALK = Path(__file__).resolve().parents[2] / "data" / "mocap" / "walk_cgm_lowerlimb.c3d"
COARSE = dn.PantsFit(n_around=8, n_along=6)


def _rotation(axis, angle: float) -> np.ndarray:
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


@pytest.fixture(scope="module")
def body():
    return lower_body_from_c3d(WALK)


@pytest.fixture(scope="module")
def pants(body):
    pattern = dn.fit_pants(body=body, frame=0, fit=COARSE)
    return pattern, dn._pants_network(pattern.geometry)


def _tube(radius: float, length: float = 0.4):
    surface = cylinder(MPI.COMM_SELF, radius=radius, length=length, n_around=8, n_along=6)
    net = pm.network_from_mesh(surface)
    fab = dn.simple_fabric(network=net, E=1.2e6, G=1e5, rho=436.0, thickness=1e-3)
    return net, fab


# ------------------------------------------------------------------------------- skinning
def test_skinning_a_rigid_rotation_about_the_hip_is_exact():
    rng = np.random.default_rng(1)
    X = rng.normal(size=(50, 3))
    hip = np.array([0.1, -0.2, 0.8])
    R = _rotation([1.0, 2.0, 0.5], 0.7)
    bone = dn.Bone(
        name="thigh", pattern_origin=hip, pattern_frame=np.eye(3), body_origin=hip, body_frame=R
    )
    x = dn.skin(X=X, bones=[bone], weights=np.ones((50, 1)))
    assert np.allclose(x, (X - hip) @ R.T + hip, atol=1e-14)
    # two copies of the same bone, any partition of unity: the same rigid motion
    w = rng.uniform(size=(50, 1))
    x2 = dn.skin(X=X, bones=[bone, bone], weights=np.hstack([w, 1 - w]))
    assert np.allclose(x2, x, atol=1e-14)


def test_bone_carries_its_frame_onto_the_body_frame():
    P, B = _rotation([0, 0, 1], 0.3), _rotation([1, 0, 0], -1.1)
    o, c = np.array([0.0, 0.1, 0.2]), np.array([1.0, 2.0, 3.0])
    bone = dn.Bone(name="b", pattern_origin=o, pattern_frame=P, body_origin=c, body_frame=B)
    # the pattern axes e_i (columns of P) go to the body axes (columns of B)
    assert np.allclose(bone.transform(o + P.T), c + B.T, atol=1e-14)


def test_skin_and_bone_reject_bad_input():
    bone = dn.Bone(
        name="b", pattern_origin=np.zeros(3), pattern_frame=np.eye(3),
        body_origin=np.zeros(3), body_frame=np.eye(3),
    )  # fmt: skip
    with pytest.raises(ValueError, match="sum to 1"):
        dn.skin(X=np.zeros((2, 3)), bones=[bone], weights=np.full((2, 1), 0.5))
    with pytest.raises(ValueError, match="shape"):
        dn.skin(X=np.zeros((2, 3)), bones=[bone], weights=np.ones((3, 1)))
    with pytest.raises(ValueError, match="right-handed"):
        dn.Bone(
            name="b", pattern_origin=np.zeros(3), pattern_frame=-np.eye(3),
            body_origin=np.zeros(3), body_frame=np.eye(3),
        )  # fmt: skip


# ---------------------------------------------------------------- fitted pattern and skeleton
def test_fitted_pattern_skeleton_lands_on_the_joint_centres(body, pants):
    pattern, _ = pants
    bones = {b.name: b for b in pattern.bones}
    g = pattern.geometry
    assert g["leg_spacing"] >= 2.2 * g["leg_radius"]
    r_thigh = max(body.radii[s][1] for s in ("L_thigh", "R_thigh"))
    assert g["leg_radius"] == pytest.approx(r_thigh + COARSE.ease)
    for s in ("L", "R"):
        thigh, shank = bones[f"{s}_thigh"], bones[f"{s}_shank"]
        f_th, f_sh = body.frames[f"{s}_thigh"], body.frames[f"{s}_shank"]
        hip_p = thigh.pattern_origin
        knee_p = shank.pattern_origin
        # pattern hip -> body hip; pattern knee (thigh length below) -> body knee by both bones
        assert np.allclose(thigh.transform(hip_p[None]), f_th.j1[0], atol=1e-12)
        assert np.allclose(thigh.transform(knee_p[None]), f_th.j2[0], atol=1e-12)
        assert np.allclose(shank.transform(knee_p[None]), f_sh.j1[0], atol=1e-12)
        # the pattern's left leg (x > 0) is the wearer's left
        assert (hip_p[0] > 0) == (s == "L")


def test_blend_weights_partition_of_unity_and_regions(pants):
    pattern, net = pants
    w = dn.blend_weights(X=net.x0, pattern=pattern)
    assert np.all(w >= 0) and np.allclose(w.sum(axis=1), 1.0, atol=1e-14)
    assert np.allclose(w[net.nodes("waist"), 0], 1.0)  # the waist follows the pelvis
    assert np.allclose(w[net.nodes("left_hem"), 2], 1.0)  # hems follow their own shank
    assert np.allclose(w[net.nodes("right_hem"), 4], 1.0)


def test_belt_positions_lie_on_the_belt_ellipse_outside_the_pelvis(body, pants):
    pattern, net = pants
    waist = net.nodes("waist")
    xb = dn.belt_positions(X=net.x0[waist], pattern=pattern)
    local = (xb - pattern.pelvis_origin) @ pattern.pelvis_frame - pattern.belt_centre
    a, b = pattern.belt_axes
    assert np.allclose((local[:, 0] / a) ** 2 + (local[:, 1] / b) ** 2, 1.0, atol=1e-9)
    assert np.allclose(local[:, 2], 0.0, atol=1e-12)
    gap, _ = dn.body_gaps(x=xb, ellipsoids=[body.ellipsoids["pelvis"].ellipsoid(0)])
    assert gap.min() > 0.0
    # the belt ring's length is the pattern waist's (the belt neither gathers nor stretches)
    ring = np.sort(np.arctan2(net.x0[waist, 0], -net.x0[waist, 1]))
    assert len(ring) == len(waist)
    g = pattern.geometry
    assert 2 * np.pi * g["waist_radius"] == pytest.approx(dn._ellipse_perimeter(a, b))


# ---------------------------------------------------------------------- growing colliders
def test_growth_scale_and_limbs_keep_their_length():
    growth = dn.Growth(start=0.2, time=0.5)
    assert growth.scale(0.0) == pytest.approx(0.2)
    assert growth.scale(0.5) == pytest.approx(1.0) == growth.scale(3.0)
    s = [growth.scale(t) for t in np.linspace(0, 0.5, 11)]
    assert np.all(np.diff(s) > 0)
    ells = [
        Ellipsoid(centre=np.zeros(3), axes=np.eye(3), radii=[0.3, 0.1, 0.1], name="L_thigh"),
        Ellipsoid(centre=np.zeros(3), axes=np.eye(3), radii=[0.3, 0.2, 0.1], name="pelvis"),
    ]
    geo, vel = dn.growing_bodies(ellipsoids=ells, growth=growth)(0.0)
    assert np.allclose(geo[0][2], [0.3, 0.02, 0.02]) and np.allclose(geo[1][2], [0.06, 0.04, 0.02])
    assert all(np.all(v == 0) for pair in vel for v in pair)


def test_tube_around_a_growing_ellipsoid_ends_outside_it():
    net, fab = _tube(radius=0.06)
    ell = Ellipsoid(
        centre=np.array([0.2, 0.0, 0.0]), axes=np.eye(3), radii=[0.3, 0.075, 0.075], name="L_arm"
    )
    gap0, _ = dn.body_gaps(x=net.x0, ellipsoids=[ell])
    assert gap0.min() < -0.01  # the tube starts well inside the full-size ellipsoid
    relax = dn.Relaxation(gravity=(0.0, 0.0, 0.0), settle_time=0.05, max_stretch=0.5)
    res = dn.don(network=net, fabric=fab, x_start=net.x0, ellipsoids=[ell], relax=relax)
    gap, _ = dn.body_gaps(x=res.x, ellipsoids=[ell])
    assert gap.min() >= relax.offset - 1e-9
    # the middle ring is pushed out to the ellipsoid's full cross radius (+ offset)
    mid = np.abs(net.x0[:, 0] - 0.2) < 1e-9
    assert np.linalg.norm(res.x[mid, 1:], axis=1).min() >= 0.075 + relax.offset - 1e-9


def test_push_out_moves_only_the_points_inside_to_the_offset():
    """Points a little inside one of two overlapping spheres end ``offset`` outside the union
    along the normal, exactly; a point outside does not move, and its move is 0."""
    a = Ellipsoid(centre=np.zeros(3), axes=np.eye(3), radii=[0.1, 0.1, 0.1], name="a")
    b = Ellipsoid(centre=np.array([0.15, 0, 0]), axes=np.eye(3), radii=[0.1] * 3, name="b")
    x = np.array([[0.0, -0.099, 0.0], [0.16, 0.0, 0.095], [0.0, 0.0, 0.2]])
    new, moved = dn.push_out(x=x, ellipsoids=[a, b], offset=5e-4)
    gap, _ = dn.body_gaps(x=new, ellipsoids=[a, b])
    assert np.allclose(gap[:2], 5e-4, rtol=0, atol=1e-12)
    assert np.allclose(new[0], [0.0, -0.1005, 0.0], atol=1e-12)
    assert moved[0] == pytest.approx(0.0015)
    assert np.array_equal(new[2], x[2]) and moved[2] == 0.0


def test_donning_a_tube_that_already_fits_leaves_it_unchanged():
    net, fab = _tube(radius=0.06)
    R, t = _rotation([0.3, 1.0, 0.2], 0.9), np.array([0.1, -0.4, 0.7])
    x_start = net.x0 @ R.T + t  # a rigid placement: no strain
    ell = Ellipsoid(centre=R @ [0.2, 0, 0] + t, axes=R.T, radii=[0.3, 0.05, 0.05], name="L_arm")
    relax = dn.Relaxation(gravity=(0.0, 0.0, 0.0), growth=dn.Growth(time=0.05), settle_time=0.02)
    res = dn.don(network=net, fabric=fab, x_start=x_start, ellipsoids=[ell], relax=relax)
    assert res.steps > 10
    assert np.abs(res.x - x_start).max() < 1e-9
    assert dn.body_gaps(x=res.x, ellipsoids=[ell])[0].min() > 0.009


def test_q9_cells_of_a_network_are_the_mesh_cells_oriented_alike():
    """The network's grid as basix Q2 cells: the same node sets as the shell mesh's cells and
    triangles all turned the same way (outward on the tube, as the mesh's cells)."""
    net, _ = _tube(radius=0.06)
    cells = dn.q9_cells(net)
    tri = triangulate_q9(cells)[0]
    x = net.x0
    n = np.cross(x[tri[:, 1]] - x[tri[:, 0]], x[tri[:, 2]] - x[tri[:, 0]])
    radial = x[tri].mean(axis=1) * [0.0, 1.0, 1.0]
    side = np.sign(np.einsum("ij,ij->i", n, radial))
    assert np.all(side == side[0])
    Xm, mcells = mesh_nodes(
        cylinder(MPI.COMM_SELF, radius=0.06, length=0.4, n_around=8, n_along=6).mesh
    )
    _, idx = cKDTree(x).query(Xm)
    assert {frozenset(c) for c in idx[mcells]} == {frozenset(c) for c in cells}


def test_winding_number_of_rings_about_a_line():
    t = np.linspace(0, 2 * np.pi, 17)[:-1]
    R = _rotation([1.0, -0.5, 2.0], 1.2)
    axis, centre = R[:, 2], np.array([0.3, -0.2, 0.5])
    ring = centre + (0.1 * np.stack([np.cos(t), np.sin(t), 0.3 * np.sin(3 * t)], 1)) @ R.T
    assert dn.winding_number(x=ring, centre=centre, axis=axis) == pytest.approx(1.0)
    assert dn.winding_number(x=ring[::-1], centre=centre, axis=axis) == pytest.approx(-1.0)
    beside = centre + 0.25 * R[:, 0]  # a parallel line outside the ring
    assert dn.winding_number(x=ring, centre=beside, axis=axis) == pytest.approx(0.0, abs=1e-12)


def test_simple_fabric_on_a_square_grid():
    net = pm.regular_patch(length=0.2, width=0.1, nx=4, ny=2)
    E, G, rho, t = 1.2e6, 1e5, 436.0, 1e-3
    fab = dn.simple_fabric(network=net, E=E, G=G, rho=rho, thickness=t)
    st = net.kind == pm.STRUCTURAL
    x0 = net.x0
    d = x0[net.pairs[:, 1]] - x0[net.pairs[:, 0]]
    inner = (
        st & (np.abs(d[:, 0]) > 0) & np.all((x0[net.pairs, 1] > 0) & (x0[net.pairs, 1] < 0.1), 1)
    )
    assert np.allclose(fab.stiffness[inner], E * t)  # interior sides: two squares each
    assert np.allclose(fab.stiffness[net.kind == pm.SHEAR], G * t)
    assert fab.mass.sum() == pytest.approx(rho * t * 0.2 * 0.1)
    with pytest.raises(ValueError, match="thickness"):
        dn.simple_fabric(network=net, E=E, G=G, rho=rho, thickness=0.0)


def test_parameters_reject_bad_values():
    with pytest.raises(ValueError, match="n_around"):
        dn.PantsFit(n_around=10)
    with pytest.raises(ValueError, match="start"):
        dn.Growth(start=0.0)
    with pytest.raises(ValueError, match="max_speed"):
        dn.Relaxation(max_speed=-1.0)
    with pytest.raises(ValueError, match="frame"):
        dn.fit_pants(body=lower_body_from_c3d(WALK), frame=10_000)


# --------------------------------------------------------------------- command line, end to end
def test_command_line_rejects_bad_arguments_before_writing(tmp_path, capsys):
    out = tmp_path / "new"
    for extra in (["--n-around", "6"], ["--frame", "-1"], ["--ease", "0"], ["--c3d", "x.c3d"]):
        assert dn.main(["--out", str(out), *extra]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("clothfem.particle.donning: error:") and "\n" not in err
        assert not out.exists()
    full = tmp_path / "full"
    full.mkdir()
    (full / "keep.txt").write_text("x")
    assert dn.main(["--out", str(full)]) == 2
    assert "not empty" in capsys.readouterr().err
    assert sorted(p.name for p in full.iterdir()) == ["keep.txt"]


def test_coarse_pants_donned_on_the_first_frame_end_outside_the_body(body, pants, tmp_path):
    out = tmp_path / "don"
    rc = dn.main(["--out", str(out), "--n-around", "8", "--n-along", "6"])
    assert rc == 0
    data = np.load(out / "donned.npz")
    _, net = pants
    assert np.array_equal(data["X"], net.x0)  # the SurfaceMesh's node order ...
    geometry = {k[5:]: data[k].item() for k in data.files if k.startswith("mesh_")}
    assert np.array_equal(data["X"], pants_lattice(**geometry).x)  # ... = the gmsh tags
    mesh = pants_mesh(MPI.COMM_SELF, **geometry).mesh  # a shell's mesh: row = input global index
    rows = np.asarray(mesh.geometry.input_global_indices)
    assert np.array_equal(data["X"][rows], np.asarray(mesh.geometry.x))
    x, gap = data["x"], data["gap"]
    assert x.shape == gap.shape + (3,) == net.x0.shape
    ells = [body.ellipsoids[n].ellipsoid(0) for n in body.names]
    again, _ = dn.body_gaps(x=x, ellipsoids=ells)
    assert np.allclose(again, gap) and gap.min() >= -1e-6  # every node outside the body
    assert int(data["inside_start_full"]) > 0  # the skinned pants start partly inside ...
    assert int(data["inside_start_small"]) == 0  # ... but outside the shrunk colliders
    assert -0.5 < float(data["strain_min_structural"]) < float(data["strain_max_structural"]) < 0.5
    # each hem goes once round its own shank and not round the other; the waist round the hips
    for s in ("L", "R"):
        for o in ("L", "R"):
            assert abs(float(data[f"winding_{s}_hem_about_{o}_shank"])) == (s == o)
    assert abs(float(data["winding_waist_about_pelvis"])) == 1.0
    assert float(data["mesh_leg_spacing"]) >= 2.2 * float(data["mesh_leg_radius"])
    # the layers never pass through each other: no intersecting triangle pair, counted on the
    # shell mesh's own cells (dolfinx numbering, nodes matched by position)
    assert int(data["self_intersections"]) == 0
    Xm, cells = mesh_nodes(mesh)
    dist, idx = cKDTree(data["X"]).query(Xm)
    assert dist.max() < 1e-12
    assert len(intersecting_pairs(x[idx], triangulate_q9(cells)[0])) == 0
    log = (out / "donning_log.txt").read_text().splitlines()
    assert any(line.startswith("# min_gap = ") for line in log)
    assert "t_s,radius_scale,min_gap_m,contact_nodes,max_strain" in log
