"""Scene files (TOML): schema, defaults, validation, ``--set`` overrides and ``--unset``.

A scene fully describes a run: fabric mesh, material and thickness, supports and loads, the
body and its motion, contact, the integrator and the outputs. The schema below is the single
source of truth: :func:`validate` checks a parsed file against it (unknown keys rejected,
keys of another integrator than the scene's refused, one-line errors naming the key and
the allowed values), fills defaults and returns the typed, frozen
:class:`clothfem.spec.Scene`, and :func:`schema_markdown` renders the schema as the reference
table of ``docs/scene.md``. The checks run on the parsed tables (dicts); the typed scene is
built once they pass, and code that needs another scene builds one from it with
:func:`dataclasses.replace` (as :func:`torque_entry`) or validates an edited file again.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import re
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .spec import Scene, SegmentSpec, TorqueSpec, scene_from_dict, section_from_dict

__all__ = [
    "SceneError",
    "load",
    "validate",
    "apply_overrides",
    "remove_keys",
    "foreign_keys",
    "schema_markdown",
    "check_boundaries",
    "mesh_file_problem",
    "torque_entry",
    "GENERATOR_BOUNDARIES",
    "MATERIALS",
]


class SceneError(ValueError):
    """An invalid scene: the message names the key and the allowed values."""


@dataclass(frozen=True)
class When:
    """A key that applies only while the key ``selector`` ("section.key") has one of
    ``values``: setting it otherwise is an error (e.g. a Newmark time step in an explicit run).
    """

    selector: str
    values: tuple[str, ...]

    def label(self) -> str:
        return ", ".join(self.values)

    def refusal(self, path: str, actual: str) -> str:
        """The one-line message for ``path`` set while the selector is ``actual``."""
        noun = self.selector.rsplit(".", 1)[-1] + ("s" if len(self.values) > 1 else "")
        allowed = ", ".join(repr(v) for v in self.values)
        return (
            f"scene: {path} applies to {noun} {allowed}, not {actual!r} "
            f"(remove it or --unset {path})"
        )


STATIC = When("solver.integrator", ("static",))
NEWMARK = When("solver.integrator", ("newmark",))
EXPLICIT = When("solver.integrator", ("explicit",))
DYNAMIC = When("solver.integrator", ("newmark", "explicit"))
IMPLICIT = When("solver.integrator", ("static", "newmark"))
PSRI = When("element.scheme", ("psri",))
SRI = When("element.scheme", ("sri",))


@dataclass(frozen=True)
class Key:
    """One scene key: kind in {str, int, float, bool, vec3, floats, choice, marker}; ``when``:
    the integrator (or element scheme) it belongs to, None for every one."""

    kind: str
    doc: str
    default: Any = None
    required: bool = False
    lo: float | None = None  # inclusive unless open_lo
    hi: float | None = None
    open_lo: bool = False
    choices: tuple[str, ...] = ()
    when: When | None = None

    def meaning(self) -> str:
        """The doc, led by the integrators (or scheme) the key belongs to."""
        return self.doc if self.when is None else f"{self.when.label()}: {self.doc}"

    def describe(self) -> str:
        if self.kind == "choice":
            return "one of " + ", ".join(repr(c) for c in self.choices)
        rng = ""
        if self.lo is not None or self.hi is not None:
            left = "(" if self.open_lo else "["
            lo = "-inf" if self.lo is None else f"{self.lo:g}"
            hi = "inf" if self.hi is None else f"{self.hi:g}"
            rng = f" in {left}{lo}, {hi}]"
        kinds = {
            "vec3": "3 numbers",
            "floats": "a list of numbers",
            "vec3s": "a list of [x, y, z]",
            "strs": "a list of strings",
            "float": "a number",
            "int": "an integer",
            "str": "a string",
            "bool": "true or false",
            "marker": "a marker name, or {midpoint = [a, b]} or {hip_centre = {...}}",
        }
        return kinds[self.kind] + rng


@dataclass(frozen=True)
class Section:
    keys: dict[str, Key]
    doc: str = ""
    many: bool = False  # an array of tables ([[...]])
    optional: bool = False  # the whole table may be absent
    variants: dict[str, tuple[str, ...]] = field(default_factory=dict)  # type -> required keys


POS = dict(lo=0.0, open_lo=True)


def _decrimping(E_c: float, E_d: float, below: float, above: float) -> dict[str, float]:
    """Keys of a decrimping law exactly crimped below the yarn stress ``below`` and exactly
    de-crimped above ``above`` [Pa] (clothfem.shell.material.transition_from_stresses)."""
    width = (above - below) / (E_c + E_d)
    et = below / E_c + width
    return dict(
        E1_decrimped=E_d,
        E2_decrimped=E_d,
        transition1=et,
        transition2=et,
        width1=width,
        width2=width,
    )


MATERIALS = {
    # Man & Swan (2007) Sec. 4.1.5; G = E / 200 for sets II and III, 0.1 MPa for set I.
    "crimped-cotton": dict(E1=1.2e6, E2=1.2e6, G12=1.0e5, rho=436.0),
    "decrimped-cotton": dict(E1=350e6, E2=350e6, G12=350e6 / 200, rho=436.0),
    "kevlar": dict(E1=7.2e9, E2=7.2e9, G12=7.2e9 / 200, rho=700.0),
    # the two cotton sets as the limits of one material: 1.2 MPa while the yarn stress is
    # below 1 MPa, 350 MPa above 10 MPa (Sec. 4.1), G12 as crimped-cotton (docs/material.md)
    "decrimping-cotton": dict(
        law="decrimping",
        E1=1.2e6,
        E2=1.2e6,
        G12=1.0e5,
        rho=436.0,
        **_decrimping(1.2e6, 350e6, 1.0e6, 10.0e6),
    ),
}
DECRIMPING_KEYS = ("E1_decrimped", "E2_decrimped", "transition1", "transition2", "width1", "width2")
VISCOSITY_KEYS = ("viscosity1", "viscosity2", "viscosity12")
FRICTION_KEYS = (
    "friction_stiffness1",
    "friction_stiffness2",
    "friction_stress1",
    "friction_stress2",
)
# yarn friction (Dahl) of clothfem.shell.hysteresis.COTTON_FRICTION: illustrative, not fitted
_COTTON_FRICTION = dict(zip(FRICTION_KEYS, (1.2e6, 1.2e6, 3.0e4, 3.0e4), strict=True))
MATERIALS["crimped-cotton-hysteretic"] = {**MATERIALS["crimped-cotton"], **_COTTON_FRICTION}
MATERIALS["decrimping-cotton-hysteretic"] = {**MATERIALS["decrimping-cotton"], **_COTTON_FRICTION}

SCHEMA: dict[str, Section] = {
    "scene": Section(
        {
            "name": Key("str", "name of the run", required=True),
            "description": Key("str", "free text", default=""),
        },
        "what the run is",
    ),
    "mesh": Section(
        {
            "generator": Key(
                "choice",
                "mesh source",
                required=True,
                choices=("strip", "cylinder", "panel", "pants", "file"),
            ),
            "file": Key("str", "gmsh .msh surface mesh with physical groups (generator = file)"),
            "length": Key("float", "strip/tube/panel length along x [m]", **POS),
            "width": Key("float", "strip width [m]", **POS),
            "radius": Key("float", "tube/panel radius [m]", **POS),
            "angle": Key("float", "panel half-opening angle [deg]", lo=0.0, hi=180.0, open_lo=True),
            "nx": Key("int", "strip cells along x", lo=1),
            "ny": Key("int", "strip cells across", lo=1),
            "n_around": Key(
                "int", "tube/panel cells around (tube, pants: multiple of 4; pants: per leg)", lo=1
            ),
            "n_along": Key("int", "tube/panel cells along x (pants: rows along each leg)", lo=1),
            "waist_radius": Key("float", "pants: waist circle radius [m] (default 0.14)", **POS),
            "hip_radius": Key(
                "float",
                "pants: radius [m] of the circle with the perimeter of the hip section (an "
                "ellipse round both legs; default: its minor semi-axis 1.05 x the smallest "
                "that encloses the legs)",
                **POS,
            ),
            "leg_radius": Key("float", "pants: leg tube radius [m] (default 0.09)", **POS),
            "leg_length": Key("float", "pants: crotch to hem [m] (default 0.75)", **POS),
            "crotch_depth": Key("float", "pants: waist to crotch [m] (default 0.25)", **POS),
            "leg_spacing": Key(
                "float",
                "pants: distance of the leg axes [m], >= 2.2 leg_radius (default 0.22)",
                **POS,
            ),
            "cell": Key(
                "choice",
                "cell type",
                default="quadrilateral",
                choices=("quadrilateral", "triangle"),
            ),
            "order": Key("int", "geometry order", default=2, lo=1, hi=2),
            "translate": Key("vec3", "translation applied to the generated mesh [m]", default=None),
        },
        "the fabric surface",
        variants={
            "strip": ("length", "width", "nx", "ny"),
            "cylinder": ("radius", "length", "n_around", "n_along"),
            "panel": ("radius", "length", "angle", "n_around", "n_along"),
            "pants": ("n_around", "n_along"),
            "file": ("file",),
        },
    ),
    "material": Section(
        {
            "preset": Key(
                "choice",
                "named material (explicit keys override it)",
                default=None,
                choices=tuple(MATERIALS),
            ),
            "law": Key(
                "choice",
                "stress-strain law: 'linear' (St. Venant-Kirchhoff) or 'decrimping' (E1, E2 "
                "while crimped, stiffening smoothly to E1_decrimped, E2_decrimped over yarn "
                "strains transition +- width; docs/material.md)",
                default="linear",
                choices=("linear", "decrimping"),
            ),
            "E1": Key("float", "warp Young's modulus [Pa] (decrimping: crimped)", **POS),
            "E2": Key("float", "weft Young's modulus [Pa] (decrimping: crimped)", **POS),
            "G12": Key("float", "in-plane shear modulus [Pa]", **POS),
            "nu12": Key("float", "major Poisson ratio [-], |nu12| < sqrt(E1/E2)", default=0.0),
            "rho": Key("float", "mass density [kg/m^3]", default=0.0, lo=0.0),
            "E1_decrimped": Key("float", "decrimping: de-crimped warp modulus [Pa], >= E1", **POS),
            "E2_decrimped": Key("float", "decrimping: de-crimped weft modulus [Pa], >= E2", **POS),
            "transition1": Key(
                "float", "decrimping: warp Green strain at the middle of the transition", **POS
            ),
            "transition2": Key(
                "float", "decrimping: weft Green strain at the middle of the transition", **POS
            ),
            "width1": Key("float", "decrimping: warp transition half-width, <= transition1", **POS),
            "width2": Key("float", "decrimping: weft transition half-width, <= transition2", **POS),
            "friction_stiffness1": Key(
                "float", "yarn friction (Dahl): warp sticking stiffness k1 [Pa]", **POS
            ),
            "friction_stiffness2": Key(
                "float", "yarn friction (Dahl): weft sticking stiffness k2 [Pa]", **POS
            ),
            "friction_stress1": Key(
                "float",
                "yarn friction (Dahl): warp sliding stress S1 [Pa] (loop half-height)",
                **POS,
            ),
            "friction_stress2": Key(
                "float",
                "yarn friction (Dahl): weft sliding stress S2 [Pa] (loop half-height)",
                **POS,
            ),
            "viscosity1": Key(
                "float",
                "membrane viscosity (Kelvin-Voigt) on the warp strain rate [Pa s]",
                lo=0.0,
                when=DYNAMIC,
            ),
            "viscosity2": Key(
                "float",
                "membrane viscosity (Kelvin-Voigt) on the weft strain rate [Pa s]",
                lo=0.0,
                when=DYNAMIC,
            ),
            "viscosity12": Key(
                "float",
                "membrane viscosity (Kelvin-Voigt) on the shear strain rate [Pa s] (a static "
                "run has no strain rate)",
                lo=0.0,
                when=DYNAMIC,
            ),
            "thickness": Key("float", "fabric thickness [m]", required=True, **POS),
            "warp": Key(
                "vec3", "global direction projected on the surface as warp", default=[1.0, 0.0, 0.0]
            ),
        },
        "the fabric material (orthotropic, plane stress; St. Venant-Kirchhoff or decrimping)",
    ),
    "supports": Section(
        {
            "type": Key(
                "choice",
                "support kind",
                required=True,
                choices=("clamp", "pin", "symmetry", "prescribed"),
            ),
            "where": Key("str", "boundary name of the mesh", required=True),
            "axis": Key("int", "symmetry plane normal axis (0 = x, 1 = y, 2 = z)", lo=0, hi=2),
            "displacement": Key("vec3", "prescribed displacement at load factor 1 [m]"),
            "components": Key("floats", "constrained displacement components", default=[0, 1, 2]),
            "rotation": Key("vec3", "prescribed director rotation vector at load factor 1 [rad]"),
        },
        "fabric supports",
        many=True,
        optional=True,
        variants={"clamp": (), "pin": (), "symmetry": ("axis",), "prescribed": ()},
    ),
    "loads": Section(
        {
            "type": Key(
                "choice",
                "load kind",
                required=True,
                choices=("gravity", "pressure", "edge_traction", "edge_moment", "point_force"),
            ),
            "acceleration": Key("vec3", "gravity [m/s^2]", default=[0.0, 0.0, -9.81]),
            "value": Key("float", "pressure [Pa]"),
            "follower": Key("bool", "pressure follows the surface", default=True),
            "where": Key("str", "boundary name (edge loads)"),
            "traction": Key("vec3", "edge force per length [N/m]"),
            "moment": Key("vec3", "edge moment per length [N m/m]"),
            "point": Key("vec3", "point of a point force [m]"),
            "force": Key("vec3", "point force [N]"),
        },
        "fabric loads (scaled by the load factor)",
        many=True,
        optional=True,
        variants={
            "gravity": (),
            "pressure": ("value",),
            "edge_traction": ("where", "traction"),
            "edge_moment": ("where", "moment"),
            "point_force": ("point", "force"),
        },
    ),
    "element": Section(
        {
            "degree": Key(
                "int",
                "polynomial degree of u and theta (2: nine-node quadrilaterals / six-node "
                "triangles on a second-order mesh; 1: four-node / three-node)",
                default=2,
                lo=1,
                hi=2,
            ),
            "reduced_quadrature": Key(
                "int",
                "quadrature degree of membrane and transverse shear (2: 2x2 Gauss points on "
                "quadrilaterals, selective reduced integration; 4: full, 3x3)",
                default=2,
                lo=1,
                hi=10,
            ),
            "scheme": Key(
                "choice",
                "integration of membrane and shear: 'psri' (partial selective reduced "
                "integration, alpha = psri_factor t^2/h^2 of them fully integrated: no "
                "spurious modes; docs/shell_element.md), 'mitc9' (assumed strains from the "
                "MITC9 tying points; 9-node quadrilaterals) or 'sri' "
                "(selective reduced, for comparison)",
                default="psri",
                choices=("psri", "mitc9", "sri"),
            ),
            "psri_factor": Key(
                "float",
                "the factor c of alpha = min(1, c t^2 / h^2), h the cell diameter",
                default=1.0,
                lo=0.0,
                hi=1e6,
                open_lo=True,
                when=PSRI,
            ),
            "stabilization": Key(
                "float",
                "alpha x the fully integrated membrane energy blended into the reduced one "
                "(removes the spurious mode of reduced integration, stiffens ovalisation)",
                default=0.0,
                lo=0.0,
                hi=1.0,
                when=SRI,
            ),
        },
        "the shell element (clothfem.shell.Quadrature)",
        optional=True,
    ),
    "solver": Section(
        {
            "integrator": Key(
                "choice",
                "time integration: 'static' (a sequence of equilibria), 'newmark' (implicit, "
                "Lagrange-multiplier contact), 'explicit' (central difference with the lumped "
                "mass, forward-increment Lagrange-multiplier contact)",
                default="static",
                choices=("static", "newmark", "explicit"),
            ),
            "safety": Key(
                "float",
                "time step = safety x the stable step dt_crit of the central difference at "
                "t = 0 (Lanczos)",
                default=0.9,
                lo=0.0,
                hi=1.0,
                open_lo=True,
                when=EXPLICIT,
            ),
            "recheck_every": Key(
                "int",
                "re-estimate the stable step every N steps and shrink the step to safety x it "
                "when smaller (0: never; the step stays safety x dt_crit at t = 0)",
                default=0,
                lo=0,
                when=EXPLICIT,
            ),
            "steps": Key("int", "initial number of load steps", default=10, lo=1, when=STATIC),
            "min_increment": Key(
                "float", "smallest load increment", default=1e-4, **POS, when=STATIC
            ),
            "max_increment": Key(
                "float",
                "largest load increment",
                default=0.25,
                lo=0.0,
                hi=1.0,
                open_lo=True,
                when=STATIC,
            ),
            "dt": Key(
                "float", "time step [s]", default=0.01, lo=0.0, hi=1.0, open_lo=True, when=NEWMARK
            ),
            "dt_min": Key(
                "float",
                "smallest time step after halvings [s] (default dt/64)",
                lo=0.0,
                open_lo=True,
                when=NEWMARK,
            ),
            "gamma": Key(
                "float",
                "gamma in [0.5, 1] (beta = (gamma + 1/2)^2 / 4); > 0.5 damps the highest "
                "frequencies",
                default=0.6,
                lo=0.5,
                hi=1.0,
                when=NEWMARK,
            ),
            "rotary_scale": Key(
                "float",
                "factor >= 1 on the rotary inertia rho t^3/12 of the director (mass scaling; "
                "1 = physical)",
                default=1.0,
                lo=1.0,
                when=DYNAMIC,
            ),
            "settle_time": Key(
                "float",
                "time [s] with the body at rest before the motion starts (settling)",
                default=0.2,
                lo=0.0,
                when=DYNAMIC,
            ),
            "settle_damping": Key(
                "float",
                "mass-proportional damping [1/s] during the settling only (dynamic relaxation "
                "of a started state, e.g. donned pants, before the motion; the motion itself "
                "is undamped); 0 = none",
                default=0.0,
                lo=0.0,
                when=EXPLICIT,
            ),
            "ramp_time": Key(
                "float",
                "time [s] over which the loads (gravity) ramp up",
                default=0.1,
                lo=0.0,
                when=DYNAMIC,
            ),
            "duration": Key(
                "float",
                "simulated time [s] (default settle_time + the longest segment motion; "
                "required without a moving segment)",
                lo=0.0,
                open_lo=True,
                when=DYNAMIC,
            ),
        },
        "the solver",
        optional=True,
    ),
    "body": Section(
        {
            "name": Key("str", "segment name (e.g. 'upper_arm', 'forearm')", required=True),
            "type": Key(
                "choice",
                "segment motion: at rest, a hinge, keyframes (poses at given times, "
                "interpolated), or motion capture (Eq. 27 frames of a C3D / TRC recording, "
                "interpolated)",
                required=True,
                choices=("fixed", "hinge", "keyframes", "mocap"),
            ),
            "radii": Key(
                "vec3",
                "ellipsoid radii (r1 along the limb axis, r2, r3) [m], all > 0",
                required=True,
            ),
            "centre": Key(
                "vec3",
                "ellipsoid centre at t = 0 [m] (mocap: where the placing segment's Eq. 27 centre "
                "is put at the window start)",
            ),
            "axis": Key("vec3", "limb axis e1 (direction of r1) at t = 0", default=[1.0, 0.0, 0.0]),
            "up": Key(
                "vec3",
                "direction of r2 at t = 0 (made orthogonal to axis); r3 along axis x up",
                default=[0.0, 0.0, 1.0],
            ),
            "joint": Key("vec3", "hinge: joint centre on the rotation axis [m]"),
            "hinge_axis": Key("vec3", "hinge: rotation axis (right-hand rule)"),
            "omega": Key(
                "float", "hinge: angular velocity [deg/s] (maps angle to time)", default=57.0, **POS
            ),
            "angle_max": Key("float", "hinge: final angle [deg]", lo=0.0, hi=180.0, open_lo=True),
            "omega_ramp": Key(
                "float",
                "hinge: smooth start, time [s] over which the angular velocity rises from 0 to "
                "omega as omega (3 x^2 - 2 x^3), x = time / omega_ramp (the angle then lags the "
                "constant rate by omega omega_ramp / 2; a smaller angle_max is reached inside the "
                "ramp); 0: the rate jumps to omega at the start",
                default=0.0,
                lo=0.0,
            ),
            "times": Key(
                "floats",
                "keyframes: the key times [s] after solver.settle_time, from 0, strictly "
                "increasing (at least 2); the segment rests at its last pose afterwards",
            ),
            "centres": Key("vec3s", "keyframes: the ellipsoid centre at each key time [m]"),
            "turns": Key(
                "vec3s",
                "keyframes: the rotation vector [rad] of the ellipsoid's axes from their pose at "
                "t = 0 (axis, up) at each key time (default: no turn); consecutive keys within "
                "90 deg (centres: cubic spline, rotations: rotation spline)",
            ),
            "file": Key(
                "str",
                "mocap: C3D or TRC recording (relative paths: from the working folder, else "
                "from the scene file's folder)",
            ),
            "placement": Key(
                "choice",
                "mocap, the placing segment: 'centre' moves the recording rigidly so that this "
                "segment's Eq. 27 pose at the window start has its centre at `centre` with "
                "axes (axis, up); 'recording' keeps the recording's own coordinates (in m; "
                "e.g. to meet a garment donned on the recorded pose)",
                default="centre",
                choices=("centre", "recording"),
            ),
            "offset": Key(
                "vec3",
                "mocap: ellipsoid centre offset from the Eq. 27 centroid (J1 + J2) / 2 in the "
                "segment frame (e1, e2, e3) [m] (e.g. the pelvis centre behind the hip line)",
            ),
            "j1": Key("marker", "mocap: proximal joint centre J1 (Eq. 27)"),
            "j2": Key("marker", "mocap: distal joint centre J2 (Eq. 27)"),
            "m": Key("marker", "mocap: auxiliary marker M fixing the roll (Eq. 27)"),
            "window": Key(
                "floats",
                "mocap: [start, end] of the recording to play [s, file time]; it starts after "
                "solver.settle_time and the segment rests at its end pose afterwards",
            ),
            "placed_by": Key(
                "str",
                "mocap: the segment whose Eq. 27 pose at the window start is put at its centre "
                "with its axis and up (default: this one); segments placed by the same one "
                "share one rigid transform of the recording",
            ),
            "max_gap": Key(
                "int", "mocap: longest marker gap filled by a spline [frames]", default=10, lo=0
            ),
            "repeat": Key(
                "int",
                "mocap: play the window (one gait cycle: foot strike to foot strike of one foot) "
                "this many times, each copy shifted by the stride and blended at the seams "
                "(clothfem.body.gait_repeat; the log and summary say it is a repeated cycle)",
                default=1,
                lo=1,
            ),
            "repeat_blend": Key(
                "float", "mocap, repeat > 1: half-width of the seam blend [s]", default=0.05, lo=0.0
            ),
            "stride_markers": Key(
                "strs",
                "mocap, repeat > 1: markers whose mean displacement over the cycle is the "
                'stride (e.g. the hip centres ["LFEP", "RFEP"])',
            ),
        },
        "rigid ellipsoid body segments (Man & Swan 2007, Sec. 3.3); a body turns contact on",
        many=True,
        optional=True,
        variants={
            "fixed": ("centre",),
            "hinge": ("centre", "joint", "hinge_axis", "angle_max"),
            "keyframes": ("times", "centres"),
            "mocap": ("file", "j1", "j2", "m", "window"),
        },
    ),
    "contact": Section(
        {
            "method": Key(
                "choice",
                "'lagrange': implicit Lagrange multipliers with an active set (Sec. 3.2; static "
                "and newmark); 'film': forward-increment Lagrange multipliers (Eqs. 22-25; "
                "explicit). Default: the one of solver.integrator",
                choices=("lagrange", "film"),
            ),
            "mu": Key(
                "float",
                "Coulomb friction coefficient (0: no friction objects)",
                default=0.0,
                lo=0.0,
            ),
            "tangential_penalty": Key(
                "float",
                "k_t [N/m] of the regularised stick law (elastic slip |f_t|/k_t); default "
                "100 x min(E1, E2) x t, at most 1e6",
                lo=0.0,
                open_lo=True,
                when=NEWMARK,
            ),
            "semismooth_passes": Key(
                "int",
                "active-set passes per step that may change the set inside Newton "
                "(semismooth); later passes converge Newton on a fixed set",
                default=5,
                lo=0,
                when=NEWMARK,
            ),
            "newton_stall_limit": Key(
                "int",
                "Newton gives up an active-set pass (the step is cut) after this many "
                "iterations in a row with a line-search step below 1/16",
                default=12,
                lo=1,
                when=NEWMARK,
            ),
            "tissue_stiffness": Key(
                "float",
                "a body that gives way: Winkler modulus k_w [Pa/m] of the soft tissue under "
                "the fabric (a node pressed with force lam sinks lam / (k_w A) into the "
                "body, A its lumped area); unset: rigid ellipsoids (the paper's)",
                lo=0.0,
                open_lo=True,
                when=IMPLICIT,
            ),
            "torque_segment": Key(
                "str",
                "segment whose joint is the Eq. 28 centre J (default: the first hinge): a "
                "hinge's joint, or a mocap segment's proximal joint J1 carried with its Eq. 27 "
                "frame (J moves with the body, e.g. the knee for a shank)",
            ),
            "torque_point": Key("vec3", "explicit Eq. 28 centre J [m] (overrides the joint)"),
            "torque_with": Key(
                "strs",
                "aj = 'touching': more segments whose contact forces count (e.g. the foot "
                "with the shank)",
            ),
            "flexion_frame": Key(
                "str",
                "mocap torque segment: the segment whose Eq. 27 frame gives the flexion axis "
                "of torque_flex (e.g. the thigh for the knee; default: the torque segment)",
            ),
            "flexion_axis": Key(
                "choice",
                "mocap torque segment: the flexion_frame axis that is the flexion axis: 'e3' "
                "(= e1 x e2; medio-lateral when M is anterior, as the lower body's thigh and "
                "shank) or 'e2' (towards M; medio-lateral when M is a lateral marker)",
                default="e3",
                choices=("e2", "e3"),
            ),
            "aj": Key(
                "choice",
                "Eq. 28 node set AJ: 'beyond_joint' = nodes past the plane through J normal "
                "to the torque segment's axis (a hinge: reference positions at t = 0; a mocap "
                "segment: current positions and the plane at t); 'touching' = nodes in "
                "contact with the torque segment (and contact.torque_with); 'all' = every node",
                default="beyond_joint",
                choices=("beyond_joint", "touching", "all"),
            ),
            "settle": Key(
                "bool",
                "ramp the loads (gravity) in solver.steps steps with the body at rest first",
                default=True,
                when=STATIC,
            ),
            "stabilization": Key(
                "float",
                "artificial viscous damping eta [Pa/m]: nodal force -eta A_i (u_i - u_i of the "
                "last sub-step) to pass wrinkling points; 0 = none (reported as "
                "stabilization_force)",
                default=0.0,
                lo=0.0,
                when=STATIC,
            ),
            "kernel": Key(
                "choice",
                "the film contact correction's implementation, 'compiled' (a C loop built "
                "on first use with the system C compiler) or 'numpy' (the vectorised "
                "reference; the same answers to round-off, slower)",
                default="compiled",
                choices=("compiled", "numpy"),
                when=EXPLICIT,
            ),
            "increments": Key(
                "int",
                "equal recorded increments of the hinge motion (quasi-static)",
                default=20,
                lo=1,
                when=STATIC,
            ),
            "self_contact": Key(
                "bool",
                "fabric-fabric contact; explicit: clothfem.contact.self_contact (proximity "
                "corrections after FILM, Coulomb friction between layers, a crossing "
                "fail-safe); newmark: clothfem.contact.self_barrier (a log barrier in the "
                "Newton system, lagged Coulomb friction between layers and a crossing step "
                "filter); false builds nothing of it",
                default=False,
                when=DYNAMIC,
            ),
            "self_mu": Key(
                "float",
                "Coulomb coefficient between fabric layers (default: contact.mu)",
                lo=0.0,
                when=DYNAMIC,
            ),
            "self_distance": Key(
                "float",
                "contact distance between mid-surfaces [m] (default: material.thickness); "
                "newmark: the barrier's activation distance",
                lo=0.0,
                open_lo=True,
                when=DYNAMIC,
            ),
            "self_pressure": Key(
                "float",
                "the pressure [Pa] two parallel fabric layers exert on each other "
                "at half the activation distance (the barrier's stiffness: how hard a fold "
                "squeezed between two bodies resists being pressed thinner)",
                default=1e3,
                lo=0.0,
                open_lo=True,
                when=NEWMARK,
            ),
        },
        "contact of the fabric with the body (only built with a [[body]])",
        optional=True,
    ),
    "torques": Section(
        {
            "name": Key(
                "str",
                "the measure's name in torques.csv and summary.json (letters, digits, _)",
                required=True,
            ),
            "segment": Key(
                "str",
                "the segment whose joint is J (as contact.torque_segment), e.g. 'L_shank' "
                "for the left knee",
                required=True,
            ),
            "torque_point": Key("vec3", "explicit centre J [m] (overrides the joint)"),
            "torque_with": Key("strs", "as contact.torque_with (aj = 'touching')"),
            "aj": Key(
                "choice",
                "as contact.aj",
                default="touching",
                choices=("beyond_joint", "touching", "all"),
            ),
            "flexion_frame": Key("str", "as contact.flexion_frame (mocap segments)"),
            "flexion_axis": Key(
                "choice", "as contact.flexion_axis", default="e3", choices=("e2", "e3")
            ),
        },
        "dynamic runs (explicit or newmark): more Eq. 28 joint torques measured besides the "
        "one of [contact] (e.g. the left knee and the hips), one row per measure and history "
        "row in torques.csv",
        many=True,
        optional=True,
    ),
    "initial": Section(
        {
            "positions": Key(
                "str",
                "NumPy .npz with X (N, 3), the reference (pattern) node positions [m], and x "
                "(N, 3), their positions at the start [m], e.g. the donned.npz of `python -m "
                "clothfem.particle.donning`; nodes matched by X; the reference stays the mesh, "
                "directors follow the deformed surface (relative paths: from the working "
                "folder, else the scene file's folder)",
            ),
            "don": Key(
                "bool",
                "don the pants onto the body's pose at the start of its window with the "
                "particle model first ([donning]; docs/donning.md) and start from the donned "
                "positions (written to donned.npz): needs mesh.generator = 'pants' and the "
                "seven segments of clothfem.body.lower_body from one C3D file; the pants "
                "dimensions left out of [mesh] are the donning fit's",
                default=False,
            ),
        },
        "the state a run starts from (default: the mesh at rest)",
        optional=True,
    ),
    "donning": Section(
        {
            "ease": Key("float", "radial ease of the fitted pants [m]", default=0.015, **POS),
            "waist_height": Key(
                "float",
                "waist above the hip line, as a fraction of the pelvis's vertical radius",
                default=0.5,
                lo=0.0,
                hi=0.9,
            ),
            "start_scale": Key(
                "float",
                "the ellipsoids' radius scale at the start of the growth",
                default=0.3,
                lo=0.0,
                hi=1.0,
                open_lo=True,
            ),  # fmt: skip
            "grow_time": Key(
                "float", "time the ellipsoids grow to full size [s]", default=0.4, **POS
            ),
            "settle_time": Key(
                "float", "relaxation at full size after the growth [s]", default=0.2, lo=0.0
            ),
            "alpha": Key("float", "mass-proportional damping [1/s]", default=10.0, lo=0.0),
            "max_stretch": Key(
                "float", "strain limit of the structural and shear springs [-]", default=0.1, **POS
            ),
            "mu": Key("float", "Coulomb friction of the donning contact", default=0.0, lo=0.0),
            "self_distance": Key(
                "float",
                "fabric-fabric contact distance [m] while donning (0: the fabric may pass "
                "through itself)",
                default=1e-3,
                lo=0.0,
            ),
        },
        "the particle donning of initial.don (clothfem.particle.donning; docs/donning.md)",
        optional=True,
    ),
    "output": Section(
        {
            "every": Key(
                "int",
                "write fields every N accepted steps (explicit: every N history rows)",
                default=1,
                lo=1,
            ),
            "png": Key(
                "bool",
                "write PNG snapshots, the torque plot and animation.gif (coloured by the contact "
                "pressure)",
                default=True,
            ),
            "frames": Key(
                "int",
                "most frames of animation.gif, drawn from the written field steps (0: none)",
                default=40,
                lo=0,
            ),
            "checkpoint_every": Key(
                "int",
                "write a restart checkpoint every N accepted steps (explicit: every N history "
                "rows; 0 = never)",
                default=10,
                lo=0,
                when=DYNAMIC,
            ),
            "interval": Key(
                "float",
                "one history row per interval [s]; its torque, resultant and multiplier sum "
                "are the means over the steps in it",
                default=0.01,
                lo=0.0,
                open_lo=True,
                when=EXPLICIT,
            ),
        },
        "what is written",
        optional=True,
    ),
}


def _fail(path: str, msg: str) -> None:
    raise SceneError(f"scene key '{path}': {msg}")


def _check_value(path: str, key: Key, value: Any) -> Any:
    def number(v) -> bool:
        return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)

    if key.kind == "str":
        if not isinstance(value, str):
            _fail(path, f"must be a string, got {value!r}")
    elif key.kind == "bool":
        if not isinstance(value, bool):
            _fail(path, f"must be true or false, got {value!r}")
    elif key.kind == "choice":
        if value not in key.choices:
            _fail(path, f"must be {key.describe()}, got {value!r}")
    elif key.kind == "vec3":
        if not (isinstance(value, list) and len(value) == 3 and all(number(v) for v in value)):
            _fail(path, f"must be 3 finite numbers, got {value!r}")
        value = [float(v) for v in value]
    elif key.kind == "marker":
        if not isinstance(value, str | dict):
            _fail(path, f"must be {key.describe()}, got {value!r}")
    elif key.kind == "strs":
        if not (isinstance(value, list) and value and all(isinstance(v, str) for v in value)):
            _fail(path, f"must be a non-empty list of strings, got {value!r}")
    elif key.kind == "vec3s":
        if not (
            isinstance(value, list)
            and all(isinstance(v, list) and len(v) == 3 and all(map(number, v)) for v in value)
        ):
            _fail(path, f"must be a list of 3-number lists, got {value!r}")
        value = [[float(x) for x in v] for v in value]
    elif key.kind == "floats":
        if not (isinstance(value, list) and all(number(v) for v in value)):
            _fail(path, f"must be a list of numbers, got {value!r}")
    elif key.kind in ("int", "float"):
        if key.kind == "int" and not (isinstance(value, int) and not isinstance(value, bool)):
            _fail(path, f"must be {key.describe()}, got {value!r}")
        if not number(value):
            _fail(path, f"must be {key.describe()}, got {value!r}")
        below = key.lo is not None and (value <= key.lo if key.open_lo else value < key.lo)
        above = key.hi is not None and value > key.hi
        if below or above:
            _fail(path, f"must be {key.describe()}, got {value!r}")
        value = float(value) if key.kind == "float" else value
    return value


def _validate_table(path: str, section: Section, table: Any) -> dict[str, Any]:
    if not isinstance(table, dict):
        _fail(path, "must be a table")
    unknown = sorted(set(table) - set(section.keys))
    if unknown:
        _fail(f"{path}.{unknown[0]}", f"unknown key; allowed: {', '.join(section.keys)}")
    out: dict[str, Any] = {}
    for name, key in section.keys.items():
        if name in table:
            out[name] = _check_value(f"{path}.{name}", key, table[name])
        elif key.required:
            _fail(f"{path}.{name}", f"required ({key.doc}; {key.describe()})")
        else:
            out[name] = copy.deepcopy(key.default)
    kind = out.get("type", out.get("generator"))
    for name in section.variants.get(kind, ()):
        if out.get(name) is None:
            _fail(f"{path}.{name}", f"required for {kind!r} ({section.keys[name].doc})")
    return out


def validate(data: dict[str, Any], *, base: str | Path | None = None) -> Scene:
    """Validate a parsed scene, fill defaults and return the typed :class:`Scene`; raises
    :class:`SceneError` (one line).
    ``base``: the scene file's folder (relative motion-capture paths are also looked up
    there)."""
    unknown = sorted(set(data) - set(SCHEMA))
    if unknown:
        _fail(unknown[0], f"unknown table; allowed: {', '.join(SCHEMA)}")
    out: dict[str, Any] = {}
    for name, section in SCHEMA.items():
        if name not in data:
            if not section.optional:
                _fail(name, f"required table ({section.doc})")
            out[name] = [] if section.many else _validate_table(name, section, {})
            continue
        if section.many:
            if not isinstance(data[name], list):
                _fail(name, "must be an array of tables ([[" + name + "]])")
            out[name] = [
                _validate_table(f"{name}[{i}]", section, t) for i, t in enumerate(data[name])
            ]
        else:
            out[name] = _validate_table(name, section, data[name])
    _validate_applies(data)
    mat = out["material"]
    if mat["preset"] is not None:
        for k, v in MATERIALS[mat["preset"]].items():
            if k not in data["material"]:
                mat[k] = v
    for k in ("E1", "E2", "G12"):
        if mat[k] is None:
            _fail(f"material.{k}", "required (or give material.preset)")
    limit = math.sqrt(mat["E1"] / mat["E2"])
    if not abs(mat["nu12"]) < limit:
        _fail("material.nu12", f"must be in (-{limit:.4g}, {limit:.4g}), got {mat['nu12']!r}")
    _validate_decrimping(data["material"], mat)
    if _all_or_none(mat, VISCOSITY_KEYS, "material.viscosity* keys (all three or none)"):
        if not any(mat[k] > 0 for k in VISCOSITY_KEYS):
            _fail(
                "material.viscosity1", "one of viscosity1, viscosity2, viscosity12 must be > 0 Pa s"
            )
    _all_or_none(mat, FRICTION_KEYS, "material.friction_* keys (all four or none)")
    if out["mesh"]["generator"] in ("cylinder", "pants") and out["mesh"]["n_around"] % 4:
        _fail(
            "mesh.n_around",
            f"must be a multiple of 4 for a {out['mesh']['generator']}, "
            f"got {out['mesh']['n_around']}",
        )
    m = out["mesh"]
    if m["generator"] == "pants":
        leg = m["leg_radius"] if m["leg_radius"] is not None else 0.09
        spacing = m["leg_spacing"] if m["leg_spacing"] is not None else 0.22
        if spacing < 2.2 * leg:
            _fail(
                "mesh.leg_spacing",
                f"must be >= 2.2 leg_radius = {2.2 * leg:.4g} m (a gap for the crotch arch), "
                f"got {spacing!r}",
            )
    _validate_element(out)
    _validate_body(data, out)
    _validate_mocap(out, base=None if base is None else Path(base))
    _validate_initial(out, base=None if base is None else Path(base))
    _validate_don(data, out)
    _validate_duration(out)
    _validate_torques(out)
    _validate_size(out)
    scene = scene_from_dict(out)
    if m["generator"] != "file":
        check_boundaries(scene, GENERATOR_BOUNDARIES[m["generator"]], m["generator"])
    sv = scene.solver
    if sv.integrator == "newmark" and sv.dt_min is not None and sv.dt_min > sv.dt:
        _fail("solver.dt_min", f"must be <= solver.dt = {sv.dt:g} s, got {sv.dt_min!r}")
    return scene


def _foreign(data: dict[str, Any]) -> list[tuple[str, When, Any]]:
    """(path, when, the selector's value) of every key a parsed scene sets that belongs to
    another integrator (or element scheme) than the scene's (:class:`When`)."""
    found = []
    for name, section in SCHEMA.items():
        given = data.get(name)
        for key_name in given if isinstance(given, dict) and not section.many else ():
            when = getattr(section.keys.get(key_name), "when", None)
            if when is None:
                continue
            table, selector = when.selector.split(".")
            chosen = data.get(table)
            default = SCHEMA[table].keys[selector].default
            actual = chosen.get(selector, default) if isinstance(chosen, dict) else default
            if actual not in when.values:
                found.append((f"{name}.{key_name}", when, actual))
    return found


def foreign_keys(data: dict[str, Any]) -> list[str]:
    """The keys (``section.key``) a parsed (unvalidated) scene sets that do not apply to its
    integrator (or element scheme): those :func:`validate` refuses, e.g. to ``--unset``
    when a scene is switched to another integrator."""
    return [path for path, _, _ in _foreign(data)]


def _validate_applies(data: dict[str, Any]) -> None:
    """Refuse the first key of another integrator (or element scheme) than the scene's."""
    found = _foreign(data)
    if found:
        path, when, actual = found[0]
        raise SceneError(when.refusal(path, actual))


def _all_or_none(mat: dict[str, Any], keys: tuple[str, ...], what: str) -> bool:
    """Fail naming the first missing key when some but not all ``keys`` of ``mat`` are given;
    True when all are given."""
    given = [k for k in keys if mat[k] is not None]
    if given and len(given) < len(keys):
        missing = next(k for k in keys if mat[k] is None)
        _fail(f"material.{missing}", f"required with the other {what}")
    return bool(given)


def _validate_duration(out: dict[str, Any]) -> None:
    sv = out["solver"]
    moving = any(seg["type"] != "fixed" for seg in out["body"])
    if sv["integrator"] != "static" and not moving and sv["duration"] is None:
        _fail(
            "solver.duration",
            f"required with solver.integrator = {sv['integrator']!r} and no moving body "
            "segment (a number of seconds > 0)",
        )
    if sv["integrator"] == "static" or not moving:
        return
    if sv["duration"] is not None and sv["duration"] <= sv["settle_time"]:
        _fail(
            "solver.duration",
            f"must be > solver.settle_time = {sv['settle_time']:g} s (else the body never "
            f"moves), got {sv['duration']!r}",
        )


def _read_motion(path: Path):
    """The marker set of a C3D or TRC file (clothfem.body readers)."""
    from .body import read_c3d, read_trc

    return read_trc(path) if path.suffix.lower() == ".trc" else read_c3d(path)


def _validate_initial(out: dict[str, Any], *, base: Path | None) -> None:
    """``initial.positions``: the file reads as two finite (N, 3) arrays; no supports (they
    would hold nodes at their pattern positions)."""
    from .initial_state import read_positions

    given = out["initial"]["positions"]
    if given is None:
        return
    path = Path(given)
    if not path.is_absolute() and not path.is_file() and base is not None:
        path = base / path
    if not path.is_file():
        _fail("initial.positions", f"{given!r} does not exist (an .npz file with X and x)")
    try:
        read_positions(path)
    except ValueError as exc:
        _fail("initial.positions", str(exc))
    if out["supports"]:
        _fail(
            "initial.positions",
            "a run from given positions takes no [[supports]] (they hold nodes at the pattern "
            f"positions), got {len(out['supports'])}",
        )
    out["initial"]["positions"] = str(path)


def _validate_don(data: dict[str, Any], out: dict[str, Any]) -> None:
    """``initial.don`` (:func:`clothfem.particle.scene_donning.check_scene`); the pants
    dimensions the scene leaves out are the donning fit's; a [donning] table needs it."""
    if not out["initial"]["don"]:
        if "donning" in data:
            _fail("donning", "applies with initial.don = true only")
        return
    from .particle.scene_donning import check_scene

    try:
        out["mesh"].update(check_scene(scene_from_dict(out)))
    except ValueError as exc:
        key, _, msg = str(exc).partition(": ")
        _fail(key, msg)


def _validate_mocap(out: dict[str, Any], *, base: Path | None) -> None:
    """Mocap segments: the file exists and reads, the window lies in the recording, the
    markers are in it (gaps no longer than max_gap), the placing segment exists."""
    from .body import validate_marker_map

    body = out["body"]
    names = [seg["name"] for seg in body]
    cache: dict[Path, Any] = {}
    for i, seg in enumerate(body):
        _validate_keyframes(seg, f"body[{i}]", out["solver"]["integrator"])
        if seg["type"] != "mocap":
            for k in ("file", "j1", "j2", "m", "window", "placed_by", "stride_markers", "offset"):
                if seg[k] is not None:
                    _fail(f"body[{i}].{k}", "is a key of type = 'mocap' segments only")
            if seg["placement"] != "centre":
                _fail(f"body[{i}].placement", "is a key of type = 'mocap' segments only")
            continue
        key = f"body[{i}]"
        if out["solver"]["integrator"] == "static":
            _fail(
                f"{key}.type",
                "'mocap' needs solver.integrator = 'explicit' or 'newmark' (the quasi-static "
                "path drives hinges only)",
            )
        for k in ("joint", "hinge_axis", "angle_max"):
            if seg[k] is not None:
                _fail(f"{key}.{k}", "is a key of type = 'hinge' segments only")
        _validate_repeat(seg, key)
        path = Path(seg["file"])
        if not path.is_absolute() and not path.is_file() and base is not None:
            path = base / path
        if not path.is_file():
            _fail(f"{key}.file", f"{seg['file']!r} does not exist (a .c3d or .trc file)")
        path = path.resolve()
        if path not in cache:
            try:
                cache[path] = _read_motion(path)
            except (ValueError, OSError, RuntimeError) as exc:
                _fail(f"{key}.file", f"cannot be read: {exc}")
        seg["file"] = str(path)
        markers = cache[path]
        t = markers.times
        w = seg["window"]
        if len(w) != 2 or not w[0] < w[1]:
            _fail(f"{key}.window", f"must be [start, end] with start < end [s], got {w!r}")
        lo, hi = float(t[0]), float(t[-1])
        tol = 1e-9 * max(1.0, abs(hi))
        if w[0] < lo - tol or w[1] > hi + tol:
            _fail(
                f"{key}.window",
                f"must lie within the recording [{lo:g}, {hi:g}] s of {path.name}, got {w!r}",
            )
        first = int(np.searchsorted(t, w[0] - tol))
        last = int(np.searchsorted(t, w[1] + tol, side="right")) - 1
        if last - first < 1:
            _fail(f"{key}.window", f"holds fewer than 2 frames of {path.name}, got {w!r}")
        seg["window"] = [float(v) for v in w]
        refs = {k: seg[k] for k in ("j1", "j2", "m")}
        try:
            validate_marker_map({seg["name"]: refs})
        except ValueError as exc:
            _fail(f"{key}.j1", str(exc))
        part = markers.window(first=first, last=last)
        for k, ref in refs.items():
            try:
                part.resolve(ref, max_gap=seg["max_gap"])
            except ValueError as exc:
                _fail(f"{key}.{k}", str(exc))
        if seg["repeat"] > 1:
            try:
                repeated_markers(section_from_dict(seg, section="body"), markers)
            except ValueError as exc:
                _fail(f"{key}.repeat", str(exc))
        placed = seg["placed_by"] or seg["name"]
        if placed not in names or body[names.index(placed)]["type"] != "mocap":
            _fail(f"{key}.placed_by", f"must name a mocap segment, one of {names}, got {placed!r}")
        placing = body[names.index(placed)]
        if placing["placement"] == "recording" and placing["centre"] is not None:
            _fail(
                f"body[{names.index(placed)}].centre",
                "is not used with placement = 'recording' (the recording stays where it is)",
            )
        if placing["placement"] == "centre" and placing["centre"] is None:
            _fail(
                f"body[{names.index(placed)}].centre",
                f"required: segment {placed!r} places the recording",
            )
        seg["placed_by"] = placed


def _validate_keyframes(seg: dict[str, Any], key: str, integrator: str) -> None:
    """A ``keyframes`` segment: its times, centres and turns (keys of it only)."""
    if seg["type"] != "keyframes":
        for k in ("times", "centres", "turns"):
            if seg[k] is not None:
                _fail(f"{key}.{k}", "is a key of type = 'keyframes' segments only")
        return
    if integrator == "static":
        _fail(f"{key}.type", "'keyframes' needs solver.integrator = 'explicit' or 'newmark'")
    t = seg["times"]
    if len(t) < 2 or t[0] != 0.0 or any(b <= a for a, b in zip(t, t[1:], strict=False)):
        _fail(f"{key}.times", f"must start at 0 and increase strictly (>= 2 keys), got {t!r}")
    for k in ("centres", "turns"):
        if seg[k] is not None and len(seg[k]) != len(t):
            _fail(f"{key}.{k}", f"must give {len(t)} entries (one per key time), got {len(seg[k])}")
    for k in ("joint", "hinge_axis", "angle_max"):
        if seg[k] is not None:
            _fail(f"{key}.{k}", "is a key of type = 'hinge' segments only")
    from .scene_body import keyframe_motion

    try:
        keyframe_motion(section_from_dict(seg, section="body"))
    except ValueError as exc:
        _fail(f"{key}.turns", str(exc))


def _validate_repeat(seg: dict[str, Any], key: str) -> None:
    """The repetition keys of a mocap segment: stride markers with repeat > 1 only."""
    if seg["repeat"] > 1 and seg["stride_markers"] is None:
        _fail(f"{key}.stride_markers", "required with repeat > 1 (e.g. the hip centres)")
    if seg["repeat"] == 1 and seg["stride_markers"] is not None:
        _fail(f"{key}.stride_markers", "is a key of repeat > 1 only")


def repeated_markers(seg: SegmentSpec, markers):
    """:class:`clothfem.body.gait_repeat.RepeatedGait` of a validated mocap segment with
    ``repeat > 1``: its window of ``markers`` played ``repeat`` times (times from 0)."""
    from .body.gait_repeat import repeat_cycle

    start, end = seg.window
    return repeat_cycle(
        markers,
        start=start,
        end=end,
        copies=seg.repeat,
        blend=seg.repeat_blend,
        pelvis_markers=seg.stride_markers,
    )


def _validate_decrimping(given: dict[str, Any], mat: dict[str, Any]) -> None:
    """The decrimping keys: all of them with law 'decrimping' (from the preset or given),
    none given with law 'linear'."""
    if mat["law"] == "linear":
        for k in DECRIMPING_KEYS:
            if k in given:
                _fail(f"material.{k}", "is a parameter of material.law = 'decrimping' only")
            mat[k] = None
        return
    for k in DECRIMPING_KEYS:
        if mat[k] is None:
            _fail(f"material.{k}", "required with material.law = 'decrimping'")
    for i in (1, 2):
        if mat[f"E{i}_decrimped"] < mat[f"E{i}"]:
            _fail(
                f"material.E{i}_decrimped",
                f"must be >= E{i} = {mat[f'E{i}']:g}, got {mat[f'E{i}_decrimped']!r}",
            )
        if mat[f"width{i}"] > mat[f"transition{i}"]:
            _fail(
                f"material.width{i}",
                f"must be in (0, transition{i} = {mat[f'transition{i}']:g}], "
                f"got {mat[f'width{i}']!r}",
            )


def _validate_element(out: dict[str, Any]) -> None:
    """element.scheme = 'mitc9' needs what its kernels implement: 9-node quadrilaterals
    (degree 2, order-2 geometry)."""
    if out["element"]["scheme"] != "mitc9":
        return
    m = out["mesh"]
    if out["element"]["degree"] != 2 or m["order"] != 2 or m["cell"] != "quadrilateral":
        _fail(
            "element.scheme",
            "'mitc9' needs 9-node quadrilaterals: mesh.cell = 'quadrilateral', mesh.order = 2 "
            "and element.degree = 2",
        )


def _validate_body(data: dict[str, Any], out: dict[str, Any]) -> None:
    body = out["body"]
    if "contact" in data and not body:
        _fail("contact", "needs a body: add [[body]] segments (contact is only built with one)")
    names = [seg["name"] for seg in body]
    for i, seg in enumerate(body):
        if names.count(seg["name"]) > 1:
            _fail(f"body[{i}].name", f"must be unique, got {seg['name']!r} twice")
        if not all(r > 0 for r in seg["radii"]):
            _fail(f"body[{i}].radii", f"must be 3 numbers > 0 m, got {seg['radii']!r}")
        axis, up = seg["axis"], seg["up"]
        if math.hypot(*axis) == 0:
            _fail(f"body[{i}].axis", "must be a non-zero vector, got [0, 0, 0]")
        cross = [
            axis[1] * up[2] - axis[2] * up[1],
            axis[2] * up[0] - axis[0] * up[2],
            axis[0] * up[1] - axis[1] * up[0],
        ]
        if math.hypot(*cross) <= 1e-9 * math.hypot(*axis) * math.hypot(*up):
            _fail(f"body[{i}].up", f"must not be parallel to axis {axis!r}, got {up!r}")
        if seg["type"] == "hinge" and math.hypot(*seg["hinge_axis"]) == 0:
            _fail(f"body[{i}].hinge_axis", "must be a non-zero vector, got [0, 0, 0]")
    if not body:
        return
    c = out["contact"]
    film = out["solver"]["integrator"] == "explicit"
    if c["method"] is None:
        c["method"] = "film" if film else "lagrange"
    elif (c["method"] == "film") != film:
        _fail(
            "contact.method",
            f"must be {'film' if film else 'lagrange'!r} with solver.integrator = "
            f"{out['solver']['integrator']!r}, got {c['method']!r}",
        )
    _validate_torque(c, body)


# the boundary names of the generated meshes (clothfem.mesh, clothfem.pants_mesh)
GENERATOR_BOUNDARIES = {
    "strip": ("root", "tip", "sides"),
    "cylinder": ("shoulder", "cuff"),
    "panel": ("start", "end", "sides"),
    "pants": ("waist", "left_hem", "right_hem"),
}


def check_boundaries(scene: Scene, names: Sequence[str], source: str) -> None:
    """Every boundary a validated ``scene`` names (supports, edge loads) is one of ``names``,
    the boundaries of the mesh ``source`` (a generator or a file name)."""
    refs = [(f"supports[{i}].where", s.where) for i, s in enumerate(scene.supports)]
    refs += [(f"loads[{i}].where", ld.where) for i, ld in enumerate(scene.loads)]
    for path, name in refs:
        if name is not None and name not in names:
            _fail(
                path,
                f"must name a boundary of the {source} mesh, one of {list(names)}, got {name!r}",
            )


def mesh_file_problem(scene: Scene) -> str | None:
    """Why a ``generator = "file"`` mesh cannot be used (one line), else None: the file must
    exist, be a gmsh mesh with 2-D elements and no 3-D ones (a surface), of 9-node
    quadrilaterals only for element.scheme = 'mitc9', and have the boundaries the scene
    names as physical groups of its curves (gmsh; serial)."""
    path = Path(scene.mesh.file)
    key = "scene key 'mesh.file'"
    if not path.is_file():
        return f"{key}: {str(path)!r} does not exist"
    import gmsh

    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    try:
        gmsh.merge(str(path))
        if not len(gmsh.model.mesh.getNodes()[0]):
            return f"{key}: {path.name!r} holds no mesh nodes"
        if not len(gmsh.model.mesh.getElements(2)[0]) or len(gmsh.model.mesh.getElements(3)[0]):
            return f"{key}: {path.name!r} must be a surface mesh (2-D elements, none 3-D)"
        quad9 = 10  # gmsh's element type of the 9-node quadrilateral
        if scene.element.scheme == "mitc9" and set(gmsh.model.mesh.getElements(2)[0]) != {quad9}:
            return (
                "scene key 'element.scheme': 'mitc9' needs 9-node quadrilaterals; "
                f"{path.name!r} has other 2-D elements (use 'psri')"
            )
        groups = gmsh.model.getPhysicalGroups(1)
        names = [gmsh.model.getPhysicalName(1, tag) or f"tag{tag}" for _, tag in groups]
    except Exception as exc:  # gmsh raises a bare Exception
        return f"{key}: {path.name!r} is not a mesh gmsh can read ({exc})"
    finally:
        gmsh.finalize()
    try:
        check_boundaries(scene, names, path.name)
    except SceneError as exc:
        return str(exc)
    return None


# resident memory of a run [bytes]: BASE + per node x nodes, measured (max RSS, serial) on
# the arm-sleeve scene on 2026-12-02: explicit 226 / 368 / 640 MB at 1,312 / 5,184 / 11,616
# nodes (~40 kB a node), newmark (MUMPS LU) 214 / 301 / 683 MB at 336 / 1,312 / 5,184 nodes
# (~100 kB a node, growing with the LU fill: an underestimate for much larger meshes)
MEMORY_BASE = 0.2e9
MEMORY_PER_NODE = {"explicit": 40e3, "newmark": 100e3, "static": 100e3}


def _node_estimate(m: dict[str, Any]) -> tuple[str, int] | None:
    """(the key that sets the size, about how many nodes) of a generated mesh; None for a
    file. Second-order cells: 2 n + 1 nodes along an open side, 2 n around a closed one."""
    k = m["order"]
    if m["generator"] == "strip":
        return "mesh.nx", (k * m["nx"] + 1) * (k * m["ny"] + 1)
    if m["generator"] == "file":
        return None
    tube = k * m["n_around"] * (k * m["n_along"] + 1)
    if m["generator"] == "panel":
        tube += k * m["n_along"] + 1
    # pants: two legs and the seat, about 2.45 tubes (2,583 nodes at 16 x 16, tube 1,056)
    return "mesh.n_around", int(2.5 * tube) if m["generator"] == "pants" else tube


def _available_memory() -> float | None:
    """MemAvailable of /proc/meminfo [bytes], None where there is none."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return float(line.split()[1]) * 1024.0
    except OSError:
        return None
    return None


def _validate_size(out: dict[str, Any]) -> None:
    """Refuse a mesh whose run would need more memory than the machine has available."""
    est, avail = _node_estimate(out["mesh"]), _available_memory()
    if est is None or avail is None:
        return
    key, nodes = est
    need = MEMORY_BASE + MEMORY_PER_NODE[out["solver"]["integrator"]] * nodes
    if need > avail:
        _fail(
            key,
            f"about {nodes:,} nodes would need ~{need / 2**30:.1f} GiB with the "
            f"{out['solver']['integrator']} integrator, more than the {avail / 2**30:.1f} GiB "
            "available; use fewer cells",
        )


#: The Eq. 28 keys a ``[[torques]]`` entry shares with ``[contact]``.
TORQUE_KEYS = ("torque_point", "torque_with", "aj", "flexion_frame", "flexion_axis")


def _validate_torques(out: dict[str, Any]) -> None:
    """The ``[[torques]]`` measures: unique names, dynamic runs with a body, and the Eq. 28
    keys checked as those of ``[contact]`` (:func:`torque_entry`)."""
    names = [m["name"] for m in out["torques"]]
    for i, m in enumerate(out["torques"]):
        path = f"torques[{i}]"
        if not re.fullmatch(r"[A-Za-z0-9_]+", m["name"]):
            _fail(f"{path}.name", f"must be letters, digits and _, got {m['name']!r}")
        if names.count(m["name"]) > 1:
            _fail(f"{path}.name", f"must be unique, got {m['name']!r} twice")
        if not out["body"]:
            _fail(path, "needs a body: add [[body]] segments")
        if out["solver"]["integrator"] == "static":
            _fail(path, "is measured by solver.integrator = 'explicit' or 'newmark', not 'static'")
        c = {**out["contact"], "torque_segment": m["segment"], **{k: m[k] for k in TORQUE_KEYS}}
        _validate_torque(c, out["body"], path=path)


def torque_entry(scene: Scene, entry: TorqueSpec) -> Scene:
    """``scene`` with the Eq. 28 keys of its ``[contact]`` replaced by those of the
    ``[[torques]]`` ``entry`` (``segment`` is ``torque_segment``)."""
    keys = {k: getattr(entry, k) for k in TORQUE_KEYS}
    contact = dataclasses.replace(scene.contact, torque_segment=entry.segment, **keys)
    return dataclasses.replace(scene, contact=contact)


def _validate_torque(c: dict[str, Any], body: list[dict[str, Any]], *, path="contact") -> None:
    """The Eq. 28 keys of ``[contact]`` (or of a ``[[torques]]`` entry at ``path``, whose
    ``segment`` is the torque segment): J, AJ and the flexion frame (torque_measure)."""
    moving = [seg["name"] for seg in body if seg["type"] in ("hinge", "mocap")]
    names = [seg["name"] for seg in body]
    hinges = [seg["name"] for seg in body if seg["type"] == "hinge"]
    named = c["torque_segment"]
    seg_key = "contact.torque_segment" if path == "contact" else f"{path}.segment"
    if named is not None and named not in moving:
        _fail(seg_key, f"must name a hinge or mocap segment, one of {moving}, got {named!r}")
    if named is None and not hinges and c["torque_point"] is None:
        _fail(
            f"{path}.torque_point",
            "required when no body segment is a hinge and contact.torque_segment is not set",
        )
    if c["aj"] != "all" and named is None and not hinges:
        _fail(f"{path}.aj", f"{c['aj']!r} needs a torque segment ({seg_key})")
    for other in c["torque_with"] or ():
        if other not in names:
            _fail(f"{path}.torque_with", f"must name body segments, one of {names}, got {other!r}")
    if c["torque_with"] and c["aj"] != "touching":
        _fail(f"{path}.torque_with", f"counts with aj = 'touching' only, got aj = {c['aj']!r}")
    mocap = [seg["name"] for seg in body if seg["type"] == "mocap"]
    if c["flexion_frame"] is not None and named not in mocap:
        _fail(f"{path}.flexion_frame", f"needs a mocap {seg_key}")
    if c["flexion_frame"] is not None and c["flexion_frame"] not in mocap:
        _fail(
            f"{path}.flexion_frame",
            f"must name a mocap segment, one of {mocap}, got {c['flexion_frame']!r}",
        )


def apply_overrides(data: dict[str, Any], overrides: list[str]) -> dict[str, Any]:
    """Apply ``key.path=value`` overrides (values in TOML syntax, e.g. ``mesh.nx=8``,
    ``material.warp=[0,1,0]``, ``loads.0.value=5``) to a parsed (unvalidated) scene."""
    data = copy.deepcopy(data)
    for item in overrides:
        if "=" not in item:
            raise SceneError(f"--set {item!r}: expected key.path=value")
        path, raw = item.split("=", 1)
        try:
            value = tomllib.loads(f"v = {raw}")["v"]
        except tomllib.TOMLDecodeError:
            value = raw  # a bare string
        parts = path.strip().split(".")
        node: Any = data
        for p in parts[:-1]:
            if isinstance(node, list):
                if not p.isdigit() or int(p) >= len(node):
                    raise SceneError(f"--set {path}: no element {p!r}")
                node = node[int(p)]
            else:
                node = node.setdefault(p, {})
        last = parts[-1]
        if isinstance(node, list):
            raise SceneError(f"--set {path}: cannot replace a whole list element")
        node[last] = value
    return data


def remove_keys(data: dict[str, Any], paths: list[str]) -> dict[str, Any]:
    """Remove the keys ``paths`` (``section.key``, or ``section.N.key`` in an array of tables,
    e.g. ``solver.dt``, ``body.1.omega_ramp``) from a parsed (unvalidated) scene. A key the
    scene does not set is left as it is; a key the schema does not know is an error."""
    data = copy.deepcopy(data)
    for path in paths:
        parts = path.strip().split(".")
        section = SCHEMA.get(parts[0])
        if section is None:
            raise SceneError(f"--unset {path}: unknown table; allowed: {', '.join(SCHEMA)}")
        shape = f"{parts[0]}.N.key" if section.many else f"{parts[0]}.key"
        if len(parts) != shape.count(".") + 1 or (section.many and not parts[1].isdigit()):
            raise SceneError(f"--unset {path}: expected {shape}")
        if parts[-1] not in section.keys:
            raise SceneError(f"--unset {path}: unknown key; allowed: {', '.join(section.keys)}")
        node = data.get(parts[0])
        if section.many and node is not None:
            if int(parts[1]) >= len(node):
                raise SceneError(f"--unset {path}: no element {parts[1]!r}")
            node = node[int(parts[1])]
        if isinstance(node, dict):
            node.pop(parts[-1], None)
    return data


def load(
    path: str | Path, overrides: list[str] | None = None, *, unset: list[str] | None = None
) -> Scene:
    """Read a scene file, remove the keys ``unset`` (:func:`remove_keys`), apply the
    ``overrides`` (:func:`apply_overrides`) and validate it."""
    path = Path(path)
    if not path.is_file():
        raise SceneError(f"scene file {str(path)!r} does not exist")
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"scene file {path.name!r} is not valid TOML: {exc}") from None
    data = apply_overrides(remove_keys(data, unset or []), overrides or [])
    return validate(data, base=path.parent)


def schema_markdown() -> str:
    """The reference table of every scene key (``docs/scene.md`` is generated from it)."""
    lines = []
    for name, section in SCHEMA.items():
        head = f"[[{name}]]" if section.many else f"[{name}]"
        opt = " (optional)" if section.optional else ""
        lines += [
            f"### `{head}`{opt}",
            "",
            section.doc,
            "",
            "| key | allowed | default | meaning |",
            "|---|---|---|---|",
        ]
        for key_name, key in section.keys.items():
            default = (
                "required" if key.required else ("—" if key.default is None else repr(key.default))
            )
            lines.append(f"| `{key_name}` | {key.describe()} | {default} | {key.meaning()} |")
        if section.variants:
            lines += [""] + [
                f"- `{kind}` requires: {', '.join(f'`{k}`' for k in req) or 'nothing more'}"
                for kind, req in section.variants.items()
            ]
        lines.append("")
    return "\n".join(lines)
