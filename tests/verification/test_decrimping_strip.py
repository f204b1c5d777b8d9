"""Decrimping fabric (clothfem.shell.DecrimpingFabric) against its closed-form stress-strain
curve: a strip in uniaxial tension and a square patch stretched in both directions.

Both states are homogeneous, which the quadratic element represents exactly, so the finite
element answer must equal the closed form at every load step up to the Newton tolerance:
the tip reaction of the strip is t b lambda1 S11(E11) with S11 = E1 E11 + (Ed1 - E1) w1
p((E11 - et1) / w1), and the edge reactions of the patch t b lambda_i S_ii(E11, E22).
"""

import dataclasses

import numpy as np
import pytest
from mpi4py import MPI

from clothfem import mesh as meshes
from clothfem.shell import DecrimpingFabric, PointPin, Prescribed, Quadrature, ShellModel
from clothfem.static import LoadStepping, solve_static

COMM = MPI.COMM_WORLD
T = 1.0e-3  # thickness [m]


def _edge_force(model, mask, comp):
    """Sum of the internal-force rows of displacement component ``comp`` over the owned
    nodes in ``mask`` (the reaction on a prescribed edge) [N]."""
    x = model.create_vector()
    model.get_state(x)
    r = x.duplicate()
    model.set_load_factor(0.0)  # no loads: the residual is the internal force
    model.residual(x, r)
    n = model.n_owned
    f = r.getArray(readonly=True)[: 3 * n].reshape(n, 3)[:, comp]
    return COMM.allreduce(float(f[mask[:n]].sum()), op=MPI.SUM)


def _stretch(green):
    return np.sqrt(1.0 + 2.0 * np.asarray(green))


@pytest.mark.parametrize("scheme", ["psri", "mitc9"])
def test_uniaxial_strip_follows_closed_form(scheme):
    """Cotton (E 1.2 -> 350 MPa, crimped below 1 MPa, de-crimped above 10 MPa) with nu12 =
    0.2: the tip force at yarn strains in the crimped range, through the transition and in
    the de-crimped range against the closed form (relative 1e-6), and the lateral strain
    -nu12 E11 of uniaxial stress.
    Both the partial selective element and MITC9 (the assumed strains of a homogeneous
    strain are exact on rectangular cells)."""
    mat = dataclasses.replace(DecrimpingFabric.cotton(), nu12=0.2)
    L, b = 1.0, 0.2
    et, w = mat.transition1, mat.width1
    strains = np.array([0.4, et - 0.5 * w, et, et + 0.5 * w, et + 1.5 * w, 1.0])
    e_max = strains[-1]
    d_max = (_stretch(e_max) - 1.0) * L
    targets = (_stretch(strains) - 1.0) * L / d_max  # lam at which E11 = strains
    sm = meshes.strip(COMM, length=L, width=b, nx=2, ny=1)
    model = ShellModel(
        sm,
        material=mat,
        thickness=T,
        quadrature=Quadrature(scheme=scheme),
        supports=[
            Prescribed("root", displacement=(0.0, 0.0, 0.0), components=(0, 2)),
            Prescribed("tip", displacement=(d_max, 0.0, 0.0), components=(0, 2)),
            PointPin(point=(0.0, 0.0, 0.0), components=(1,)),
        ],
    )
    tip = np.isclose(model.x_nodes[:, 0], L)
    corner = np.array([L, 0.5 * b, 0.0])
    got, want, lateral = [], [], []

    def on_step(rec):
        lam = rec.load_factor
        if not np.any(np.isclose(lam, targets, rtol=0, atol=1e-12)):
            return
        e11 = 0.5 * ((1.0 + lam * d_max / L) ** 2 - 1.0)
        got.append(_edge_force(model, tip, 0))
        want.append(T * b * _stretch(e11) * mat.uniaxial_stress(e11))
        uy = model.displacement_at(corner)[1]
        lateral.append((0.5 * ((1.0 + uy / (0.5 * b)) ** 2 - 1.0), -mat.nu12 * e11))

    solve_static(
        model,
        stepping=LoadStepping(initial_increment=0.05, max_increment=0.1),
        targets=targets,
        on_step=on_step,
    )
    assert len(got) == len(targets)
    np.testing.assert_allclose(got, want, rtol=1e-6)
    lat = np.array(lateral)
    np.testing.assert_allclose(lat[:, 0], lat[:, 1], rtol=1e-6)
    # the curve spans both limits: secant ~ E_c at first, tangent E_d at the end
    assert want[0] / (T * b * _stretch(0.4) * 0.4) == pytest.approx(mat.E1, rel=1e-9)


@pytest.mark.parametrize("scheme", ["psri", "mitc9"])
def test_biaxial_patch_follows_closed_form(scheme):
    """An orthotropic law (different moduli and transitions in warp and weft, nu12 = 0.3) on
    a square patch with both yarn strains prescribed (E11 to 0.2, E22 to 0.25): the warp and
    weft edge forces at several steps against the closed form S(E11, E22) (relative 1e-6),
    crossing the warp transition (0.07..0.13) and the weft one (0.1..0.2).
    Both the partial selective element and MITC9 (the assumed strains of a homogeneous
    strain are exact on rectangular cells)."""
    mat = DecrimpingFabric(
        E1=1.2e6,
        E2=0.8e6,
        G12=1.0e5,
        nu12=0.3,
        E1_decrimped=350e6,
        E2_decrimped=200e6,
        transition1=0.1,
        transition2=0.15,
        width1=0.03,
        width2=0.05,
    )
    a = 0.5
    e_end = np.array([0.2, 0.25])
    stretch = _stretch(e_end)

    def ux(X, lam):
        out = np.zeros((len(X), 3))
        out[:, 0] = lam * (stretch[0] - 1.0) * X[:, 0]
        return out

    def uy(X, lam):
        out = np.zeros((len(X), 3))
        out[:, 1] = lam * (stretch[1] - 1.0) * X[:, 1]
        return out

    sm = meshes.strip(COMM, length=a, width=a, nx=2, ny=2)
    model = ShellModel(
        sm,
        material=mat,
        thickness=T,
        quadrature=Quadrature(scheme=scheme),
        supports=[
            Prescribed("root", displacement=ux, components=(0, 2)),
            Prescribed("tip", displacement=ux, components=(0, 2)),
            Prescribed("sides", displacement=uy, components=(1, 2)),
        ],
    )
    X = model.x_nodes
    tip, top = np.isclose(X[:, 0], a), np.isclose(X[:, 1], 0.5 * a)
    targets = np.array([0.25, 0.45, 0.55, 0.65, 0.8, 1.0])
    rows = []

    def on_step(rec):
        lam = rec.load_factor
        if not np.any(np.isclose(lam, targets, rtol=0, atol=1e-12)):
            return
        lam_i = 1.0 + lam * (stretch - 1.0)
        e11, e22 = 0.5 * (lam_i**2 - 1.0)
        s11, s22, _ = mat.stress(e11, e22)
        # corner nodes belong to both edges: each edge's sum has the corner's full force
        # in its own direction (the other edge's prescribed component is the other one)
        rows.append(
            (
                _edge_force(model, tip, 0),
                _edge_force(model, top, 1),
                T * a * lam_i[0] * s11,
                T * a * lam_i[1] * s22,
            )
        )

    solve_static(
        model,
        stepping=LoadStepping(initial_increment=0.05, max_increment=0.1),
        targets=targets,
        on_step=on_step,
    )
    r = np.array(rows)
    assert len(r) == len(targets)
    np.testing.assert_allclose(r[:, 0], r[:, 2], rtol=1e-6)
    np.testing.assert_allclose(r[:, 1], r[:, 3], rtol=1e-6)
