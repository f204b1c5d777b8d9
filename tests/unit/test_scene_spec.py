"""The typed scene (clothfem.spec): one frozen dataclass per schema section with exactly the
schema's keys."""

import dataclasses

from clothfem import scene as scenes
from clothfem.spec import SECTIONS, Scene


def test_fields_are_the_schema_keys():
    """Every section's dataclass has the schema's keys as fields, in the schema's order, and
    the scene's fields are the schema's sections."""
    assert list(SECTIONS) == list(scenes.SCHEMA)
    assert [f.name for f in dataclasses.fields(Scene)] == list(scenes.SCHEMA)
    for name, section in scenes.SCHEMA.items():
        assert [f.name for f in dataclasses.fields(SECTIONS[name])] == list(section.keys), name
