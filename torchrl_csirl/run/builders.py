"""The builders every recipe shares, by concern (this module gathers their names):

* :mod:`torchrl_csirl.run.experts`: the demonstrations (``expert`` section);
* :mod:`torchrl_csirl.run.collection`: environments, collector, the CPU policy mirror (``collector``);
* :mod:`torchrl_csirl.run.assembly`: input map, online buffer, logger, :class:`Run`, :func:`assemble_trainer`;
* :mod:`torchrl_csirl.run.lifecycle`: start, resume, training, a recipe's whole command line (:func:`run_recipe`);
* :mod:`torchrl_csirl.run.final`: the final test, ``policy.pt``, plots and summary fields.

Each ``make_*`` takes sections of the typed configuration (:mod:`torchrl_csirl.run.config`) and returns one
TorchRL / torchrl-csirl piece; library code below the run layer takes plain arguments.
"""
from torchrl_csirl.run.assembly import Run, assemble_trainer, make_logger, make_online_buffer, model_input_features
from torchrl_csirl.run.collection import (
    PolicyMirror,
    check_collector,
    check_collector_config,
    check_whole_episodes,
    envs_per_worker,
    make_collector,
    make_eval_env,
    make_worker_env_fn,
)
from torchrl_csirl.run.experts import curriculum_first, load_experts, recorded_in_traffic
from torchrl_csirl.run.final import evaluation_summary, final_summary
from torchrl_csirl.run.lifecycle import (
    open_configured_run,
    record_resumed_settings,
    resume_run,
    run_recipe,
    start_run,
    timed_summary,
    train,
    train_and_finish,
)

__all__ = [
    "PolicyMirror",
    "Run",
    "assemble_trainer",
    "check_collector",
    "check_collector_config",
    "check_whole_episodes",
    "curriculum_first",
    "envs_per_worker",
    "evaluation_summary",
    "final_summary",
    "load_experts",
    "make_collector",
    "make_eval_env",
    "make_logger",
    "make_online_buffer",
    "make_worker_env_fn",
    "model_input_features",
    "open_configured_run",
    "record_resumed_settings",
    "recorded_in_traffic",
    "resume_run",
    "run_recipe",
    "start_run",
    "timed_summary",
    "train",
    "train_and_finish",
]
