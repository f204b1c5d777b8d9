"""Shell verification against exact solutions and published benchmarks."""

import math

import pytest

from clothfem import verification as V


def test_rollup_closes_the_circle():
    """End moment M = 2 pi EI / L rolls the strip into a full circle: tip back at the root."""
    res, _ = V.run_rollup(nx=20, ny=2, steps=10)
    assert res.error < 0.005  # of L


def test_elastica_reference_matches_published_values():
    """Independent shooting solution vs Mattiasson (1981) at PL^2/EI = 4."""
    u, w = V.elastica_tip(4.0)
    assert abs(u - 0.32894) < 1e-5 and abs(w - 0.66996) < 1e-5


@pytest.mark.parametrize("k", [1.0, 2.0, 4.0])
def test_elastica(k):
    for res in V.run_elastica(k=k, nx=20, ny=2):
        assert res.error < 0.005, res


def test_scordelis_lo_roof():
    """Membrane-bending coupled cylindrical roof, reference 0.3024 (Belytschko et al. 1985)."""
    res = V.run_scordelis_lo(n=16)
    assert res.error < 0.01, res


def test_mesh_convergence_rate_is_cubic_in_L2():
    """Quadratic elements: L2 displacement error O(h^3) against this model's exact arc
    (from 8 cells on: the PSRI weight t^2/h^2 changes with h, and at 4 cells of L/t = 25
    the fully integrated part still stiffens the arc, rate 2.5 from 4 to 8)."""
    errs = [V.run_arc_bending(nx=n).value for n in (8, 16, 32)]
    rates = [math.log2(errs[i] / errs[i + 1]) for i in range(2)]
    assert min(rates) > 2.8, (errs, rates)


def test_scordelis_lo_half_model_with_symmetry_support():
    """The same roof cut at midspan with a Symmetry support gives the full model's answer."""
    half = V.run_scordelis_lo(n=16, half=True)
    full = V.run_scordelis_lo(n=16)
    assert half.error < 0.01, half
    assert abs(half.value - full.value) < 1e-6 * full.value


def test_prescribed_rotation_bends_a_free_tip_into_an_arc():
    """Rotating the tip director by 90 degrees (tip otherwise free) bends the strip into a
    quarter circle: tip at (R, R) from the root with R = 2L/pi (Euler-Bernoulli; this
    model's stretch coupling is ~(t/R)^2/12 ~ 2e-4)."""
    from mpi4py import MPI

    from clothfem.shell import Prescribed
    from clothfem.static import LoadStepping, solve_static

    L = V.STRIP["length"]
    model = V._strip_model(
        MPI.COMM_WORLD,
        16,
        1,
        [],
        supports=[V.Clamp("root"), Prescribed("tip", rotation=(0.0, -0.5 * math.pi, 0.0))],
    )
    solve_static(model, stepping=LoadStepping(initial_increment=0.25))
    R = 2 * L / math.pi
    tip = model.displacement_at((L, 0.0, 0.0)) + (L, 0.0, 0.0)
    assert math.isclose(tip[0], R, rel_tol=1e-3) and math.isclose(tip[2], R, rel_tol=1e-3)


def _errors(points):
    return [p.result.error for p in points]


def test_rollup_curve_against_the_exact_arc():
    """Sze 3.2: tip deflection under the end moment at 1/4, 1/2, 3/4 and all of 2 pi EI/L
    against this model's exact arc (the published inextensible circle less the second-order
    membrane strain -t^2 k^2 / 12, within 0.25 % of it); the error shrinks from 10 to 20 to
    40 cells at every load, below 5e-4 on 40 (measured 2026-12-02: at 3/4 of the moment
    2.4e-2, 2.4e-3, 1.7e-4: the weight of the partial selective rule stiffens coarse
    bending)."""
    w_model, w_circle = V.rollup_tip_model(0.75)[1], V.rollup_tip(0.75)[1]
    assert abs(w_model / w_circle - 1) < 2.5e-3
    curves = [_errors(V.run_rollup_curve(nx=n)) for n in (10, 20, 40)]
    assert max(curves[-1]) < 5e-4, curves
    for coarse, fine in zip(curves, curves[1:], strict=False):
        assert all(f < c for f, c in zip(fine, coarse, strict=True)), curves


def test_elastica_curve_against_the_shooting_solution():
    """Sze 3.1: tip deflection under a dead end shear at PL^2/EI = 1, 2, 4 against the
    exact elastica; the error shrinks from 10 to 20 cells, below 1e-4 on 20."""
    coarse, fine = (V.run_elastica_curve(nx=n) for n in (10, 20))
    assert max(_errors(fine)) < 1e-4, fine
    assert all(f < c for f, c in zip(_errors(fine), _errors(coarse), strict=True))


def test_pinched_semicylinder_against_sze():
    """Sze 3.7 at P/Pmax = 0.1, 0.25, 0.5, 0.75, 1 against the published curve (ABAQUS S4R
    40 x 40). The plain selective rule drifted away with refinement (+1.0 % at 16x16, +3.6 %
    at 32x32 at P = 2000); the default element converges: within 0.3 % at P = 2000 on
    12x12 and 16x16, within 1.7 % everywhere (the published curve's steep part near 0.25
    Pmax is where the finer meshes of docs/results/verification.md settle at +1.5 %)."""
    for n in (12, 16):
        pts = V.run_semicylinder(n=n)
        assert pts[-1].result.error < 3e-3, pts[-1]
        assert max(_errors(pts)) < 0.017, pts


def test_pinched_cylinder_with_diaphragms():
    """MacNeal & Harder: 1.8248e-5 (thin-shell theory). Within 1.3 % on 8x8 and 16x16 (a
    shear-deformable shell under a point load differs from thin-shell theory by a term that
    grows like log(1/h): +0.35 % on 8x8, +1.24 % on 16x16)."""
    for n in (8, 16):
        res = V.run_pinched_cylinder(n=n)
        assert res.error < 0.013, res


def test_hemisphere_with_a_hole():
    """MacNeal & Harder's hemisphere (Sze 3.4 in its linear range): u_x = 0.094 at the
    loads, a value given to two digits (+-0.5 %). 8x8 and 16x16 quarter models are within
    0.5 % of it and within 0.1 % of each other (converged)."""
    coarse, fine = (V.run_hemisphere(n=n) for n in (8, 16))
    assert coarse.error < 5e-3 and fine.error < 5e-3, (coarse, fine)
    assert abs(fine.value - coarse.value) < 1e-3 * fine.value


@pytest.mark.parametrize("slenderness", [100.0, 1000.0, 10000.0])
def test_clamped_plate_does_not_lock(slenderness):
    """Clamped square plate under pressure, t/a from 1/100 to 1/10000: the centre
    deflection stays within 0.2 % of Kirchhoff's 0.00126532 q a^4/D on 8x8 and 16x16 (a
    locking element would fall towards 0 as t/a shrinks)."""
    for n in (8, 16):
        res = V.run_clamped_plate(n=n, slenderness=slenderness)
        assert res.error < 2e-3, res


# ---------------------------------------------------------------- the MITC9 element
MITC9 = V.Quadrature(scheme="mitc9")


def test_mitc9_linear_benchmarks_converge_to_the_published_values():
    """MITC9 (assumed membrane and shear strains) on the linear benchmarks, at 8x8 and
    16x16: Scordelis-Lo (0.3024) and the hemisphere (0.094, two digits) within 1.1 % and
    closer on the finer mesh (measured 2026-12-02: -0.77 / -0.50 % and -1.08 / -0.56 %;
    both approach from below, as MITC elements do); the pinched cylinder's log(1/h) point
    load term as for the default element (+0.30 / +0.92 %)."""
    for run, tol in ((V.run_scordelis_lo, 0.011), (V.run_hemisphere, 0.011)):
        coarse, fine = (run(n=n, quadrature=MITC9) for n in (8, 16))
        assert coarse.error < tol and fine.error < 0.01, (coarse, fine)
        assert fine.error < coarse.error, (coarse, fine)
    for n in (8, 16):
        assert V.run_pinched_cylinder(n=n, quadrature=MITC9).error < 0.013


@pytest.mark.parametrize("slenderness", [100.0, 1000.0, 10000.0])
def test_mitc9_clamped_plate_does_not_lock(slenderness):
    """The clamped plate from t/a = 1/100 to 1/10000 with MITC9 on 8x8 and 16x16: within
    0.2 % of Kirchhoff's deflection for the thin plates; at t/a = 1/100 the shear
    flexibility of a Reissner-Mindlin plate adds about 0.25 % (the selective rule, which
    does not lock, gives +0.25 / +0.20 % there, MITC9 +0.24 %), so 0.3 %."""
    tol = 3e-3 if slenderness == 100.0 else 2e-3
    for n in (8, 16):
        res = V.run_clamped_plate(n=n, slenderness=slenderness, quadrature=MITC9)
        assert res.error < tol, res


def test_mitc9_bending_converges_at_the_cubic_rate():
    """The arc under an end moment (this model's exact arc), L2 error of u at 4, 8, 16
    cells: rate 3 of quadratic elements from the coarsest mesh on (no PSRI weight adds
    parasitic energy: measured 2026-12-02 8.5e-5 at 8 cells, 9.4x below PSRI's 8.0e-4)."""
    errs = [V.run_arc_bending(nx=n, quadrature=MITC9).value for n in (4, 8, 16)]
    rates = [math.log2(errs[i] / errs[i + 1]) for i in range(2)]
    assert min(rates) > 2.8, (errs, rates)


def test_mitc9_nonlinear_curves():
    """Sze 3.1 and 3.2 (elastica and roll-up, exact) and the pinched semi-cylinder (Sze
    3.7, P/Pmax = 0.1 .. 1, 12x12) with MITC9. The elastica within 1e-4 on 20 cells; the
    roll-up against this model's exact arc within 3e-4 on 20 cells, and at 3/4 of the
    moment (the largest error) converging at rate 4 from 20 to 40 cells (measured
    2026-12-02: 2.6e-4, 1.65e-5). The semi-cylinder within 1.2 % (0.16 % at P = 2000;
    measured 2026-12-02: +1.06, +0.63, +0.02, +1.07, +0.16 %)."""
    assert max(_errors(V.run_elastica_curve(nx=20, quadrature=MITC9))) < 1e-4
    fine, finer = (_errors(V.run_rollup_curve(nx=n, quadrature=MITC9)) for n in (20, 40))
    assert max(fine) < 3e-4, fine
    assert math.log2(fine[2] / finer[2]) > 3.5, (fine, finer)
    pts = V.run_semicylinder(n=12, quadrature=MITC9)
    assert pts[-1].result.error < 3e-3 and max(_errors(pts)) < 0.012, pts
