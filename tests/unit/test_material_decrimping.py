"""DecrimpingFabric: the smoothed ramp and its derivatives, convexity, the cotton preset
against the paper's stress levels, the UFL energy against the closed form, Taylor tests of
residual and Jacobian through every piece of the law, the stable step, bad input."""

import dataclasses
import math

import numpy as np
import pytest
from _taylor import energy_orders, jacobian_orders, random_state
from mpi4py import MPI

from clothfem import mesh as meshes
from clothfem.dynamics import ShellSystem, stable_time_step
from clothfem.shell import DecrimpingFabric, FabricMaterial, Pressure, ShellModel
from clothfem.shell.material import transition_from_stresses, yarn_ramp

COMM = MPI.COMM_WORLD
# a law whose transition random test states cross: warp 0.02 +- 0.015, weft 0.03 +- 0.02
MAT = DecrimpingFabric(
    E1=1.0e6,
    E2=0.6e6,
    G12=0.2e6,
    nu12=0.3,
    rho=500.0,
    E1_decrimped=50e6,
    E2_decrimped=20e6,
    transition1=0.02,
    transition2=0.03,
    width1=0.015,
    width2=0.02,
)


def test_ramp_derivatives_and_continuity():
    """P' = p and p' = h (central differences), values and derivatives continuous at the
    piece boundaries s = +-1, the limits 0 and max(s, 0) + const outside."""
    s = np.linspace(-2.5, 2.5, 5001)
    P, p, h = yarn_ramp(s)
    ds = s[1] - s[0]
    np.testing.assert_allclose((P[2:] - P[:-2]) / (2 * ds), p[1:-1], atol=1e-6)
    np.testing.assert_allclose((p[2:] - p[:-2]) / (2 * ds), h[1:-1], atol=1e-6)
    for b in (-1.0, 1.0):
        for f in yarn_ramp(np.array([b - 1e-12, b + 1e-12])):
            assert abs(f[1] - f[0]) < 1e-10
    assert np.all(P[s <= -1] == 0) and np.all(h[s <= -1] == 0) and np.all(h[s >= 1] == 1)
    np.testing.assert_allclose(p[s >= 1], s[s >= 1])
    assert np.all(np.diff(h) >= 0) and np.all((h >= 0) & (h <= 1))


def test_yarn_energy_is_convex():
    """The yarn tangent dS/dE >= E_crimped > 0 from -0.5 to 1.5 strain (both directions),
    equal to the finite-difference slope of the closed-form stress; the in-plane Hessian of
    W(E11, E22, E12) (finite differences of the energy) is positive definite at random
    strains crossing both transitions."""
    e = np.linspace(-0.5, 1.5, 4001)
    for d, Ec in ((1, MAT.E1), (2, MAT.E2)):
        k = MAT.yarn_tangent(e, direction=d)
        assert np.all(k >= Ec * (1 - 1e-12))
        dS = MAT.uniaxial_stress(e + 1e-7, direction=d) - MAT.uniaxial_stress(e - 1e-7, direction=d)
        np.testing.assert_allclose(dS / 2e-7, k, rtol=1e-6)
    rng = np.random.default_rng(0)
    hstep = 1e-5
    for _ in range(50):
        E = rng.uniform([-0.2, -0.2, -0.2], [0.1, 0.1, 0.2])
        H = np.empty((3, 3))
        for i in range(3):
            for j in range(3):
                di, dj = np.eye(3)[i] * hstep, np.eye(3)[j] * hstep
                H[i, j] = (
                    MAT.energy_density(*(E + di + dj))
                    - MAT.energy_density(*(E + di - dj))
                    - MAT.energy_density(*(E - di + dj))
                    + MAT.energy_density(*(E - di - dj))
                ) / (4 * hstep**2)
        assert np.linalg.eigvalsh(0.5 * (H + H.T)).min() > 0


def test_cotton_preset_matches_the_paper():
    """Man & Swan Sec. 4.1: E = 1.2 MPa while the stress is below 1 MPa, 350 MPa above
    10 MPa; G12 0.1 MPa, rho 436 kg/m^3; in between the tangent rises monotonically."""
    m = DecrimpingFabric.cotton()
    assert (m.E1, m.E2, m.E1_decrimped, m.G12, m.rho) == (1.2e6, 1.2e6, 350e6, 1e5, 436.0)
    e = np.linspace(0.0, 1.2, 12001)
    S, k = m.uniaxial_stress(e), m.yarn_tangent(e)
    np.testing.assert_allclose(k[S <= 1.0e6 * (1 - 1e-9)], 1.2e6, rtol=1e-12)
    np.testing.assert_allclose(k[S >= 10.0e6 * (1 + 1e-9)], 350e6, rtol=1e-12)
    mid = (S > 1e6) & (S < 10e6)
    assert mid.sum() > 10 and np.all(np.diff(k[mid]) >= 0)
    et, w = transition_from_stresses(
        E_crimped=1.2e6, E_decrimped=350e6, crimped_below=1e6, decrimped_above=10e6
    )
    assert m.uniaxial_stress(et - w) == pytest.approx(1e6, rel=1e-12)
    assert m.uniaxial_stress(et + w) == pytest.approx(10e6, rel=1e-12)


def _homogeneous(model, F2):
    """Set u = (F - I) X for a 2x2 in-plane deformation gradient F2 of a flat strip."""
    F = np.eye(3)
    F[:2, :2] = F2
    X = model.x_nodes
    model.u.x.array[:] = (X @ (F - np.eye(3)).T).ravel()
    model.theta.x.array[:] = 0.0
    model.update_director()


@pytest.mark.parametrize("F2", [[[1.01, 0.0], [0.0, 0.995]], [[1.2, 0.05], [0.02, 1.1]]])
def test_ufl_energy_equals_closed_form(F2):
    """The compiled strain energy of a homogeneous in-plane state equals t A W(E) of the
    closed form (within the crimped range and across both transitions); in the crimped
    range it also equals that of FabricMaterial with the crimped moduli."""
    sm = meshes.strip(COMM, length=1.0, width=0.5, nx=2, ny=2)
    t = 1e-3
    model = ShellModel(sm, material=MAT, thickness=t, warp=(1.0, 0.0, 0.0))
    _homogeneous(model, np.array(F2))
    Fm = np.array(F2)
    E = 0.5 * (Fm.T @ Fm - np.eye(2))
    want = t * 0.5 * MAT.energy_density(E[0, 0], E[1, 1], E[0, 1])
    assert model.strain_energy() == pytest.approx(want, rel=1e-10)
    if E[0, 0] < MAT.transition1 - MAT.width1 and E[1, 1] < MAT.transition2 - MAT.width2:
        lin = FabricMaterial(E1=MAT.E1, E2=MAT.E2, G12=MAT.G12, nu12=MAT.nu12)
        ref = ShellModel(sm, material=lin, thickness=t, warp=(1.0, 0.0, 0.0))
        _homogeneous(ref, Fm)
        assert model.strain_energy() == pytest.approx(ref.strain_energy(), rel=1e-12)


@pytest.fixture(scope="module")
def panel():
    return meshes.cylinder_panel(
        COMM, radius=1.0, length=1.5, angle=math.radians(50), n_around=4, n_along=3
    )


def _yarn_pieces(model):
    """Area fractions of the current state where the warp and the weft strain are below
    and above their transitions (assembled indicator functions)."""
    import ufl
    from dolfinx import fem

    eps = model.strains[0]
    cnt = []
    for i, (et, w) in enumerate(((MAT.transition1, MAT.width1), (MAT.transition2, MAT.width2))):
        s = (eps[i, i] - et) / w
        for cond in (ufl.lt(s, -1.0), ufl.gt(s, 1.0)):
            part = fem.assemble_scalar(fem.form(ufl.conditional(cond, 1.0, 0.0) * ufl.dx))
            cnt.append(COMM.allreduce(part, op=MPI.SUM))
        area = COMM.allreduce(fem.assemble_scalar(fem.form(1.0 * ufl.dx(model.mesh))), op=MPI.SUM)
        cnt[-2:] = [c / area for c in cnt[-2:]]
    return cnt  # fractions: warp below, warp above, weft below, weft above


def test_residual_is_energy_gradient(panel):
    """|Pi(x + h dx) - Pi(x) - h R . dx| = O(h^2) at a state crossing both transitions."""
    model = ShellModel(
        panel, material=MAT, thickness=0.01, warp=(1.0, 0.3, 0.0), loads=[Pressure(50.0)]
    )
    model.set_load_factor(0.0)
    x, dx = random_state(model, 0.1, 2), random_state(model, 1.0, 3)
    model.set_state(x)
    fr = _yarn_pieces(model)
    assert all(0.02 < f < 0.98 for f in fr), fr  # some of the area in every piece

    steps = (1e-3, 5e-4, 2.5e-4, 1.25e-4)
    assert min(energy_orders(model, x, dx, steps, model.strain_energy)) > 1.9


def test_jacobian_taylor(panel):
    """|R(x + h dx) - R(x) - h K dx| = O(h^2) at a state crossing both transitions."""
    model = ShellModel(panel, material=MAT, thickness=0.01, warp=(1.0, 0.3, 0.0))
    model.set_load_factor(0.0)
    x, dx = random_state(model, 0.1, 0), random_state(model, 1.0, 1)
    assert min(jacobian_orders(model, x, dx, (1e-3, 5e-4, 2.5e-4, 1.25e-4))) > 1.9


def test_stable_step_shrinks_as_yarns_decrimp():
    """Explicit dynamics: lumped mass as for the linear law, dt_crit from the tangent at the
    current state. With the rotary inertia scaled up (x 1e4) so that membrane modes set
    omega_max, the stable step of a strip stretched into the de-crimped range (E11 = et +
    2 w, tangent 50 MPa) is about sqrt(E_crimped / E_decrimped) = 0.14 x that of the
    unstretched strip; with physical rotary inertia (t = 1 mm, h = 5 cm: director modes set
    omega_max) it hardly changes. A run whose yarns de-crimp needs solver.recheck_every."""
    sm = meshes.strip(COMM, length=0.2, width=0.1, nx=4, ny=2)
    mat = dataclasses.replace(MAT, nu12=0.0, E2_decrimped=MAT.E2)
    e = mat.transition1 + 2 * mat.width1
    ratios = []
    for scale in (1e4, 1.0):
        model = ShellModel(sm, material=mat, thickness=1e-3)
        system = ShellSystem(model, rotary_scale=scale)
        assert system.total_mass == pytest.approx(mat.rho * 1e-3 * 0.02, rel=1e-12)
        dt0 = stable_time_step(system).dt_crit
        _homogeneous(model, np.diag([math.sqrt(1 + 2 * e), 1.0]))
        ratios.append(stable_time_step(system).dt_crit / dt0)
    assert 0.1 < ratios[0] < 0.2 and ratios[1] > 0.9, ratios


def test_bad_input_one_line_errors():
    base = dict(E1=1e6, E2=1e6, G12=1e5, transition1=0.1, transition2=0.1)
    ok = dict(base, E1_decrimped=1e8, E2_decrimped=1e8, width1=0.01, width2=0.01)
    DecrimpingFabric(**ok)
    with pytest.raises(ValueError, match=r"material E1_decrimped must be a finite number >= E1"):
        DecrimpingFabric(**dict(ok, E1_decrimped=1e5))
    with pytest.raises(ValueError, match=r"material width2 must be in \(0, transition2 = 0.1\]"):
        DecrimpingFabric(**dict(ok, width2=0.2))
    with pytest.raises(ValueError, match=r"material transition1 must be a finite number > 0"):
        DecrimpingFabric(**dict(ok, transition1=0.0))
    with pytest.raises(ValueError, match=r"decrimped_above must be a finite number > "):
        transition_from_stresses(
            E_crimped=1e6, E_decrimped=1e8, crimped_below=1e6, decrimped_above=1e6
        )
    with pytest.raises(ValueError, match="direction must be 1 or 2"):
        MAT.uniaxial_stress(0.1, direction=3)


SCENE = {
    "scene": {"name": "decrimp"},
    "mesh": {"generator": "strip", "length": 1.0, "width": 0.2, "nx": 2, "ny": 1},
    "material": {"preset": "decrimping-cotton", "thickness": 1e-3},
}


def test_scene_preset_builds_the_cotton_law():
    """Scene preset 'decrimping-cotton' gives DecrimpingFabric.cotton(); explicit keys
    override it; the decrimping keys are refused with law 'linear' and required with
    'decrimping'; the runner's model reproduces the closed-form energy of a stretch into
    the de-crimped range."""
    from clothfem import scene as scenes
    from clothfem.run import build_material, build_model

    s = scenes.validate(scenes.apply_overrides(SCENE, []))
    assert build_material(s.material) == DecrimpingFabric.cotton()
    s = scenes.validate(scenes.apply_overrides(SCENE, ["material.E2_decrimped=2e8"]))
    assert build_material(s.material).E2_decrimped == 2e8
    lin = scenes.validate(scenes.apply_overrides(SCENE, ["material.law='linear'"]))
    assert type(build_material(lin.material)) is FabricMaterial
    bad = [
        (["material.preset='crimped-cotton'", "material.width1=0.1"], "only"),
        (["material.preset='crimped-cotton'", "material.law='decrimping'"], "required with"),
        (["material.E1_decrimped=1e5"], r"must be >= E1 = 1.2e\+06"),
        (["material.width2=0.9"], r"must be in \(0, transition2 = 0.8589"),
    ]
    for sets, msg in bad:
        with pytest.raises(scenes.SceneError, match=msg):
            scenes.validate(scenes.apply_overrides(SCENE, sets))
    model, log = build_model(scenes.validate(scenes.apply_overrides(SCENE, [])), COMM)
    assert any("decrimping, crimped E1 1.2e+06" in line for line in log)
    e = 1.0
    _homogeneous(model, np.diag([math.sqrt(1 + 2 * e), 1.0]))
    want = 1e-3 * 0.2 * DecrimpingFabric.cotton().energy_density(e, 0.0)
    assert model.strain_energy() == pytest.approx(want, rel=1e-10)
