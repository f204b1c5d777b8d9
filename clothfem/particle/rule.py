"""Spring stiffnesses and nodal masses from the orthotropic fabric moduli.

The rule (stiffness-tensor matching on the grid squares)
---------------------------------------------------------
Each nine-node cell is four grid squares ("sub-squares") q with mean side lengths a (along
the cell's xi lines) and b (eta lines), area A_q and the reduced stiffness of
:class:`clothfem.shell.FabricMaterial` rotated into the square's axes, Qbar (Pa; the angle
between the xi line and the surface projection of ``warp``). A central-force lattice has the
in-plane stiffness tensor ``C_ijkl = sum_s k_s L_s^2 n_i n_j n_k n_l / A``; the rule makes
it equal to ``t Qbar`` where a spring lattice can:

* **shear** springs (two diagonals of length L_d per square): ``k_d = t Qbar66 L_d^2 / (2 A_q)``,
  so that a uniform shear of a rectangular square stores ``t Qbar66 gamma^2 A_q / 2``;
* **flexion** springs (Provot 1995; rest length L0 = 2 a_f over the middle node, width w =
  tributary area / length of the two structural springs they span): the flexural rigidity
  ``B = w t^3 Ebar / 12`` (Ebar the direction's modulus) and ``k_f = 16 B / (theta_ref^2 a_f^3)``:
  a linear flexion spring has no small-angle bending stiffness at all (its chord shortens by
  ``a_f theta^2 / 4`` at a fold ``theta`` over the middle node, an energy ~ theta^4); this k_f
  stores the hinge energy ``B theta^2 / (2 a_f)`` of a fold of ``theta_ref`` (default pi/2), a
  secant match;
* **structural** springs take the rest: square q gives each of its two xi sides (length L)
  ``k += (t Qbar11 - C^shear_xi - C^flexion_xi) (A_q / 2) / L^2`` (and likewise for eta),
  ``C^shear_xi = sum_d k_d L_d^2 (n_d . e_xi)^4 / A_q`` and ``C^flexion_xi = 64 Ebar t^3 /
  (12 theta_ref^2 a^2)`` (the flexion springs' share of the stretch stiffness; 0 in the
  Choi & Ko option, where flexion springs carry no tension).

On a regular rectangular grid aligned with the warp the lattice then has exactly
``C1111 = t Q11``, ``C2222 = t Q22`` and ``C1212 = t Q66``: a uniform stretch along the warp
with the weft held gives the membrane force ``t Q11 eps`` per unit width (``E1 t eps`` for
nu12 = 0), also on a finite patch (boundary rows have half the tributary width). A
central-force lattice obeys the Cauchy relation ``C1122 = C1212``, so the Poisson coupling
is ``t Qbar66`` instead of ``t Q12``: free lateral contraction gives ``t (Q11 - Q66^2 / Q22)``
(0.7 % below ``E1 t`` for crimped cotton). Q16, Q26 of off-axis grids are not represented.
Springs derived from squares that are not rectangles are approximations of the same rule.

Choi & Ko (2002), "Stable but responsive cloth", ACM Trans. Graph. 21(3), 604-611: the
option ``bending="choi-ko"`` treats a compressed structural or flexion spring as a buckled
column with pinned ends (a circular arc of length L0 through both ends): its force follows
``f_b = B kappa^2 / (sinc(kappa L0 / 2) - cos(kappa L0 / 2))`` with ``|x_ij| = L0 sinc(kappa L0
/ 2)``, which starts at ``12 B / L0^2`` and rises to ``4 pi^2 B / L0^2`` as the ends meet. The
compressive force joins the linear pre-buckling branch ``k delta`` and the column smoothly,
``P = ((k delta)^-p + f_b^-p)^(-1/p)`` with p = 4 (within 16 % of ``min(k delta, f_b)``, equal
to it away from the crossing; a plain ``min`` has a kink at which Newton's method chatters);
flexion springs carry no tension. Shear springs stay linear.

Lumped masses: ``rho t A_q / 4`` to each corner of every square.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .network import FLEXION, SHEAR, STRUCTURAL, SpringNetwork

__all__ = [
    "ParticleFabric",
    "SpringRule",
    "buckled_force",
    "column_energy",
    "compressive_force",
    "fabric_from_material",
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, kw_only=True)
class SpringRule:
    """Choices of the stiffness rule (module docstring).

    bending: "provot" (linear flexion springs) or "choi-ko" (buckling-aware structural and
    flexion springs in compression).
    fold_angle: theta_ref [rad] in (0, pi] of the flexion springs' secant match.
    warp: global vector whose surface projection is the warp (material 1) direction.
    """

    bending: str = "provot"
    fold_angle: float = 0.5 * math.pi
    warp: tuple[float, float, float] = (1.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if self.bending not in ("provot", "choi-ko"):
            raise ValueError(
                f"SpringRule bending must be 'provot' or 'choi-ko', got {self.bending!r}"
            )
        if not (math.isfinite(self.fold_angle) and 0.0 < self.fold_angle <= math.pi):
            raise ValueError(
                f"SpringRule fold_angle must be in (0, pi] rad, got {self.fold_angle!r}"
            )
        w = np.asarray(self.warp, dtype=float)
        if w.shape != (3,) or not np.all(np.isfinite(w)) or np.linalg.norm(w) == 0.0:
            raise ValueError(
                f"SpringRule warp must be a finite non-zero 3-vector, got {self.warp!r}"
            )
        object.__setattr__(self, "warp", tuple(float(c) for c in w))


@dataclass(frozen=True, eq=False, kw_only=True)
class ParticleFabric:
    """Spring constants and masses of a network.

    stiffness: (m,) axial stiffness k [N/m] of each spring.
    rigidity: (m,) flexural rigidity B [N m^2] of the column a spring stands for (Choi & Ko).
    buckling: (m,) True where compression follows the buckled column.
    tension: (m,) False where the spring carries no tension (Choi & Ko flexion springs).
    mass: (n,) lumped nodal masses [kg].
    area: (n,) nodal tributary areas [m^2].
    thickness: t [m]; rule: the :class:`SpringRule` used.
    """

    stiffness: FloatArray
    rigidity: FloatArray
    buckling: NDArray[np.bool_]
    tension: NDArray[np.bool_]
    mass: FloatArray
    area: FloatArray
    thickness: float
    rule: SpringRule


def _squares(net: SpringNetwork) -> tuple[np.ndarray, ...]:
    """Corner nodes (s, 4) of all squares, in the order p00, p10, p11, p01."""
    g = net.grid
    q = [
        np.stack([g[:, i, j], g[:, i + 1, j], g[:, i + 1, j + 1], g[:, i, j + 1]], axis=1)
        for i in range(2)
        for j in range(2)
    ]
    return np.concatenate(q)


def _qbar(Q: np.ndarray, c2: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Rotated reduced stiffness (Qbar11, Qbar22, Qbar66) [Pa] for cos^2 of the angle."""
    s2 = 1.0 - c2
    q11, q22, q12, q66 = Q[0, 0], Q[1, 1], Q[0, 1], Q[2, 2]
    mix = c2 * s2
    b11 = q11 * c2**2 + 2.0 * (q12 + 2.0 * q66) * mix + q22 * s2**2
    b22 = q11 * s2**2 + 2.0 * (q12 + 2.0 * q66) * mix + q22 * c2**2
    b66 = (q11 + q22 - 2.0 * q12 - 2.0 * q66) * mix + q66 * (s2**2 + c2**2)
    return b11, b22, b66


def _unit(v: FloatArray) -> FloatArray:
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _spring_index(net: SpringNetwork, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    n = net.n_nodes
    keys = net.pairs[:, 0] * n + net.pairs[:, 1]
    want = np.minimum(a, b) * n + np.maximum(a, b)
    idx = np.searchsorted(keys, want)
    if np.any(keys[np.minimum(idx, len(keys) - 1)] != want):
        raise RuntimeError("spring network: a grid-square side has no structural spring")
    return idx


def _square_geometry(net: SpringNetwork, sq: np.ndarray, warp: FloatArray) -> dict:
    x = net.x0
    p00, p10, p11, p01 = (x[sq[:, k]] for k in range(4))
    sx = [p10 - p00, p11 - p01]
    sy = [p01 - p00, p11 - p10]
    ex, ey = _unit(sx[0] + sx[1]), _unit(sy[0] + sy[1])
    normal = np.cross(ex, ey)
    area = 0.5 * np.linalg.norm(np.cross(p11 - p00, p01 - p10), axis=1)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    wp = warp - (normal @ warp)[:, None] * normal
    wn = np.linalg.norm(wp, axis=1)
    if np.any(wn < 1e-8):
        raise ValueError("SpringRule warp must not be normal to the surface anywhere")
    c2 = np.clip(np.einsum("ij,ij->i", wp / wn[:, None], ex) ** 2, 0.0, 1.0)
    a = 0.5 * sum(np.linalg.norm(v, axis=1) for v in sx)
    b = 0.5 * sum(np.linalg.norm(v, axis=1) for v in sy)
    return dict(ex=ex, ey=ey, area=area, c2=c2, a=a, b=b)


def fabric_from_material(
    network: SpringNetwork, *, material, thickness: float, rule: SpringRule = SpringRule()
) -> ParticleFabric:
    """Stiffnesses and masses of ``network`` for a :class:`clothfem.shell.FabricMaterial` of
    thickness ``thickness`` [m] by the rule of the module docstring."""
    t = float(thickness)
    if not (math.isfinite(t) and t > 0.0):
        raise ValueError(f"thickness must be a finite number > 0 m, got {thickness!r}")
    if not material.rho > 0.0:
        raise ValueError(
            f"material rho must be > 0 kg/m^3 for a particle model, got {material.rho!r}"
        )
    net, n = network, network.n_nodes
    sq = _squares(net)
    geo = _square_geometry(net, sq, np.asarray(rule.warp, float))
    b11, b22, b66 = _qbar(material.plane_stress_stiffness(), geo["c2"])
    A = geo["area"]
    k = np.zeros(net.n_springs)
    diag = [_spring_index(net, sq[:, 0], sq[:, 2]), _spring_index(net, sq[:, 1], sq[:, 3])]
    c_shear = [np.zeros(len(sq)), np.zeros(len(sq))]
    for d in diag:
        L = net.rest[d]
        kd = t * b66 * L**2 / (2.0 * A)
        np.add.at(k, d, kd)
        nd = (net.x0[net.pairs[d, 1]] - net.x0[net.pairs[d, 0]]) / L[:, None]
        for axis, e in enumerate((geo["ex"], geo["ey"])):
            c_shear[axis] += kd * L**2 * np.einsum("ij,ij->i", nd, e) ** 4 / A
    theta2 = rule.fold_angle**2
    flex = rule.bending == "provot"
    sides = {0: ((0, 1), (3, 2)), 1: ((0, 3), (1, 2))}  # xi sides, eta sides (corner pairs)
    trib, modw = np.zeros(net.n_springs), np.zeros(net.n_springs)
    for axis, (qbar, h) in enumerate(((b11, geo["a"]), (b22, geo["b"]))):
        c_flex = 64.0 * qbar * t**3 / (12.0 * theta2 * h**2) if flex else 0.0
        c_struct = t * qbar - c_shear[axis] - c_flex
        if np.any(c_struct <= 0.0):
            raise ValueError(
                "thickness and mesh give structural stiffness <= 0 (shear or flexion springs "
                "exceed E t): coarsen the mesh, raise SpringRule fold_angle or use 'choi-ko'"
            )
        for i, j in sides[axis]:
            s = _spring_index(net, sq[:, i], sq[:, j])
            np.add.at(k, s, c_struct * 0.5 * A / net.rest[s] ** 2)
            np.add.at(trib, s, 0.5 * A)
            np.add.at(modw, s, 0.5 * A * qbar)
    rig = np.zeros(net.n_springs)
    st = net.kind == STRUCTURAL
    rig[st] = modw[st] * t**3 / (12.0 * net.rest[st])  # E w t^3 / 12, w = tributary / L
    _flexion(net, k, rig, trib, modw, t, theta2)
    mass_area = np.zeros(n)
    for c in range(4):
        np.add.at(mass_area, sq[:, c], 0.25 * A)
    choi = rule.bending == "choi-ko"
    buckling = (net.kind != SHEAR) & choi
    tension = ~((net.kind == FLEXION) & choi)
    return ParticleFabric(
        stiffness=k, rigidity=rig, buckling=buckling, tension=tension,
        mass=material.rho * t * mass_area, area=mass_area, thickness=t, rule=rule,
    )  # fmt: skip


def _flexion(net, k, rig, trib, modw, t, theta2) -> None:
    """Flexion springs: B from the two structural springs they span, k_f = 16 B / (theta^2
    a^3) with a = L0 / 2 (in place)."""
    f = np.flatnonzero(net.kind == FLEXION)
    p, q, r = net.pairs[f, 0], net.middle[f], net.pairs[f, 1]
    s1, s2 = _spring_index(net, p, q), _spring_index(net, q, r)
    width = (trib[s1] + trib[s2]) / (net.rest[s1] + net.rest[s2])
    modulus = (modw[s1] + modw[s2]) / (trib[s1] + trib[s2])
    rig[f] = width * modulus * t**3 / 12.0
    half = 0.5 * net.rest[f]
    k[f] = 16.0 * rig[f] / (theta2 * half**3)


# --- Choi & Ko (2002): the buckled column -------------------------------------------------
def _column_table(n: int = 4001) -> tuple[FloatArray, ...]:
    """s = L / L0 = sinc(x) (increasing), G = x^2 / (sinc x - cos x), dG/ds and the work
    W(s) = int_s^1 G ds' on x in [0, pi): f_b = 4 B G / L0^2, work 4 B W / L0."""
    x = np.linspace(0.0, math.pi * (1.0 - 1e-6), n)
    s = np.sinc(x / math.pi)
    den = np.where(x < 1e-2, x**2 / 3.0 - x**4 / 30.0 + x**6 / 840.0, s - np.cos(x))
    G = np.empty_like(x)
    G[0] = 3.0
    G[1:] = x[1:] ** 2 / den[1:]
    dG = np.gradient(G, s)
    s, G, dG = s[::-1].copy(), G[::-1].copy(), dG[::-1].copy()
    W = np.concatenate([[0.0], np.cumsum(0.5 * (G[1:] + G[:-1]) * np.diff(s))])
    return s, G, dG, W[-1] - W


_S, _G, _DG, _W = _column_table()


def buckled_force(
    length: FloatArray, rest: FloatArray, rigidity: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Compressive force f_b >= 0 [N] of a buckled pinned column of rest length ``rest`` and
    flexural rigidity ``rigidity`` [N m^2] with its ends ``length`` apart, and d f_b / d length
    [N/m] (Choi & Ko 2002, circular-arc column)."""
    s = np.clip(length / rest, _S[0], 1.0)
    scale = 4.0 * rigidity / rest**2
    return scale * np.interp(s, _S, _G), scale * np.interp(s, _S, _DG) / rest


SMOOTH_P = 4.0  # exponent of the smooth minimum of the pre-buckling and column branches


def compressive_force(
    length: FloatArray, rest: FloatArray, stiffness: FloatArray, rigidity: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Compressive force P >= 0 [N] of a Choi & Ko spring at ``length`` <= ``rest``, the
    smooth minimum of ``k delta`` and ``f_b``, and dP/d length [N/m]."""
    p = SMOOTH_P
    a = stiffness * np.maximum(rest - length, 0.0)
    fb, dfb = buckled_force(length, rest, rigidity)
    P = np.zeros_like(a)
    dP = -stiffness.astype(float).copy()  # P = k delta at delta = 0
    on = a > 0.0
    a, fb, dfb = a[on], fb[on], dfb[on]
    Pon = (a**-p + fb**-p) ** (-1.0 / p)
    P[on] = Pon
    dP[on] = Pon ** (p + 1.0) * (-stiffness[on] * a ** -(p + 1.0) + dfb * fb ** -(p + 1.0))
    return P, dP


def column_energy(
    length: FloatArray, rest: FloatArray, stiffness: FloatArray, rigidity: FloatArray
) -> FloatArray:
    """Work [J] of :func:`compressive_force` from the rest length to ``length`` < ``rest``
    (24-point Gauss-Legendre on the compression; the integrand is smooth)."""
    gx, gw = np.polynomial.legendre.leggauss(24)
    delta = rest - length
    work = np.zeros_like(delta)
    for xi, wi in zip(gx, gw, strict=True):
        d = 0.5 * delta * (xi + 1.0)
        P, _ = compressive_force(rest - d, rest, stiffness, rigidity)
        work += 0.5 * delta * wi * P
    return work
