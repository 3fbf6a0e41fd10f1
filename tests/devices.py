"""Devices the device-parametrised tests run on: the CPU always, CUDA where present.

CI has no GPU; the CUDA cases run in the GPU checks (``benchmarks/gpu_checks.sh``).
"""
from __future__ import annotations

import pytest
import torch

DEVICES = ["cpu", pytest.param("cuda", marks=pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device"))]
