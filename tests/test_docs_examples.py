"""Every page under docs/components/ runs as written.

Convention: only the blocks fenced exactly as ```python run (a page's blocks in order, in one
fresh namespace per page, as a reader pasting them one after the other would); a sketch that
must not run is fenced ```py or ```text. Each page also gets a check of what its examples leave
behind, below; a new page needs one.
"""
from __future__ import annotations

import glob
import os
import tempfile

import pytest
import torch
from markdown_examples import ROOT, _run_python_blocks


def _reward_transforms(ns: dict) -> None:
    assert ns["matching"].subgoal == 8  # moved with set_subgoal after the first sample
    assert torch.equal(ns["rollout"]["next", "reward"], ns["rollout"]["next", "matching_reward"])


def _ensemble_sac(ns: dict) -> None:
    assert ns["q"].shape == (5, ns["B"]) and ns["uncertainty"].shape == (ns["B"],)
    assert ns["grad_w"].abs().item() > 0 and ns["auto"].target_entropy == -ns["action_dim"]


def _meta_reward(ns: dict) -> None:
    out = ns["out"]
    assert {"loss_qvalue", "loss_actor", "loss_meta", "loss_imitation", "loss_reward_l1"} <= set(out.keys())
    assert out["meta_grad_norm_imitation"] > 0 and out["meta_grad_norm_l1"] > 0


def _curriculum(ns: dict) -> None:
    assert ns["curriculum"].subgoal == ns["matching"].subgoal == 10
    assert ns["selection"].profile.shape == (ns["curriculum"].length,)


def _datasets(ns: dict) -> None:
    assert ns["batch"].batch_size == (64,)
    assert ns["published"].num_trajectories == 2 and ns["demos"].num_trajectories == 5


def _tasks(ns: dict) -> None:
    assert ns["spec"].matching_features == ("cos_theta", "sin_theta")
    assert ns["demos"].observation_dim == 3 and torch.isfinite(ns["out"]["loss_qvalue"])


def _trainer(ns: dict) -> None:
    assert (ns["trainer"].frames, ns["trainer"].rounds) == (200, 2)
    assert len(ns["selection"].history) == 2 and "loss_qvalue" in ns["losses"]


CHECKS = {
    "reward-transforms.md": _reward_transforms,
    "ensemble-sac.md": _ensemble_sac,
    "meta-reward.md": _meta_reward,
    "curriculum.md": _curriculum,
    "datasets.md": _datasets,
    "tasks.md": _tasks,
    "trainer.md": _trainer,
}


def _pages() -> list[str]:
    return sorted(os.path.basename(p) for p in glob.glob(os.path.join(ROOT, "docs", "components", "*.md")))


def test_every_component_page_has_a_check() -> None:
    assert _pages() == sorted(CHECKS)


@pytest.fixture
def one_thread_and_tmpdir(tmp_path, monkeypatch):
    """One intra-op thread (the examples are tiny: threads only spin on a busy machine) and
    ``tempfile`` pointed at ``tmp_path`` (the examples write into ``tempfile.mkdtemp()``)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    try:
        yield
    finally:
        torch.set_num_threads(threads)


@pytest.mark.parametrize("page", _pages())
def test_component_page_examples_run(page: str, one_thread_and_tmpdir) -> None:
    namespace = _run_python_blocks(f"docs/components/{page}", shared_namespace=True)
    CHECKS[page](namespace)
