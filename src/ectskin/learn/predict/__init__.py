"""Trained models for live use, one predictor per task: load a run, feed calibrated frames, get
answers.

==================  ========================================================================
``predict.base``    :class:`Predictor` (a model rebuilt from its checkpoint, the ONNX Runtime
                    switch), :func:`as_input` (checks a frame or batch at the door) and
                    :func:`forward_batches` (the one batched inference path)
``predict.touch``   :class:`TouchPredictor`: touch class probabilities (TouchMLP or the run's
                    selected classical model)
``predict.track``   :class:`TrackPredictor`: marker coordinates from a window (C2DT)
``predict.contact`` :class:`ContactPredictor`: finger count, points, forces, hover
                    (:class:`ContactReading` of :class:`FingerEstimate`)
==================  ========================================================================
"""

from __future__ import annotations

from ectskin.learn.predict.base import Predictor, as_input, forward_batches
from ectskin.learn.predict.contact import ContactPredictor, ContactReading, FingerEstimate
from ectskin.learn.predict.touch import TouchPredictor
from ectskin.learn.predict.track import TrackPredictor

__all__ = [
    "ContactPredictor",
    "ContactReading",
    "FingerEstimate",
    "Predictor",
    "TouchPredictor",
    "TrackPredictor",
    "as_input",
    "forward_batches",
]
