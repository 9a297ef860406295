"""Learning from recordings: data sets, the paper's models, training, baselines and evaluation.

Modules (import them directly; this package imports nothing heavy on purpose, so that
``import ectskin.learn`` stays cheap and does not pull in torch). Lowest first:

==========================  ==============================================================
``learn.metrics``           pure test-set metrics: accuracy, confusions, Eq. 3 distance
``learn.profiles``          training profiles (``paper``, ``quick``, ``robust``)
``learn.threads``           the torch CPU thread policy
``learn.datasets``          TouchData / TrackData from a recording (``splits``: trial-
                            exclusive splits; ``normalizer``: training-set statistics)
``learn.models``            TouchMLP (touch classes) and C2DT (marker coordinates)
``learn.checkpoint``        self-describing model files (config + weights + normaliser)
``learn.predict``           batched inference; TouchPredictor / TrackPredictor for live use
``learn.baselines``         trivial and classical baselines
``learn.augment``           the robust touch recipe's augmentation
``learn.distributed``       DDP set-up (torchrun)
``learn.engine``            the epoch loops: train_one_epoch, evaluate
``learn.runfiles``          the files of a run directory (metrics.csv, config.json, ...)
``learn.tasks``             one class per task (touch, track): model, loss, metrics, figures
``learn.train``             train / train_from_recording (TrainConfig), resume, DDP
``learn.evaluate``          evaluate_run: a run's test metrics, baselines and figures
==========================  ==============================================================
"""
