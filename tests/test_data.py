"""Tests of the expert-demonstration container, its .npz format and the published-data importer."""
from __future__ import annotations

import hashlib
import os
import pickle

import numpy as np
import pytest
import torch

from torchrl_csirl.data import (
    ExpertDemonstrations,
    RestrictedUnpickler,
    import_published,
)


def _episode(length: int, obs_dim: int = 4, act_dim: int = 2, *, seed: int = 0, terminal: bool = True, reward: bool = False):
    g = torch.Generator().manual_seed(seed)
    obs = torch.randn(length + 1, obs_dim, generator=g)
    ep = {
        "observation": obs[:-1],
        "action": torch.rand(length, act_dim, generator=g) * 2 - 1,
        "next_observation": obs[1:],
        "terminated": torch.zeros(length, dtype=torch.bool),
        "truncated": torch.zeros(length, dtype=torch.bool),
    }
    if terminal:
        ep["terminated"][-1] = True
    else:
        ep["truncated"][-1] = True
    if reward:
        ep["reward"] = torch.randn(length, generator=g)
    return ep


@pytest.fixture
def demos() -> ExpertDemonstrations:
    episodes = [_episode(5, seed=0), _episode(3, seed=1, terminal=False), _episode(4, seed=2)]
    return ExpertDemonstrations.from_episodes(episodes, metadata={"scenario": "merge", "seed": 7})


class TestContainer:
    def test_layout(self, demos):
        assert demos.num_trajectories == 3
        assert len(demos) == 12
        assert demos.lengths.tolist() == [5, 3, 4]
        td = demos.transitions()
        for key in ["observation", "action", ("next", "observation"), ("next", "terminated"),
                    ("next", "truncated"), ("next", "done"), ("collector", "traj_ids")]:
            assert key in td.keys(True), key
        assert td["collector", "traj_ids"].tolist() == [0] * 5 + [1] * 3 + [2] * 4
        assert torch.equal(td["next", "done"], td["next", "terminated"] | td["next", "truncated"])
        assert td["next", "terminated"].shape == (12, 1)

    def test_trajectory_matches_episode(self, demos):
        ep = _episode(3, seed=1, terminal=False)
        traj = demos.trajectory(1)
        assert traj.batch_size == (3,)
        torch.testing.assert_close(traj["observation"], ep["observation"])
        torch.testing.assert_close(traj["next", "observation"], ep["next_observation"])
        assert traj["next", "truncated"].squeeze(-1).tolist() == [False, False, True]
        assert not traj["next", "terminated"].any()
        assert torch.equal(demos.trajectory(-1)["observation"], demos.trajectory(2)["observation"])
        obs = demos.trajectory_observations(1, include_final=True)
        assert obs.shape == (4, 4)
        torch.testing.assert_close(obs[-1], ep["next_observation"][-1])

    def test_trajectory_is_a_copy(self, demos):
        traj = demos.trajectory(0)
        traj["observation"].zero_()
        assert demos.trajectory(0)["observation"].abs().sum() > 0

    def test_subset_and_metadata(self, demos):
        sub = demos.subset(2)
        assert sub.num_trajectories == 2 and len(sub) == 8
        assert sub.metadata["scenario"] == "merge" and sub.metadata["num_trajectories"] == 2
        torch.testing.assert_close(sub.trajectory(1)["action"], demos.trajectory(1)["action"])
        meta = demos.metadata
        meta["scenario"] = "changed"
        assert demos.metadata["scenario"] == "merge"
        with pytest.raises(ValueError, match="n must be in"):
            demos.subset(4)
        with pytest.raises(IndexError):
            demos.trajectory(3)

    def test_from_rollout_tensordicts(self):
        from torchrl.testing.mocking_classes import ContinuousActionVecMockEnv

        env = ContinuousActionVecMockEnv()
        env.set_seed(0)
        rollouts = [env.rollout(4, break_when_any_done=False) for _ in range(2)]
        demos = ExpertDemonstrations.from_episodes(rollouts)
        assert demos.num_trajectories == 2 and len(demos) == 8
        torch.testing.assert_close(demos.trajectory(1)["action"], rollouts[1]["action"])
        torch.testing.assert_close(demos.trajectory(0)["next", "observation"], rollouts[0]["next", "observation"])

    def test_replay_buffer(self, demos):
        rb = demos.as_replay_buffer(batch_size=6)
        assert len(rb) == len(demos)
        sample = rb.sample()
        assert sample.batch_size == (6,)
        all_obs = demos.transitions()["observation"]
        # every sampled observation is one of the stored transitions
        dist = torch.cdist(sample["observation"], all_obs).min(-1).values
        assert torch.all(dist < 1e-6)
        assert ("collector", "traj_ids") in sample.keys(True)

    @pytest.mark.parametrize(
        "change,match",
        [
            (lambda ep: ep.pop("observation"), "no observation"),
            (lambda ep: ep.__setitem__("action", torch.zeros(2, 2)), "action must have shape"),
            (lambda ep: ep.__setitem__("next_observation", torch.zeros(5, 3)), "next observation shape"),
            (lambda ep: ep.__setitem__("done", torch.zeros(5, dtype=torch.bool)), "done must equal"),
        ],
    )
    def test_bad_episodes(self, change, match):
        ep = _episode(5)
        change(ep)
        with pytest.raises(ValueError, match=match):
            ExpertDemonstrations.from_episodes([ep])

    def test_bad_metadata(self):
        with pytest.raises(TypeError, match="JSON"):
            ExpertDemonstrations.from_episodes([_episode(2)], metadata={"x": object()})


class TestNpzFormat:
    def test_roundtrip(self, demos, tmp_path):
        path = demos.save(tmp_path / "demos")
        assert path.endswith(".npz")
        loaded = ExpertDemonstrations.load(path)
        assert loaded == demos
        assert loaded.metadata == {"scenario": "merge", "seed": 7}
        # readable without pickle, with the documented members
        with np.load(path, allow_pickle=False) as npz:
            assert int(npz["format_version"]) == 1
            assert npz["observation"].dtype == np.float32 and npz["terminated"].dtype == np.bool_
            assert npz["lengths"].tolist() == [5, 3, 4]

    def test_roundtrip_with_reward(self, tmp_path):
        demos = ExpertDemonstrations.from_episodes([_episode(3, reward=True), _episode(2, seed=3, reward=True)])
        loaded = ExpertDemonstrations.load(demos.save(tmp_path / "r.npz"))
        torch.testing.assert_close(loaded.transitions()["next", "reward"], demos.transitions()["next", "reward"])

    def test_deterministic_bytes(self, demos, tmp_path):
        a = demos.save(tmp_path / "a.npz")
        os.utime(tmp_path, (0, 0))
        # rebuilt from scratch: same content -> same bytes, whatever the wall clock says
        rebuilt = ExpertDemonstrations.from_episodes(
            [_episode(5, seed=0), _episode(3, seed=1, terminal=False), _episode(4, seed=2)],
            metadata={"seed": 7, "scenario": "merge"},
        )
        b = rebuilt.save(tmp_path / "b.npz")
        digest = [hashlib.sha256(open(p, "rb").read()).hexdigest() for p in (a, b)]
        assert digest[0] == digest[1]
        c = demos.with_metadata(scenario="highway-fast").save(tmp_path / "c.npz")
        assert hashlib.sha256(open(c, "rb").read()).hexdigest() != digest[0]

    def test_load_rejects_wrong_files(self, demos, tmp_path):
        np.savez(tmp_path / "other.npz", x=np.zeros(3))
        with pytest.raises(ValueError, match="missing members"):
            ExpertDemonstrations.load(tmp_path / "other.npz")
        arrays = dict(np.load(demos.save(tmp_path / "d.npz")))
        arrays["format_version"] = np.asarray(99)
        np.savez(tmp_path / "v99.npz", **arrays)
        with pytest.raises(ValueError, match="format version"):
            ExpertDemonstrations.load(tmp_path / "v99.npz")

    def test_load_rejects_non_finite_values_naming_the_file_and_member(self, demos, tmp_path):
        arrays = dict(np.load(demos.save(tmp_path / "d.npz")))
        arrays["action"][6, 1] = np.nan  # one action entry, in the second trajectory
        np.savez(tmp_path / "nan.npz", **arrays)
        with pytest.raises(ValueError) as info:
            ExpertDemonstrations.load(tmp_path / "nan.npz")
        message = str(info.value)
        assert len(message.splitlines()) == 1
        assert message == (f"{tmp_path / 'nan.npz'}: action holds 1 non-finite value (NaN or inf), the first at "
                           "transition 6 (trajectory 1).")
        episode = _episode(3)
        episode["observation"][1, 0] = float("inf")
        with pytest.raises(ValueError, match=r"observation holds 1 non-finite value .* transition 1 \(trajectory 0\)"):
            ExpertDemonstrations.from_episodes([episode])


def _published_dict(n: int = 3, width: int = 6, obs_dim: int = 5, act_dim: int = 2, seed: int = 0):
    rng = np.random.default_rng(seed)
    states = rng.normal(size=(n, width, obs_dim)).astype(np.float32)
    lengths = np.array([width, 4, 2][:n])
    dones = np.zeros((n, width), dtype=np.float32)
    for i, length in enumerate(lengths):
        dones[i, length - 1] = 1.0
    return {
        "states": states,
        "next_states": np.roll(states, -1, axis=1),
        "actions": rng.uniform(-1, 1, size=(n, width, act_dim)).astype(np.float32),
        "rewards": rng.normal(size=(n, width)).astype(np.float32),
        "dones": dones,
        "lengths": lengths,
    }


def _save_published(tmp_path, data, name="expert.npy"):
    path = tmp_path / name
    np.save(path, data, allow_pickle=True)
    return path


class TestImportPublished:
    def test_import(self, tmp_path):
        data = _published_dict()
        demos = import_published(_save_published(tmp_path, data))
        assert demos.num_trajectories == 3
        assert demos.lengths.tolist() == [6, 4, 2]
        traj = demos.trajectory(1)
        np.testing.assert_allclose(traj["observation"].numpy(), data["states"][1, :4])
        np.testing.assert_allclose(traj["next", "observation"].numpy(), data["next_states"][1, :4])
        np.testing.assert_allclose(traj["action"].numpy(), data["actions"][1, :4])
        np.testing.assert_allclose(traj["next", "reward"].squeeze(-1).numpy(), data["rewards"][1, :4])
        assert demos.metadata["source"] == "published"

    def test_done_mapping(self, tmp_path):
        path = _save_published(tmp_path, _published_dict())
        demos = import_published(path)
        # full-length episode ending with done: truncation; shorter ones: termination
        full = demos.trajectory(0)["next"]
        assert full["truncated"].squeeze(-1).tolist()[-1] and not full["terminated"].any()
        short = demos.trajectory(1)["next"]
        assert short["terminated"].squeeze(-1).tolist() == [False, False, False, True]
        assert not short["truncated"].any()
        legacy = import_published(path, done_mapping="terminated")
        assert legacy.trajectory(0)["next", "terminated"].squeeze(-1).tolist()[-1]
        assert not legacy.transitions()["next", "truncated"].any()
        # an explicit, longer time limit makes the full-width episode a termination
        limited = import_published(path, max_episode_steps=10)
        assert limited.trajectory(0)["next", "terminated"][-1].item()

    def test_final_step_without_done_is_truncated(self, tmp_path):
        data = _published_dict()
        data["dones"][1, 3] = 0.0
        demos = import_published(_save_published(tmp_path, data))
        assert demos.trajectory(1)["next", "truncated"][-1].item()
        assert not demos.trajectory(1)["next", "terminated"].any()

    def test_roundtrip_to_npz(self, tmp_path):
        demos = import_published(_save_published(tmp_path, _published_dict()))
        assert ExpertDemonstrations.load(demos.save(tmp_path / "converted.npz")) == demos

    @pytest.mark.parametrize(
        "corrupt,match",
        [
            (lambda d: d.pop("actions"), r"missing key\(s\) \['actions'\]"),
            (lambda d: d.__setitem__("states", d["states"][:, :, 0]), "'states' must have shape"),
            (lambda d: d.__setitem__("next_states", d["next_states"][:, :5]), "'next_states' shape"),
            (lambda d: d["states"].__setitem__((1, 2, 0), np.nan), "NaN"),
            (lambda d: d["actions"].__setitem__((0, 1, 1), 1.5), r"actions must lie in \[-1, 1\]"),
            (lambda d: d.__setitem__("lengths", np.array([6, 0, 2])), "'lengths' must lie in"),
            (lambda d: d.__setitem__("lengths", np.array([6, 7, 2])), "'lengths' must lie in"),
            (lambda d: d.__setitem__("lengths", np.array([6, 4])), "'lengths' must have shape"),
            (lambda d: d.__setitem__("dones", d["dones"][:2]), "'dones' must have shape"),
        ],
    )
    def test_rejects_malformed(self, tmp_path, corrupt, match):
        data = _published_dict()
        corrupt(data)
        with pytest.raises(ValueError, match=match):
            import_published(_save_published(tmp_path, data))

    def test_early_done_is_kept_and_reported(self, tmp_path):
        data = _published_dict()
        data["dones"][0, 2] = 1.0
        path = _save_published(tmp_path, data)
        demos = import_published(path)
        assert demos.lengths.tolist() == [6, 4, 2] and demos.metadata["early_dones"] == [[0, 2]]
        assert import_published(path, end_at="first_done").lengths.tolist() == [3, 4, 2]

    @pytest.mark.parametrize(
        "kwargs,match",
        [
            ({"end_at": "first_crash"}, "end_at must be one of"),
            ({"end_at": "termination"}, "needs the scenario"),
            ({"done_mapping": "truncated"}, "done_mapping must be one of"),
            ({"scenario": "mars"}, "Unknown scenario 'mars'"),
            ({"scenario": "merge"}, "observations of size 5, but 'merge' has 25"),
        ],
    )
    def test_rejects_bad_options(self, tmp_path, kwargs, match):
        with pytest.raises(ValueError, match=match):
            import_published(_save_published(tmp_path, _published_dict()), **kwargs)

    def test_nan_in_padding_is_ignored(self, tmp_path):
        data = _published_dict()
        data["states"][2, 4, :] = np.nan  # beyond length 2: padding
        assert import_published(_save_published(tmp_path, data)).num_trajectories == 3

    def test_refuses_malicious_pickle(self, tmp_path):
        marker = tmp_path / "pwned"

        class Exploit:
            def __reduce__(self):
                return (os.system, (f"touch {marker}",))

        data = _published_dict()
        data["states"] = Exploit()
        path = tmp_path / "evil.npy"
        # the numpy header for a pickled object array, followed by the malicious pickle
        np.save(path, np.array(None, dtype=object), allow_pickle=True)
        raw = open(path, "rb").read()
        header_end = raw.index(b"\n") + 1
        with open(path, "wb") as f:
            f.write(raw[:header_end] + pickle.dumps(data, protocol=3))
        with pytest.raises(pickle.UnpicklingError, match="refusing to load global"):
            import_published(path)
        # also as a bare pickle file
        bare = tmp_path / "evil.pkl"
        bare.write_bytes(pickle.dumps({"x": Exploit()}))
        with pytest.raises(pickle.UnpicklingError, match="system"):
            import_published(bare)
        assert not marker.exists()

    def test_restricted_unpickler_allows_numpy(self):
        import io

        payload = pickle.dumps({"a": np.arange(4, dtype=np.int32), "b": [np.float64(1.5)], "c": (1, "x")})
        obj = RestrictedUnpickler(io.BytesIO(payload)).load()
        assert obj["a"].tolist() == [0, 1, 2, 3] and obj["b"][0] == 1.5 and obj["c"] == (1, "x")

    def test_not_a_dict(self, tmp_path):
        np.save(tmp_path / "plain.npy", np.zeros((2, 3)))
        with pytest.raises(ValueError, match="expected a pickled dict"):
            import_published(tmp_path / "plain.npy")


@pytest.fixture(scope="module")
def published_files(tmp_path_factory):
    """scenario -> {N: path} of synthetic files in the published layout (tests/published_fixtures.py)."""
    from published_fixtures import write_published_files

    folder = tmp_path_factory.mktemp("published")
    written: dict[str, dict[int, str]] = {}

    def files(scenario: str) -> dict[int, str]:
        if scenario not in written:
            written[scenario] = write_published_files(folder, scenario)
        return written[scenario]

    return files


def _shipped_length(scenario: str, curriculum: str, index: int) -> int:
    from torchrl_csirl.data import expert_dataset_path

    return int(ExpertDemonstrations.load(expert_dataset_path(scenario, curriculum)).lengths[index])


class TestPublishedFiles:
    """The facts about the authors' files (issue 17), on synthetic files that reproduce them."""

    @pytest.mark.parametrize("scenario", ["highway-fast", "merge", "roundabout", "intersection"])
    def test_every_file_loads_with_the_defaults(self, published_files, scenario):
        from published_fixtures import D_ACTIONS_SIZES, PADDED_WIDTH, PUBLISHED_SIZES

        width = PADDED_WIDTH[scenario]
        files = published_files(scenario)
        largest = import_published(files[25])
        for size in PUBLISHED_SIZES:
            raw = np.load(files[size], allow_pickle=True).item()
            assert raw["lengths"] == [width] * size and raw["dones"][:, -5:].all()
            demos = import_published(files[size])
            assert demos.num_trajectories == size and demos.lengths.tolist() == [width] * size
            flags = demos.transitions()["next"]
            # the padding dones end the recording: every trajectory ends truncated, none terminates
            assert not flags["terminated"].any() and int(flags["truncated"].sum()) == size
            assert demos.metadata["ignored_keys"] == (["d_actions"] if size in D_ACTIONS_SIZES else [])
            np.testing.assert_array_equal(demos.trajectory(size - 1)["observation"].numpy(), raw["states"][-1])
            stalled = scenario == "roundabout" and size == 24
            for i in range(size - 1 if stalled else size):  # nested files (but roundabout's 24-file)
                torch.testing.assert_close(demos.trajectory(i)["observation"], largest.trajectory(i)["observation"])

    def test_roundabout_early_dones(self, published_files):
        from published_fixtures import ROUNDABOUT_EARLY_DONES

        path = published_files("roundabout")[25]
        demos = import_published(path)
        early = demos.metadata["early_dones"]
        assert [i for i, _ in early] == list(ROUNDABOUT_EARLY_DONES)
        first_done = import_published(path, end_at="first_done")
        for i, length in enumerate(first_done.lengths.tolist()):
            expected = dict(early).get(i, 55 - 5) + 1
            assert length == expected and first_done.trajectory(i)["next", "terminated"][-1].item()

    def test_termination_merge(self, published_files):
        files = published_files("merge")
        raw = np.load(files[25], allow_pickle=True).item()
        # recorded past our termination (x = 370 m, 0.74 normalised) to about 390 m
        assert raw["next_states"][:, -1, 1].min() > 0.77
        # two distinct trajectories; the expert never accelerates
        assert len(np.unique(raw["states"], axis=0)) == 2 and raw["actions"][..., 0].max() <= 0.0
        demos = import_published(files[25], end_at="termination", scenario="merge")
        expected = [_shipped_length("merge", "empty", 0)] + [_shipped_length("merge", "traffic", 1)] * 24
        assert demos.lengths.tolist() == expected
        assert demos.transitions()["next", "terminated"].sum() == 25
        assert demos.metadata["scenario"] == "merge" and demos.metadata["end_at"] == "termination"

    def test_termination_intersection(self, published_files):
        demos = import_published(published_files("intersection")[5], end_at="termination", scenario="intersection")
        # the curriculum trajectory stops short of the finish: the time limit truncates it
        assert demos.lengths[0] == 65 and demos.trajectory(0)["next", "truncated"][-1].item()
        # the others are cut at the step our environment sees the arrival
        assert demos.lengths[1:].tolist() == [_shipped_length("intersection", "traffic", i) for i in range(1, 5)]
        assert all(demos.trajectory(i)["next", "terminated"][-1].item() for i in range(1, 5))

    def test_termination_roundabout_and_highway(self, published_files):
        from published_fixtures import ROUNDABOUT_EARLY_DONES

        demos = import_published(published_files("roundabout")[24], end_at="termination", scenario="roundabout")
        early = dict(demos.metadata["early_dones"])
        assert sorted(early) == list(ROUNDABOUT_EARLY_DONES)
        arrivals = [_shipped_length("roundabout", "empty", 0)]
        arrivals += [_shipped_length("roundabout", "traffic", i) for i in range(1, 23)]
        for i, length in enumerate(demos.lengths.tolist()):
            terminated = demos.trajectory(i)["next", "terminated"][-1].item()
            if i == 23:  # stalls before the ring: runs to our time limit
                assert (length, terminated) == (55, False)
            else:  # cut where our scene ends the episode: the arrival (before any later off-road done)
                assert (length, terminated) == (arrivals[i], True)
                assert i not in early or early[i] + 1 > length
        highway = import_published(published_files("highway-fast")[4], end_at="termination", scenario="highway-fast")
        # the curriculum trajectory reaches x = 650 m on its last step; the others (600-650 m) never arrive
        assert highway.lengths.tolist() == [75] * 4
        assert highway.transitions()["next", "terminated"].reshape(4, 75)[:, -1].tolist() == [True, False, False, False]
        # highway episodes end at x of about 600-650 m (x in [150, 700] normalised to [-1, 1])
        final_x = 150 + (np.stack([highway.trajectory(i)["next", "observation"][-1, 1].numpy() for i in range(4)]) + 1) * 275
        assert final_x.min() > 550 and final_x.max() < 700


class TestDemonstrationMixer:
    @staticmethod
    def _online(n: int = 40):
        from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
        from torchrl.envs import Compose

        from torchrl_csirl.transforms import CombineRewards, SubgoalMatchingReward

        expert_path = torch.linspace(0, 1, 6).unsqueeze(-1).expand(6, 4).contiguous()
        matching = SubgoalMatchingReward(expert_path, subgoal=3, scale=10.0, position_feature_indices=[0])
        online = TensorDictReplayBuffer(storage=LazyTensorStorage(100), batch_size=16,
                                        transform=Compose(matching, CombineRewards(["matching_reward"])))
        rollout = ExpertDemonstrations.from_episodes([_episode(n, seed=5)]).transitions()
        rollout.set("extra_online_entry", torch.zeros(n))  # an entry the demonstrations lack
        online.extend(rollout)
        return online, matching

    def test_share_and_rewards_of_the_expert_part(self, demos):
        from torchrl_csirl.data import DemonstrationMixer

        online, matching = self._online()
        mixer = DemonstrationMixer(online, demos.as_replay_buffer(batch_size=8), expert_fraction=0.25)
        batch = mixer.sample()
        assert batch.batch_size == (16,) and mixer.num_expert == 4
        assert "extra_online_entry" not in batch.keys()
        expert_obs = demos.transitions()["observation"]
        is_expert = torch.cdist(batch["observation"], expert_obs, compute_mode="donot_use_mm_for_euclid_dist").min(-1).values < 1e-6
        assert is_expert.tolist() == [False] * 12 + [True] * 4
        # the expert part carries the reward the online transforms give, for the current subgoal
        expected = matching(batch[12:].exclude(("next", "matching_reward")).clone())["next", "matching_reward"]
        torch.testing.assert_close(batch[12:]["next", "reward"], expected)
        matching.set_subgoal(0)
        later = mixer.sample()
        torch.testing.assert_close(
            later[12:]["next", "reward"],
            matching(later[12:].exclude(("next", "matching_reward")).clone())["next", "matching_reward"],
        )

    def test_zero_fraction_is_the_online_buffer(self, demos):
        from torchrl_csirl.data import DemonstrationMixer

        online, _ = self._online()
        batch = DemonstrationMixer(online, demos.as_replay_buffer(batch_size=8), expert_fraction=0.0).sample()
        assert batch.batch_size == (16,) and "extra_online_entry" in batch.keys()

    @pytest.mark.parametrize("fraction", [-0.1, 1.0, 1.5])
    def test_bad_fraction(self, demos, fraction):
        from torchrl_csirl.data import DemonstrationMixer

        online, _ = self._online()
        with pytest.raises(ValueError, match="expert_fraction must be in"):
            DemonstrationMixer(online, demos.as_replay_buffer(batch_size=8), expert_fraction=fraction)
