"""Shell verification against exact solutions and published benchmarks (issue 2)."""

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
    """Quadratic elements: L2 displacement error O(h^3) against this model's exact arc."""
    errs = [V.run_arc_bending(nx=n).value for n in (4, 8, 16)]
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
