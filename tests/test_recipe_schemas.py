"""Every script's typed schema is importable from ``torchrl_csirl.launch`` (a documentation build's
configuration reference reads them there) and is the schema the script itself uses."""
from __future__ import annotations

import importlib
import os

import pytest

import torchrl_csirl.launch as common
import torchrl_csirl.scripts
from torchrl_csirl.launch import config

SCRIPTS = os.path.dirname(torchrl_csirl.scripts.__file__)


def _schema(recipe: str) -> type:
    module, _, name = common.RECIPE_SCHEMAS[recipe].partition(":")
    return getattr(importlib.import_module(module), name)


def test_every_configured_recipe_has_its_schema_listed():
    configured = {name[:-3] for name in os.listdir(SCRIPTS)
                  if name.endswith(".py") and "help_requested" in open(os.path.join(SCRIPTS, name)).read()}
    # the robotics recipes pass their schema to their driving recipe's main
    configured |= {"csirl_robotics", "imitation_robotics"}
    assert set(common.RECIPE_SCHEMAS) == configured


@pytest.mark.parametrize("recipe", sorted(common.RECIPE_SCHEMAS))
def test_schema_describes_every_key_and_is_the_recipes_own(recipe):
    schema = _schema(recipe)
    lines = config.describe(schema)
    assert any(line.startswith("seed = ") for line in lines)
    for klass in schema.__mro__:
        config.attribute_docs(klass)
    script = importlib.import_module(f"torchrl_csirl.scripts.{recipe}")
    assert getattr(script, schema.__name__) is schema


def test_the_glue_finds_the_recipes_preset_config_group():
    from torchrl_csirl.launch import csirl

    assert config.preset_names(csirl.CONFIG_DIR) == ("default", "paper")
    assert csirl.load_config(["preset=paper"]).preset == "paper"


def test_a_scenarios_own_defaults_go_under_the_preset_and_the_command_line(tmp_path):
    from torchrl_csirl.launch import csirl

    scenes = config.scene_defaults(csirl.CONFIG_DIR)
    assert "intersection" in scenes and "merge" not in scenes
    (key, value), *_ = scenes["intersection"].items()
    section, leaf = key.split(".")
    # the scene's value, where the schema's default differs from it
    assert config.flatten_config(csirl.load_config(["env.scenario=intersection"]))[key] == value
    assert config.flatten_config(csirl.load_config(["env.scenario=merge"]))[key] != value
    # a named preset and the command line go over it
    assert csirl.load_config(["env.scenario=intersection", "preset=paper"]).model.lane_features is False
    flipped = not value if isinstance(value, bool) else None
    if flipped is not None:
        cli = csirl.load_config(["env.scenario=intersection", f"{key}={str(flipped).lower()}"])
        assert getattr(getattr(cli, section), leaf) is flipped
    # an unknown key in a scene file is one line naming it
    (tmp_path / "scene").mkdir()
    (tmp_path / "scene" / "merge.yaml").write_text("model:\n  lane_featurs: true\n")
    with pytest.raises(config.ConfigError, match="model.lane_featurs: unknown configuration key"):
        config.load_config(csirl.CSIRLHighwayConfig, ["env.scenario=merge"], str(tmp_path))
