"""Expert demonstrations: the :class:`ExpertDemonstrations` container, its ``.npz`` format, importers
and Minari interop (:mod:`torchrl_csirl.data.minari`), and the replay-buffer checkpointer that writes
the filled rows only (:class:`FilledRowsCheckpointer`)."""
from __future__ import annotations

from torchrl_csirl.data.checkpointing import FilledRowsCheckpointer
from torchrl_csirl.data.expert import FORMAT_VERSION, ExpertDemonstrations
from torchrl_csirl.data.minari import load_minari_dataset, minari_experience_replay, save_minari_dataset
from torchrl_csirl.data.mixing import DemonstrationMixer
from torchrl_csirl.data.published import RestrictedUnpickler, import_published, load_published_dict
from torchrl_csirl.data.recording import record_demonstrations
from torchrl_csirl.data.shipped import (
    available_expert_datasets,
    curriculum_trajectory,
    expert_dataset_path,
    load_expert_demonstrations,
)

__all__ = [
    "DemonstrationMixer",
    "ExpertDemonstrations",
    "FORMAT_VERSION",
    "FilledRowsCheckpointer",
    "RestrictedUnpickler",
    "available_expert_datasets",
    "curriculum_trajectory",
    "expert_dataset_path",
    "import_published",
    "load_expert_demonstrations",
    "load_minari_dataset",
    "load_published_dict",
    "minari_experience_replay",
    "record_demonstrations",
    "save_minari_dataset",
]
