"""What a run ran on, for the report's "Machine" table."""

from __future__ import annotations

import os
import platform
from typing import Any

from ectskin import __version__


def machine_info() -> dict[str, Any]:
    """What this run ran on: OS, Python, CPU count, torch version and GPU (if torch imports)."""
    info: dict[str, Any] = {
        "platform": platform.platform(),
        "python": platform.python_version(),
        "processor": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "ectskin": __version__,
    }
    try:  # imported here: the report itself does not need torch
        import torch

        info["torch"] = torch.__version__
        info["torch_threads"] = torch.get_num_threads()
        if torch.cuda.is_available():
            info["gpu"] = [torch.cuda.get_device_name(k) for k in range(torch.cuda.device_count())]
        else:
            info["gpu"] = []
    except ImportError:  # pragma: no cover - torch is a dependency
        info["torch"] = None
    return info
