"""Tests of the replay-buffer checkpointer that writes the filled rows only."""
from __future__ import annotations

import os

import pytest
import torch
from tensordict import TensorDict
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer

from torchrl_csirl.data import FilledRowsCheckpointer


def _buffer(capacity: int, checkpointer=None) -> TensorDictReplayBuffer:
    return TensorDictReplayBuffer(storage=LazyTensorStorage(capacity), batch_size=4, checkpointer=checkpointer)


def _transitions(n: int, start: int = 0) -> TensorDict:
    obs = torch.arange(start, start + n, dtype=torch.float32).unsqueeze(-1).expand(n, 8).clone()
    return TensorDict({"observation": obs, "action": -obs[:, :2], "next": {"reward": obs[:, :1] * 0.5}}, [n])


def _bytes_on_disk(path) -> int:
    return sum(os.stat(os.path.join(d, f)).st_blocks * 512 for d, _, files in os.walk(path) for f in files)


def test_filled_rows_round_trip_with_a_fraction_of_the_disk(tmp_path):
    saved = _buffer(100_000, FilledRowsCheckpointer())
    saved.extend(_transitions(300))
    saved.dumps(tmp_path / "compact")
    reference = _buffer(100_000)  # TorchRL's own checkpointer: the whole capacity
    reference.extend(_transitions(300))
    reference.dumps(tmp_path / "full")
    assert _bytes_on_disk(tmp_path / "compact") * 20 < _bytes_on_disk(tmp_path / "full")

    restored = _buffer(100_000, FilledRowsCheckpointer())
    restored.loads(tmp_path / "compact")
    assert len(restored) == 300
    assert (restored[:300] == saved[:300]).all()
    restored.extend(_transitions(5, start=300))  # the writer goes on where the saved one stopped
    assert restored[300:305]["observation"][:, 0].tolist() == [300.0, 301.0, 302.0, 303.0, 304.0]


def test_a_full_wrapped_buffer_keeps_its_rows_and_cursor(tmp_path):
    saved = _buffer(8, FilledRowsCheckpointer())
    saved.extend(_transitions(13))  # wraps: rows 0-4 hold 8..12
    saved.dumps(tmp_path)
    restored = _buffer(8, FilledRowsCheckpointer())
    restored.loads(tmp_path)
    assert len(restored) == 8 and (restored[:] == saved[:]).all()
    restored.extend(_transitions(1, start=13))
    assert restored[5]["observation"][0].item() == 13.0


def test_an_emptied_buffer_loads_empty_and_old_checkpoints_still_load(tmp_path):
    emptied = _buffer(50, FilledRowsCheckpointer())
    emptied.extend(_transitions(10))
    emptied.empty()
    emptied.dumps(tmp_path / "empty")
    restored = _buffer(50, FilledRowsCheckpointer())
    restored.extend(_transitions(3))
    restored.loads(tmp_path / "empty")
    assert len(restored) == 0

    old = _buffer(50)  # a checkpoint written before FilledRowsCheckpointer
    old.extend(_transitions(10))
    old.dumps(tmp_path / "old")
    restored = _buffer(50, FilledRowsCheckpointer())
    restored.loads(tmp_path / "old")
    assert len(restored) == 10 and (restored[:10] == old[:10]).all()


def test_a_capacity_mismatch_is_refused_by_name(tmp_path):
    saved = _buffer(100, FilledRowsCheckpointer())
    saved.extend(_transitions(10))
    saved.dumps(tmp_path)
    with pytest.raises(ValueError, match="capacity 100; this storage holds 50"):
        _buffer(50, FilledRowsCheckpointer()).loads(tmp_path)


def test_save_hooks_get_torchrls_own_format(tmp_path):
    calls = []

    def hook(data, path):
        calls.append(path)
        return data

    saved = _buffer(50, FilledRowsCheckpointer())
    saved.register_save_hook(hook)
    saved.extend(_transitions(10))
    saved.dumps(tmp_path)
    assert len(calls) == 1  # the hook ran: the parent's path, whole storage
    restored = _buffer(50, FilledRowsCheckpointer())
    restored.loads(tmp_path)
    assert len(restored) == 10 and (restored[:10] == saved[:10]).all()
