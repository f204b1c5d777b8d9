"""Verification problems with exact or published answers (used by tests and the table of
docs/results/verification.md).

Each ``run_*`` function builds a model, solves it and returns a :class:`Result` with the
computed quantity, the reference, the relative error and the wall time. References:

* roll-up of a cantilever under end moment M = 2 pi EI / L: the strip closes into a circle
  and the tip returns to the root (exact, Euler-Bernoulli with nu = 0);
* cantilever under a dead end shear: the exact elastica, computed here by an independent
  shooting method (:func:`elastica_tip`); at PL^2/EI = 4 it gives u/L = 0.32894,
  w/L = 0.66996 (Mattiasson 1981, Int. J. Numer. Meth. Eng. 17, 145-153);
* pure bending to a quarter circle: the exact midsurface is a circular arc (used for the
  mesh-convergence rate);
* Scordelis-Lo roof (MacNeal & Harder 1985, Finite Elem. Anal. Des. 1, 3-20): vertical
  deflection at the midside of the free edge 0.3024 (Belytschko et al. 1985, Comput. Methods
  Appl. Mech. Eng. 51, 221-258).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI

from . import mesh as meshes
from .shell import (
    Clamp,
    EdgeMoment,
    EdgeTraction,
    FabricMaterial,
    Gravity,
    PointForce,
    PointPin,
    Prescribed,
    Pressure,
    Quadrature,
    ShellModel,
    Symmetry,
)
from .static import LoadStepping, NewtonSolver, solve_static

__all__ = [
    "Result",
    "elastica_tip",
    "run_rollup",
    "run_elastica",
    "run_arc_bending",
    "arc_solution",
    "run_scordelis_lo",
    "SCORDELIS_LO_REFERENCE",
]

SCORDELIS_LO_REFERENCE = 0.3024  # Belytschko et al. (1985)

# Strip of the issue: L = 10, b = 1, t = 0.1, E = 1.2e6, nu = 0
STRIP = dict(length=10.0, width=1.0, thickness=0.1, E=1.2e6)


@dataclass(frozen=True)
class Result:
    name: str
    mesh: str
    value: float
    reference: float
    error: float  # relative
    wall_time: float  # s, build + solve (includes JIT compilation unless cached)
    newton: int  # total Newton iterations


def elastica_tip(k: float, *, n: int = 20000) -> tuple[float, float]:
    """Exact cantilever elastica under a dead tip load P normal to the undeformed axis.

    theta'' = -k cos(theta), theta(0) = 0, theta'(1) = 0 with k = P L^2 / EI, solved by
    shooting on theta'(0) (RK4, ``n`` steps, bisection). Returns (u/L, w/L): the axial
    shortening and the deflection of the tip.
    """

    def shoot(c: float):
        h = 1.0 / n
        y = np.array([0.0, c, 0.0, 0.0])  # theta, theta', x, w

        def f(y):
            return np.array([y[1], -k * math.cos(y[0]), math.cos(y[0]), math.sin(y[0])])

        for _ in range(n):
            k1 = f(y)
            k2 = f(y + 0.5 * h * k1)
            k3 = f(y + 0.5 * h * k2)
            k4 = f(y + h * k3)
            y = y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        return y

    lo, hi = 0.0, k  # theta'(1) > 0 at c = k, < 0 at c = 0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if shoot(mid)[1] > 0:
            hi = mid
        else:
            lo = mid
    y = shoot(0.5 * (lo + hi))
    return 1.0 - y[2], y[3]


def arc_solution(*, moment: float, EI: float, thickness: float) -> tuple[float, float]:
    """Exact pure-bending solution of this shell model (nu = 0): a circular arc.

    The SVK bending strain a . d' includes the midsurface stretch s, so stationarity of
    EA eps^2/2 + EI (s k)^2/2 - M k L gives EI s^2 k = M and eps = (s^2 - 1)/2 = -t^2 k^2/12
    (a second-order membrane strain absent from Euler-Bernoulli theory, relative size
    (t k)^2/12). Returns (k, s): the rotation per unit reference length [1/m] and the stretch.
    """
    s = 1.0
    for _ in range(100):
        k = moment / (EI * s * s)
        s_new = math.sqrt(1.0 - thickness**2 * k**2 / 6.0)
        if abs(s_new - s) < 1e-16:
            break
        s = s_new
    return moment / (EI * s * s), s


def _strip_model(comm, nx, ny, loads, supports=None, quadrature=None):
    s = STRIP
    sm = meshes.strip(comm, length=s["length"], width=s["width"], nx=nx, ny=ny)
    mat = FabricMaterial.isotropic(E=s["E"], nu=0.0)
    return ShellModel(
        sm,
        material=mat,
        thickness=s["thickness"],
        loads=loads,
        supports=supports or [Clamp("root")],
        quadrature=quadrature or Quadrature(),
    )


def _EI() -> float:
    s = STRIP
    return s["E"] * s["width"] * s["thickness"] ** 3 / 12


def run_rollup(
    *,
    nx: int = 20,
    ny: int = 2,
    steps: int = 10,
    comm: MPI.Comm = MPI.COMM_WORLD,
    quadrature: Quadrature | None = None,
) -> tuple[Result, ShellModel]:
    """End moment 2 pi EI / L: |tip position - root| / L (exact 0)."""
    t0 = time.perf_counter()
    L, b = STRIP["length"], STRIP["width"]
    m = 2 * math.pi * _EI() / L / b
    model = _strip_model(comm, nx, ny, [EdgeMoment("tip", (0.0, -m, 0.0))], quadrature=quadrature)
    inc = 1.0 / steps
    recs = solve_static(model, stepping=LoadStepping(initial_increment=inc, max_increment=inc))
    tip = np.array([L, 0.0, 0.0]) + model.displacement_at((L, 0.0, 0.0))
    err = float(np.linalg.norm(tip)) / L
    res = Result(
        "roll-up (tip to root)/L",
        f"{nx}x{ny}",
        err,
        0.0,
        err,
        time.perf_counter() - t0,
        sum(r.newton_iterations for r in recs),
    )
    return res, model


def run_elastica(
    *,
    k: float,
    nx: int = 20,
    ny: int = 2,
    comm: MPI.Comm = MPI.COMM_WORLD,
    quadrature: Quadrature | None = None,
) -> tuple[Result, Result]:
    """Dead end shear P = k EI / L^2: (u/L, w/L) against :func:`elastica_tip`."""
    t0 = time.perf_counter()
    L, b = STRIP["length"], STRIP["width"]
    P = k * _EI() / L**2
    model = _strip_model(
        comm, nx, ny, [EdgeTraction("tip", (0.0, 0.0, P / b))], quadrature=quadrature
    )
    recs = solve_static(model, stepping=LoadStepping(initial_increment=0.25, max_increment=0.5))
    tip = model.displacement_at((L, 0.0, 0.0))
    wall = time.perf_counter() - t0
    its = sum(r.newton_iterations for r in recs)
    u_ex, w_ex = elastica_tip(k)
    u, w = -tip[0] / L, tip[2] / L
    mesh = f"{nx}x{ny}"
    return (
        Result(f"elastica PL2/EI={k:g} u/L", mesh, u, u_ex, abs(u - u_ex) / u_ex, wall, its),
        Result(f"elastica PL2/EI={k:g} w/L", mesh, w, w_ex, abs(w - w_ex) / w_ex, wall, its),
    )


def run_arc_bending(
    *,
    nx: int,
    ny: int = 1,
    angle: float = 0.5 * math.pi,
    comm: MPI.Comm = MPI.COMM_WORLD,
    quadrature: Quadrature | None = None,
) -> Result:
    """End moment bending the strip to a circular arc of opening ``angle``; returns the
    relative L2 error of the displacement field against the exact arc."""
    t0 = time.perf_counter()
    L, b = STRIP["length"], STRIP["width"]
    m = angle * _EI() / L / b
    model = _strip_model(comm, nx, ny, [EdgeMoment("tip", (0.0, -m, 0.0))], quadrature=quadrature)
    recs = solve_static(model, stepping=LoadStepping(initial_increment=0.5, max_increment=0.5))
    k, stretch = arc_solution(moment=m * b, EI=_EI(), thickness=STRIP["thickness"])
    r = stretch / k
    X = ufl.SpatialCoordinate(model.mesh)
    u_ex = ufl.as_vector([r * ufl.sin(k * X[0]) - X[0], 0.0, r * (1 - ufl.cos(k * X[0]))])
    dx = ufl.dx(metadata={"quadrature_degree": 8})
    e2 = fem.form(ufl.dot(model.u - u_ex, model.u - u_ex) * dx)
    n2 = fem.form(ufl.dot(u_ex, u_ex) * dx)
    err2 = comm.allreduce(fem.assemble_scalar(e2), op=MPI.SUM)
    ref2 = comm.allreduce(fem.assemble_scalar(n2), op=MPI.SUM)
    err = math.sqrt(err2 / ref2)
    return Result(
        "arc bending L2(u)",
        f"{nx}x{ny}",
        err,
        0.0,
        err,
        time.perf_counter() - t0,
        sum(r.newton_iterations for r in recs),
    )


def run_scordelis_lo(
    *,
    n: int,
    half: bool = False,
    comm: MPI.Comm = MPI.COMM_WORLD,
    quadrature: Quadrature | None = None,
) -> Result:
    """Scordelis-Lo roof, full model with ``n`` x ``n`` cells: R = 25, L = 50, 80 degree
    arc, t = 0.25, E = 4.32e8, nu = 0, self weight 90 per unit area, rigid diaphragms at
    the ends (u_y = u_z = 0), free straight edges. Solved at a load factor of 1e-3 and
    scaled back (the reference is linear). ``half``: the half x <= L/2 with a symmetry
    support at midspan and n x n/2 cells (the same cell size)."""
    t0 = time.perf_counter()
    R, L, t = 25.0, 50.0, 0.25
    sm = meshes.cylinder_panel(
        comm,
        radius=R,
        length=L / 2 if half else L,
        angle=math.radians(40),
        n_around=n,
        n_along=n // 2 if half else n,
    )
    mat = FabricMaterial.isotropic(E=4.32e8, nu=0.0)
    mat = FabricMaterial(E1=mat.E1, E2=mat.E2, G12=mat.G12, rho=90.0 / t)

    def crest_midspan(x):  # gmsh places arc nodes to ~1e-9 R
        return np.linalg.norm(x.T - np.array([L / 2, 0.0, R]), axis=1) < 1e-6 * R

    diaphragm = dict(displacement=(0.0, 0.0, 0.0), components=(1, 2))
    if half:
        supports = [Prescribed("start", **diaphragm), Symmetry("end", axis=0)]
    else:
        supports = [
            Prescribed("start", **diaphragm),
            Prescribed("end", **diaphragm),
            Prescribed(crest_midspan, displacement=(0.0, 0.0, 0.0), components=(0,)),
        ]
    model = ShellModel(
        sm,
        material=mat,
        thickness=t,
        loads=[Gravity((0.0, 0.0, -1.0))],
        supports=supports,
        quadrature=quadrature or Quadrature(),
    )
    lam = 1e-3
    solver = NewtonSolver(model)
    ok, its, _, _ = solver.solve(lam)
    if not ok:
        raise RuntimeError("Scordelis-Lo: Newton did not converge")
    edge = (L / 2, R * math.sin(math.radians(40)), R * math.cos(math.radians(40)))
    w = -model.displacement_at(edge)[2] / lam
    ref = SCORDELIS_LO_REFERENCE
    return Result(
        "Scordelis-Lo w(midside free edge)" + (" half+symmetry" if half else ""),
        f"{n}x{n // 2}" if half else f"{n}x{n}",
        w,
        ref,
        abs(w - ref) / ref,
        time.perf_counter() - t0,
        its,
    )


# ---------------------------------------------------------------- load-deflection curves
# Sze, Liu & Lo (2004), Finite Elem. Anal. Des. 40:1551-1569, problem 3.7 (pinched
# semi-cylinder), their reference curve (ABAQUS S4R, 40 x 40): P / Pmax -> -w at the load.
SEMICYLINDER_REFERENCE = {
    0.1: 0.16100,
    0.25: 0.48537,
    0.5: 1.32653,
    0.75: 1.56584,
    1.0: 1.71505,
}
# MacNeal & Harder (1985), Finite Elem. Anal. Des. 1:3-20: pinched cylinder with end
# diaphragms, radial displacement under a unit load (linear).
PINCHED_CYLINDER_REFERENCE = 1.8248e-5


@dataclass(frozen=True)
class CurvePoint:
    """One point of a load-deflection curve: the load fraction and the Result there."""

    fraction: float
    result: Result


def _curve(model, *, fractions, measure, reference, name, mesh, stepping, t0, absolute_below=0.0):
    """Solve through ``fractions`` of the load; ``measure(model)`` at each against
    ``reference(fraction)``. Relative errors, absolute where |reference| <= ``absolute_below``
    (0: only where the reference is 0)."""
    values: dict[float, float] = {}
    fr = np.asarray(sorted(fractions), dtype=float)

    def on_step(rec):
        hit = fr[np.isclose(fr, rec.load_factor, rtol=0, atol=1e-12)]
        if hit.size:
            values[float(hit[0])] = measure(model)

    recs = solve_static(model, stepping=stepping, targets=fr, on_step=on_step)
    wall, its = time.perf_counter() - t0, sum(r.newton_iterations for r in recs)
    out = []
    for f in fr:
        ref, val = reference(float(f)), values[float(f)]
        err = abs(val - ref) / abs(ref) if abs(ref) > absolute_below else abs(val - ref)
        out.append(CurvePoint(float(f), Result(name, mesh, val, ref, err, wall, its)))
    return out


def rollup_tip(fraction: float) -> tuple[float, float]:
    """Tip of the inextensible strip (Euler-Bernoulli, the published reference) under the end
    moment ``fraction`` x 2 pi EI / L: a circular arc of opening theta = 2 pi fraction; (u/L,
    w/L), u the axial, w the transverse displacement of the tip (Sze et al. 2004, problem
    3.2)."""
    th = 2 * math.pi * fraction
    return math.sin(th) / th - 1.0, (1.0 - math.cos(th)) / th


def rollup_tip_model(fraction: float) -> tuple[float, float]:
    """Tip of this shell model's exact arc (:func:`arc_solution`) under the end moment
    ``fraction`` x 2 pi EI / L on :data:`STRIP`: (u/L, w/L). The second-order membrane
    strain -t^2 k^2 / 12 shortens the arc and turns it further than the inextensible circle of
    :func:`rollup_tip`: on the strip (t / L = 1/100) w/L is 0.211718 against 0.212207 at 3/4
    of the moment (-0.23 %), and the closing tip stays 1.4e-6 L from the root."""
    L, t = STRIP["length"], STRIP["thickness"]
    moment = fraction * 2 * math.pi * _EI() / L
    k, stretch = arc_solution(moment=moment, EI=_EI(), thickness=t)
    r = stretch / k  # radius of the deformed arc [m]
    return (r * math.sin(k * L) - L) / L, r * (1 - math.cos(k * L)) / L


def run_rollup_curve(
    *,
    nx: int,
    ny: int = 1,
    fractions=(0.25, 0.5, 0.75, 1.0),
    comm: MPI.Comm = MPI.COMM_WORLD,
    quadrature: Quadrature | None = None,
) -> list[CurvePoint]:
    """Roll-up under the end moment (Sze 3.2): the tip's transverse deflection w/L at several
    load fractions against this model's exact arc (:func:`rollup_tip_model`, within 0.23 %
    of the published inextensible circle); relative errors, absolute (in units of L) at the
    closing point where the exact w is 1.4e-6 L."""
    t0 = time.perf_counter()
    L, b = STRIP["length"], STRIP["width"]
    m = 2 * math.pi * _EI() / L / b
    model = _strip_model(comm, nx, ny, [EdgeMoment("tip", (0.0, -m, 0.0))], quadrature=quadrature)

    def tip(mdl):
        return float(mdl.displacement_at((L, 0.0, 0.0))[2] / L)

    return _curve(
        model,
        fractions=fractions,
        measure=tip,
        reference=lambda f: rollup_tip_model(f)[1],
        name="roll-up w/L",
        mesh=f"{nx}x{ny}",
        stepping=LoadStepping(initial_increment=0.05, max_increment=0.1),
        t0=t0,
        absolute_below=1e-3,
    )


def run_elastica_curve(
    *,
    nx: int,
    ny: int = 1,
    k_max: float = 4.0,
    fractions=(0.25, 0.5, 1.0),
    comm: MPI.Comm = MPI.COMM_WORLD,
    quadrature: Quadrature | None = None,
) -> list[CurvePoint]:
    """Cantilever under a dead end shear P = fraction x k_max EI / L^2 (Sze 3.1, the
    elastica): tip deflection w/L against :func:`elastica_tip` at each fraction."""
    t0 = time.perf_counter()
    L, b = STRIP["length"], STRIP["width"]
    P = k_max * _EI() / L**2
    model = _strip_model(
        comm, nx, ny, [EdgeTraction("tip", (0.0, 0.0, P / b))], quadrature=quadrature
    )
    return _curve(
        model,
        fractions=fractions,
        measure=lambda mdl: float(mdl.displacement_at((L, 0.0, 0.0))[2] / L),
        reference=lambda f: elastica_tip(f * k_max)[1],
        name=f"elastica w/L (PL2/EI up to {k_max:g})",
        mesh=f"{nx}x{ny}",
        stepping=LoadStepping(initial_increment=0.125, max_increment=0.25),
        t0=t0,
    )


def run_semicylinder(
    *,
    n: int,
    fractions=tuple(SEMICYLINDER_REFERENCE),
    comm: MPI.Comm = MPI.COMM_WORLD,
    quadrature: Quadrature | None = None,
) -> list[CurvePoint]:
    """Pinched semi-cylinder (Sze 3.7): R = 1.016, L = 3.048, t = 0.03, E = 2.0685e7,
    nu = 0.3; clamped at x = 0, free at x = L, symmetry (u_z = 0, director in the plane)
    on the straight edges, P up to 2000 downwards at the top of the free end; -w there
    against Sze's reference curve. ``n`` x ``n`` cells on the whole semi-cylinder."""
    t0 = time.perf_counter()
    R, L, t, P = 1.016, 3.048, 0.03, 2000.0
    sm = meshes.cylinder_panel(comm, radius=R, length=L, angle=0.5 * math.pi, n_around=n, n_along=n)
    model = ShellModel(
        sm,
        material=FabricMaterial.isotropic(E=2.0685e7, nu=0.3),
        thickness=t,
        loads=[PointForce((L, 0.0, R), (0.0, 0.0, -P))],
        supports=[Clamp("start"), Symmetry("sides", axis=2)],
        quadrature=quadrature or Quadrature(),
    )
    return _curve(
        model,
        fractions=fractions,
        measure=lambda mdl: float(-mdl.displacement_at((L, 0.0, R))[2]),
        reference=lambda f: SEMICYLINDER_REFERENCE[f],
        name="pinched semi-cylinder -w",
        mesh=f"{n}x{n}",
        stepping=LoadStepping(initial_increment=0.05, max_increment=0.1),
        t0=t0,
    )


def run_pinched_cylinder(
    *,
    n: int,
    thickness: float = 3.0,
    comm: MPI.Comm = MPI.COMM_WORLD,
    quadrature: Quadrature | None = None,
) -> Result:
    """Pinched cylinder with rigid end diaphragms (MacNeal & Harder 1985): R = 300, L = 600,
    E = 3e6, nu = 0.3, t = 3, two opposite unit loads at midspan; one octant with ``n`` x
    ``n`` cells. A ``thickness`` other than 3 scales E by (3/t)^3 (the same bending
    stiffness, a stiffer membrane): the locking study; the reference is then not exact."""
    t0 = time.perf_counter()
    R, L = 300.0, 600.0
    sm = meshes.cylinder_panel(
        comm, radius=R, length=L / 2, angle=0.25 * math.pi, n_around=n, n_along=n
    )
    _rotate_about_x(sm, 0.25 * math.pi)  # the arc from the crest (y = 0) to z = 0
    tol = 1e-6 * R
    model = ShellModel(
        sm,
        material=FabricMaterial.isotropic(E=3.0e6 * (3.0 / thickness) ** 3, nu=0.3),
        thickness=thickness,
        loads=[PointForce((L / 2, 0.0, R), (0.0, 0.0, -0.25))],  # a quarter of P = 1
        supports=[
            Prescribed("start", displacement=(0.0, 0.0, 0.0), components=(1, 2)),
            Symmetry("end", axis=0),
            Symmetry(lambda x: np.abs(x[1]) < tol, axis=1),
            Symmetry(lambda x: np.abs(x[2]) < tol, axis=2),
        ],
        quadrature=quadrature or Quadrature(),
    )
    its = _solve_small_load(model, prefix="pinch_")
    w = -model.displacement_at((L / 2, 0.0, R))[2]
    ref = PINCHED_CYLINDER_REFERENCE
    name = f"pinched cylinder w (t/R = 1/{R / thickness:g})"
    return Result(name, f"{n}x{n}", w, ref, abs(w - ref) / ref, time.perf_counter() - t0, its)


def _rotate_about_x(sm, angle: float) -> None:
    """Rotate a mesh's geometry about the x axis by ``angle`` (from +z towards +y)."""
    x = sm.mesh.geometry.x
    c, s = math.cos(angle), math.sin(angle)
    y, z = x[:, 1].copy(), x[:, 2].copy()
    x[:, 1], x[:, 2] = c * y + s * z, -s * y + c * z


# Clamped square plate under uniform pressure, Kirchhoff solution: w_centre = c q a^4 / D
# with c = 0.00126532 (Timoshenko & Woinowsky-Krieger 1959, Sec. 44, table 35: 0.00126).
CLAMPED_PLATE_COEFFICIENT = 0.00126532


def run_clamped_plate(
    *,
    n: int,
    slenderness: float,
    comm: MPI.Comm = MPI.COMM_WORLD,
    quadrature: Quadrature | None = None,
) -> Result:
    """Clamped square plate (a = 1, nu = 0.3, t = a / ``slenderness``, E such that
    D = E t^3 / 12 (1 - nu^2) = 1) under a uniform pressure giving w ~ 1e-3 t: centre
    deflection against Kirchhoff's c q a^4 / D. The transverse-shear correction of
    Reissner-Mindlin theory is O((t/a)^2) (below 0.1 % at t/a = 1/100): a locking element
    shows as a deflection far below the reference."""
    t0 = time.perf_counter()
    a, nu, D = 1.0, 0.3, 1.0
    t = a / slenderness
    E = 12 * (1 - nu**2) * D / t**3
    q = 1e-3 * t * D / (CLAMPED_PLATE_COEFFICIENT * a**4)
    sm = meshes.strip(comm, length=a, width=a, nx=n, ny=n)
    model = ShellModel(
        sm,
        material=FabricMaterial.isotropic(E=E, nu=nu),
        thickness=t,
        loads=[Pressure(q, follower=False)],
        supports=[Clamp("root"), Clamp("tip"), Clamp("sides")],
        quadrature=quadrature or Quadrature(),
    )
    its = _solve_small_load(model, prefix="plate_")
    w = abs(model.displacement_at((0.5 * a, 0.0, 0.0))[2]) * D / (q * a**4)
    ref = CLAMPED_PLATE_COEFFICIENT
    name = f"clamped plate w D/(q a^4) (t/a = 1/{slenderness:g})"
    return Result(name, f"{n}x{n}", w, ref, abs(w - ref) / ref, time.perf_counter() - t0, its)


def _solve_small_load(model: ShellModel, *, prefix: str) -> int:
    """The linear solution of a linear-regime benchmark: one full Newton step from the
    reference state at load factor 1, K(0) du = F (the references are linear theory).
    Returns the iterations (1)."""
    from petsc4py import PETSc

    PETSc.Options()[prefix + "snes_max_it"] = 1
    _, its, _, _ = NewtonSolver(model, prefix=prefix).solve(1.0)
    if its != 1:
        raise RuntimeError(f"{prefix.rstrip('_')}: the linear step was not taken")
    return its


# MacNeal & Harder (1985): hemisphere with an 18-degree hole, radial displacement at the
# load points under unit loads on the quarter model (linear).
HEMISPHERE_REFERENCE = 0.094


def run_hemisphere(
    *, n: int, comm: MPI.Comm = MPI.COMM_WORLD, quadrature: Quadrature | None = None
) -> Result:
    """Hemisphere with an 18-degree polar hole (MacNeal & Harder 1985; Sze et al. 2004
    problem 3.4 in its linear range): R = 10, t = 0.04, E = 6.825e7, nu = 0.3; a quarter
    model with ``n`` x ``n`` cells, symmetry on the two meridians, a unit force pulling
    outwards at (R, 0, 0) and one pushing inwards at (0, R, 0); u_x at the first."""
    t0 = time.perf_counter()
    R = 10.0
    sm = meshes.sphere_quarter(comm, radius=R, hole_angle=math.radians(18), n=n)
    model = ShellModel(
        sm,
        material=FabricMaterial.isotropic(E=6.825e7, nu=0.3),
        thickness=0.04,
        loads=[
            PointForce((R, 0.0, 0.0), (1.0, 0.0, 0.0)),
            PointForce((0.0, R, 0.0), (0.0, -1.0, 0.0)),
        ],
        supports=[
            Symmetry("xz", axis=1),
            Symmetry("yz", axis=0),
            PointPin(point=(R, 0.0, 0.0), components=(2,)),
        ],
        quadrature=quadrature or Quadrature(),
    )
    its = _solve_small_load(model, prefix="hemi_")
    u = model.displacement_at((R, 0.0, 0.0))[0]
    ref = HEMISPHERE_REFERENCE
    return Result(
        "hemisphere u_x (MacNeal-Harder)",
        f"{n}x{n}",
        u,
        ref,
        abs(u - ref) / ref,
        time.perf_counter() - t0,
        its,
    )
