"""Implicit Lagrange-multiplier contact (Man & Swan 2007, Eqs. 15-21, 28) against closed forms.

All problems use a sleeve (clothfem.mesh.cylinder, axis +x, radius R0, length L0, t = 1 mm,
9-node quadrilaterals) on a rigid "cylinder": an ellipsoid with radii (10 m, Rb, Rb) centred
on the tube's axis, 50 times longer than the tube, so that over the tube its surface is the
cylinder of radius Rb to 1e-4 relative. Every assertion is on values reduced over MPI ranks, so
the file runs unchanged under ``mpirun -n 2``.
"""

import math

import numpy as np
import pytest
from mpi4py import MPI

from clothfem import mesh as meshes
from clothfem.contact.lagrange import (
    LagrangeContact,
    LagrangeContactParameters,
)
from clothfem.shell import Clamp, FabricMaterial, Prescribed, ShellModel

COMM = MPI.COMM_WORLD
R0, L0, T, E = 0.05, 0.2, 1e-3, 1.2e6
RB = 0.052  # 4 % hoop stretch
LBIG = 10.0


def _point(p):
    p = np.asarray(p, dtype=float)
    return lambda x: np.linalg.norm(x.T - p, axis=1) < 1e-6


def _sleeve(nu: float, supports) -> ShellModel:
    sm = meshes.cylinder(COMM, radius=R0, length=L0, n_around=16, n_along=4)
    mat = FabricMaterial.isotropic(E=E, nu=nu)
    return ShellModel(sm, material=mat, thickness=T, supports=supports)


def _expand(contact: LagrangeContact, steps: int = 4):
    """Grow the rigid cylinder from just above R0 to RB (radii updated in place)."""
    recs = []
    for r in np.linspace(1.01 * R0, RB, steps):
        contact.set_pose(0, radii=(LBIG, r, r))
        recs.append(contact.solve_step(float(contact.model.lam.value)))
    return recs


def _cylinder_body(r: float = 0.999 * R0):
    return (np.array([L0 / 2, 0.0, 0.0]), np.eye(3), np.array([LBIG, r, r]))


def _kkt_ok(rec, total: float) -> None:
    assert rec.max_penetration <= 1e-3 * T, rec
    assert rec.min_multiplier >= -1e-9 * max(total, 1.0), rec  # lam >= 0 to round-off
    assert rec.complementarity <= 1e-9 * T * max(total, 1.0), rec


# ----------------------------------------------------------------------------- parameters
@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"mu": -0.1}, "mu"),
        ({"mu": float("nan")}, "mu"),
        ({"tangential_penalty": 0.0}, "tangential_penalty"),
        ({"gap_tolerance": -1e-6}, "gap_tolerance"),
        ({"multiplier_tolerance": 1.0}, "multiplier_tolerance"),
        ({"newton_rtol": 0.0}, "newton_rtol"),
        ({"max_newton": 0}, "max_newton"),
        ({"max_active_set": 2.5}, "max_active_set"),
        ({"newton_stall_limit": 0}, "newton_stall_limit"),
        ({"tissue_stiffness": 0.0}, "tissue_stiffness"),
        ({"prefix": ""}, "prefix"),
    ],
)
def test_parameters_are_validated(kwargs, field):
    with pytest.raises(ValueError, match=field) as err:
        LagrangeContactParameters(**kwargs)
    assert "\n" not in str(err.value)


def test_mu_zero_builds_no_friction_objects():
    """mu = 0: no friction state, no friction forces, no stick/slip bookkeeping."""
    sm = meshes.strip(COMM, length=1.0, width=0.2, nx=2, ny=1)
    model = ShellModel(
        sm, material=FabricMaterial.isotropic(E=E, nu=0.3), thickness=T, supports=[Clamp("root")]
    )
    body = (np.array([0.5, 0.0, -0.3]), np.eye(3), np.array([0.3, 0.3, 0.2]))
    c0 = LagrangeContact(model, [body])
    assert c0.friction is None
    assert not any("friction" in type(v).__name__.lower() for v in vars(c0).values())
    c1 = LagrangeContact(model, [body], params=LagrangeContactParameters(mu=0.2))
    assert c1.friction is not None
    with pytest.raises(ValueError, match="k must index"):
        c0.set_pose(3, centre=(0, 0, 0))
    with pytest.raises(ValueError, match="radii"):
        c0.set_pose(0, radii=(0.1, -0.1, 0.1))


# ----------------------------------------------------------------------------- normal contact
def test_sleeve_on_rigid_cylinder_closed_form():
    """Frictionless sleeve stretched over a rigid cylinder of radius Rb > R0.

    Exact state (membrane theory, St. Venant-Kirchhoff, plane stress, isotropic E, nu):
    uniform hoop stretch s = Rb/R0, hoop Green-Lagrange strain E_tt = (s^2 - 1)/2. The ends are
    free of axial traction (only u_x = 0 on the shoulder ring, which the exact state satisfies,
    plus u_z = 0 at one node against the free rotation about the axis), so S_xx = 0 gives
    E_xx = -nu E_tt and S_tt = E E_tt exactly (E_eff = E), with axial stretch
    l_x = sqrt(1 - 2 nu E_tt). Hoop tension per unit current axial length
    N = t s S_tt / l_x, contact pressure per unit current area p = N / Rb, and the summed
    normal contact force is p 2 pi Rb L0 l_x = 2 pi L0 t s E E_tt (independent of nu).
    The bending energy of the curvature change (R0 -> Rb) adds a relative
    t^2 / (12 (1 - nu^2) R0 Rb) = 3.5e-5 to both: negligible against the 1 % tolerance.
    """
    nu = 0.3
    supports = [
        Prescribed("shoulder", displacement=(0.0, 0.0, 0.0), components=(0,)),
        Prescribed(_point((0.0, R0, 0.0)), displacement=(0.0, 0.0, 0.0), components=(2,)),
    ]
    model = _sleeve(nu, supports)
    contact = LagrangeContact(model, [_cylinder_body()])
    recs = _expand(contact)
    s, e_tt = RB / R0, 0.5 * ((RB / R0) ** 2 - 1.0)
    total_exact = 2 * math.pi * L0 * T * s * E * e_tt
    lx = math.sqrt(1.0 - 2.0 * nu * e_tt)
    p_exact = T * s * E * e_tt / lx / RB
    rec = recs[-1]
    _kkt_ok(rec, rec.total_normal_force)
    assert rec.n_active == 32 * 9  # every node of the sleeve touches
    assert rec.total_normal_force == pytest.approx(total_exact, rel=0.01)
    st = contact.state()
    mid = np.abs(st.x[:, 0] - 0.5 * L0 * lx) < 0.3 * L0  # away from the ends
    pmin = COMM.allreduce(float(st.pressure[mid].min()) if mid.any() else np.inf, op=MPI.MIN)
    pmax = COMM.allreduce(float(st.pressure[mid].max()) if mid.any() else -np.inf, op=MPI.MAX)
    assert pmin == pytest.approx(p_exact, rel=0.01)
    assert pmax == pytest.approx(p_exact, rel=0.01)
    # radii of the contact nodes: all on the body's cross-section circle at their x
    rad = np.linalg.norm(st.x[:, 1:], axis=1)
    r_body = RB * np.sqrt(1.0 - ((st.x[:, 0] - L0 / 2) / LBIG) ** 2)
    dev = COMM.allreduce(float(np.max(np.abs(rad - r_body))) if len(rad) else 0.0, op=MPI.MAX)
    assert dev <= 1e-3 * T
    # self-equilibrated radial forces: zero resultant and zero Eq. 28 torque about the axis
    assert np.linalg.norm(contact.resultant()) <= 1e-4 * total_exact
    assert np.linalg.norm(contact.torque((L0 / 2, 0.0, 0.0))) <= 1e-4 * total_exact * R0


def test_union_rule_inner_ellipsoid_is_ignored():
    """Body = union of the rigid cylinder and a thinner coaxial one inside it (listed first):
    the union's surface is the outer cylinder, so the closed form of the previous test holds
    (summed normal force 2 pi L0 t s E E_tt within 1 %, nu = 0)."""
    supports = [
        Prescribed("shoulder", displacement=(0.0, 0.0, 0.0), components=(0,)),
        Prescribed(_point((0.0, R0, 0.0)), displacement=(0.0, 0.0, 0.0), components=(2,)),
    ]
    model = _sleeve(0.0, supports)
    inner = (np.array([L0 / 2, 0.0, 0.0]), np.eye(3), np.array([LBIG, 0.8 * R0, 0.8 * R0]))
    contact = LagrangeContact(model, [inner, _cylinder_body()])
    for r in np.linspace(1.01 * R0, RB, 4):
        contact.set_pose(1, radii=(LBIG, r, r))
        rec = contact.solve_step(0.0)
    s, e_tt = RB / R0, 0.5 * ((RB / R0) ** 2 - 1.0)
    _kkt_ok(rec, rec.total_normal_force)
    assert rec.total_normal_force == pytest.approx(2 * math.pi * L0 * T * s * E * e_tt, rel=0.01)


def test_sleeve_on_soft_cylinder_closed_form():
    """The same sleeve (nu = 0) pushed over a cylinder whose surface gives way as a Winkler
    foundation of modulus k_w (contact.tissue_stiffness): it settles at the radius r where
    the tissue's force equals the membrane's.

    Closed form: the uniform hoop stretch s = r / R0 gives the summed normal force
    F(r) = 2 pi L0 t s E E_tt (previous test, nu = 0) and the tissue, indented by
    Rb - r under every node (force per node k_w A_i (Rb - r), A_i the undeformed area),
    pushes with k_w 2 pi R0 L0 (Rb - r); r solves F(r) = k_w 2 pi R0 L0 (Rb - r). k_w is
    chosen so that the sleeve sinks by about half of Rb - R0.
    """
    from scipy.optimize import brentq

    kw = 5e5  # Pa/m
    supports = [
        Prescribed("shoulder", displacement=(0.0, 0.0, 0.0), components=(0,)),
        Prescribed(_point((0.0, R0, 0.0)), displacement=(0.0, 0.0, 0.0), components=(2,)),
    ]
    model = _sleeve(0.0, supports)
    params = LagrangeContactParameters(tissue_stiffness=kw)
    contact = LagrangeContact(model, [_cylinder_body()], params=params)
    rec = _expand(contact)[-1]

    def membrane(r: float) -> float:
        s = r / R0
        return 2 * math.pi * L0 * T * s * E * 0.5 * (s * s - 1.0)

    r = brentq(lambda r: membrane(r) - kw * 2 * math.pi * R0 * L0 * (RB - r), R0, RB)
    assert 0.3 < (RB - r) / (RB - R0) < 0.7  # the tissue's give is half the problem
    assert rec.n_active == 32 * 9
    assert rec.total_normal_force == pytest.approx(membrane(r), rel=0.01)
    assert rec.max_indentation == pytest.approx(RB - r, rel=0.01)
    # the constraint with the give holds to round-off (gap + lam / (k_w A) = 0)
    assert rec.max_penetration <= 1e-6 * T and rec.complementarity <= 1e-6 * T * membrane(r)
    rad = np.linalg.norm(contact.state().x[:, 1:], axis=1)
    lo = COMM.allreduce(float(rad.min()) if len(rad) else np.inf, op=MPI.MIN)
    hi = COMM.allreduce(float(rad.max()) if len(rad) else -np.inf, op=MPI.MAX)
    assert lo == pytest.approx(r, rel=1e-3) and hi == pytest.approx(r, rel=1e-3)


# ----------------------------------------------------------------------------- friction
def test_sleeve_pulled_along_cylinder_slides_at_mu_N():
    """Coulomb sliding of the whole sleeve: pull force = mu * sum of normal forces.

    The sleeve (nu = 0, so axial stress leaves the hoop stress and the normal forces
    unchanged) is first stretched over the cylinder as in the frictionless test, then its cuff
    ring is pulled along +x by a prescribed displacement. Once every node slips, global
    equilibrium along x of the rigid-plastic Coulomb law gives (Coulomb 1785; see e.g. Wriggers,
    Computational Contact Mechanics, 2006) the pull force
    F = mu * sum_i lam_i, the resultant friction force on the body along +x equals F, its Eq. 28
    torque about J = (0, 0, -d) is J-lever times F: tau = (0, d F, 0) (the axisymmetric part
    cancels), and the dissipation of a fully sliding step is F times the cuff displacement
    increment (steady sliding: every node moves by the same increment).
    """
    mu, delta = 0.3, 0.02
    supports = [
        Prescribed("cuff", displacement=(delta, 0.0, 0.0), components=(0,)),
        Prescribed(_point((L0, R0, 0.0)), displacement=(0.0, 0.0, 0.0), components=(2,)),
    ]
    model = _sleeve(0.0, supports)
    contact = LagrangeContact(model, [_cylinder_body()], params=LagrangeContactParameters(mu=mu))
    _expand(contact)
    n0 = contact.n
    # from partial stick (0.05) to sliding in steps of 0.05: one step 0.05 -> 0.15 left the
    # contact Newton unconverged on 2 ranks with the partial selective element
    lams = [0.05, 0.1, 0.15, 0.25, 0.35, 0.45]
    recs, pulls = [], []
    for lam in lams:
        rec = contact.solve_step(lam)
        rows, vals = contact.reactions()
        xrows = (rows < 3 * n0) & (rows % 3 == 0)
        pulls.append(COMM.allreduce(float(vals[xrows].sum()), op=MPI.SUM))
        recs.append(rec)
    last = recs[-1]
    _kkt_ok(last, last.total_normal_force)
    assert last.n_slip == last.n_active == 32 * 9 and last.n_stick == 0
    mu_n = mu * last.total_normal_force
    assert pulls[-1] == pytest.approx(mu_n, rel=0.02)  # support pulls the cuff along +x
    assert pulls[-2] == pytest.approx(mu * recs[-2].total_normal_force, rel=0.02)
    # before full sliding the pull is below mu N (partial stick)
    assert 0.0 < pulls[0] < 0.9 * mu * recs[0].total_normal_force
    # resultant on the body and Eq. 28 torque about an off-axis joint
    res = contact.resultant()
    assert res[0] == pytest.approx(mu_n, rel=0.02)
    d = 0.1
    tau = contact.torque((0.0, 0.0, -d))
    assert tau[1] == pytest.approx(d * mu_n, rel=0.02)
    # Eq. 28 over a node set AJ (shoulder half of the sleeve): tau_y = d mu sum_{AJ} lam
    st = contact.state()
    half = contact.X[:, 0] < L0 / 2
    lam_half = COMM.allreduce(float(st.lam_n[half].sum()), op=MPI.SUM)
    tau_half = contact.torque((0.0, 0.0, -d), nodes=lambda X: X[0] < L0 / 2)
    assert tau_half[1] == pytest.approx(d * mu * lam_half, rel=0.02)
    # frictional dissipation of the last (fully sliding) step
    dd = (lams[-1] - lams[-2]) * delta
    assert last.dissipation == pytest.approx(mu_n * dd, rel=0.02)


# ----------------------------------------------------------------------------- moving body
def test_body_moving_through_fabric_never_lets_a_node_through():
    """A rigid ellipsoid rises through a pretensioned fabric patch and drags it sideways: at
    every quasi-static step no fabric node is inside the body (gap >= -1e-3 t), active
    multipliers are compressive and lam * gap = 0 (KKT, Eqs. 16-17)."""
    sm = meshes.strip(COMM, length=0.3, width=0.1, nx=12, ny=4)
    model = ShellModel(
        sm,
        material=FabricMaterial.isotropic(E=E, nu=0.3),
        thickness=T,
        supports=[
            Clamp("root"),
            Prescribed("tip", displacement=(0.003, 0.0, 0.0), rotation=(0.0, 0.0, 0.0)),
        ],
    )
    radii = np.array([0.05, 0.03, 0.03])
    contact = LagrangeContact(model, [(np.array([0.15, 0.0, -0.04]), np.eye(3), radii)])
    contact.solve_step(1.0)  # pretension, no contact
    path = [(0.15, z) for z in np.linspace(-0.025, 0.01, 15)]  # 2.5 mm steps up
    path += [(x, 0.01) for x in np.linspace(0.155, 0.175, 5)]  # 5 mm steps sideways
    n_touch = 0
    for xc, zc in path:
        contact.set_pose(0, centre=(xc, 0.0, zc))
        rec = contact.solve_step(1.0)
        _kkt_ok(rec, rec.total_normal_force)
        st = contact.state()
        gmin = COMM.allreduce(float(st.gap.min()) if len(st.gap) else np.inf, op=MPI.MIN)
        assert gmin >= -1e-3 * T, (xc, zc, gmin)
        n_touch = max(n_touch, rec.n_active)
    assert n_touch >= 5
    # the fabric pushes the body down (-z), as a tensioned membrane must
    assert contact.resultant()[2] < 0.0


@pytest.mark.slow
def test_body_dragging_fabric_with_friction_keeps_kkt_and_coulomb_cone():
    """Same patch, mu = 0.3, poses driven by :meth:`LagrangeContact.advance` (automatic
    sub-steps): at every converged sub-step no node is inside the body, the KKT conditions
    hold, every friction force lies in the Coulomb disc |f_t| <= mu lam_n (Coulomb's law) and
    is tangential, and the dissipation increments are >= 0."""
    mu = 0.3
    sm = meshes.strip(COMM, length=0.3, width=0.1, nx=12, ny=4)
    model = ShellModel(
        sm,
        material=FabricMaterial.isotropic(E=E, nu=0.3),
        thickness=T,
        supports=[
            Clamp("root"),
            Prescribed("tip", displacement=(0.003, 0.0, 0.0), rotation=(0.0, 0.0, 0.0)),
        ],
    )
    radii = np.array([0.05, 0.03, 0.03])
    contact = LagrangeContact(
        model,
        [(np.array([0.15, 0.0, -0.04]), np.eye(3), radii)],
        params=LagrangeContactParameters(mu=mu),
    )
    contact.solve_step(1.0)
    checked = []

    def check(rec):
        _kkt_ok(rec, rec.total_normal_force)
        assert rec.dissipation >= 0.0
        st = contact.state()
        gmin = COMM.allreduce(float(st.gap.min()) if len(st.gap) else np.inf, op=MPI.MIN)
        assert gmin >= -1e-3 * T
        ft = np.linalg.norm(st.friction, axis=1)
        excess = ft - mu * st.lam_n * (1 + 1e-9) - 1e-12
        assert COMM.allreduce(float(excess.max()) if len(ft) else 0.0, op=MPI.MAX) <= 0.0
        tang = np.abs(np.einsum("ij,ij->i", st.friction, st.normal))
        assert COMM.allreduce(float(tang.max()) if len(ft) else 0.0, op=MPI.MAX) <= 1e-9
        checked.append(rec)

    for centre in [(0.15, 0.0, -0.02), (0.15, 0.0, 0.01), (0.2, 0.0, 0.01)]:
        contact.advance(1.0, poses={0: (centre, None, None)}, on_step=check)
    assert len(checked) >= 4
    assert checked[-1].n_slip + checked[-1].n_stick == checked[-1].n_active > 0
    assert contact.dissipation_total > 0.0
    res = contact.resultant()
    assert res[0] < 0.0 and res[2] < 0.0  # dragged along +x: fabric holds the body back


@pytest.mark.parametrize("depth", [0.0, 5e-3])
def test_contact_tangent_taylor(depth):
    """The contact terms' tangent (curvature and friction, stick and slip) is the derivative
    of the force on the fabric: |f(x + h dx) - f(x) + h K_t dx| = O(h^2), for nodes on the
    body (rigid) and 5 mm inside it (the give of a compliant body)."""
    model = _sleeve(0.0, [])
    rb = R0 + depth
    body = (np.array([L0 / 2, 0.0, 0.0]), np.eye(3), np.array([LBIG, rb, rb]))
    params = LagrangeContactParameters(mu=0.3, tangential_penalty=1e4)
    contact = LagrangeContact(model, [body], params=params)
    n = contact.n
    rng = np.random.default_rng(3 + COMM.rank)
    x0 = contact.X.copy()
    contact.friction.commit(x0, contact.bodies, np.zeros((n, 3)))  # anchors under each node
    pairs = np.arange(n)  # node i against the one body
    lam = rng.uniform(0.5, 1.5, n)  # N
    # tangential offsets from the anchors, well inside (every other node: stick) or well
    # outside (slip) the cone |k_t du| = mu lam, so that no pair switches along h dx
    radial = x0 * np.array([0.0, 1.0, 1.0])
    radial /= np.linalg.norm(radial, axis=1)[:, None]
    t = rng.normal(size=(n, 3))
    t -= np.sum(t * radial, axis=1)[:, None] * radial
    t /= np.linalg.norm(t, axis=1)[:, None]
    cone = params.mu * lam / params.tangential_penalty  # m
    x = x0 + (np.where(np.arange(n) % 2, 3.0, 0.3) * cone)[:, None] * t
    dx = rng.normal(size=(n, 3)) * 1e-4
    _, _, f0, _, blocks, fr = contact._contact_terms(x, pairs, lam)
    if n:
        assert fr.stick.any() and (~fr.stick).any()
    kdx = np.einsum("nij,nj->ni", blocks, dx)
    errs = []
    for h in (4e-2, 2e-2, 1e-2, 5e-3):
        fh = contact._contact_terms(x + h * dx, pairs, lam)[2]
        errs.append(np.sum((fh - f0 + h * kdx) ** 2))
    errs = [math.sqrt(COMM.allreduce(e, op=MPI.SUM)) for e in errs]
    orders = [math.log2(errs[i] / errs[i + 1]) for i in range(len(errs) - 1)]
    assert min(orders) > 1.8, orders
