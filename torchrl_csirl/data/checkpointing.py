"""A replay-buffer storage checkpointer that writes the filled rows only.

TorchRL's :class:`~torchrl.data.replay_buffers.checkpointers.TensorStorageCheckpointer` memory-maps
the whole pre-allocated storage: a 1 000 000-transition buffer holding 2 000 transitions still
writes 1 000 000 rows (about 280 MB for a driving run, 700 MB for Relocate) at every checkpoint.
:class:`FilledRowsCheckpointer` writes rows ``[0, len(storage))`` and, on loading, writes them back
into the pre-allocated storage, so checkpoints grow with the data collected instead of the capacity.
Pass it as ``checkpointer=`` to the replay buffer (the buffer sets its storage's checkpointer).
"""
from __future__ import annotations

import json
from pathlib import Path

from tensordict import TensorDict, is_tensor_collection
from torchrl.data.replay_buffers.checkpointers import TensorStorageCheckpointer
from torchrl.data.replay_buffers.storages import TensorStorage

__all__ = ["FilledRowsCheckpointer"]

_METADATA_FILE = "storage_metadata.json"


class FilledRowsCheckpointer(TensorStorageCheckpointer):
    """Saves a one-dimensional tensordict storage's filled rows ``[0, len)``, not its capacity.

    A round-robin writer fills rows in order, so until the storage is full its data are exactly
    the first ``len`` rows; once full, every row is written (as TorchRL does). Other storages
    (pytrees, several batch dimensions) and checkpointers with save hooks fall back to the parent
    class. Checkpoints written by the parent load too; those written here need this checkpointer
    to load (a buffer built without it fails on the missing ``is_pytree`` entry).

    Examples:
        >>> import tempfile, torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
        >>> def make_buffer():
        ...     return TensorDictReplayBuffer(storage=LazyTensorStorage(1_000_000), batch_size=4,
        ...                                   checkpointer=FilledRowsCheckpointer())
        >>> rb = make_buffer()
        >>> _ = rb.extend(TensorDict({"observation": torch.arange(10.0).unsqueeze(-1)}, [10]))
        >>> path = tempfile.mkdtemp()
        >>> rb.dumps(path)
        >>> restored = make_buffer()
        >>> restored.loads(path)
        >>> len(restored), restored[:3]["observation"].squeeze(-1).tolist()
        (10, [0.0, 1.0, 2.0])
    """

    def dumps(self, storage: TensorStorage, path: str | Path) -> None:
        if self._save_hooks or not self._handles(storage):
            return super().dumps(storage, path)
        path = Path(path)
        path.mkdir(exist_ok=True)
        filled = storage._storage[: storage._len]
        filled.memmap(path / "rows", copy_existing=True)
        with open(path / _METADATA_FILE, "w") as file:
            json.dump({"len": storage._len, "filled_rows": True, "max_size": storage.max_size}, file)

    def loads(self, storage: TensorStorage, path: str | Path) -> None:
        path = Path(path)
        with open(path / _METADATA_FILE) as file:
            metadata = json.load(file)
        if not metadata.get("filled_rows"):  # written by TorchRL's checkpointer (or ours with hooks)
            return super().loads(storage, path)
        if metadata["max_size"] != storage.max_size:
            raise ValueError(
                f"The checkpoint at {path} holds a buffer of capacity {metadata['max_size']}; "
                f"this storage holds {storage.max_size}: rebuild it with the saved capacity."
            )
        rows = TensorDict.load_memmap(path / "rows")
        if rows.shape[0]:
            if not storage.initialized:
                storage._init(rows[0])
            storage._storage[: rows.shape[0]].update_(rows)  # copies leaf by leaf, to the storage's device
        storage._len = metadata["len"]

    @staticmethod
    def _handles(storage: TensorStorage) -> bool:
        if not storage.initialized:
            raise RuntimeError("Cannot save a non-initialized storage.")
        return is_tensor_collection(storage._storage) and storage.ndim == 1

