"""Learning from recordings: calibration (paper Eq. 2), datasets, splits, the paper's models,
training, baselines and evaluation.

Modules (import them directly; this package imports nothing heavy on purpose, so that
``import ectskin.learn`` stays cheap and does not pull in torch):

==========================  ==============================================================
``learn.datasets``          TouchData / TrackData, trial-exclusive splits, Normalizer
``learn.models``            TouchMLP (touch classes) and C2DT (marker coordinates)
``learn.checkpoint``        self-describing model files (config + weights + normaliser)
``learn.train``             training with the ``paper`` / ``quick`` profiles, resume, DDP
``learn.predict``           TouchPredictor / TrackPredictor for live use
``learn.baselines``         trivial and classical baselines
``learn.evaluate``          metrics (accuracy, Eq. 3 average distance) of a run
==========================  ==============================================================
"""
