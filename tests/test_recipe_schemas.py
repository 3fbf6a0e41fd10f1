"""Every recipe is registered once (:mod:`torchrl_csirl.run.recipes`) with its schemas, which describe every
key; each training script runs its registered recipe; the task's family picks the schema."""
from __future__ import annotations

import importlib
import os

import pytest

import torchrl_csirl.scripts
from torchrl_csirl.run import config, recipe_for, recipe_schemas, registered_recipes

SCRIPTS = os.path.dirname(torchrl_csirl.scripts.__file__)


def test_every_configured_script_runs_a_registered_recipe():
    configured = {name[:-3] for name in os.listdir(SCRIPTS)
                  if name.endswith(".py") and "help_requested" in open(os.path.join(SCRIPTS, name)).read()}
    assert configured == {r.script.rpartition(".")[2] for r in registered_recipes().values()}
    for recipe in registered_recipes().values():
        source = open(os.path.join(SCRIPTS, recipe.script.rpartition(".")[2] + ".py")).read()
        assert "run_recipe(" in source and recipe.trainer is not None and recipe.finish is not None


@pytest.mark.parametrize("schema", recipe_schemas())
def test_schema_describes_every_key(schema):
    module, _, name = schema.partition(":")
    klass = getattr(importlib.import_module(module), name)
    lines = config.describe(klass)
    assert any(line.startswith("seed = ") for line in lines)
    for base in klass.__mro__:
        config.attribute_docs(base)


@pytest.mark.parametrize("method, task, schema", [
    ("csirl", "merge", "CSIRLHighwayConfig"), ("csirl", "relocate", "CSIRLTaskConfig"),
    ("csirl-b", "hopper", "CSIRLTaskConfig"), ("bc", "roundabout", "ImitationHighwayConfig"),
    ("gail", "antmaze-umaze", "ImitationTaskConfig"),
])
def test_the_tasks_family_picks_the_schema(method, task, schema):
    assert recipe_for(method).schema_for(task).__name__ == schema


def test_a_method_belongs_to_one_recipe_and_an_unknown_one_is_named():
    owners = [m for r in registered_recipes().values() for m in r.methods]
    assert len(owners) == len(set(owners))
    with pytest.raises(KeyError, match="unknown method 'nope'"):
        recipe_for("nope")


def test_the_glue_finds_the_recipes_preset_config_group():
    from torchrl_csirl.methods import csirl

    assert config.preset_names(csirl.CONFIG_DIR) == ("default", "paper")
    assert csirl.load_config(["preset=paper"]).preset == "paper"


def test_every_task_has_the_published_procedure_as_a_preset():
    from torchrl_csirl.methods import csirl

    assert config.preset_names(csirl.TASK_CONFIG_DIR) == ("default", "paper")
    load = recipe_for("csirl").load_config
    default, paper = load(["env.task=antmaze-umaze"]), load(["env.task=antmaze-umaze", "preset=paper"])
    driving = csirl.load_config(["preset=paper"])
    for key in ("collector.init_random_frames", "replay_buffer.clear_each_round", "replay_buffer.expert_fraction",
                "optim.utd_ratio", "csirl.updates_per_round", "csirl.meta_every", "csirl.matching_target",
                "csirl.matching_features", "csirl.fixed_alpha"):
        assert config.flatten_config(paper)[key] == config.flatten_config(driving)[key], key
    assert paper.csirl.actor_bc_coef == 0 and paper.csirl.goal_conditioned is False
    assert default.csirl.matching_target != paper.csirl.matching_target
    assert paper.collector.frames_per_batch == default.collector.frames_per_batch  # the task's batch
    assert csirl.total_frames(paper, curriculum_length=280) == 280 * (20000 + 1280)
    # the command line goes over the preset
    assert load(["env.task=halfcheetah", "preset=paper", "csirl.meta_every=3"]).csirl.meta_every == 3
    with pytest.raises(config.ConfigError, match="preset=fast: must be one of default, paper"):
        load(["env.task=antmaze-umaze", "preset=fast"])


def test_a_scenarios_own_defaults_go_under_the_preset_and_the_command_line(tmp_path):
    from torchrl_csirl.methods import csirl

    scenes = config.scene_defaults(csirl.CONFIG_DIR)
    assert "intersection" in scenes and "merge" not in scenes
    (key, value), *_ = scenes["intersection"].items()
    section, leaf = key.split(".")
    # the scene's value, where the schema's default differs from it
    assert config.flatten_config(csirl.load_config(["env.task=intersection"]))[key] == value
    assert config.flatten_config(csirl.load_config(["env.task=merge"]))[key] != value
    # a named preset and the command line go over it
    assert csirl.load_config(["env.task=intersection", "preset=paper"]).model.lane_features is False
    flipped = not value if isinstance(value, bool) else None
    if flipped is not None:
        cli = csirl.load_config(["env.task=intersection", f"{key}={str(flipped).lower()}"])
        assert getattr(getattr(cli, section), leaf) is flipped
    # an unknown key in a scene file is one line naming it
    (tmp_path / "scene").mkdir()
    (tmp_path / "scene" / "merge.yaml").write_text("model:\n  lane_featurs: true\n")
    with pytest.raises(config.ConfigError, match="model.lane_featurs: unknown configuration key"):
        config.load_config(csirl.CSIRLHighwayConfig, ["env.task=merge"], str(tmp_path))


def test_a_tasks_own_defaults_apply_to_that_task_alone_and_go_under_the_command_line():
    """``config/csirl_task/scene/<task>.yaml`` for the tasks outside the driving schema: the HalfCheetah trains
    without expert transitions (docs/studies/outside-driving.md), by either spelling of its name."""
    from torchrl_csirl.methods import csirl
    from torchrl_csirl.run.recipes import recipe_for

    tasks = config.scene_defaults(csirl.TASK_CONFIG_DIR)
    assert tasks["halfcheetah"] == {"replay_buffer.expert_fraction": 0.0}
    recipe = recipe_for("csirl")
    for spelling in ("env.scenario", "env.task"):
        assert recipe.load_config([f"{spelling}=halfcheetah"]).replay_buffer.expert_fraction == 0.0
    assert recipe.load_config(["env.task=halfcheetah", "replay_buffer.expert_fraction=0.25"]).replay_buffer.expert_fraction == 0.25
    assert recipe.load_config(["env.task=hopper"]).replay_buffer.expert_fraction == 0.25
    assert recipe.load_config(["env.task=merge"]).replay_buffer.expert_fraction == 0.25
