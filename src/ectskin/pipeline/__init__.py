"""The reproduction pipeline: the paper's runs as cached steps, driven by one config.

config (:class:`ReproduceConfig`, the runs) ─► runner (cached steps, ``reproduce.json``)
─► steps (simulate, characterise, train, evaluate) ─► metrics (``metrics.json``, figures)
─► :mod:`ectskin.report` (``report.md``, ``report.html``).

Usage::

    from ectskin.pipeline import ReproduceConfig, reproduce

    metrics = reproduce(ReproduceConfig("out", profile="quick", seed=0))
"""

from ectskin.pipeline.config import PROFILES, RUNS, ReproduceConfig
from ectskin.pipeline.reproduce import reproduce

__all__ = ["PROFILES", "RUNS", "ReproduceConfig", "reproduce"]
