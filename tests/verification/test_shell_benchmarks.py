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
