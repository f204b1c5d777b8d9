"""The fabric shell model: spaces, nodal directors, compiled forms and the discrete system.

Unknowns per node A (Man & Swan 2007, Eq. 10): the midsurface displacement u_A (3) and two
rotations theta_A (2) in the nodal fibre basis. The energy is written in UFL in terms of the
interpolated displacement u and the interpolated *nodal* director d = sum_A N_A d_A(theta_A)
(Eq. 5), so that rigid motions give zero strain exactly. Residual and Jacobian blocks in
(u, d) come from ``ufl.derivative`` of that energy; the nodal chain rule of Eq. 10,
d_A = d_A(theta_A) from Euler's formula, turns them into the (u, theta) system:

    R = P^T R_w,        K = P^T K_w P + G,     P = diag(I, dd_A/dtheta_A),
    G_A = sum_k (R_d)_Ak d2 d_Ak / dtheta_A^2      (nodal, 2x2)

Element: quadratic Lagrange (9-node quadrilaterals by default) for u and theta, with full
quadrature for bending and reduced quadrature for membrane and transverse shear (selective
reduced integration, Hughes 1987), which removes membrane and shear locking; see
docs/results/verification.md for the measurements behind this choice.

Model / state / control: forms are compiled once in the constructor; the load factor ``lam``
is a ``fem.Constant`` and prescribed values are arrays updated in place.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import dolfinx
import dolfinx.fem.petsc as fem_petsc
import numpy as np
import ufl
from dolfinx import fem, la
from mpi4py import MPI
from petsc4py import PETSc

from ..mesh import SurfaceMesh
from . import rotation
from .conditions import (
    Clamp,
    EdgeMoment,
    EdgeTraction,
    Gravity,
    Pin,
    PointForce,
    PointPin,
    Prescribed,
    Pressure,
    Symmetry,
)
from .hysteresis import YarnFriction
from .kinematics import lamina_frame, shell_strains
from .material import (
    DecrimpingFabric,
    FabricMaterial,
    bending_energy,
    decrimping_membrane_energy,
    membrane_energy,
    shear_energy,
)
from .viscosity import MembraneViscosity

__all__ = ["ShellModel", "Quadrature", "SCHEMES"]

#: The ways to integrate membrane and shear (:class:`Quadrature` ``scheme``).
SCHEMES = ("psri", "sri", "mitc9")
#: The quadrature degree whose Gauss points (3 x 3 on quadrilaterals) the MITC9 kernels
#: integrate at; the material histories of a MITC9 model live at its points.
MITC_DEGREE = 4


@dataclass(frozen=True, kw_only=True)
class Quadrature:
    """How the membrane and transverse-shear energies are integrated (bending: ``full``).

    ``scheme = "psri"`` (default): partial selective reduced integration (Arnold & Brezzi
    1993/1997; the weight of FEniCS-Shells): in each cell a fraction alpha of the membrane
    and shear energies is integrated with the full rule and 1 - alpha with the reduced one,

        alpha = min(1, psri_factor x t^2 / h^2),    h = the cell diameter.

    The fully integrated part has no zero-energy modes of its own, so the element has exactly
    the six rigid modes; because alpha ~ (t/h)^2 is the ratio of bending to membrane
    stiffness at the mesh scale, it adds at most O(1) x the bending stiffness to
    inextensional modes and so does not lock as t -> 0 (docs/shell_element.md).

    ``scheme = "mitc9"``: assumed covariant membrane and transverse-shear strains from the
    tying points of MITC9 (Bucalem & Bathe 1993), integrated with the full rule; no
    spurious modes and no locking without a weight (:mod:`clothfem.shell.mitc`: hand-written
    kernels, with every material law; 9-node quadrilaterals only).

    ``scheme = "sri"``: selective reduced integration (Hughes 1987) with a constant blend
    ``stabilization`` of the fully integrated membrane energy (0: plain SRI, which leaves a
    spurious zero-energy mode on a free tube); kept for comparison.

    The defaults ``full`` = 4 and ``reduced`` = 2 are 3x3 and 2x2 Gauss points on
    quadrilaterals.
    """

    full: int = 4
    reduced: int = 2
    scheme: str = "psri"
    psri_factor: float = 1.0
    stabilization: float = 0.0

    def __post_init__(self) -> None:
        for name in ("full", "reduced"):
            if getattr(self, name) not in range(1, 11):
                raise ValueError(f"Quadrature {name} must be an integer in 1..10")
        if self.scheme not in SCHEMES:
            raise ValueError(
                f"Quadrature scheme must be one of {', '.join(SCHEMES)}, got {self.scheme!r}"
            )
        if not (0.0 < self.psri_factor <= 1e6):
            raise ValueError(
                f"Quadrature psri_factor must be in (0, 1e6], got {self.psri_factor!r}"
            )
        if not (0.0 <= self.stabilization <= 1.0):
            raise ValueError(
                f"Quadrature stabilization must be in [0, 1], got {self.stabilization!r}"
            )
        if self.scheme != "sri" and self.stabilization != 0.0:
            raise ValueError("Quadrature stabilization is a parameter of scheme 'sri' only")


def _blend(density, dx_r, dx_f, alpha):
    """(1 - alpha) x reduced + alpha x full quadrature of an energy density."""
    if isinstance(alpha, float) and alpha == 0.0:
        return density * dx_r
    return (1.0 - alpha) * density * dx_r + alpha * density * dx_f


def _owned_nodes(V: fem.FunctionSpace) -> int:
    return V.dofmap.index_map.size_local


def _assemble_owned(form: fem.FormMetaClass) -> np.ndarray:
    """Assemble a linear form and return its owned entries (ghost contributions added)."""
    b = fem_petsc.assemble_vector(form)
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    out = b.getArray(readonly=True).copy()
    b.destroy()
    return out


class ShellModel:
    """A fabric shell on a :class:`~clothfem.mesh.SurfaceMesh` with loads and supports.

    Parameters
    ----------
    surface: the fabric mesh (2-D manifold in 3-D).
    material: the fabric material.
    thickness: fabric thickness t [m] (> 0).
    loads, supports: sequences from :mod:`clothfem.shell.conditions`.
    warp: global vector whose projection on the surface is the warp (material 1) direction.
    degree: polynomial degree of u and theta (2 recommended).
    quadrature: see :class:`Quadrature`.
    """

    def __init__(
        self,
        surface: SurfaceMesh,
        *,
        material: FabricMaterial,
        thickness: float,
        loads: Sequence = (),
        supports: Sequence = (),
        warp: Sequence[float] = (1.0, 0.0, 0.0),
        degree: int = 2,
        quadrature: Quadrature = Quadrature(),
    ) -> None:
        if not (np.isfinite(thickness) and thickness > 0):
            raise ValueError(f"thickness must be a finite number > 0 (metres), got {thickness!r}")
        mesh = surface.mesh
        if mesh.topology.dim != 2 or mesh.geometry.dim != 3:
            raise ValueError(
                "mesh must be a surface mesh in 3-D (topological dim 2, geometric dim 3), got "
                f"dims {mesh.topology.dim}/{mesh.geometry.dim}"
            )
        if degree not in (1, 2):
            raise ValueError(f"degree must be 1 or 2, got {degree!r}")
        self.surface, self.mesh, self.comm = surface, mesh, mesh.comm
        self.material, self.thickness, self.degree = material, float(thickness), degree
        self.loads, self.supports = tuple(loads), tuple(supports)
        for c in (*self.supports, *self.loads):  # one-line error on an unknown tag
            for name in (getattr(c, "where", None), getattr(c, "on", None)):
                if isinstance(name, str):
                    surface.facets(name)

        family = "Q" if mesh.topology.cell_type == dolfinx.mesh.CellType.quadrilateral else "P"
        self.V = fem.VectorFunctionSpace(mesh, (family, degree), dim=3)  # u and d
        self.Vt = fem.VectorFunctionSpace(mesh, (family, degree), dim=2)  # theta
        self.n_owned = _owned_nodes(self.V)
        self.n_local = self.n_owned + self.V.dofmap.index_map.num_ghosts
        self.x_nodes = self.V.tabulate_dof_coordinates()  # (n_local, 3)

        # Controls
        self.lam = fem.Constant(mesh, 0.0)

        # State
        self.u = fem.Function(self.V, name="displacement")
        self.theta = fem.Function(self.Vt, name="rotation")
        self.d = fem.Function(self.V, name="director")
        self.D = fem.Function(self.V, name="reference_director")

        self._build_directors()
        self._build_supports()
        self.quadrature = quadrature
        self._build_forms(warp, quadrature)
        self._Rw_at: np.ndarray | None = None  # state at which self._Rw was assembled
        self._yarn_strain: fem.Expression | None = None  # built on first use
        self._build_transfer()
        self.update_director()

    # ------------------------------------------------------------------ geometry
    def _node_mask(self, where) -> np.ndarray:
        """Boolean mask over local nodes (owned + ghost), consistent across ranks."""
        if isinstance(where, str):
            facets = self.surface.facets(where)
            nodes = fem.locate_dofs_topological(self.V, 1, facets)
        else:
            nodes = np.flatnonzero(np.asarray(where(self.x_nodes.T.copy()), dtype=bool))
        marker = fem.Function(fem.FunctionSpace(self.mesh, self.V.ufl_element().sub_elements()[0]))
        marker.x.array[nodes] = 1.0
        marker.x.scatter_reverse(la.ScatterMode.add)
        marker.x.scatter_forward()
        return marker.x.array > 0

    def _nodal_normals(self, out: fem.Function) -> np.ndarray:
        """Unit cell normals of the reference surface summed at the nodes into ``out``
        (collective) and returned normalised, (n_local, 3); nodes where they cancel
        (|sum| < 0.5) get NaN."""
        mesh, V = self.mesh, self.V
        J = ufl.Jacobian(mesh)
        t1, t2 = (ufl.as_vector([J[i, k] for i in range(3)]) for k in (0, 1))
        n = ufl.cross(t1, t2)
        points = V.element.interpolation_points()
        expr = fem.Expression(n / ufl.sqrt(ufl.dot(n, n)), points)
        n_cells = mesh.topology.index_map(2).size_local  # may be 0 on a rank
        acc = np.zeros((self.n_local, 3))
        if n_cells:
            values = expr.eval(np.arange(n_cells, dtype=np.int32)).reshape(n_cells, -1, 3)
            dofs = V.dofmap.list.array.reshape(-1, len(points))[:n_cells]
            np.add.at(acc, dofs.ravel(), values.reshape(-1, 3))
        out.x.array[:] = acc.ravel()
        out.x.scatter_reverse(la.ScatterMode.add)
        out.x.scatter_forward()
        normals = out.x.array.reshape(-1, 3).copy()
        norms = np.linalg.norm(normals, axis=1)
        normals /= np.where(norms < 0.5, np.nan, norms)[:, None]
        return normals

    def _build_directors(self) -> None:
        """Nodal reference directors: averaged unit cell normals at the nodes."""
        normals = self._nodal_normals(self.D)
        if np.isnan(normals).any():
            raise ValueError(
                "mesh orientation is inconsistent: cell normals cancel at some nodes "
                "(orient all cells the same way before meshing)"
            )
        self.D.x.array[:] = normals.ravel()
        axes = np.zeros((self.n_local, 3), dtype=bool)  # node on the symmetry plane x, y, z
        for s in self.supports:
            if isinstance(s, Symmetry):
                axes[self._node_mask(s.where), s.axis] = True
        self._symmetry_axes = axes
        # e1 along the (first) symmetry-plane normal: theta2 = 0 keeps the director in it
        first = np.eye(3)[np.argmax(axes, axis=1)]
        self._preferred = np.where(axes.any(axis=1)[:, None], first, np.nan)  # NaN: none
        self.basis = self._fibre_basis(normals, np.arange(self.n_local))

    def _fibre_basis(self, directors: np.ndarray, nodes: np.ndarray) -> np.ndarray:
        """Hughes' fibre bases of ``nodes`` around ``directors``, e1 aligned with a symmetry
        plane normal where a Symmetry support asks for it (the x, y, z order decides at a
        node on two planes, whose rotations are both fixed)."""
        pref = self._preferred[nodes]
        has = ~np.isnan(pref[:, 0])
        out = rotation.fibre_basis(directors)
        if has.any():
            out[has] = rotation.fibre_basis(directors[has], pref[has])
        return out

    # ------------------------------------------------------------------ supports
    def _build_supports(self) -> None:
        """Constrained rows of the (u, theta) system and how to compute their values."""
        nu = 3 * self.n_owned
        self._bc_rows: list[np.ndarray] = []  # local rows in the (u, theta) layout
        self._bc_value_fns = []
        owned = np.zeros(self.n_local, dtype=bool)
        owned[: self.n_owned] = True
        for s in self.supports:
            if isinstance(s, PointPin):
                i, _ = self._nearest_node(s.point, on=s.on)
                if i >= 0:
                    self._add_bc(3 * i + np.array(s.components))
                continue
            nodes = np.flatnonzero(self._node_mask(s.where) & owned)
            if isinstance(s, Clamp | Pin | Symmetry):
                comps = (s.axis,) if isinstance(s, Symmetry) else (0, 1, 2)
                rows = (3 * nodes[:, None] + np.array(comps)).ravel()
                self._add_bc(rows)
                if isinstance(s, Clamp):
                    self._add_bc((nu + 2 * nodes[:, None] + np.arange(2)).ravel())
            elif isinstance(s, Prescribed):
                X = self.x_nodes[nodes]
                comps = np.array(s.components)
                if s.displacement is not None:
                    rows = (3 * nodes[:, None] + comps).ravel()
                    disp = s.displacement
                    if callable(disp):

                        def fn(lam, X=X, disp=disp, comps=comps):
                            return np.asarray(disp(X, lam), dtype=float)[:, comps].ravel()

                    else:
                        vec, count = np.asarray(disp)[comps], len(nodes)

                        def fn(lam, vec=vec, count=count):
                            return np.tile(lam * vec, count)

                    self._add_bc(rows, fn)
                if s.rotation is not None:
                    rows = (nu + 2 * nodes[:, None] + np.arange(2)).ravel()
                    D0, omega = self.D.x.array.reshape(-1, 3)[nodes], np.array(s.rotation)

                    def fn(lam, nodes=nodes, D0=D0, omega=omega):  # current basis: see rebase()
                        Rm = rotation.rotation_matrix((lam * omega)[None, :])[0]
                        return rotation.rotation_from_director(self.basis[nodes], D0 @ Rm.T).ravel()

                    self._add_bc(rows, fn)
        self._add_symmetry_rotations()

    def _add_symmetry_rotations(self) -> None:
        """Director rotations fixed by the Symmetry supports, node by node: on one plane of
        normal a = e1, theta2 = 0 (delta d . a = theta . (e3 x a) = theta2 there); on two
        planes the director is on their intersection and both rotations are fixed."""
        n = self.n_owned
        planes = np.count_nonzero(self._symmetry_axes[:n], axis=1)
        one, more = np.flatnonzero(planes == 1), np.flatnonzero(planes > 1)
        self._add_bc(3 * n + 2 * one + 1)
        self._add_bc((3 * n + 2 * more[:, None] + np.arange(2)).ravel())

    def _add_bc(self, rows: np.ndarray, fn=None) -> None:
        """Constrain ``rows``; ``fn(lam)`` gives their values (zero when None)."""
        rows = np.asarray(rows, dtype=np.int32)
        self._bc_rows.append(rows)
        self._bc_value_fns.append(fn or (lambda lam, n=rows.size: np.zeros(n)))

    def bc_rows_and_values(self, lam: float) -> tuple[np.ndarray, np.ndarray]:
        """Local rows (in the owned (u, theta) layout) and their prescribed values at ``lam``."""
        if not self._bc_rows:
            return np.zeros(0, dtype=np.int32), np.zeros(0)
        rows = np.concatenate(self._bc_rows)
        values = np.concatenate([fn(lam) for fn in self._bc_value_fns])
        return rows, values

    # ------------------------------------------------------------------ forms
    def _build_forms(self, warp, quadrature: Quadrature) -> None:
        mesh, mat, t = self.mesh, self.material, self.thickness
        self.Q = fem.Constant(mesh, mat.plane_stress_stiffness())
        self.kG = fem.Constant(mesh, mat.transverse_shear())
        self.t = fem.Constant(mesh, t)
        self.rho = fem.Constant(mesh, float(mat.rho))
        self.warp = fem.Constant(mesh, np.asarray(warp, dtype=float))
        frame = lamina_frame(mesh, self.warp)
        self.frame = frame
        u, d, D = self.u, self.d, self.D
        eps, kappa, gamma = shell_strains(u, d, D, frame)
        self.strains = (eps, kappa, gamma)
        dx_f = ufl.dx(domain=mesh, metadata={"quadrature_degree": quadrature.full})
        dx_r = ufl.dx(domain=mesh, metadata={"quadrature_degree": quadrature.reduced})
        self.dx_full, self.dx_reduced = dx_f, dx_r
        self._mitc = None
        if quadrature.scheme == "mitc9":
            self.alpha = None
            self._build_mitc(eps)
            self._energy_terms = {"bending": bending_energy(kappa, self.Q, self.t) * dx_f}
            self._build_load_forms(frame)
            return
        if isinstance(mat, DecrimpingFabric):  # yarn-direction stiffening (same weights)
            self.yarn = fem.Constant(mesh, mat.yarn_parameters())
            psi_m = decrimping_membrane_energy(eps, self.Q, self.yarn, self.t)
        else:
            psi_m = membrane_energy(eps, self.Q, self.t)
        psi_s = shear_energy(gamma, self.kG, self.t)
        if quadrature.scheme == "psri":
            self.alpha = self._psri_weight(quadrature.psri_factor)
            membrane, shear = (_blend(p, dx_r, dx_f, self.alpha) for p in (psi_m, psi_s))
        else:
            self.alpha = None
            membrane = _blend(psi_m, dx_r, dx_f, quadrature.stabilization)
            shear = psi_s * dx_r
        self.friction = None
        if mat.friction is not None:  # yarn friction, history at the reduced rule's points
            self.friction = YarnFriction(
                mesh, mat.friction, eps, self.t, degree=quadrature.reduced, dx=dx_r
            )
            membrane = membrane + self.friction.energy
        self.viscosity = None
        if mat.viscosity is not None:  # Kelvin-Voigt membrane, history at the same points
            self.viscosity = MembraneViscosity(
                mesh, mat.viscosity, eps, self.t, degree=quadrature.reduced, dx=dx_r
            )
            membrane = membrane + self.viscosity.energy
        self._energy_terms = {
            "membrane": membrane,
            "bending": bending_energy(kappa, self.Q, self.t) * dx_f,
            "shear": shear,
        }
        self._build_load_forms(frame)

    def _build_mitc(self, eps) -> None:
        """The MITC9 membrane and shear kernels (9-node cells only), with the material's
        decrimping, yarn friction and viscosity; the histories at the kernels' 3 x 3 points
        (the rule of degree 4) follow the assumed strains (``eps``, the UFL strains, only
        name the history's components)."""
        from .mitc import MitcForms

        mat, mesh = self.material, self.mesh
        dx_m = ufl.dx(domain=mesh, metadata={"quadrature_degree": MITC_DEGREE})
        yarn = None
        if isinstance(mat, DecrimpingFabric):
            self.yarn = yarn = fem.Constant(mesh, mat.yarn_parameters())
        histories = {}  # yarn friction follows (E11, E22), viscosity (E11, E22, E12)
        for name, cls, term, comps in (
            ("friction", YarnFriction, mat.friction, 2),
            ("viscosity", MembraneViscosity, mat.viscosity, 3),
        ):
            histories[name] = None if term is None else cls(
                mesh, term, eps, self.t, degree=MITC_DEGREE, dx=dx_m,
                # read from the residual's kernels when they ran at this state
                point_strains=lambda k=comps: self._mitc.history_strains(
                    k, at_residual=self._Rw_at is not None
                ),
            )  # fmt: skip
        self.friction, self.viscosity = histories["friction"], histories["viscosity"]
        self._mitc = MitcForms(
            self.V,
            u=self.u,
            d=self.d,
            D=self.D,
            Q=self.Q,
            kG=self.kG,
            t=self.t,
            warp=self.warp,
            yarn=yarn,
            friction=self.friction,
            viscosity=self.viscosity,
        )

    def _build_load_forms(self, frame) -> None:
        """External work, follower loads and the compiled residual, Jacobian and energy
        forms of the energy terms and loads."""
        mesh, u, d = self.mesh, self.u, self.d
        dx_f = self.dx_full
        ds = ufl.Measure("ds", domain=mesh, subdomain_data=self.surface.facet_tags)
        Pi = sum(self._energy_terms.values())

        # external work of dead loads on u, and non-conservative follower loads
        W_ext = 0
        follower = 0
        v = ufl.TestFunction(self.V)
        self._point_forces: list[PointForce] = []
        self._moment_work = 0
        E1 = fem.Function(self.V)
        E2 = fem.Function(self.V)
        E1.x.array[:] = self.basis[:, 0].ravel()
        E2.x.array[:] = self.basis[:, 1].ravel()
        self._fibre_e = (E1, E2)
        for load in self.loads:
            if isinstance(load, Gravity):
                g = fem.Constant(mesh, np.array(load.acceleration))
                W_ext += self.lam * (self.rho * (self.t * ufl.dot(g, u))) * dx_f
            elif isinstance(load, Pressure):
                p = fem.Constant(mesh, float(load.value))
                if load.follower:
                    Fu = ufl.grad(u)
                    a1, a2 = frame[0] + Fu * frame[0], frame[1] + Fu * frame[1]
                    follower += -self.lam * (p * ufl.dot(ufl.cross(a1, a2), v)) * dx_f
                else:
                    W_ext += self.lam * (p * ufl.dot(frame[2], u)) * dx_f
            elif isinstance(load, EdgeTraction):
                tr = fem.Constant(mesh, np.array(load.traction))
                W_ext += self.lam * ufl.dot(tr, u) * ds(self.surface.boundaries[load.where])
            elif isinstance(load, EdgeMoment):
                m = fem.Constant(mesh, np.array(load.moment))
                th = self.theta
                rotvec = th[0] * E1 + th[1] * E2
                self._moment_work += (
                    self.lam * ufl.dot(m, rotvec) * ds(self.surface.boundaries[load.where])
                )
            elif isinstance(load, PointForce):
                self._point_forces.append(load)
            else:
                raise ValueError(f"unknown load {load!r}")
        self._Pi_int = Pi
        self._W_ext = W_ext
        # residual R = R_int(u, d) - F_ext: the internal part does not depend on the load
        # factor (one assembly per state serves every lam); the dead loads are linear in u,
        # so their force is state-independent and assembled once per lam; follower loads
        # depend on the state and are assembled with it
        R_int = [ufl.derivative(Pi, u, v), ufl.derivative(Pi, d, v)]
        F_dead = ufl.derivative(W_ext, u, v) if W_ext != 0 else None
        R_u = R_int[0] + follower  # the dead loads do not enter the Jacobian
        w = ufl.TrialFunction(self.V)
        a = [[ufl.derivative(R, f, w) for f in (u, d)] for R in (R_u, R_int[1])]
        self._R_forms = fem.form(R_int)
        self._K_forms = fem.form(a)
        self._Fdead_form = fem.form(F_dead) if F_dead is not None else None
        self._Ffollow_form = fem.form(-follower) if follower != 0 else None
        self._energy_form = fem.form(Pi)
        self._wext_form = fem.form(W_ext) if W_ext != 0 else None
        if self._moment_work != 0:
            self._Rm_form = fem.form(
                ufl.derivative(self._moment_work, self.theta, ufl.TestFunction(self.Vt))
            )
            self._wm_form = fem.form(self._moment_work)
        else:
            self._Rm_form = self._wm_form = None
        self._point_rows, self._point_values = self._locate_point_forces()

    def _psri_weight(self, factor: float) -> fem.Function:
        """Cellwise PSRI weight alpha = min(1, factor t^2 / h^2) (DG0), h the cell diameter
        (largest distance between two of its vertices, as UFL's CellDiameter). Collective;
        a rank may hold no cells."""
        W = fem.FunctionSpace(self.mesh, ("DG", 0))
        alpha = fem.Function(W, name="psri_weight")
        geo = self.mesh.geometry
        n_cells = len(geo.dofmap.offsets) - 1  # owned and ghost cells of this rank
        if n_cells:
            n_vertices = 4 if self.mesh.topology.cell_type.name == "quadrilateral" else 3
            nodes = geo.dofmap.array.reshape(n_cells, -1)[:, :n_vertices]
            corners = geo.x[nodes]
            pairs = [(a, b) for a in range(n_vertices) for b in range(a + 1, n_vertices)]
            h = np.max([np.linalg.norm(corners[:, a] - corners[:, b], axis=1) for a, b in pairs], 0)
            dofs = W.dofmap.list.array.reshape(-1)[:n_cells]
            alpha.x.array[dofs] = np.minimum(1.0, factor * self.thickness**2 / h**2)
        alpha.x.scatter_forward()
        return alpha

    def _locate_point_forces(self):
        rows, values = [], []
        for pf in self._point_forces:
            i, _ = self._nearest_node(pf.point, on=pf.on)
            if i >= 0:
                rows.append(3 * i + np.arange(3))
                values.append(np.array(pf.force))
        if rows:
            return np.concatenate(rows).astype(np.int32), np.concatenate(values)
        return np.zeros(0, dtype=np.int32), np.zeros(0)

    # ------------------------------------------------------------------ algebra
    def _build_transfer(self) -> None:
        """P: (u, theta) -> (u, d) block layout; the K_w matrix; work vectors."""
        n = self.n_owned
        self._Kw = fem_petsc.create_matrix_block(self._K_forms)
        self._Rw = fem_petsc.create_vector_block(self._R_forms)
        if self._mitc is not None:  # the MITC9 membrane and shear, assembled beside
            self._Rm = fem_petsc.create_vector(self._mitc.R)
        rw0, rw1 = self._Kw.getOwnershipRange()
        assert rw1 - rw0 == 6 * n
        nv = 5 * n
        v0 = self.comm.scan(nv) - nv
        self.v_range = (v0, v0 + nv)
        # CSR of P: rows 0..3n-1 identity on u; rows 3n.. 3 per node x 2 theta columns
        indptr = np.concatenate([np.arange(3 * n + 1), 3 * n + 2 * np.arange(1, 3 * n + 1)])
        cols_u = v0 + np.arange(3 * n)
        cols_t = v0 + 3 * n + (2 * np.repeat(np.arange(n), 3)[:, None] + np.arange(2)).ravel()
        self._P_indptr = indptr.astype(PETSc.IntType)
        self._P_indices = np.concatenate([cols_u, cols_t]).astype(PETSc.IntType)
        self._P_data = np.concatenate([np.ones(3 * n), np.zeros(6 * n)])
        P = PETSc.Mat().createAIJ(((6 * n, None), (nv, None)), comm=self.comm)
        P.setPreallocationCSR((self._P_indptr, self._P_indices, self._P_data))
        P.assemble()
        self._P = P
        self._P_stale = False  # True: _P_data holds newer values than the matrix
        self._f_ext = P.createVecRight()
        self._f_ext_lam: float | None = None  # the load factor f_ext was assembled at
        self._fe_work = P.createVecRight()
        # G: 2x2 blocks on the theta diagonal
        g_indptr = np.concatenate([np.zeros(3 * n, dtype=int), 2 * np.arange(2 * n + 1)])
        g_cols = v0 + 3 * n + (2 * np.repeat(np.arange(n), 2)[:, None] + np.arange(2)).ravel()
        self._G_indptr = g_indptr.astype(PETSc.IntType)
        self._G_indices = g_cols.astype(PETSc.IntType)
        G = PETSc.Mat().createAIJ(((nv, None), (nv, None)), comm=self.comm)
        G.setPreallocationCSR((self._G_indptr, self._G_indices, np.zeros(4 * n)))
        G.assemble()
        self._G = G

    def update_director(self) -> None:
        """d_A = d_A(theta_A) at every local node (owned and ghost); P from dd_A/dtheta_A.

        Call it after changing ``u`` or ``theta`` by hand (it also drops the cached residual).
        """
        self._Rw_at = None
        th = self.theta.x.array.reshape(-1, 2)
        self.d.x.array[:] = rotation.director(self.basis, th).ravel()
        n = self.n_owned
        T = rotation.director_tangent(self.basis[:n], th[:n])
        self._H = None  # d2d/dtheta2: only the Jacobian needs it (_second_derivatives)
        self._T, self._T_at = T, th[:n].copy()
        self._P_data[3 * n :] = T.reshape(-1)  # rows (node, k), columns a
        self._P_stale = True  # the matrix P gets these values when it is used (rotation_map)

    def rotation_map(self) -> PETSc.Mat:
        """P = d(u, d)/d(u, theta) at the current rotations, as a matrix (its values set on
        the first call after :meth:`update_director`; collective, as its users are: the
        tangent P^T K_w P, the consistent mass). The residual applies P^T without it."""
        if self._P_stale:
            self._P.setValuesCSR(self._P_indptr, self._P_indices, self._P_data)
            self._P.assemble()
            self._P_stale = False
        return self._P

    def director_jacobian(self) -> np.ndarray:
        """dd_A/dtheta_A (n_owned, 3, 2) at the current rotations (from the last
        :meth:`update_director` when the rotations have not changed since)."""
        n = self.n_owned
        th = self.theta.x.array[: 2 * n].reshape(n, 2)
        if not np.array_equal(th, self._T_at):
            self._T = rotation.director_tangent(self.basis[:n], th)
            self._T_at = th.copy()
        return self._T

    def _second_derivatives(self) -> np.ndarray:
        """d2d_A/dtheta_A^2 (n_owned, 3, 2, 2) at the rotations of the last
        :meth:`update_director` (computed on the first call after it)."""
        if self._H is None:
            n = self.n_owned
            th = self.theta.x.array[: 2 * n].reshape(n, 2)
            self._H = rotation.director_derivatives(self.basis[:n], th)[1]
        return self._H

    def rebase(self, *, threshold: float = 0.5) -> np.ndarray:
        """Re-base the fibre basis of every node with |theta| > ``threshold`` [rad] on its
        current director and set its rotation to zero; the director, the strains and the
        energy are unchanged. This keeps the total-rotation parametrisation of Eqs. 7-9 away
        from its singularity at |theta| = pi (folding fabric). Moment loads then do work on
        the rotation since the last re-basing. Returns the re-based local nodes (owned and
        ghost; the decision uses ghost-updated rotations, so ranks agree)."""
        th = self.theta.x.array.reshape(-1, 2)
        nodes = np.flatnonzero(np.hypot(th[:, 0], th[:, 1]) > threshold)
        if len(nodes):
            d = self.d.x.array.reshape(-1, 3)[nodes]
            self.basis[nodes] = self._fibre_basis(d, nodes)
            th[nodes] = 0.0
            for k, E in enumerate(self._fibre_e):
                E.x.array.reshape(-1, 3)[nodes] = self.basis[nodes, k]
        if self.comm.allreduce(len(nodes), op=MPI.SUM):  # collective decision
            self._f_ext_lam = None  # edge moments act on the rotation in the new bases
            self.update_director()  # collective (assembles P)
        return nodes

    def _neighbourhood_rotations(self, u: np.ndarray) -> np.ndarray:
        """Per local node, the rotation (n_local, 3, 3) that best maps the reference
        positions of the nodes sharing a cell with it, relative to it, onto the displaced
        ones (Kabsch: the SVD of the covariance, summed over cells and ranks; collective)."""
        V = self.V
        n_cells = self.mesh.topology.index_map(2).size_local
        dofs = V.dofmap.list.array.reshape(-1, V.dofmap.dof_layout.num_dofs)[:n_cells]
        H = np.zeros((self.n_local, 3, 3))
        X, x = self.x_nodes, self.x_nodes + u
        for a in range(dofs.shape[1]):
            dX = X[dofs] - X[dofs[:, a]][:, None, :]  # (cells, nodes per cell, 3)
            dx = x[dofs] - x[dofs[:, a]][:, None, :]
            np.add.at(H, dofs[:, a], np.einsum("cki,ckj->cij", dX, dx))
        acc = fem.Function(
            fem.VectorFunctionSpace(self.mesh, (V.ufl_element().family(), self.degree), dim=9)
        )
        acc.x.array[:] = H.ravel()
        acc.x.scatter_reverse(la.ScatterMode.add)
        acc.x.scatter_forward()
        U, _, Vt = np.linalg.svd(acc.x.array.reshape(-1, 3, 3))
        sign = np.sign(np.linalg.det(np.einsum("nji,nkj->nik", Vt, U)))
        return np.einsum("nji,nj,nkj->nik", Vt, np.stack([np.ones_like(sign)] * 2 + [sign], 1), U)

    def start_at(self, u: np.ndarray) -> None:
        """Start from the displacement ``u`` [m] of every local node (n_local, 3), owned and
        ghost (e.g. a donned garment: the reference stays the pattern), with each director
        the reference one turned by the best-fit rotation of the node's cell neighbourhood
        (exact for a rigid motion; folds and creases get the mean rotation): the fibre bases
        are re-based on those directors and the rotations set to 0, as :meth:`rebase` does
        (collective)."""
        if u.shape != (self.n_local, 3) or not np.all(np.isfinite(u)):
            raise ValueError(f"u must be finite with shape {(self.n_local, 3)}, got {u.shape}")
        self.u.x.array[:] = u.ravel()
        self.u.x.scatter_forward()
        D = self.D.x.array.reshape(-1, 3)
        normals = np.einsum("nij,nj->ni", self._neighbourhood_rotations(u), D)
        self.basis[:] = self._fibre_basis(normals, np.arange(self.n_local))
        for k, E in enumerate(self._fibre_e):
            E.x.array.reshape(-1, 3)[:] = self.basis[:, k]
        self.theta.x.array[:] = 0.0
        self._f_ext_lam = None
        self.update_director()

    def state_arrays(self) -> dict[str, np.ndarray]:
        """The rank-local state to checkpoint: u, theta (owned + ghost), the nodal fibre bases
        (changed by :meth:`rebase`), the load factor and, with yarn friction, its history.
        Restore with :meth:`restore_arrays` on the same mesh and number of ranks."""
        data = {
            "u": self.u.x.array.copy(),
            "theta": self.theta.x.array.copy(),
            "basis": self.basis.copy(),
            "load_factor": np.array(float(self.lam.value)),
        }
        for history in (self.friction, self.viscosity):
            if history is not None:
                data.update(history.state_arrays())
        return data

    def commit_material(self) -> None:
        """Advance the material history (yarn friction, membrane viscosity) to the current
        state; nothing for an elastic material. Call it once after every accepted step or
        load increment; no collective call (measure with :meth:`dissipated_material`)."""
        for history in (self.friction, self.viscosity):
            if history is not None:
                history.advance()
                self._Rw_at = None  # the residual's history changed

    def set_time_step(self, dt: float) -> None:
        """The size [s] of the step about to be taken (the membrane viscosity's rate
        (E - E_n) / dt; nothing without viscosity). The integrators call it."""
        if self.viscosity is not None and float(self.viscosity.inv_h.value) != 1.0 / dt:
            self.viscosity.inv_h.value = 1.0 / dt
            self._Rw_at = None  # the residual depends on the step

    def dissipated_material(self) -> float:
        """Energy [J] dissipated by the material since the start (yarn friction and membrane
        viscosity; 0 for an elastic material; collective)."""
        total = 0.0
        for history in (self.friction, self.viscosity):
            if history is not None:
                total += history.dissipated()
        return total

    def restore_arrays(self, data: dict[str, np.ndarray]) -> None:
        """Inverse of :meth:`state_arrays` (collective: updates the directors)."""
        for key, arr in (("u", self.u.x.array), ("theta", self.theta.x.array)):
            if data[key].shape != arr.shape:
                raise ValueError(
                    f"checkpoint {key!r} has {data[key].shape[0]} local values, the model "
                    f"{arr.shape[0]}: resume needs the same mesh and number of ranks"
                )
            arr[:] = data[key]
        self.basis[:] = data["basis"]
        for history, key in (
            (self.friction, "friction_history"),
            (self.viscosity, "viscous_history"),
        ):
            if history is not None:
                if key not in data:
                    raise ValueError(f"checkpoint has no {key}; the model's material has one")
                history.restore_arrays(data)
        for k, E in enumerate(self._fibre_e):
            E.x.array.reshape(-1, 3)[:] = self.basis[:, k]
        self._f_ext_lam = None
        self.set_load_factor(float(data["load_factor"]))
        self.update_director()

    def create_vector(self) -> PETSc.Vec:
        """A vector of the (u, theta) system."""
        return self._P.createVecRight()

    def get_state(self, x: PETSc.Vec) -> None:
        """Copy the owned state (u, theta) into ``x``."""
        n = self.n_owned
        arr = x.getArray()
        arr[: 3 * n] = self.u.x.array[: 3 * n]
        arr[3 * n :] = self.theta.x.array[: 2 * n]

    def set_state(self, x: PETSc.Vec) -> None:
        """Set (u, theta) from ``x``, update ghosts and directors."""
        n = self.n_owned
        arr = x.getArray(readonly=True)
        self.u.x.array[: 3 * n] = arr[: 3 * n]
        self.theta.x.array[: 2 * n] = arr[3 * n :]
        self.u.x.scatter_forward()
        self.theta.x.scatter_forward()
        self.update_director()

    def set_load_factor(self, lam: float) -> None:
        """Set the load factor and assemble the parts of the load that do not depend on the
        state (point forces, edge moments, dead loads) into the external force vector (only
        when ``lam`` or the fibre bases changed since the last call)."""
        if lam == self._f_ext_lam:  # f_ext already at lam (and at the current bases)
            return
        self.lam.value = lam
        self._f_ext_lam = lam
        self._f_ext.zeroEntries()
        n = self.n_owned
        arr = self._f_ext.getArray()
        if len(self._point_rows):
            np.add.at(arr, self._point_rows, lam * self._point_values)
        if self._Rm_form is not None:
            arr[3 * n :] += _assemble_owned(self._Rm_form)
        if self._Fdead_form is not None:
            arr[: 3 * n] += _assemble_owned(self._Fdead_form)

    def _assemble_Rw(self, x: PETSc.Vec) -> None:
        """Set the state to ``x`` and assemble the (u, d) residual, unless both are already
        at ``x`` (SNES asks for the Jacobian at the point whose residual it just had)."""
        arr = x.getArray(readonly=True)
        same = self._Rw_at is not None and np.array_equal(arr, self._Rw_at)
        if self.comm.allreduce(same, op=MPI.LAND):  # collective decision
            return
        self.set_state(x)
        with self._Rw.localForm() as loc:
            loc.set(0.0)
        fem_petsc.assemble_vector_block(self._Rw, self._R_forms, self._K_forms, bcs=[])
        if self._mitc is not None:
            self._add_mitc_residual()
        self._Rw_at = arr.copy()

    def _add_mitc_residual(self) -> None:
        """R_w += the MITC9 membrane and shear residual (owned u rows, then d rows)."""
        vec = self._Rm
        with vec.localForm() as loc:
            loc.set(0.0)
        fem_petsc.assemble_vector(vec, self._mitc.R)
        vec.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        n = self.n_owned
        r6 = vec.getArray(readonly=True).reshape(n, 6)
        rw = self._Rw.getArray()
        rw[: 3 * n] += r6[:, :3].ravel()
        rw[3 * n : 6 * n] += r6[:, 3:].ravel()

    def residual(self, x: PETSc.Vec, f: PETSc.Vec) -> None:
        """f = R(x) in the (u, theta) layout, without support conditions."""
        self.forces(x, f, self._fe_work)

    def forces(self, x: PETSc.Vec, r: PETSc.Vec, fe: PETSc.Vec) -> None:
        """r = R(x) = f_int(x) - f_ext(x) and fe = f_ext(x) at the current load factor, in
        the (u, theta) layout without support conditions (one internal assembly)."""
        self._assemble_Rw(x)
        self._f_ext.copy(fe)
        if self._Ffollow_form is not None:  # state-dependent: at x (set above)
            fe.getArray()[: 3 * self.n_owned] += _assemble_owned(self._Ffollow_form)
        # r = P^T R_w, node by node (P is block diagonal: identity on u, T_A^T on d_A), in the
        # summation order of the sparse transpose product it replaces (same bits)
        n = self.n_owned
        rw = self._Rw.getArray(readonly=True)
        ra = r.getArray()
        ra[: 3 * n] = rw[: 3 * n]
        rd, T = rw[3 * n : 6 * n].reshape(n, 3), self._T
        for a in range(2):
            t = T[:, :, a]
            ra[3 * n + a :: 2] = t[:, 0] * rd[:, 0] + t[:, 1] * rd[:, 1] + t[:, 2] * rd[:, 2]
        r.axpy(-1.0, fe)

    def jacobian(self, x: PETSc.Vec, K: PETSc.Mat | None = None) -> PETSc.Mat:
        """K = P^T K_w P + G at ``x`` (created if ``K`` is None), without supports."""
        self._assemble_Rw(x)
        Rw = self._Rw
        self._Kw.zeroEntries()
        fem_petsc.assemble_matrix_block(self._Kw, self._K_forms, bcs=[])
        if self._mitc is not None:  # added into the same matrix: the same cell couplings
            fem_petsc.assemble_matrix_block(self._Kw, self._mitc.K, bcs=[])
        self._Kw.assemble()
        if K is None:
            K = self._Kw.ptap(self.rotation_map())
            K.setOption(PETSc.Mat.Option.KEEP_NONZERO_PATTERN, True)
            K.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        else:
            self._Kw.ptap(self.rotation_map(), result=K)
        # geometric term of the nodal rotation map
        n = self.n_owned
        Rd = Rw.getArray(readonly=True)[3 * n : 6 * n].reshape(n, 3)
        G = np.einsum("nk,nkab->nab", Rd, self._second_derivatives())
        self._G.setValuesCSR(self._G_indptr, self._G_indices, G.reshape(-1))
        self._G.assemble()
        K.axpy(1.0, self._G, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
        return K

    # ------------------------------------------------------------------ outputs
    def strain_energy(self) -> float:
        """Internal strain energy [J] at the current state."""
        local = fem.assemble_scalar(self._energy_form)
        if self._mitc is not None:
            local += sum(fem.assemble_scalar(f) for f in self._mitc.energy.values())
        return self.comm.allreduce(local, op=MPI.SUM)

    def yarn_strain_range(self) -> tuple[float, float]:
        """Smallest and largest Green strain along the yarns (E11, E22 in the lamina frame)
        over the points of the full membrane rule of every cell, at the current state
        (collective). -0.5 is a yarn crushed to zero length. Where these extremes are far
        beyond the strains at the reduced rule's points, the displacement field carries a
        membrane mode that the reduced rule does not see and the PSRI weight alpha (of
        order t^2 / h^2) hardly resists (docs/shell_element.md)."""
        if self._mitc is not None:  # the assumed strains, which the energy sees
            e = self._mitc.yarn_strains()
        else:
            e = self._yarn_strain_values()
        lo = float(e.min()) if e.size else math.inf
        hi = float(e.max()) if e.size else -math.inf
        return self.comm.allreduce(lo, op=MPI.MIN), self.comm.allreduce(hi, op=MPI.MAX)

    def _yarn_strain_values(self) -> np.ndarray:
        """E11, E22 of the full membrane rule's points of the owned cells (UFL strains)."""
        if self._yarn_strain is None:
            from ffcx.element_interface import create_quadrature

            eps = self.strains[0]
            points, _ = create_quadrature(
                self.mesh.ufl_cell().cellname(), self.quadrature.full, "default"
            )
            self._yarn_strain = fem.Expression(ufl.as_vector([eps[0, 0], eps[1, 1]]), points)
        n_cells = self.mesh.topology.index_map(2).size_local
        return self._yarn_strain.eval(np.arange(n_cells, dtype=np.int32))

    def external_work(self) -> float:
        """Work of the conservative loads [J] at the current state and load factor."""
        w = 0.0
        if self._wext_form is not None:
            w += fem.assemble_scalar(self._wext_form)
        if self._wm_form is not None:
            w += fem.assemble_scalar(self._wm_form)
        u_owned = self.u.x.array[: 3 * self.n_owned]
        w += float(np.dot(u_owned[self._point_rows], self.lam.value * self._point_values))
        return self.comm.allreduce(w, op=MPI.SUM)

    def energy_parts(self) -> dict[str, float]:
        """Membrane, bending and shear strain energy [J]."""
        forms = dict(self._energy_part_forms())
        if self._mitc is not None:
            forms.update(self._mitc.energy)
        return {
            name: self.comm.allreduce(fem.assemble_scalar(forms[name]), op=MPI.SUM)
            for name in ("membrane", "bending", "shear")
        }

    def _energy_part_forms(self):
        if not hasattr(self, "_part_forms"):
            self._part_forms = {k: fem.form(v) for k, v in self._energy_terms.items()}
        return self._part_forms

    def displacement_at(self, point: Sequence[float], *, on: str | None = None) -> np.ndarray:
        """Displacement [m] of the node nearest to ``point`` [m], among the nodes of the
        boundary ``on`` if given (selects one side where nodes coincide, as at a slit);
        collective, the same answer on every rank."""
        i, owner = self._nearest_node(point, on=on)
        val = self.u.x.array[3 * i : 3 * i + 3].copy() if i >= 0 else None
        return self.comm.bcast(val, root=owner)

    def _nearest_node(self, point: Sequence[float], *, on: str | None) -> tuple[int, int]:
        """(local index, owner rank) of the owned node nearest to ``point`` over all ranks,
        among the nodes of boundary ``on`` if given; the index is -1 on the other ranks.
        Collective; ties go to the lowest rank, then the lowest local index."""
        xo = self.x_nodes[: self.n_owned]
        dist = np.linalg.norm(xo - np.asarray(point, dtype=float), axis=1)
        if on is not None:
            dist[~self._node_mask(on)[: self.n_owned]] = np.inf
        i = int(np.argmin(dist)) if len(dist) else -1
        best = self.comm.allreduce(
            (float(dist[i]) if i >= 0 else np.inf, self.comm.rank), op=MPI.MINLOC
        )
        if not np.isfinite(best[0]):
            raise ValueError(f"no mesh node on boundary {on!r} to locate {tuple(point)!r} on")
        return (i if best[1] == self.comm.rank else -1), best[1]
