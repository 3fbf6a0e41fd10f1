"""Re-reads the critic checks of recorded runs whose health reports predate SAC's entropy bonus in the returns.

``python docs/studies/scripts/entropy_bonus_records.py <record dir> [<record dir> ...]``

A soft critic estimates the learner's reward plus ``-alpha log pi`` at every next state; health reports written
before the report counted that bonus compared the critics with the reward's return alone. A record (``rounds.csv``,
``config.yaml``, ``health.json``: ``torchrl-csirl record`` keeps them) holds no networks to probe again, but its last
round holds alpha and the policy's entropy ``H = -E[log pi]``: the bonus is about ``alpha H`` a step, and over the
discounted horizon of the measured states (95 % of it or more left) about ``alpha H gamma / (1 - gamma)``. Each
record's two checks are then read again, approximately (the means only), with that bonus added to the recorded
return. A run probed by the current report needs none of this: ``torchrl-csirl diagnose <run dir>``.

The last line is JSON; a Markdown table goes to stderr.
"""
from __future__ import annotations

import argparse
import json
import os
import sys

import torch
import yaml

from torchrl_csirl.analysis.diagnostics import critic_calibration
from torchrl_csirl.scripts.record import read_rounds


def horizon_bonus(alpha: float, entropy: float, gamma: float) -> float:
    """The entropy bonus's discounted sum from a state on, at ``alpha H`` a step after it.

    Examples:
        >>> round(horizon_bonus(0.1, -8.0, 0.99), 1)
        -79.2
    """
    return alpha * entropy * gamma / (1.0 - gamma)


def reread_record(record: str) -> dict[str, object]:
    """One record's end-of-run alpha, entropy, bonus, and each critic check as recorded and re-read."""
    last = read_rounds(record)[-1]
    with open(os.path.join(record, "config.yaml"), encoding="utf-8") as f:
        gamma = float(yaml.safe_load(f)["csirl"]["gamma"])
    with open(os.path.join(record, "health.json"), encoding="utf-8") as f:
        checks = {c["name"]: c for c in json.load(f)["checks"]}
    alpha, entropy = float(last["alpha"]), float(last["entropy"])
    bonus = horizon_bonus(alpha, entropy, gamma)
    out: dict[str, object] = {"record": record, "alpha": alpha, "entropy": entropy, "bonus": bonus}
    for where in ("expert", "policy"):
        check = checks.get(f"critic_calibration_{where}", {})
        figures = check.get("figures") or {}
        if "value_mean" not in figures or figures.get("entropy_return_mean") is not None:
            continue  # not measured, or already read with the bonus
        q, g = float(figures["value_mean"]), float(figures["return_mean"])
        reread = critic_calibration(torch.tensor([[q]]), torch.tensor([g + bonus]), where, torch.tensor([bonus]))
        out[where] = {"value": q, "return": g, "soft_return": g + bonus, "recorded_ok": check.get("ok"),
                      "reread_ok": reread.ok, "reread": reread.message}
    return out


def main(argv: list[str] | None = None) -> list[dict[str, object]]:
    parser = argparse.ArgumentParser(prog="entropy_bonus_records.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("records", nargs="+", help="record directories (rounds.csv, config.yaml, health.json)")
    rows = [reread_record(r) for r in parser.parse_args(argv).records]
    print("| record | alpha | entropy | bonus over the horizon | states | critics | return | with the bonus | "
          "flagged as recorded | flagged re-read |", file=sys.stderr)
    print("|---|---|---|---|---|---|---|---|---|---|", file=sys.stderr)
    for row in rows:
        for where in ("expert", "policy"):
            if where in row:
                c = row[where]
                print(f"| {row['record']} | {row['alpha']:.3g} | {row['entropy']:.3g} | {row['bonus']:.3g} | {where} | "
                      f"{c['value']:.3g} | {c['return']:.3g} | {c['soft_return']:.3g} | {c['recorded_ok'] is False} | "
                      f"{c['reread_ok'] is False} |", file=sys.stderr)
    print(json.dumps(rows, default=float))
    return rows


if __name__ == "__main__":
    main()
