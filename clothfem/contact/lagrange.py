"""Implicit frictional contact of a fabric shell with rigid ellipsoids by Lagrange multipliers.

Man & Swan (2007), Sec. 3.2, Eqs. 15-21, solved implicitly with the active-set ("trial and
error") procedure described after Eq. 21: activate penetrating nodes, deactivate nodes whose
multiplier turns tensile, iterate until the set stops changing.

Formulation
-----------
Slave nodes are the fabric nodes (all nodes of the shell's ``u`` space, quadratic elements
included); the master surface is the union of rigid ellipsoids given as ``(c, Q, r)`` triples
(axes as **columns**; ``clothfem.body.Ellipsoid`` gives ``(e.centre, e.axes.T, e.radii)``).
Being outside the union means being outside every ellipsoid, so the constraints are per
(node, ellipsoid) pair: for an active pair ``(i, k)`` the constraint is
``gap_ik(x_i) = (x_i - p_ik) . n_ik = 0`` with the exact closest point ``p_ik`` and outward
normal ``n_ik`` of ellipsoid ``k`` (:func:`~clothfem.contact.geometry.closest_point_ellipsoid`).
Each gap is smooth; projecting on the union instead switches a node between ellipsoids in the
concave crease where two of them meet (the elbow), and Newton then cycles (measured on the
arm-sleeve scene at 33 degrees of flexion). A node normally carries one constraint, on its
most penetrated ellipsoid, chosen between Newton solves; a node pushed into the crease can
end with two (one per ellipsoid, when the anti-cycling rule below keeps a pair that kept
switching), which is the physical answer there (both surfaces hold it).
Since ``d gap / d x = n`` for an exact projection, the constraint row is ``G_ik = n_ik^T`` on
the three ``u`` dofs of node ``i`` (Eq. 21 with a rigid master: the master dofs are
prescribed, not unknowns).

Per Newton iteration we solve the bordered (saddle-point) system

    [ K + K_t        -(n + mu s) ] [du ]   [ -(R - G^T lam - f_t) ]
    [ -G               0         ] [dlam] = [  gap                 ]

``K`` the shell tangent, ``R`` its residual, ``lam`` the normal multipliers (force on the
fabric ``+lam n``, on the body ``-lam n``) and ``f_t``/``K_t`` the friction force and its
consistent tangent (below).  Why a bordered system and not a nodal rotation: it returns the
multipliers as unknowns of the solve (no post-processing of reactions), keeps the model's
``(u, theta)`` layout untouched, and one MUMPS factorisation of the small extra block costs
nothing here.  The curvature of the constraint is in the tangent: ``d(lam n)/dx =
lam W (I + gap W)^-1`` with ``W = P H P / |grad f|`` the Weingarten map of the ellipsoid at
``p`` (``H`` the Hessian of Eq. 26).  Each Newton step is followed by a backtracking line search
on ``|R - G^T lam - f_t|^2 + (E t)^2 |gap|^2`` (needed at stick/slip transitions and where the
released fabric wrinkles); a pass that keeps stalling is abandoned early so that
:meth:`LagrangeContact.advance` can halve the step.  The
bordered matrix is assembled as one AIJ matrix from the CSR rows of ``K`` with columns
renumbered to the layout ``[u, theta owned; lam owned]`` per rank; every constraint lives on
the rank that owns its node, so all extra entries are local.

Friction (only built when ``mu > 0``)
-------------------------------------
Regularised Coulomb law with a tangential penalty ``k_t`` and a return map (Wriggers,
*Computational Contact Mechanics*, 2nd ed. 2006; Laursen & Simo 1993): the slip of node
``i`` over the step is ``du = P_t (p_i - a_i)``, ``p_i`` its current closest point and ``a_i``
the body material point it touched at the last converged step (body-local coordinates ``xi_i``
carried with the body, ``c_k + Q_k xi_i``, and put back on the possibly resized surface);
trial force ``f_tr = P_t f_old - k_t du`` and
:func:`~clothfem.contact.friction.coulomb_return_map` (stick if ``|f_tr| <= mu lam``, else
``f_t = mu lam f_tr/|f_tr|``).  Consistent tangent: stick ``K_t = k_t P_t``; slip
``K_t = mu lam k_t / |f_tr| (I - s s^T) P_t``, both times ``dp/dx = P_t - gap dn/dx`` (a node
inside a compliant body), and the extra coupling ``-mu s`` in the multiplier
column (``s = f_tr / |f_tr|``), which makes the bordered matrix unsymmetric (MUMPS LU).  In full
slip ``|f_t| = mu lam`` exactly whatever ``k_t``; ``k_t`` only sets the elastic (pre-sliding)
slip ``|f_t| / k_t`` while sticking.  The frictional dissipation of a step is
``sum mu lam |du_p|`` (plastic slip of the return map).

Outputs (per owned node; scalars are reduced over ranks): normal multipliers, normals, gaps,
friction forces, contact force on the fabric and on the body, contact pressure
``lam / A_i`` with ``A_i`` lumped nodal areas of the current configuration (HRZ diagonal
lumping), resultant, Eq. 28 torque, accumulated dissipation and KKT diagnostics.

PETSc options: the linear solver has the prefix ``contact_lagrange_`` (default MUMPS LU,
redundant on more than one rank, :mod:`clothfem.petsc_options`); override with e.g.
``-contact_lagrange_pc_type lu`` (MUMPS's distributed LU).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import NoReturn, Protocol

import dolfinx.fem.petsc as fem_petsc
import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI
from numpy.typing import ArrayLike, NDArray
from petsc4py import PETSc

from ..petsc_options import direct_lu, set_defaults
from ..shell.model import ShellModel
from .forces import diagnostics, joint_torque
from .friction import coulomb_return_map
from .geometry import (
    EllipsoidData,
    _check_bodies,
    closest_points,
)
from .kkt import BorderedMatrix

__all__ = [
    "ContactDivergence",
    "ContactState",
    "ContactStepRecord",
    "LagrangeContact",
    "LagrangeContactParameters",
]

FloatArray = NDArray[np.float64]

log = logging.getLogger("clothfem.contact.lagrange")

# N/m: cap of the default tangential penalty. Stiffer sticking only shrinks an elastic slip
# that is already negligible (|f_t| / k_t <= 1e-8 m at 0.01 N), while it makes the return map
# switch stick/slip on round-off: a 7.2 GPa sleeve with k_t = 100 E t = 7.2e8 N/m stalled
# Newton at |r| ~ mu lam (measured); with k_t = 1e6 it converged in 4-5 iterations.
KT_MAX = 1e6


class ContactDivergence(RuntimeError):
    """Newton or the active-set iteration failed in a step; the state was restored."""


@dataclass(frozen=True, kw_only=True)
class LagrangeContactParameters:
    """Controls of :class:`LagrangeContact` (SI units).

    mu: Coulomb friction coefficient (>= 0); 0 builds no friction terms at all.
    tangential_penalty: k_t in N/m (> 0) of the regularised stick law; None means
        ``min(100 * min(E1, E2) * t, KT_MAX)`` (100 x the membrane stiffness scale of a node,
        at most 1e6 N/m).
    gap_tolerance: activation threshold in m (> 0): an inactive node is activated when its gap
        is below ``-gap_tolerance``; None means ``1e-4 * thickness``.
    multiplier_tolerance: relative deactivation threshold (in [0, 1)): an active node is
        released when ``lam < -multiplier_tolerance * max|lam|``.
    newton_rtol: Newton stops when the free-row residual drops below newton_rtol times its
        largest value in the active-set pass (in (0, 1)), with max|gap| <= 1e-3 gap_tolerance.
    newton_stol: ... or when ``max|du| <= newton_stol * L`` with L the mesh size (in (0, 1)).
    max_newton: Newton iterations per active-set pass (>= 1).
    newton_stall_limit: Newton gives up a pass (and the caller cuts the step) after this many
        iterations in a row whose line search took a step below 1/16 (>= 1). 12 since
        2026-11-23 (was 4): Newton often recovers after 5-11 such iterations when newly
        added pairs with friction are closed, and a cut-back costs more than the wait.
    max_active_set: active-set passes per step (>= 1).
    semismooth_passes: in the first this many passes (>= 0) the active set is updated as soon
        as a Newton iterate penetrates or pulls (primal-dual active set / semismooth Newton:
        no Newton solve to convergence with a set that is already known to be wrong); later
        passes converge Newton with a fixed set (the paper's trial-and-error procedure),
        which cannot cycle inside Newton. 0: always the latter.
    release_penetration: in m (> 0); None means ``1e-2 * thickness``. A pair that keeps
        switching in and out of the active set (6 times in a step) is kept active; if it then
        pulls on the body by more than 1 % of the largest multiplier, it is released for the
        rest of the step instead, and the step is accepted if such a released pair penetrates
        by at most release_penetration (reported as the step's max_penetration); otherwise
        the step fails (and is cut).
    tissue_stiffness: Winkler modulus k_w of the body's soft tissue in Pa/m (> 0); None
        means rigid bodies (the paper's). With it an active pair's constraint is
        ``gap + lam / (k_w A_i) = 0``: the body surface gives way by ``lam / (k_w A_i)``
        under node ``i`` (``A_i`` its HRZ-lumped area on the undeformed mesh), so a node
        pressed by two bodies that overlap (the fabric pinched in a flexed elbow) has a
        solution; each (node, ellipsoid) pair is then a constraint of its own (no
        one-body-per-node rule: the compliance keeps two nearly parallel constraints on a
        node well posed).
    prefix: PETSc options prefix of the bordered linear solve.
    """

    mu: float = 0.0
    tangential_penalty: float | None = None
    gap_tolerance: float | None = None
    multiplier_tolerance: float = 1e-9
    newton_rtol: float = 1e-9
    newton_stol: float = 1e-11
    max_newton: int = 50
    newton_stall_limit: int = 12
    max_active_set: int = 30
    semismooth_passes: int = 5
    release_penetration: float | None = None
    tissue_stiffness: float | None = None
    prefix: str = "contact_lagrange_"

    def __post_init__(self) -> None:
        if not (math.isfinite(self.mu) and self.mu >= 0):
            raise ValueError(f"mu must be a finite friction coefficient >= 0, got {self.mu!r}")
        units = {
            "tangential_penalty": "N/m",
            "gap_tolerance": "m",
            "release_penetration": "m",
            "tissue_stiffness": "Pa/m",
        }
        for name, unit in units.items():
            v = getattr(self, name)
            if v is not None and not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be None or a finite number > 0 {unit}, got {v!r}")
        if not (math.isfinite(self.multiplier_tolerance) and 0 <= self.multiplier_tolerance < 1):
            raise ValueError(
                f"multiplier_tolerance must be in [0, 1), got {self.multiplier_tolerance!r}"
            )
        for name in ("newton_rtol", "newton_stol"):
            v = getattr(self, name)
            if not (math.isfinite(v) and 0 < v < 1):
                raise ValueError(f"{name} must be in (0, 1), got {v!r}")
        for name in ("max_newton", "newton_stall_limit", "max_active_set"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= 1):
                raise ValueError(f"{name} must be an integer >= 1, got {v!r}")
        if not (isinstance(self.semismooth_passes, int) and self.semismooth_passes >= 0):
            raise ValueError(
                f"semismooth_passes must be an integer >= 0, got {self.semismooth_passes!r}"
            )
        if not (isinstance(self.prefix, str) and self.prefix and " " not in self.prefix):
            raise ValueError(
                f"prefix must be a non-empty PETSc options prefix, got {self.prefix!r}"
            )


@dataclass(frozen=True)
class ContactStepRecord:
    """One converged contact step (all values reduced over ranks).

    n_active: active nodes; max_penetration: max(0, -min gap) in m over all nodes;
    min_multiplier: smallest active lam in N (0 if none); complementarity: max|lam gap| in N m;
    active_set_iterations: passes until the set stopped changing; newton_iterations: total;
    n_stick / n_slip: active nodes sticking / slipping (0 at mu = 0); dissipation: frictional
    dissipation of the step in J; total_normal_force: sum of lam in N; wall_time in s;
    max_indentation: the largest give of a compliant body's surface in m (0 when rigid).
    On a compliant body max_penetration and complementarity measure the gap plus the give.
    """

    step: int
    load_factor: float
    n_active: int
    max_penetration: float
    min_multiplier: float
    complementarity: float
    active_set_iterations: int
    newton_iterations: int
    n_stick: int
    n_slip: int
    dissipation: float
    total_normal_force: float
    wall_time: float
    max_indentation: float = 0.0

    def line(self) -> str:
        return (
            f"step {self.step:3d}  lam {self.load_factor:7.4f}  active {self.n_active:5d}  "
            f"pen {self.max_penetration:9.2e} m  min lam {self.min_multiplier:9.2e} N  "
            f"|lam gap| {self.complementarity:8.1e}  sets {self.active_set_iterations:2d}  "
            f"newton {self.newton_iterations:3d}  stick/slip {self.n_stick}/{self.n_slip}  "
            f"sum lam {self.total_normal_force:9.4g} N  {self.wall_time:6.2f} s"
        )


@dataclass(frozen=True)
class ContactState:
    """Contact state of the rank's **owned** nodes (arrays of length ``n_owned``).

    x: current positions (m); gap: signed gap to the union (m, < 0 penetration); active: mask;
    lam_n: normal multipliers (N, 0 off the active set); normal: outward body normal at the
    closest point; friction: tangential friction force on the fabric (N); force_on_fabric:
    ``lam_n n + friction``; force_on_body: its negative (use it in Eq. 28); area: lumped nodal
    area of the current configuration (m^2); pressure: ``lam_n / area`` (Pa).
    """

    x: FloatArray
    gap: FloatArray
    active: NDArray[np.bool_]
    lam_n: FloatArray
    normal: FloatArray
    friction: FloatArray
    force_on_fabric: FloatArray
    force_on_body: FloatArray
    area: FloatArray
    pressure: FloatArray


class Operator(Protocol):
    """The fabric's residual and tangent as the contact solver sees them (the model itself,
    or e.g. the model plus the inertia of a Newmark step)."""

    def residual(self, x: PETSc.Vec, f: PETSc.Vec) -> None: ...

    def jacobian(self, x: PETSc.Vec, K: PETSc.Mat | None = None) -> PETSc.Mat: ...


class LagrangeContact:
    """Frictional contact of a :class:`ShellModel` with a union of rigid, moving ellipsoids.

    Parameters
    ----------
    model: the fabric shell (supports and loads as usual).
    bodies: sequence of ``(c, Q, r)`` (centre m, axes as columns, radii m). They are copied into
        arrays owned by this object; move the bodies with :meth:`set_pose` (in place).
    params: :class:`LagrangeContactParameters`.
    slaves: optional ``f(X) -> bool mask`` of reference node coordinates (shape (3, N), like
        dolfinx locators) selecting the nodes that may touch; default all nodes.
    operator: the residual and tangent solved for (:class:`Operator`); default the model's.
    step_filter: optional ``f(x0, dx) -> alpha`` (this rank's (u, theta) arrays; collective,
        the same value on every rank): the largest admissible fraction of a Newton step,
        where the line search starts (e.g. no fabric self-intersection along it).

    Nodes whose three displacement components are all prescribed never enter the active set.
    """

    def __init__(
        self,
        model: ShellModel,
        bodies: Sequence[EllipsoidData],
        *,
        params: LagrangeContactParameters = LagrangeContactParameters(),
        slaves: Callable[[np.ndarray], np.ndarray] | None = None,
        operator: Operator | None = None,
        step_filter: Callable[[FloatArray, FloatArray], float] | None = None,
    ) -> None:
        if not isinstance(params, LagrangeContactParameters):
            raise ValueError("params must be a LagrangeContactParameters instance")
        self.model, self.params, self.comm = model, params, model.comm
        self.operator: Operator = model if operator is None else operator
        self.step_filter = step_filter
        self.bodies = [tuple(np.array(a, dtype=float) for a in b) for b in _check_bodies(bodies)]
        n = model.n_owned
        self.n = n
        self.X = model.x_nodes[:n].copy()
        mat = model.material
        t = model.thickness
        self.gap_tol = params.gap_tolerance if params.gap_tolerance is not None else 1e-4 * t
        rp = params.release_penetration
        self.release_penetration = rp if rp is not None else 1e-2 * t
        lo = self.X.min(axis=0) if n else np.full(3, np.inf)
        hi = self.X.max(axis=0) if n else np.full(3, -np.inf)
        self.comm.Allreduce(MPI.IN_PLACE, lo, op=MPI.MIN)
        self.comm.Allreduce(MPI.IN_PLACE, hi, op=MPI.MAX)
        self.L = float(np.linalg.norm(hi - lo))
        self.stiffness_scale = max(mat.E1, mat.E2) * t  # N/m
        self.force_scale = self.stiffness_scale * self.L  # N
        self.slave = np.ones(n, dtype=bool)
        if slaves is not None:
            self.slave = np.asarray(slaves(self.X.T.copy()), dtype=bool)[:n]
        # state: multipliers on the active set (stored per node), friction history
        # one constraint per (node, ellipsoid) pair: outside the union = outside every
        # ellipsoid, and each ellipsoid's gap is smooth (a union projection switches body
        # in the concave crease between two ellipsoids, and Newton cycles there)
        self.nb = len(self.bodies)
        self._pose_version = 0  # bumped by set_pose (cache key of _gaps)
        self._gap_cache: tuple[int, FloatArray, FloatArray] | None = None
        self._act = np.zeros((n, self.nb), dtype=bool)
        self._lam = np.zeros((n, self.nb))
        self.step_count = 0
        self.dissipation_total = 0.0
        self._friction: _FrictionState | None = None
        if params.mu > 0:
            kt = params.tangential_penalty
            kt = kt if kt is not None else min(100.0 * min(mat.E1, mat.E2) * t, KT_MAX)
            self._friction = _FrictionState(n, self.nb, params.mu, kt)
            self._friction.commit(self._positions(), self.bodies, np.zeros((n * self.nb, 3)))
        self._last_friction = np.zeros((n, 3))  # per node [N]
        self._last_friction_pairs = np.zeros((n * self.nb, 3))
        self._build_solver()
        self._build_area_forms()
        # m/N per owned node: the tissue's give under a unit force (None: rigid bodies)
        self._compliance: FloatArray | None = None
        if params.tissue_stiffness is not None:
            self._compliance = 1.0 / (params.tissue_stiffness * self._reference_area())
        self._K: PETSc.Mat | None = None
        self._kkt: BorderedMatrix | None = None
        self._kkt_slots = np.zeros(0, dtype=np.intp)  # pairs with a multiplier row in _kkt
        # (slots, bc rows) of a checkpoint's bordered matrix, rebuilt by the next _kkt_matrix
        self._kkt_restored: tuple[NDArray[np.intp], NDArray[np.int32]] | None = None
        # cumulative wall time [s] by part: fabric residual/tangent assembly, the contact layer
        # (projections, friction, bordered matrix), the linear solve
        self.timers = {"assembly": 0.0, "contact": 0.0, "solve": 0.0}

    # ------------------------------------------------------------------ checkpoint
    def state_arrays(self) -> dict[str, np.ndarray]:
        """Rank-local contact state to checkpoint (active set, multipliers, friction history,
        body poses, counters); restore with :meth:`restore_arrays` on the same ranks."""
        out = {
            "active": self._act.copy(),
            "lam": self._lam.copy(),
            "last_friction": self._last_friction_pairs.copy(),
            "counters": np.array([self.step_count, self.dissipation_total]),
            # the bordered matrix's multiplier slots (they outlive the pairs that left the
            # set): a resumed run factors the same matrix, so it repeats bit for bit
            "kkt_slots": self._kkt_slots.copy(),
            "kkt_bc_rows": (
                self._kkt.bc_rows.copy() if self._kkt is not None else np.zeros(0, np.int32)
            ),
            "kkt_built": np.array(self._kkt is not None),
        }
        for k, (c, Q, r) in enumerate(self.bodies):
            out[f"body{k}"] = np.concatenate([c, Q.ravel(), r])
        if self._friction is not None:
            f = self._friction
            out.update(fr_xi=f.xi.copy(), fr_force=f.force_old.copy())
        return out

    def restore_arrays(self, data: dict[str, np.ndarray]) -> None:
        """Inverse of :meth:`state_arrays`."""
        if data["active"].shape != self._act.shape:
            raise ValueError("checkpoint contact state does not match this mesh / rank count")
        self._act[:], self._lam[:] = data["active"], data["lam"]
        self._last_friction_pairs[:] = data["last_friction"]
        self._last_friction[:] = 0.0
        pair_node = np.arange(self.n * self.nb) // self.nb
        np.add.at(self._last_friction, pair_node, data["last_friction"])
        self.step_count, self.dissipation_total = int(data["counters"][0]), data["counters"][1]
        if "kkt_slots" in data and bool(data["kkt_built"]):
            self._kkt_restored = (data["kkt_slots"].astype(np.intp), data["kkt_bc_rows"])
        for k in range(len(self.bodies)):
            b = data[f"body{k}"]
            self.set_pose(k, centre=b[:3], axes=b[3:12].reshape(3, 3), radii=b[12:])
        if self._friction is not None:
            f = self._friction
            f.set_history(data["fr_xi"], data["fr_force"])

    @property
    def active(self) -> NDArray[np.bool_]:
        """Nodes in contact with at least one ellipsoid (owned nodes)."""
        return self._act.any(axis=1)

    @property
    def lam(self) -> FloatArray:
        """Normal multiplier per node in N (sum over the ellipsoids it touches)."""
        return np.where(self._act, self._lam, 0.0).sum(axis=1)

    def _project_pairs(self, x: FloatArray, pairs: NDArray[np.intp]):
        """Gap, outward normal and closest point of node ``pairs // nb`` (positions ``x`` of
        all owned nodes) on ellipsoid ``pairs % nb``."""
        nodes, body = pairs // self.nb, pairs % self.nb
        m = len(pairs)
        gap, nrm, point = np.zeros(m), np.zeros((m, 3)), np.zeros((m, 3))
        sels = [np.flatnonzero(body == k) for k in range(self.nb)]
        for sel, pr in zip(
            sels, closest_points([x[nodes[sel]] for sel in sels], self.bodies), strict=True
        ):
            gap[sel], nrm[sel], point[sel] = pr.gap, pr.normal, pr.point
        return nodes, body, gap, nrm, point

    def _gaps(self, x: FloatArray) -> FloatArray:
        """Signed gap of every owned node to every ellipsoid, (n, nb) [m] (read-only; the
        last result is reused while the positions and poses stay the same: the active-set
        test and the commit ask at the point Newton has just evaluated)."""
        hit = self._gap_cache
        if hit is not None and hit[0] == self._pose_version and np.array_equal(hit[1], x):
            return hit[2]
        out = np.zeros((len(x), self.nb))
        if len(x):
            for k, pr in enumerate(closest_points([x] * self.nb, self.bodies)):
                out[:, k] = pr.gap
        out.flags.writeable = False
        self._gap_cache = (self._pose_version, x.copy(), out)
        return out

    def _constraint(self, gap: FloatArray, pairs: NDArray[np.intp], lam: FloatArray) -> FloatArray:
        """The constraint residual [m] of the (node, ellipsoid) ``pairs`` with gaps ``gap``
        and multipliers ``lam`` [N]: the gap, plus the tissue's give ``c_i lam`` when the
        body is compliant (0 at equilibrium on the active set)."""
        if self._compliance is None:
            return gap
        return gap + self._compliance[pairs // self.nb] * lam

    def pair_forces(self):
        """Active (node, ellipsoid) pairs at the last converged step: (nodes, body index,
        force on the fabric [N] (normal multiplier plus friction), outward normal)."""
        pairs = np.flatnonzero(self._act.ravel())
        nodes, body, _, nrm, _ = self._project_pairs(self._positions(), pairs)
        f = self._lam.ravel()[pairs][:, None] * nrm + self._last_friction_pairs[pairs]
        return nodes, body, f, nrm

    # ------------------------------------------------------------------ controls
    @property
    def friction(self) -> _FrictionState | None:
        """Friction data (None when mu = 0: no friction objects are built)."""
        return self._friction

    def set_pose(
        self,
        k: int,
        *,
        centre: ArrayLike | None = None,
        axes: ArrayLike | None = None,
        radii: ArrayLike | None = None,
    ) -> None:
        """Move ellipsoid ``k`` in place: centre (3,) m, axes (3, 3) as columns, radii (3,) m."""
        if not (isinstance(k, int | np.integer) and 0 <= k < len(self.bodies)):
            raise ValueError(f"k must index a body in [0, {len(self.bodies)}), got {k!r}")
        c, Q, r = self.bodies[k]
        new = (
            c if centre is None else centre,
            Q if axes is None else axes,
            r if radii is None else radii,
        )
        c2, Q2, r2 = _check_bodies([new])[0]
        c[:], Q[:], r[:] = c2, Q2, r2
        self._pose_version += 1

    # ------------------------------------------------------------------ setup
    def _build_solver(self) -> None:
        ksp = PETSc.KSP().create(self.comm)
        prefix = self.params.prefix
        ksp.setOptionsPrefix(prefix)
        # the bordered matrix is indefinite (zero multiplier block): LU with pivoting
        set_defaults(prefix, direct_lu(self.comm))
        ksp.setFromOptions()
        self.ksp = ksp
        self._ksp_sizes = None

    def _build_area_forms(self) -> None:
        m = self.model
        mesh = m.mesh
        self.S = fem.FunctionSpace(mesh, m.V.ufl_element().sub_elements()[0])
        xs = self.S.tabulate_dof_coordinates()[: self.n]
        if self.S.dofmap.index_map.size_local != self.n or not np.allclose(xs, self.X):
            raise RuntimeError("scalar and vector spaces have different node layouts")
        J = ufl.Jacobian(mesh)
        g = ufl.grad(m.u)
        a0 = ufl.as_vector([J[i, 0] for i in range(3)])
        a1 = ufl.as_vector([J[i, 1] for i in range(3)])
        c0, c1 = a0 + g * a0, a1 + g * a1
        n0 = ufl.cross(a0, a1)
        nc = ufl.cross(c0, c1)
        ratio = ufl.sqrt(ufl.dot(nc, nc) / ufl.dot(n0, n0))  # current / reference area
        dx = m.dx_full
        w, v = ufl.TrialFunction(self.S), ufl.TestFunction(self.S)
        self._mass_form = fem.form(ratio * w * v * dx)
        self._area_form = fem.form(ratio * dx)
        self._M = fem_petsc.create_matrix(self._mass_form)

    # ------------------------------------------------------------------ geometry
    def _positions(self) -> FloatArray:
        u = self.model.u.x.array[: 3 * self.n].reshape(-1, 3)
        return self.X + u

    def lumped_area(self) -> FloatArray:
        """HRZ-lumped nodal areas (m^2) of the current configuration, owned nodes (collective)."""
        return self._lumped(self._mass_form, self._area_form)

    def _reference_area(self) -> FloatArray:
        """HRZ-lumped nodal areas (m^2) of the reference (mesh) configuration (collective)."""
        w, v = ufl.TrialFunction(self.S), ufl.TestFunction(self.S)
        dx = self.model.dx_full
        one = fem.Constant(self.model.mesh, 1.0)
        return self._lumped(fem.form(w * v * dx), fem.form(one * dx))

    def _lumped(self, mass_form: fem.FormMetaClass, area_form: fem.FormMetaClass) -> FloatArray:
        M = self._M
        M.zeroEntries()
        fem_petsc.assemble_matrix(M, mass_form)
        M.assemble()
        d = M.getDiagonal()
        diag = d.getArray(readonly=True).copy()
        total = self.comm.allreduce(fem.assemble_scalar(area_form), op=MPI.SUM)
        sdiag = self.comm.allreduce(float(diag.sum()), op=MPI.SUM)
        d.destroy()
        return diag * (total / sdiag)

    # ------------------------------------------------------------------ algebra
    def _kkt_matrix(
        self, pairs: NDArray[np.intp], bc_rows: NDArray[np.int32]
    ) -> tuple[BorderedMatrix, NDArray[np.intp], NDArray[np.bool_]]:
        """The bordered matrix serving the active ``pairs`` (flat node * nb + body), the
        position of each pair among its slots and the slots' in-use mask. Its slots are kept
        while they contain the active pairs and are not more than twice as many (+ 16); a
        new pattern takes the union with the old slots, so pairs that come and go between
        Newton passes keep their slot (and the LU its analysis). Collective."""
        kkt, slots, restored = self._kkt, self._kkt_slots, self._kkt_restored
        self._kkt_restored = None
        prev_bc = kkt.bc_rows if kkt is not None else None
        if kkt is None and restored is not None:  # a checkpoint's slots (restore_arrays)
            slots, prev_bc = restored
        fits = (
            prev_bc is not None
            and np.array_equal(prev_bc, bc_rows)
            and (kkt is None or kkt.matches(self._K))
            and len(slots) <= 2 * len(pairs) + 16
            and bool(np.isin(pairs, slots).all())
        )
        if not self.comm.allreduce(fits, op=MPI.LAND):
            if prev_bc is not None:
                if kkt is not None:
                    kkt.destroy()
                union = np.union1d(slots, pairs)
                slots = union if len(union) <= 2 * len(pairs) + 16 else pairs.copy()
            else:
                slots = pairs.copy()
            kkt = self._kkt = BorderedMatrix(self._K, slots // self.nb, bc_rows)
            self._kkt_slots = slots
        elif kkt is None:  # the checkpoint's slots fit: the matrix the run had
            kkt = self._kkt = BorderedMatrix(self._K, slots // self.nb, bc_rows)
            self._kkt_slots = slots
        where = np.searchsorted(slots, pairs)
        used = np.zeros(len(slots), dtype=bool)
        used[where] = True
        return kkt, where, used

    def _contact_terms(self, x: FloatArray, pairs: NDArray[np.intp], lam: FloatArray):
        """Gap, normal and friction terms of the active (node, ellipsoid) pairs at ``x``."""
        _, body, gap, nrm, point = self._project_pairs(x, pairs)
        force = lam[:, None] * nrm
        col = -nrm.copy()
        # curvature of the constraint: d(lam n)/dx = lam W (I + gap W)^-1 P with W the
        # Weingarten map of the body at p; its negative enters the tangent
        dndx = _weingarten(point, nrm, gap, body, self.bodies)
        blocks = -lam[:, None, None] * dndx
        fr = None
        if self._friction is not None:
            fr = self._friction.evaluate(
                point, pairs, nrm, body, lam, self.bodies, self._pose_version
            )
            force = force + fr.force
            col = col - fr.dforce_dlam
            # the friction law sees the closest point p: dp/dx = (I + gap W)^-1 P = P - gap
            # dn/dx, which matters for a node inside a compliant body (gap = -lam c); with
            # P alone Newton converged only linearly there (rate 0.92-0.97 per iteration)
            P = np.eye(3)[None] - nrm[:, :, None] * nrm[:, None, :]
            dpdx = P - gap[:, None, None] * dndx
            blocks = blocks + np.einsum("nij,njk->nik", fr.tangent, dpdx)
        kt_blocks = blocks
        return gap, nrm, force, col, kt_blocks, fr

    # ------------------------------------------------------------------ solve
    def _evaluate(self, xv: PETSc.Vec, f: PETSc.Vec, pairs, lam, bc_rows, bc_vals, free):
        """Residual of the bordered system at ``xv``: (r_u, constraint residual (the gaps,
        with the tissue's give on a compliant body), terms, |r_u free|, its max, max|bc
        error|, merit), all norms reduced over ranks."""
        n = self.n
        t0 = time.perf_counter()
        self.operator.residual(xv, f)
        t1 = time.perf_counter()
        xa = xv.getArray(readonly=True)
        x = self.X + xa[: 3 * n].reshape(-1, 3)
        gap, nrm, force, col, kt_blocks, fr = self._contact_terms(x, pairs, lam)
        gap = self._constraint(gap, pairs, lam)
        nodes = pairs // self.nb
        self.timers["assembly"] += t1 - t0
        self.timers["contact"] += time.perf_counter() - t1
        r = f.getArray(readonly=True).copy()
        urows = (3 * nodes[:, None] + np.arange(3)).ravel()
        np.add.at(r, urows, -force.ravel())
        r[bc_rows] = xa[bc_rows] - bc_vals
        comm = self.comm
        fnorm = math.sqrt(comm.allreduce(float(np.dot(r[free], r[free])), op=MPI.SUM))
        gmax = comm.allreduce(float(np.max(np.abs(gap))) if len(gap) else 0.0, op=MPI.MAX)
        bcmax = comm.allreduce(
            float(np.max(np.abs(r[bc_rows]))) if len(bc_rows) else 0.0, op=MPI.MAX
        )
        # line-search merit: force residual and constraint violation (through the membrane
        # stiffness scale of a node, N/m) in one norm
        g2 = comm.allreduce(float(np.dot(gap, gap)), op=MPI.SUM)
        merit = math.sqrt(fnorm**2 + self.stiffness_scale**2 * g2)
        return r, gap, (nrm, col, kt_blocks, fr), fnorm, gmax, bcmax, merit

    def _newton(self, xv: PETSc.Vec, nodes, lam, bc_rows, bc_vals, set_changed=None):
        """Newton on the bordered system with the active (node, ellipsoid) pairs ``nodes``
        (flat indices node * nb + body) fixed, with a
        backtracking line search on the merit of :meth:`_evaluate` (needed at stick/slip
        transitions, where the return map makes the residual only piecewise smooth, and where
        released fabric wrinkles).

        Returns (ok, iterations, lam, last friction evaluation)."""
        p = self.params
        n = self.n
        f = xv.duplicate()
        free = np.ones(5 * n, dtype=bool)
        free[bc_rows] = False
        stol = p.newton_stol * self.L
        atol = 1e-13 * self.force_scale
        last_step = np.inf
        r, gap, terms, fnorm, gmax, bcmax, merit = self._evaluate(
            xv, f, nodes, lam, bc_rows, bc_vals, free
        )
        prev = [fnorm]
        stalled = 0
        for its in range(p.max_newton + 1):
            nrm, col, kt_blocks, fr = terms
            if not math.isfinite(fnorm):
                return False, its, lam, fr
            geom_ok = gmax <= 1e-3 * self.gap_tol and bcmax <= stol
            # reference: the largest residual of the pass (the first one can be ~0 when only
            # the gaps are violated, e.g. after the body moved)
            fref = max(prev)
            if geom_ok and (fnorm <= atol or (its > 0 and fnorm <= p.newton_rtol * fref)):
                return True, its, lam, fr
            if its > 0 and geom_ok and last_step <= stol:
                return True, its, lam, fr
            if its >= 2 and geom_ok and fnorm <= 1e-6 * fref and fnorm > 0.5 * prev[-2]:
                return True, its, lam, fr  # round-off floor reached
            if its == p.max_newton:
                break
            t0 = time.perf_counter()
            self._K = self.operator.jacobian(xv, self._K)
            t1 = time.perf_counter()
            kkt, where, in_use = self._kkt_matrix(nodes, bc_rows)
            ns = len(in_use)
            slot_col, slot_row = np.zeros((ns, 3)), np.zeros((ns, 3))
            slot_blocks = np.zeros((ns, 3, 3))
            slot_col[where], slot_row[where], slot_blocks[where] = col, -nrm, kt_blocks
            slot_diag = np.zeros(ns)  # d(constraint)/d(lam): minus the tissue's compliance
            if self._compliance is not None:
                slot_diag[where] = -self._compliance[nodes // self.nb]
            B = kkt.update(self._K, slot_col, slot_row, slot_blocks, in_use, slot_diag)
            t2 = time.perf_counter()
            self.timers["assembly"] += t1 - t0
            self.timers["contact"] += t2 - t1
            rhs, sol = B.createVecs()
            ra = rhs.getArray()
            ra[: 5 * n] = -r
            ra[5 * n :] = 0.0
            ra[5 * n + where] = gap
            if B.getSizes() != self._ksp_sizes:  # the active set changed the system size
                self.ksp.reset()
                self.ksp.setFromOptions()
                self._ksp_sizes = B.getSizes()
            self.ksp.setOperators(B)
            self.ksp.solve(rhs, sol)
            self.timers["solve"] += time.perf_counter() - t2
            ok_solve = self.ksp.getConvergedReason() > 0
            s = sol.getArray(readonly=True).copy()
            s = np.concatenate([s[: 5 * n], s[5 * n + where]])  # the slots in use
            rhs.destroy()
            sol.destroy()
            ok_solve = ok_solve and bool(np.all(np.isfinite(s)))
            if not self.comm.allreduce(ok_solve, op=MPI.LAND):
                return False, its, lam, fr
            x0 = xv.getArray(readonly=True).copy()
            lam0 = lam
            # the largest admissible fraction of the step (e.g. no self-intersection)
            alpha = 1.0 if self.step_filter is None else self.step_filter(x0, s[: 5 * n])
            used = filtered = alpha
            for _ in range(8):  # backtracking: alpha = 1, 1/2, ..., 1/128
                used = alpha
                xv.getArray()[:] = x0 + alpha * s[: 5 * n]
                lam = lam0 + alpha * s[5 * n :]
                trial = self._evaluate(xv, f, nodes, lam, bc_rows, bc_vals, free)
                if trial[6] <= (1.0 - 1e-4 * alpha) * merit or trial[3] <= atol:
                    break
                alpha *= 0.5
            r, gap, terms, fnorm, gmax, bcmax, merit = trial
            prev.append(fnorm)
            log.debug(
                "newton %d: |r| %.3e N (ref %.3e), max|gap| %.2e m, line search %.4g "
                "(step filter %.4g), %d active, %s sticking (this rank)",
                its + 1,
                fnorm,
                max(prev),
                gmax,
                used,
                filtered,
                len(nodes),
                "-" if terms[3] is None else int(terms[3].stick.sum()),
            )
            last_step = used * self.comm.allreduce(
                float(np.max(np.abs(s[: 3 * n]))) if n else 0.0, op=MPI.MAX
            )
            # give up early when the line search keeps stalling (the caller cuts the step)
            stalled = stalled + 1 if used < 1.0 / 16.0 else 0
            if stalled >= p.newton_stall_limit:
                return False, its + 1, lam, terms[3]
            # semismooth variant: leave as soon as the iterate says the set is wrong
            if set_changed is not None and set_changed(xv, lam):
                return True, its + 1, lam, terms[3]
        return False, its, lam, terms[3]

    def solve_step(self, lam_load: float) -> ContactStepRecord:
        """Solve the static equilibrium with contact at load factor ``lam_load`` and the current
        body poses, starting from the last converged state.

        Raises :class:`ContactDivergence` (state restored) if Newton or the active set fails.
        """
        t0 = time.perf_counter()
        m, p = self.model, self.params
        n = self.n
        saved_u, saved_t = m.u.x.array.copy(), m.theta.x.array.copy()
        saved_active, saved_lam = self._act.copy(), self._lam.copy()
        saved_load = float(m.lam.value)

        def fail(message: str) -> NoReturn:
            self._restore(saved_u, saved_t, saved_active, saved_lam, saved_load)
            raise ContactDivergence(message)

        def positions(xv: PETSc.Vec) -> FloatArray:
            return self.X + xv.getArray(readonly=True)[: 3 * n].reshape(-1, 3)

        m.set_load_factor(lam_load)
        bc_rows, bc_vals = m.bc_rows_and_values(lam_load)
        fixed = np.zeros(3 * n, dtype=int)
        ub = bc_rows[bc_rows < 3 * n]
        fixed[ub] = 1
        can_touch = (self.slave & (fixed.reshape(-1, 3).sum(axis=1) < 3))[:, None]
        xv = m.create_vector()
        m.get_state(xv)
        xv.getArray()[bc_rows] = bc_vals
        active = self._act & can_touch  # (n, nb): node i against ellipsoid k
        # predictor: activate the nodes that the prescribed motions made penetrate (on their
        # most penetrated ellipsoid; see changes_of)
        g0 = self._gaps(positions(xv))
        compliant = self._compliance is not None
        if n and self.nb and compliant:  # every penetrating pair is a constraint of its own
            active |= can_touch & (g0 < -self.gap_tol)
        elif n and self.nb:
            k0 = np.argmin(g0, axis=1)
            new = can_touch[:, 0] & ~active.any(axis=1) & (g0[np.arange(n), k0] < -self.gap_tol)
            active[np.flatnonzero(new), k0[new]] = True
        lam_pairs = np.where(active, self._lam, 0.0).ravel()
        newton_total, sets = 0, 0
        fr = None
        flips = np.zeros(active.shape, dtype=int)
        frozen = np.zeros(active.shape, dtype=bool)
        released = np.zeros(active.shape, dtype=bool)  # cycling pairs let go for this step

        def changes_of(xv: PETSc.Vec, pairs, lam_a) -> tuple[NDArray, NDArray, int]:
            """Pairs to release (tensile multiplier) and to add (penetrating), and their
            number over all ranks."""
            lam_all = np.zeros(n * self.nb)
            lam_all[pairs] = lam_a
            gap = np.where(released, np.inf, self._gaps(positions(xv)))
            lam_max = self.comm.allreduce(
                float(np.max(np.abs(lam_a))) if len(lam_a) else 0.0, op=MPI.MAX
            )
            drop = active & (lam_all.reshape(n, self.nb) < -p.multiplier_tolerance * lam_max)
            if compliant:  # each pair on its own: the tissue under it gives way
                add = can_touch & ~active & (gap < -self.gap_tol)
            else:
                # one constraint per node, on its most penetrated ellipsoid (the union rule), but
                # chosen between Newton solves only: within a solve the body is fixed (a union
                # projection switching body at every iterate makes Newton cycle in the crease),
                # and two constraints on one node with nearly parallel normals make the bordered
                # matrix nearly singular
                worst = np.argmin(gap, axis=1) if self.nb else np.zeros(n, dtype=np.intp)
                gmin = gap[np.arange(n), worst] if self.nb else np.zeros(n)
                onehot = np.zeros_like(active)
                onehot[np.arange(n), worst] = True
                penetrating = can_touch[:, 0] & (gmin < -self.gap_tol)
                own = np.where(active, gap, np.inf).min(axis=1) if self.nb else np.zeros(n)
                move = active.any(axis=1) & penetrating & (gmin < own - self.gap_tol)
                drop |= active & move[:, None]
                add = onehot & (penetrating & ~active.any(axis=1) | move)[:, None]
            # pairs that kept flipping in this step stay active (see the loop below), even
            # where the rule above moved the node to the other ellipsoid: a node pushed into
            # the crease then keeps both constraints
            drop &= ~frozen
            add |= frozen & ~active
            return drop, add, self.comm.allreduce(int(drop.sum() + add.sum()), op=MPI.SUM)

        while True:
            sets += 1
            pairs = np.flatnonzero(active.ravel())
            early = None
            if p.semismooth_passes >= sets:  # the set may change inside Newton (semismooth)
                early = lambda xv, lam_a, pairs=pairs: changes_of(xv, pairs, lam_a)[2] > 0  # noqa: E731
            ok, its, lam_a, fr = self._newton(
                xv, pairs, lam_pairs[pairs], bc_rows, bc_vals, set_changed=early
            )
            newton_total += its
            if not ok:
                fail(
                    f"Newton failed at load factor {lam_load:.6g} in active-set pass {sets} "
                    f"({len(pairs)} active node-ellipsoid pairs on rank {self.comm.rank})"
                )
            lam_pairs[:] = 0.0
            lam_pairs[pairs] = lam_a
            drop, add, changes = changes_of(xv, pairs, lam_a)
            if changes == 0:  # (an early exit always has changes: same test)
                # a kept pair that pulls by more than 1 % of the largest multiplier is let go
                # for the rest of the step (once), and the passes go on without it; the step
                # then stands if it penetrates by at most release_penetration (below)
                if not self.comm.allreduce(bool(frozen.any()), op=MPI.LOR):  # on every rank
                    break
                lam_max = self.comm.allreduce(
                    float(np.max(np.abs(lam_pairs), initial=0.0)), op=MPI.MAX
                )
                lam_nb = lam_pairs.reshape(n, self.nb)
                pulling = frozen & (lam_nb < -1e-2 * lam_max)
                if not self.comm.allreduce(bool(pulling.any()), op=MPI.LOR):
                    break
                pull = self.comm.allreduce(float(np.min(lam_nb[pulling], initial=0.0)), op=MPI.MIN)
                if self.comm.allreduce(bool(released.any()), op=MPI.LOR):
                    fail(
                        f"active set cycling at load factor {lam_load:.6g}: a pair kept active "
                        f"pulls with {pull:.3g} N after cycling pairs were released"
                    )
                log.debug("active set cycling: releasing pairs that pull with up to %.3g N", pull)
                released |= pulling
                frozen &= ~pulling
                active &= ~pulling
                lam_pairs[pulling.ravel()] = 0.0
                continue
            if sets >= p.max_active_set:
                fail(
                    f"active set still changing after {sets} passes at load factor "
                    f"{lam_load:.6g} ({changes} changes)"
                )
            active = (active & ~drop) | add
            lam_pairs[drop.ravel()] = 0.0
            # anti-cycling: a pair switched in or out 6 times in one step is kept active for
            # the rest of the step (adhesion up to 1 % of the largest multiplier accepted)
            flips += drop | add
            frozen |= (flips >= 6) & ~released
        if self.comm.allreduce(bool(released.any()), op=MPI.LOR):
            depth = self.comm.allreduce(
                float(-np.min(self._gaps(positions(xv))[released], initial=np.inf)), op=MPI.MAX
            )
            if depth > self.release_penetration:
                fail(
                    f"active set cycling at load factor {lam_load:.6g}: a released pair "
                    f"penetrates by {depth:.3g} m > release_penetration "
                    f"{self.release_penetration:.3g} m"
                )
        # commit
        m.set_state(xv)
        x = positions(xv)
        gap = self._gaps(x)
        self._act, self._lam = active, lam_pairs.reshape(n, self.nb)
        self.step_count += 1
        n_stick = n_slip = 0
        diss = 0.0
        friction = np.zeros((n * self.nb, 3))
        if self._friction is not None and fr is not None:
            friction[pairs] = fr.force
            n_stick = self.comm.allreduce(int(fr.stick.sum()), op=MPI.SUM)
            n_slip = self.comm.allreduce(int((~fr.stick).sum()), op=MPI.SUM)
            diss = self.comm.allreduce(float(fr.dissipation.sum()), op=MPI.SUM)
            self._friction.commit(x, self.bodies, friction)
        self._last_friction_pairs = friction
        self._last_friction = friction.reshape(n, self.nb, 3).sum(axis=1)
        self.dissipation_total += diss
        # on a compliant body the penetration past the tissue's give counts (lam = 0 off
        # the active set); the give itself is the indentation
        give = np.zeros(n * self.nb)
        if compliant:
            give = np.repeat(self._compliance, self.nb) * lam_pairs
        d = diagnostics(gap.ravel() + give, lam_pairs, active=active.ravel())
        indent = self.comm.allreduce(float(np.max(give, initial=0.0)), op=MPI.MAX)
        n_act = self.comm.allreduce(int(active.any(axis=1).sum()), op=MPI.SUM)
        pen = self.comm.allreduce(d.max_penetration, op=MPI.MAX)
        lmin = self.comm.allreduce(d.min_multiplier if d.n_active else np.inf, op=MPI.MIN)
        comp = self.comm.allreduce(d.complementarity, op=MPI.MAX)
        total = self.comm.allreduce(float(lam_pairs.sum()), op=MPI.SUM)
        return ContactStepRecord(
            self.step_count,
            float(lam_load),
            n_act,
            pen,
            lmin if n_act else 0.0,
            comp,
            sets,
            newton_total,
            n_stick,
            n_slip,
            diss,
            total,
            time.perf_counter() - t0,
            max_indentation=indent,
        )

    def advance(
        self,
        lam_load: float,
        *,
        poses: dict[int, tuple[ArrayLike | None, ArrayLike | None, ArrayLike | None]] | None = None,
        max_cutbacks: int = 6,
        on_step: Callable[[ContactStepRecord], None] | None = None,
    ) -> list[ContactStepRecord]:
        """Go from the current load factor and poses to ``lam_load`` and the target ``poses``
        ({k: (centre, axes, radii)}, None entries unchanged) in sub-steps, halving the
        sub-step after a failed one (at most ``max_cutbacks`` halvings in a row) and doubling
        it after an easy one. Centres, radii and the load factor are interpolated linearly,
        axes by spherical linear interpolation. Returns the records of the sub-steps.

        Raises :class:`ContactDivergence` (state restored to the last converged sub-step).
        """
        if not (isinstance(max_cutbacks, int) and max_cutbacks >= 0):
            raise ValueError(f"max_cutbacks must be an integer >= 0, got {max_cutbacks!r}")
        from scipy.spatial.transform import Rotation, Slerp

        lam0 = float(self.model.lam.value)
        starts, ends, slerps = {}, {}, {}
        for k, (c, Q, r) in (poses or {}).items():
            if not (isinstance(k, int | np.integer) and 0 <= k < len(self.bodies)):
                raise ValueError(f"poses keys must index bodies in [0, {len(self.bodies)})")
            c0, Q0, r0 = (a.copy() for a in self.bodies[k])
            c1 = c0 if c is None else np.asarray(c, dtype=float)
            Q1 = Q0 if Q is None else np.asarray(Q, dtype=float)
            r1 = r0 if r is None else np.asarray(r, dtype=float)
            _check_bodies([(c1, Q1, r1)])
            starts[k], ends[k] = (c0, Q0, r0), (c1, Q1, r1)
            if np.linalg.det(Q0) > 0 and np.linalg.det(Q1) > 0:
                slerps[k] = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([Q0, Q1])))

        def place(frac: float) -> None:
            for k in starts:
                (c0, Q0, r0), (c1, Q1, r1) = starts[k], ends[k]
                Q = slerps[k](frac).as_matrix() if k in slerps else (Q0 if frac < 1 else Q1)
                self.set_pose(k, centre=c0 + frac * (c1 - c0), axes=Q, radii=r0 + frac * (r1 - r0))

        done, h, cuts, records = 0.0, 1.0, 0, []
        while done < 1.0 - 1e-12:
            trial = min(1.0, done + h)
            place(trial)
            try:
                rec = self.solve_step(lam0 + trial * (lam_load - lam0))
            except ContactDivergence:
                place(done)
                cuts += 1
                if cuts > max_cutbacks:
                    raise
                h *= 0.5
                continue
            records.append(rec)
            if on_step is not None:
                on_step(rec)
            done, cuts = trial, 0
            if rec.newton_iterations <= 10 * rec.active_set_iterations:
                h *= 2.0
        return records

    def _restore(self, u, th, active, lam, load_factor: float) -> None:
        m = self.model
        m.set_load_factor(load_factor)
        m.u.x.array[:] = u
        m.theta.x.array[:] = th
        m.update_director()
        self._act, self._lam = active, lam

    # ------------------------------------------------------------------ outputs
    def state(self) -> ContactState:
        """Contact state of the owned nodes at the last converged step (collective: areas).
        Per node: gap = smallest over the ellipsoids; lam_n = sum of its multipliers;
        normal = direction of its normal force (a node in the crease between two ellipsoids
        has two constraints)."""
        n = self.n
        x = self._positions()
        gap = self._gaps(x).min(axis=1) if self.nb else np.full(n, np.inf)
        nodes, _, f_pairs, nrm = self.pair_forces()
        lam_p = self._lam.ravel()[np.flatnonzero(self._act.ravel())]
        fn = np.zeros((n, 3))
        np.add.at(fn, nodes, lam_p[:, None] * nrm)
        mag = np.linalg.norm(fn, axis=1)
        normal = np.where(mag[:, None] > 0, fn / np.maximum(mag, 1e-300)[:, None], 0.0)
        lam = self.lam
        f = fn + self._last_friction
        area = self.lumped_area()
        return ContactState(
            x, gap, self.active, lam, normal, self._last_friction.copy(), f, -f, area, lam / area
        )

    def _forces_on_body(self) -> FloatArray:
        """Contact force on the body per owned node [N] (sum over its pairs), (n, 3)."""
        nodes, _, f_pairs, _ = self.pair_forces()
        f = np.zeros((self.n, 3))
        np.add.at(f, nodes, -f_pairs)
        return f

    def resultant(self) -> FloatArray:
        """Resultant contact force on the body in N (sum over all ranks), (3,)."""
        return self.comm.allreduce(self._forces_on_body().sum(axis=0), op=MPI.SUM)

    def torque(self, joint: ArrayLike, *, nodes: Callable[[np.ndarray], np.ndarray] | None = None):
        """Eq. 28 torque (N m) the fabric exerts on the body about ``joint``, over the nodes
        selected by ``nodes(X)`` (reference coordinates, shape (3, N); all nodes if None)."""
        sel = None if nodes is None else np.asarray(nodes(self.X.T.copy()), dtype=bool)
        tau = (
            joint_torque(self._positions(), self._forces_on_body(), joint, nodes=sel)
            if self.n
            else np.zeros(3)
        )
        return self.comm.allreduce(tau, op=MPI.SUM)

    def reactions(self) -> tuple[NDArray[np.int32], FloatArray]:
        """Support reactions at the constrained rows (local (u, theta) layout) in N: the force
        the supports exert on the fabric, ``R(x) - f_contact`` at those rows (collective)."""
        m = self.model
        rows, _ = m.bc_rows_and_values(float(m.lam.value))
        xv = m.create_vector()
        m.get_state(xv)
        f = xv.duplicate()
        self.operator.residual(xv, f)
        r = f.getArray(readonly=True).copy()
        r[: 3 * self.n] += self._forces_on_body().ravel()  # minus the force on the fabric
        return rows, r[rows]


def _weingarten(point, nrm, gap, body, bodies) -> FloatArray:
    """d n / d x (N, 3, 3) of the exact projection onto the ellipsoids ``body`` at ``point``:
    ``W (I + gap W)^-1`` with ``W = P H P / |grad f|`` (H the Hessian of Eq. 26)."""
    m = len(point)
    out = np.zeros((m, 3, 3))
    if m == 0:
        return out
    P = np.eye(3)[None] - nrm[:, :, None] * nrm[:, None, :]
    for k, (c, Q, r) in enumerate(bodies):
        sel = np.flatnonzero(body == k)
        if sel.size == 0:
            continue
        H = 2.0 * (Q / r**2) @ Q.T
        grad = 2.0 * ((point[sel] - c) @ Q / r**2) @ Q.T
        gn = np.linalg.norm(grad, axis=1)
        W = np.einsum("nij,jk,nkl->nil", P[sel], H, P[sel]) / gn[:, None, None]
        A = np.eye(3)[None] + gap[sel, None, None] * W
        out[sel] = np.linalg.solve(A, W)
    return out


class _FrictionEval:
    """Friction at the active nodes for one Newton iterate (internal)."""

    def __init__(self, force, tangent, dforce_dlam, stick, dissipation):
        self.force, self.tangent, self.dforce_dlam = force, tangent, dforce_dlam
        self.stick, self.dissipation = stick, dissipation


class _FrictionState:
    """History of the regularised Coulomb law per (node, ellipsoid) pair: body-local
    coordinates of the last contact point and the old friction force.

    Only created when mu > 0.
    """

    def __init__(self, n: int, nb: int, mu: float, kt: float) -> None:
        self.mu, self.kt, self.nb = mu, kt, nb
        self.xi = np.zeros((n * nb, 3))  # body-local coordinates of the last contact point
        self.force_old = np.zeros((n * nb, 3))
        # anchors depend on the pairs, the poses and xi only: fixed within a step's Newton
        self._anchors: tuple[tuple[int, bytes], FloatArray] | None = None

    def commit(self, x: FloatArray, bodies, force: FloatArray) -> None:
        """Anchor every pair at the closest point of its ellipsoid; ``force`` (n * nb, 3)."""
        if len(x) == 0:
            return
        xi = self.xi.reshape(len(x), self.nb, 3)
        for k, ((c, Q, _), pr) in enumerate(
            zip(bodies, closest_points([x] * self.nb, bodies), strict=True)
        ):
            xi[:, k] = (pr.point - c) @ Q
        self.force_old[:] = force
        self._anchors = None

    def set_history(self, xi: FloatArray, force_old: FloatArray) -> None:
        """Restore the history (checkpoint)."""
        self.xi[:], self.force_old[:] = xi, force_old
        self._anchors = None

    def anchors(self, pairs, body, bodies, pose_version: int) -> FloatArray:
        """The body material point each pair touched at the last converged step, carried
        with the body and put back on its (possibly resized) surface (m, 3) [m]; reused
        while the pairs, the poses (``pose_version``) and the history stay the same."""
        key = (pose_version, pairs.tobytes())
        if self._anchors is not None and self._anchors[0] == key:
            return self._anchors[1]
        anchor = np.empty((len(pairs), 3))
        sels = [np.flatnonzero(body == k) for k in range(len(bodies))]
        moved = [c + self.xi[pairs[sel]] @ Q.T for sel, (c, Q, _) in zip(sels, bodies, strict=True)]
        for sel, pr in zip(sels, closest_points(moved, bodies), strict=True):
            anchor[sel] = pr.point
        anchor.flags.writeable = False
        self._anchors = (key, anchor)
        return anchor

    def evaluate(self, point, pairs, nrm, body, lam, bodies, pose_version: int) -> _FrictionEval:
        m = len(pairs)
        P = np.eye(3)[None] - nrm[:, :, None] * nrm[:, None, :]
        anchor = self.anchors(pairs, body, bodies, pose_version)
        du = np.einsum("nij,nj->ni", P, point - anchor)
        f_old = self.force_old[pairs]
        trial = np.einsum("nij,nj->ni", P, f_old) - self.kt * du
        lam_pos = np.maximum(lam, 0.0)
        rm = coulomb_return_map(lam_pos, trial, self.mu, penalty=self.kt)
        tangent = self.kt * P.copy()
        dlam = np.zeros((m, 3))
        slip = ~rm.stick
        if np.any(slip):
            mag = np.linalg.norm(trial[slip], axis=1)
            s = trial[slip] / np.maximum(mag, 1e-300)[:, None]
            proj = np.eye(3)[None] - s[:, :, None] * s[:, None, :]
            fac = self.mu * lam_pos[slip] * self.kt / np.maximum(mag, 1e-300)
            tangent[slip] = fac[:, None, None] * np.einsum("nij,njk->nik", proj, P[slip])
            dlam[slip] = np.where((lam[slip] > 0)[:, None], self.mu * s, 0.0)
        return _FrictionEval(rm.force, tangent, dlam, rm.stick, rm.dissipation)
