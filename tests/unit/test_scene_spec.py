"""The typed scene (clothfem.spec): one frozen dataclass per schema section with exactly the
schema's keys, built by the validation, and its dict form."""

import dataclasses
import tomllib
from pathlib import Path

import pytest

from clothfem import scene as scenes
from clothfem.spec import SECTIONS, Scene, to_dict

ROOT = Path(__file__).resolve().parents[2]
ARM = ROOT / "demos" / "scenes" / "arm_sleeve.toml"


def test_fields_are_the_schema_keys():
    """Every section's dataclass has the schema's keys as fields, in the schema's order, and
    the scene's fields are the schema's sections."""
    assert list(SECTIONS) == list(scenes.SCHEMA)
    assert [f.name for f in dataclasses.fields(Scene)] == list(scenes.SCHEMA)
    for name, section in scenes.SCHEMA.items():
        assert [f.name for f in dataclasses.fields(SECTIONS[name])] == list(section.keys), name


def test_scene_is_frozen_with_tuples():
    s = scenes.load(ARM)
    assert isinstance(s, Scene) and isinstance(s.body, tuple) and isinstance(s.supports, tuple)
    assert s.material.warp == (1.0, 0.0, 0.0) and isinstance(s.body[0].radii, tuple)
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.contact.mu = 0.5  # type: ignore[misc]
    moved = dataclasses.replace(s, contact=dataclasses.replace(s.contact, mu=0.5))
    assert moved.contact.mu == 0.5 and s.contact.mu == scenes.load(ARM).contact.mu


def test_dict_form():
    """to_dict gives the plain nested dict of the scene (sections and keys in schema order,
    lists); equal files validate to equal scenes."""
    s = scenes.load(ARM)
    d = to_dict(s)
    assert list(d) == list(scenes.SCHEMA) and d["material"]["warp"] == [1.0, 0.0, 0.0]
    assert d["body"][1]["name"] == s.body[1].name and isinstance(d["body"], list)
    assert scenes.validate(tomllib.loads(ARM.read_text()), base=ARM.parent) == s
    assert list(d["solver"]) == list(scenes.SCHEMA["solver"].keys)
