"""Per-(node, ellipsoid) contact pairs of :class:`LagrangeContact`: the concave crease between
two ellipsoids, the anti-cycling guard of the active-set loop and the default tangential
penalty of the friction law.

Crease geometry: two equal prolate ellipsoids, axes along x, radii (A, R, R), centres at
``xc -+ C`` (C = A/2, so they overlap). Their union is a body of revolution about the x axis
with a waist in the plane ``x = xc``: the concave crease, a circle of radius
``R sqrt(1 - (C/A)^2)``, where the surfaces meet at an angle of 2 x 13 degrees (gentler than two
spheres 1.5 R apart, 2 x 48 degrees, which a coarse shell cannot follow). A sleeve
(clothfem.mesh.cylinder, radius RT, length LT, axis x) is centred on the waist and the
ellipsoids are grown (``set_pose``) until the whole sleeve is stretched over it. Its node
rings at ``x = k LT / 8``: the middle ring lies in the crease plane.

Every assertion is on values reduced over MPI ranks (the pair count per node is checked on
each rank, it is a per-node property), so the file runs unchanged under ``mpirun -n 2``.
"""

import math

import numpy as np
import pytest
import ufl
from dolfinx import fem
from mpi4py import MPI

from clothfem import mesh as meshes
from clothfem.contact.geometry import closest_point_ellipsoid
from clothfem.contact.lagrange import (
    KT_MAX,
    ContactDivergence,
    LagrangeContact,
    LagrangeContactParameters,
)
from clothfem.shell import FabricMaterial, Gravity, PointForce, Prescribed, ShellModel

COMM = MPI.COMM_WORLD
T = 1e-3  # fabric thickness [m]
E = 1.2e6  # soft fabric [Pa]

# crease of two prolate ellipsoids (see module docstring)
A, C = 0.1, 0.05  # semi-axis along x, centre offset from the crease plane [m]
R_FINAL = 0.04  # final cross-section radius of the ellipsoids [m]
RT, LT = 0.034, 0.02  # sleeve radius and length [m]
XC = LT / 2  # crease plane x = XC


def _allmin(a) -> float:
    return COMM.allreduce(float(np.min(a)) if np.size(a) else np.inf, op=MPI.MIN)


def _allmax(a) -> float:
    return COMM.allreduce(float(np.max(a)) if np.size(a) else -np.inf, op=MPI.MAX)


def _all(flag) -> bool:
    return COMM.allreduce(bool(flag), op=MPI.LAND)


def _allsum(a):
    return COMM.allreduce(np.asarray(a, dtype=float).sum(axis=0), op=MPI.SUM)


def _at(p):
    p = np.asarray(p, dtype=float)
    return lambda x: np.linalg.norm(x.T - p, axis=1) < 1e-9


def _union_radius(x, R):
    """Radius of the union of the two crease ellipsoids (cross-section radius R) at x."""
    return R * np.sqrt(1.0 - ((C - np.abs(x - XC)) / A) ** 2)


def _crease_bodies(R):
    return [
        (np.array([XC - C, 0.0, 0.0]), np.eye(3), np.array([A, R, R])),
        (np.array([XC + C, 0.0, 0.0]), np.eye(3), np.array([A, R, R])),
    ]


def _sleeve_on_crease(loads, *, rho=0.0, load_factor=0.0):
    """The sleeve stretched over the waist: the ellipsoids grow in 4 steps from just touching
    the end rings (union radius 1.0005 RT there) to cross-section radius R_FINAL, at which
    the union radius is 1.019 RT at the crease and 1.078 RT at the ends, so every ring is
    stretched. Supports: u_y = 0 at the top node of the x = 0 ring only (it removes the
    rotation about the axis, the one rigid motion the frictionless contact leaves free; it
    lies on the mirror plane y = 0 of the problem, so its reaction vanishes by symmetry)."""
    sm = meshes.cylinder(COMM, radius=RT, length=LT, n_around=16, n_along=4)
    model = ShellModel(
        sm,
        material=FabricMaterial.isotropic(E=E, nu=0.3, rho=rho),
        thickness=T,
        loads=loads,
        supports=[Prescribed(_at((0.0, 0.0, RT)), displacement=(0.0, 0.0, 0.0), components=(1,))],
    )
    r0 = 1.0005 * RT / _union_radius(0.0, 1.0)
    contact = LagrangeContact(model, _crease_bodies(r0))
    for R in np.linspace(r0, R_FINAL, 4):
        for k in range(2):
            contact.set_pose(k, radii=(A, R, R))
        contact.solve_step(load_factor)
    return model, contact


def _positions(contact):
    n = contact.n
    return contact.X + contact.model.u.x.array[: 3 * n].reshape(-1, 3)


def _gaps(contact):
    """Signed gap of every owned node to every ellipsoid, computed here, (n, nb) [m]."""
    x = _positions(contact)
    if len(x) == 0:
        return np.zeros((0, len(contact.bodies)))
    return np.stack([closest_point_ellipsoid(x, c, Q, r).gap for c, Q, r in contact.bodies], axis=1)


def _support_sum(contact):
    """Sum over all ranks of the support reactions on the displacement rows, (3,) [N]."""
    rows, vals = contact.reactions()
    out = np.zeros(3)
    u = rows < 3 * contact.n
    np.add.at(out, rows[u] % 3, vals[u])
    return COMM.allreduce(out, op=MPI.SUM)


def _reference_area(model):
    """Reference area of the discrete surface with the model's full quadrature (degree 4,
    the measure the gravity load is integrated with), summed over ranks."""
    dx = ufl.dx(domain=model.mesh, metadata={"quadrature_degree": 4})
    one = fem.Constant(model.mesh, 1.0)
    return COMM.allreduce(fem.assemble_scalar(fem.form(one * dx)), op=MPI.SUM)


# ----------------------------------------------------------------------------- 1. crease
def test_sleeve_in_crease_of_two_ellipsoids_one_pair_per_node_and_weight_balance():
    """Sleeve stretched over the waist of two overlapping ellipsoids, under its own weight.

    Exact expectations:
    * one constraint per node (union rule): at most one active (node, ellipsoid) pair;
    * outside the union = outside every ellipsoid: no node penetrates either ellipsoid by
      more than the gap tolerance (gaps computed here with closest_point_ellipsoid);
    * an active pair is on the ellipsoid whose surface the node lies on: its gap is 0 to the
      Newton tolerance (1e-3 x gap tolerance), and the node lies on the ellipsoid's side of
      the crease plane (for x < XC the union's surface is ellipsoid 0, for x > XC ellipsoid 1);
    * Kuhn-Tucker: multipliers >= 0 to round-off;
    * both ellipsoids carry the sleeve (the crease is exercised): the rings on either side
      of the crease plane touch, each on its own ellipsoid; the crease ring itself bridges
      the V (bending stiffness keeps it ~0.3 mm above the crease circle), so it is not
      required to touch;
    * global equilibrium of the fabric (internal forces sum to zero): force on the bodies =
      weight + support reactions, with weight = rho t g times the discrete reference area;
      the single support lies on the mirror plane y = 0 and its reaction is zero by
      symmetry, so the bodies carry the full weight.
    """
    rho, g = 500.0, 9.81
    model, contact = _sleeve_on_crease([Gravity((0.0, 0.0, -g))], rho=rho, load_factor=1.0)
    tol = contact.gap_tol
    act, lam = contact._act, contact._lam

    # one pair per node, on every rank
    assert _all(np.all(act.sum(axis=1) <= 1))

    # no penetration of any ellipsoid
    gaps = _gaps(contact)
    assert _allmin(gaps) >= -tol

    # active pairs: on the surface of their ellipsoid, on its side of the crease plane
    nodes, body = np.nonzero(act)
    assert _allmax(np.abs(gaps[nodes, body])) <= 1e-3 * tol
    x = _positions(contact)
    side = np.where(x[nodes, 0] < XC, 0, 1)
    assert _all(np.all(side == body))

    # compressive multipliers (the library drops a pair below -1e-9 max|lam|)
    lam_max = _allmax(np.abs(lam[act]))
    assert lam_max > 0.0
    assert _allmin(lam[act]) >= -1e-9 * lam_max

    # both ellipsoids used; every node outside the crease ring touches (all rings stretched)
    per_body = COMM.allreduce(act.sum(axis=0), op=MPI.SUM)
    assert per_body[0] > 0 and per_body[1] > 0
    away = np.abs(contact.X[:, 0] - XC) > 1e-9
    assert _all(np.all(contact.active[away]))

    # weight balance
    area = _reference_area(model)
    assert area == pytest.approx(2 * math.pi * RT * LT, rel=1e-3)  # the discrete tube
    weight = np.array([0.0, 0.0, -rho * T * g * area])
    res = contact.resultant()
    support = _support_sum(contact)
    assert np.linalg.norm(res - (weight + support)) <= 1e-9 * abs(weight[2])
    assert np.linalg.norm(support) <= 1e-9 * abs(weight[2])  # zero by symmetry
    assert res == pytest.approx(weight, rel=1e-9, abs=1e-9 * abs(weight[2]))


def test_node_pushed_into_crease_is_held_by_both_ellipsoids():
    """A point force F (-z) on the top node of the crease ring pushes it into the crease of
    the stretched sleeve. A node there flips between the two ellipsoids under the
    one-constraint-per-node rule: this is the situation the anti-cycling guard exists for.
    With the current active-set loop the step at lambda = 0.25 converges after the guard
    froze the node's pair, and the node ends with both of its pairs active (the frozen one
    and the one the union rule adds); that count is deliberately not asserted here.

    Once the node sits in the crease its position is fixed by the two surfaces; the rest of
    the fabric does not feel the load, so a load increment dF changes nothing but the
    contact force at that node. Exact expectations, independent of how many constraints the
    node carries:
    * the node lies on both ellipsoids (both gaps 0 within the gap tolerance);
    * no node penetrates either ellipsoid, multipliers >= 0;
    * from lambda = 0.5 to 1 the displacements and rotations do not change, and the contact
      force on that node grows by exactly (0, 0, F dlambda);
    * global equilibrium: force on the bodies = F + support reactions (zero by symmetry).
    """
    F = 1.0
    top = np.array([XC, 0.0, RT])
    model, contact = _sleeve_on_crease([PointForce(tuple(top), (0.0, 0.0, -F))])
    mine = np.flatnonzero(_at(top)(contact.X.T))
    assert COMM.allreduce(len(mine), op=MPI.SUM) == 1
    tol = contact.gap_tol

    def node_force():
        return _allsum(contact.state().force_on_fabric[mine])

    saved = {}
    for lam_load in (0.25, 0.5, 1.0):
        contact.solve_step(lam_load)
        gaps = _gaps(contact)
        assert _allmin(gaps) >= -tol
        assert _allmax(np.abs(gaps[mine])) <= tol  # in the crease: on both surfaces
        act, lam = contact._act, contact._lam
        lam_max = _allmax(np.abs(lam[act]))
        assert _allmin(lam[act]) >= -1e-9 * lam_max
        res, support = contact.resultant(), _support_sum(contact)
        applied = np.array([0.0, 0.0, -F * lam_load])
        assert np.linalg.norm(res - (applied + support)) <= 1e-8 * F
        assert np.linalg.norm(support) <= 1e-8 * F
        saved[lam_load] = (
            model.u.x.array.copy(),
            model.theta.x.array.copy(),
            node_force(),
        )
    u1, th1, f1 = saved[0.5]
    u2, th2, f2 = saved[1.0]
    assert _allmax(np.abs(u2 - u1)) <= 1e-9 * T
    assert _allmax(np.abs(th2 - th1)) <= 1e-9
    assert f2 - f1 == pytest.approx([0.0, 0.0, 0.5 * F], abs=1e-9 * F)


# ----------------------------------------------------------------------------- 2. guard
R0S, L0S, RBS = 0.05, 0.2, 0.052  # sleeve on a rigid cylinder (test_contact_lagrange)


def _sleeve_on_cylinder(release_penetration=None):
    """Frictionless sleeve stretched 4 % over a rigid cylinder: every node in contact."""
    sm = meshes.cylinder(COMM, radius=R0S, length=L0S, n_around=16, n_along=4)
    model = ShellModel(
        sm,
        material=FabricMaterial.isotropic(E=E, nu=0.3),
        thickness=T,
        supports=[
            Prescribed("shoulder", displacement=(0.0, 0.0, 0.0), components=(0,)),
            Prescribed(_at((0.0, R0S, 0.0)), displacement=(0.0, 0.0, 0.0), components=(2,)),
        ],
    )
    body = (np.array([L0S / 2, 0.0, 0.0]), np.eye(3), np.array([10.0, 0.999 * R0S, 0.999 * R0S]))
    params = LagrangeContactParameters(release_penetration=release_penetration)
    contact = LagrangeContact(model, [body], params=params)
    for r in (1.01 * R0S, 0.5 * (1.01 * R0S + RBS), RBS):
        contact.set_pose(0, radii=(10.0, r, r))
        contact.solve_step(0.0)
    return model, contact


@pytest.mark.parametrize("mode", ["pull", "pull_let_go", "weak_pull", "released"])
def test_anticycling_guard(monkeypatch, mode):
    """Control flow of the anti-cycling guard, with a simulated cycling pair.

    What is simulated: after a converged step of the sleeve on the cylinder, the same step
    is solved again (nothing changed, so the true answer is the converged state) while
    ``LagrangeContact._newton`` is wrapped: each time the pair P with the largest multiplier
    (one per rank, so that all ranks freeze together) is in the active set, the wrapper
    replaces P's returned multiplier by a tensile value. The active-set loop then releases
    P; the next Newton solve, without P's constraint, lets P's node sink into the body, so
    P is activated again: P flips in/out once per pass. After 6 flips (3 releases, 3
    re-activations) P must be kept active, so the wrapper sees P active exactly 4 times
    (passes 1, 3, 5, 7); without the guard it would keep flipping until max_active_set.

    * ``pull``: P keeps pulling with 50 % of the largest multiplier: P is let go for the
      rest of the step, its node then sinks into the cylinder by more than the default
      release_penetration (1 % of t), so the step must raise ContactDivergence and restore
      u, theta, the active pairs and the multipliers exactly (step counter unchanged).
    * ``pull_let_go``: the same with release_penetration = 1 m: the step must converge with
      P inactive and report P's node's depth (> gap tolerance) as its max_penetration.
    * ``weak_pull``: P pulls with 0.5 % (< the 1 % adhesion allowance) every time: the step
      must converge with P active, its multiplier being that small tensile value.
    * ``released``: P pulls only the first 3 times, then Newton's own multiplier is
      returned: the step must converge with P active, lam_P >= 0, at the previous
      equilibrium (the problem did not change).
    """
    model, contact = _sleeve_on_cylinder(1.0 if mode == "pull_let_go" else None)
    act0, lam0 = contact._act.copy(), contact._lam.copy()
    u0, th0 = model.u.x.array.copy(), model.theta.x.array.copy()
    steps0 = contact.step_count
    assert _all(act0.any())  # every rank has active pairs
    flat = np.where(act0, lam0, -np.inf).ravel()
    P = int(np.argmax(flat))  # flat pair index node * nb + body
    lam_P0 = flat[P]
    assert _allmin(lam_P0) > 0.0

    original = LagrangeContact._newton
    seen = []

    def cycling_newton(self, xv, pairs, lam, *args, **kwargs):
        ok, its, lam_a, fr = original(self, xv, pairs, lam, *args, **kwargs)
        where = np.flatnonzero(pairs == P)
        if where.size:
            seen.append(float(lam_a[where[0]]))
            big = float(np.max(np.abs(lam_a)))
            value = -5e-3 * big if mode == "weak_pull" else -0.5 * big
            if mode != "released" or len(seen) <= 3:
                lam_a = lam_a.copy()
                lam_a[where] = value
        return ok, its, lam_a, fr

    monkeypatch.setattr(LagrangeContact, "_newton", cycling_newton)
    lam_load = float(model.lam.value)
    if mode == "pull":
        with pytest.raises(ContactDivergence, match="released pair penetrates by"):
            contact.solve_step(lam_load)
        restored = (
            len(seen) == 4
            and np.array_equal(model.u.x.array, u0)
            and np.array_equal(model.theta.x.array, th0)
            and np.array_equal(contact._act, act0)
            and np.array_equal(contact._lam, lam0)
        )
        assert _all(restored), seen
        assert contact.step_count == steps0
        # a failed step at another load factor restores the load factor too
        monkeypatch.setattr(
            LagrangeContact, "_newton", lambda self, xv, pairs, lam, *a, **k: (False, 0, lam, None)
        )
        with pytest.raises(ContactDivergence, match="Newton failed"):
            contact.solve_step(lam_load + 0.5)
        assert float(model.lam.value) == lam_load
        return

    rec = contact.solve_step(lam_load)
    assert _all(len(seen) == 4), seen
    assert contact.step_count == steps0 + 1
    if mode == "pull_let_go":
        assert _all(not contact._act.ravel()[P])
        depth = -float(_gaps(contact).ravel()[P])
        assert _allmin(depth) > contact.gap_tol
        assert rec.max_penetration == pytest.approx(_allmax(depth), rel=1e-12)
        return
    assert _all(contact._act.ravel()[P])
    lam_P = float(contact._lam.ravel()[P])
    lam_max = _allmax(np.abs(contact._lam[contact._act]))
    if mode == "weak_pull":
        assert _all(-1e-2 * lam_max < lam_P < 0.0), lam_P
        assert rec.min_multiplier == pytest.approx(_allmin(lam_P), rel=1e-12)
    else:
        assert _all(lam_P >= 0.0 and abs(lam_P - lam_P0) <= 1e-6 * lam_P0), (lam_P, lam_P0)
        assert rec.min_multiplier >= -1e-9 * lam_max
    # the true problem did not change: the equilibrium is the one of the previous step
    assert _all(np.array_equal(contact._act, act0))
    assert _allmax(np.abs(model.u.x.array - u0)) <= 1e-6 * T
    assert _allmax(np.abs(_gaps(contact)[act0])) <= 1e-3 * contact.gap_tol


# ----------------------------------------------------------------------------- 3. friction
def _strip_model(material):
    sm = meshes.strip(COMM, length=0.1, width=0.05, nx=2, ny=1)
    return ShellModel(sm, material=material, thickness=T)


_BODY = (np.array([0.05, 0.0, -0.05]), np.eye(3), np.array([0.05, 0.05, 0.04]))


@pytest.mark.parametrize(
    "E1, E2, expected",
    [
        (7.2e9, 7.2e9, KT_MAX),  # 100 E t = 7.2e8 N/m > KT_MAX: capped
        (1.2e6, 1.2e6, 100.0 * 1.2e6 * T),  # 1.2e5 N/m < KT_MAX: 100 E t exactly
        (7.2e9, 1.2e6, 100.0 * 1.2e6 * T),  # orthotropic: the smaller modulus counts
    ],
)
def test_default_tangential_penalty_is_capped(E1, E2, expected):
    """Default k_t = min(100 min(E1, E2) t, KT_MAX), KT_MAX = 1e6 N/m."""
    assert KT_MAX == 1e6
    mat = FabricMaterial(E1=E1, E2=E2, G12=min(E1, E2) / 2.6, nu12=0.0)
    contact = LagrangeContact(_strip_model(mat), [_BODY], params=LagrangeContactParameters(mu=0.3))
    assert contact.friction is not None
    assert contact.friction.kt == expected
    assert contact.friction.mu == 0.3


@pytest.mark.parametrize("kt", [3.0e4, 5.0e7])
def test_explicit_tangential_penalty_is_used_as_given(kt):
    """An explicit tangential_penalty overrides the default, below or above KT_MAX."""
    model = _strip_model(FabricMaterial.isotropic(E=7.2e9, nu=0.3))
    params = LagrangeContactParameters(mu=0.2, tangential_penalty=kt)
    contact = LagrangeContact(model, [_BODY], params=params)
    assert contact.friction.kt == kt


def test_mu_zero_builds_no_friction_state_for_a_stiff_material():
    """mu = 0: no friction state at all, whatever the material (and k_t is not computed)."""
    model = _strip_model(FabricMaterial.isotropic(E=7.2e9, nu=0.3))
    assert LagrangeContact(model, [_BODY]).friction is None
    params = LagrangeContactParameters(mu=0.0, tangential_penalty=1e5)
    assert LagrangeContact(model, [_BODY], params=params).friction is None
