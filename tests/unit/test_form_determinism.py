"""A model's compiled forms do not depend on what the process built before it.

UFL 2022.2 puts the two factors of a product of two ``fem.Constant``s in the order of their
``repr`` strings, which end in a global counter compared as digits ("10" sorts before "9").
A product of three Constants then compiles to another kernel, with other rounding, when the
counter crosses a power of ten between its factors. The model writes every such product
with one Constant per factor pair (e.g. ``lam * (rho * (t * g . u))``), so the ordering is
by expression type only.
"""

from pathlib import Path

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc

from clothfem import scene as scenes
from clothfem.run import build_model
from clothfem.shell import inertia

CI = Path(__file__).resolve().parents[2] / "demos" / "scenes" / "arm_sleeve_ci.toml"
SETS = ["solver.integrator=explicit", "solver.rotary_scale=1000"]
UNSET = ["solver.steps", "contact.increments"]


def _forces_and_rotary_mass(scene) -> tuple[object, np.ndarray, np.ndarray]:
    """Build the scene's model; its external force at load factor 1 and the diagonal of
    its scaled rotary mass."""
    model, _ = build_model(scene)
    x, r, fe = model.create_vector(), model.create_vector(), model.create_vector()
    model.get_state(x)
    model.set_load_factor(1.0)
    model.forces(x, r, fe)
    scale = fem.Constant(model.mesh, 1000.0)
    form = fem.form(inertia.rotary_mass(model.V, model.rho, model.t, model.dx_full, scale))
    M = fem_petsc.assemble_matrix(form)
    M.assemble()
    return model, fe.getArray().copy(), M.getDiagonal().getArray().copy()


def _advance_counter_to(domain, count: int) -> None:
    """Create Constants until the next one made gets the global number ``count``."""
    probe = ufl.Constant(domain)
    for _ in range(count - probe.count() - 1):
        ufl.Constant(domain)


def test_kernels_do_not_depend_on_the_constants_made_before():
    """The CI arm scene built twice: once with its load factor, thickness and density
    numbered on one side of a power of ten, once across it. The external (gravity) force
    and the rotary mass are the same bits. With the dead load written as one chain of
    Constants (lam * rho * t * g . u) the build across the boundary gives a gravity force
    8.7e-18 N off, and this test fails."""
    scene = scenes.load(CI, SETS, unset=UNSET)
    first, f_ref, m_ref = _forces_and_rotary_mass(scene)
    domain = first.mesh.ufl_domain()
    nxt = ufl.Constant(domain).count() + 1
    power = 10 ** len(str(nxt + 2))
    _advance_counter_to(domain, power - 2)  # lam below the power, rho and t above it
    model, f, m = _forces_and_rotary_mass(scene)
    digits = [len(str(c.count())) for c in (model.lam, model.t, model.rho)]
    assert digits[0] < digits[2], digits  # the crossing this test is about
    assert np.any(f != 0.0) and np.any(m != 0.0)
    assert np.array_equal(f, f_ref)
    assert np.array_equal(m, m_ref)
