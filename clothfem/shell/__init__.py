"""Fabric shell: pure-UFL physics (kinematics, material) and the discrete model."""

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
from .hysteresis import DahlFriction
from .material import DecrimpingFabric, FabricMaterial
from .model import Quadrature, ShellModel
from .viscosity import FabricViscosity

__all__ = [
    "Clamp",
    "DahlFriction",
    "DecrimpingFabric",
    "EdgeMoment",
    "EdgeTraction",
    "FabricMaterial",
    "FabricViscosity",
    "Gravity",
    "Pin",
    "PointForce",
    "PointPin",
    "Prescribed",
    "Pressure",
    "Quadrature",
    "ShellModel",
    "Symmetry",
]
