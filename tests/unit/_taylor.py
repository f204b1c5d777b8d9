"""Taylor checks shared by the shell-model tests: random states, observed orders, and the
remainders of the energy (R = dPi/dx) and of the Jacobian (K = dR/dx) along a direction."""

import math
from collections.abc import Callable, Sequence

import numpy as np
from mpi4py import MPI


def random_state(model, scale: float, seed: int):
    """A vector of the model's (u, theta) system with N(0, scale^2) entries (rank-seeded)."""
    rng = np.random.default_rng(seed + MPI.COMM_WORLD.rank)
    x = model.create_vector()
    x.setArray(rng.normal(size=x.getLocalSize()) * scale)
    return x


def orders(errors: Sequence[float]) -> list[float]:
    """Observed orders log2(e_k / e_k+1) of errors at halving steps."""
    return [math.log2(errors[i] / errors[i + 1]) for i in range(len(errors) - 1)]


def energy_orders(model, x, dx, steps: Sequence[float], energy: Callable[[], float]):
    """Orders of |Pi(x + h dx) - Pi(x) - h R(x) . dx| over the halving steps h, Pi =
    ``energy()`` evaluated after ``model.set_state``."""

    def at(v):
        model.set_state(v)
        return energy()

    f = x.duplicate()
    model.residual(x, f)
    slope, e0 = f.dot(dx), at(x)
    errs = []
    for h in steps:
        xh = x.copy()
        xh.axpy(h, dx)
        errs.append(abs(at(xh) - e0 - h * slope))
    return orders(errs)


def jacobian_orders(model, x, dx, steps: Sequence[float]) -> list[float]:
    """Orders of |R(x + h dx) - R(x) - h K(x) dx| over the halving steps h."""
    f0 = x.duplicate()
    model.residual(x, f0)
    Kdx = x.duplicate()
    model.jacobian(x).mult(dx, Kdx)
    errs = []
    for h in steps:
        xh = x.copy()
        xh.axpy(h, dx)
        fh = x.duplicate()
        model.residual(xh, fh)
        errs.append((fh - f0 - h * Kdx).norm())
    return orders(errs)
