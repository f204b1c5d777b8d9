"""The typed scene: one frozen dataclass per section, built by :func:`clothfem.scene.validate`.

A validated scene is a :class:`Scene` whose fields are the sections of the scene file;
``[[supports]]``, ``[[loads]]``, ``[[body]]`` and ``[[torques]]`` are tuples of their
entries, lists are tuples, and every key the schema knows is a field (None where a scene
leaves an optional key without a default out). Values are SI: lengths in m, times in s,
stresses in Pa, angles in deg unless a comment says rad. A run reads ``scene.solver.dt``;
code that needs another scene builds one with :func:`dataclasses.replace` or validates an
edited file again.

The schema table :data:`clothfem.scene.SCHEMA` stays the single source of truth for the keys,
their defaults, ranges and meanings (``clothfem schema``, docs/scene.md); the dataclasses
here are written out by hand rather than generated from it with
:func:`dataclasses.make_dataclass`, so that type checkers, editors and readers see every
field and its type, and a test (tests/unit/test_scene_spec.py) keeps their fields equal to
the schema's keys, section by section. The dataclasses carry no defaults (the validation
fills every key); the comments give units only, the meaning of a key is its schema doc.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, is_dataclass
from typing import Any, Literal

__all__ = [
    "Scene",
    "SceneInfo",
    "MeshSpec",
    "MaterialSpec",
    "SupportSpec",
    "LoadSpec",
    "ElementSpec",
    "SolverSpec",
    "SegmentSpec",
    "ContactSpec",
    "TorqueSpec",
    "InitialSpec",
    "DonningSpec",
    "OutputSpec",
    "SECTIONS",
    "section_from_dict",
    "scene_from_dict",
    "to_dict",
]

#: A point or direction [x, y, z].
Vec3 = tuple[float, float, float]
#: A marker reference of a mocap segment: a marker name, or ``{midpoint = [a, b]}`` or
#: ``{hip_centre = {...}}`` (clothfem.body.validate_marker_map), as the scene gives it.
Marker = str | dict[str, Any]


@dataclass(frozen=True, kw_only=True)
class SceneInfo:
    """``[scene]``: what the run is."""

    name: str
    description: str


@dataclass(frozen=True, kw_only=True)
class MeshSpec:
    """``[mesh]``: the fabric surface."""

    generator: Literal["strip", "cylinder", "panel", "pants", "file"]
    file: str | None
    length: float | None  # [m]
    width: float | None  # [m]
    radius: float | None  # [m]
    angle: float | None  # [deg]
    nx: int | None
    ny: int | None
    n_around: int | None
    n_along: int | None
    waist_radius: float | None  # [m]
    hip_radius: float | None  # [m]
    leg_radius: float | None  # [m]
    leg_length: float | None  # [m]
    crotch_depth: float | None  # [m]
    leg_spacing: float | None  # [m]
    cell: Literal["quadrilateral", "triangle"]
    order: int
    translate: Vec3 | None  # [m]


@dataclass(frozen=True, kw_only=True)
class MaterialSpec:
    """``[material]``: the fabric material (orthotropic, plane stress), preset resolved."""

    preset: str | None  # a key of clothfem.scene.MATERIALS
    law: Literal["linear", "decrimping"]
    E1: float | None  # [Pa]
    E2: float | None  # [Pa]
    G12: float | None  # [Pa]
    nu12: float  # [-]
    rho: float  # [kg/m^3]
    E1_decrimped: float | None  # [Pa]
    E2_decrimped: float | None  # [Pa]
    transition1: float | None
    transition2: float | None
    width1: float | None
    width2: float | None
    friction_stiffness1: float | None  # [Pa]
    friction_stiffness2: float | None  # [Pa]
    friction_stress1: float | None  # [Pa]
    friction_stress2: float | None  # [Pa]
    viscosity1: float | None  # [Pa s]
    viscosity2: float | None  # [Pa s]
    viscosity12: float | None  # [Pa s]
    thickness: float  # [m]
    warp: Vec3


@dataclass(frozen=True, kw_only=True)
class SupportSpec:
    """``[[supports]]``: fabric supports."""

    type: Literal["clamp", "pin", "symmetry", "prescribed"]
    where: str
    axis: int | None
    displacement: Vec3 | None  # [m]
    components: tuple[float, ...]
    rotation: Vec3 | None  # [rad]


@dataclass(frozen=True, kw_only=True)
class LoadSpec:
    """``[[loads]]``: fabric loads (scaled by the load factor)."""

    type: Literal["gravity", "pressure", "edge_traction", "edge_moment", "point_force"]
    acceleration: Vec3  # [m/s^2]
    value: float | None  # [Pa]
    follower: bool
    where: str | None
    traction: Vec3 | None  # [N/m]
    moment: Vec3 | None  # [N m/m]
    point: Vec3 | None  # [m]
    force: Vec3 | None  # [N]


@dataclass(frozen=True, kw_only=True)
class ElementSpec:
    """``[element]``: the shell element (clothfem.shell.Quadrature)."""

    degree: int
    reduced_quadrature: int
    scheme: Literal["psri", "mitc9", "sri"]
    psri_factor: float
    stabilization: float


@dataclass(frozen=True, kw_only=True)
class SolverSpec:
    """``[solver]``: the solver."""

    integrator: Literal["static", "newmark", "explicit"]
    safety: float
    recheck_every: int
    steps: int
    min_increment: float
    max_increment: float
    dt: float  # [s]
    dt_min: float | None  # [s]
    gamma: float
    rotary_scale: float
    settle_time: float  # [s]
    settle_damping: float  # [1/s]
    ramp_time: float  # [s]
    duration: float | None  # [s]


@dataclass(frozen=True, kw_only=True)
class SegmentSpec:
    """``[[body]]``: one rigid ellipsoid segment and its motion (Sec. 3.3)."""

    name: str
    type: Literal["fixed", "hinge", "keyframes", "mocap"]
    radii: Vec3  # [m]
    centre: Vec3 | None  # [m]
    axis: Vec3
    up: Vec3
    joint: Vec3 | None  # [m]
    hinge_axis: Vec3 | None
    omega: float  # [deg/s]
    angle_max: float | None  # [deg]
    omega_ramp: float  # [s]
    times: tuple[float, ...] | None  # [s]
    centres: tuple[Vec3, ...] | None  # [m]
    turns: tuple[Vec3, ...] | None  # [rad]
    file: str | None
    placement: Literal["centre", "recording"]
    offset: Vec3 | None  # [m]
    j1: Marker | None
    j2: Marker | None
    m: Marker | None
    window: tuple[float, ...] | None  # [s, file time]
    placed_by: str | None
    max_gap: int  # [frames]
    repeat: int
    repeat_blend: float  # [s]
    stride_markers: tuple[str, ...] | None


@dataclass(frozen=True, kw_only=True)
class ContactSpec:
    """``[contact]``: contact of the fabric with the body (built only with a body)."""

    method: Literal["lagrange", "film"] | None
    mu: float
    tangential_penalty: float | None  # [N/m]
    semismooth_passes: int
    newton_stall_limit: int
    tissue_stiffness: float | None  # [Pa/m]
    torque_segment: str | None
    torque_point: Vec3 | None  # [m]
    torque_with: tuple[str, ...] | None
    flexion_frame: str | None
    flexion_axis: Literal["e2", "e3"]
    aj: Literal["beyond_joint", "touching", "all"]
    settle: bool
    stabilization: float  # [Pa/m]
    kernel: Literal["compiled", "numpy"]
    increments: int
    self_contact: bool
    self_mu: float | None
    self_distance: float | None  # [m]
    self_pressure: float  # [Pa]


@dataclass(frozen=True, kw_only=True)
class TorqueSpec:
    """``[[torques]]``: one more Eq. 28 joint torque measured by a dynamic run."""

    name: str
    segment: str
    torque_point: Vec3 | None  # [m]
    torque_with: tuple[str, ...] | None
    aj: Literal["beyond_joint", "touching", "all"]
    flexion_frame: str | None
    flexion_axis: Literal["e2", "e3"]


@dataclass(frozen=True, kw_only=True)
class InitialSpec:
    """``[initial]``: the state a run starts from (default: the mesh at rest)."""

    positions: str | None  # an .npz file
    don: bool


@dataclass(frozen=True, kw_only=True)
class DonningSpec:
    """``[donning]``: the particle donning of ``initial.don`` (docs/donning.md)."""

    ease: float  # [m]
    waist_height: float
    start_scale: float
    grow_time: float  # [s]
    settle_time: float  # [s]
    alpha: float  # [1/s]
    max_stretch: float  # [-]
    mu: float
    self_distance: float  # [m]


@dataclass(frozen=True, kw_only=True)
class OutputSpec:
    """``[output]``: what is written."""

    every: int
    png: bool
    frames: int
    checkpoint_every: int
    interval: float  # [s]


@dataclass(frozen=True, kw_only=True)
class Scene:
    """A validated scene: its sections, ``[[...]]`` tables as tuples in file order."""

    scene: SceneInfo
    mesh: MeshSpec
    material: MaterialSpec
    supports: tuple[SupportSpec, ...]
    loads: tuple[LoadSpec, ...]
    element: ElementSpec
    solver: SolverSpec
    body: tuple[SegmentSpec, ...]
    contact: ContactSpec
    torques: tuple[TorqueSpec, ...]
    initial: InitialSpec
    donning: DonningSpec
    output: OutputSpec


#: The dataclass of each scene section, by section name.
SECTIONS: dict[str, type] = {
    "scene": SceneInfo,
    "mesh": MeshSpec,
    "material": MaterialSpec,
    "supports": SupportSpec,
    "loads": LoadSpec,
    "element": ElementSpec,
    "solver": SolverSpec,
    "body": SegmentSpec,
    "contact": ContactSpec,
    "torques": TorqueSpec,
    "initial": InitialSpec,
    "donning": DonningSpec,
    "output": OutputSpec,
}


def _frozen(value: Any) -> Any:
    """Lists (nested too) as tuples; other values (numbers, strings, marker tables) as given."""
    if isinstance(value, list):
        return tuple(_frozen(v) for v in value)
    return value


def section_from_dict(table: dict[str, Any], *, section: str) -> Any:
    """The dataclass of ``section`` (e.g. "body") from its validated ``table`` (every key
    present)."""
    return SECTIONS[section](**{k: _frozen(v) for k, v in table.items()})


def scene_from_dict(data: dict[str, Any]) -> Scene:
    """The :class:`Scene` of a validated scene ``data`` (sections as dicts, every key filled)."""
    sections: dict[str, Any] = {}
    for name, table in data.items():
        if isinstance(table, list):
            sections[name] = tuple(section_from_dict(t, section=name) for t in table)
        else:
            sections[name] = section_from_dict(table, section=name)
    return Scene(**sections)


def _plain(value: Any) -> Any:
    """A field's value with dataclasses as dicts and tuples (nested too) as lists."""
    if is_dataclass(value):
        return to_dict(value)
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    return value


def to_dict(spec: Any) -> dict[str, Any]:
    """A :class:`Scene` (or one section's dataclass) as the plain nested dict of the scene
    file: sections and keys in schema order, ``[[...]]`` tables and lists as lists."""
    return {f.name: _plain(getattr(spec, f.name)) for f in fields(spec)}
