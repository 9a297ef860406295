"""Learning from recordings: data sets, the paper's models, training, baselines and evaluation.

One organising axis: per concern a package with a module per task (``touch``, ``track``,
``contact``) beside a ``base`` module of what the tasks share. Import the modules directly; this
package imports nothing heavy on purpose, so that ``import ectskin.learn`` stays cheap and does
not pull in torch. Lowest first:

==========================  ==============================================================
``learn.metrics``           pure test-set metrics per task: accuracy and confusions, Eq. 3
                            distance, contact localisation / force / hover / count
``learn.profiles``          training profiles (``paper``, ``quick``, ``robust``), TrainConfig
``learn.threads``           the torch CPU thread policy
``learn.data``              SampleData (``base``) and TouchData / TrackData / ContactData from
                            a recording (``splits``: trial-exclusive splits; ``normalizer``:
                            training-set statistics; ``channels``: the measured channels)
``learn.models``            TouchMLP, C2DT (marker coordinates), ContactNet
``learn.checkpoint``        self-describing model files (config + weights + normaliser)
``learn.candidates``        the classical touch candidates: fit, choose, ``candidates.json``
``learn.classical``         a classical touch model (scaler + classifier), ``model.skops``
``learn.classical_onnx``    its single-frame ONNX Runtime export, checked against scikit-learn
``learn.predict``           batched inference and one predictor per task for live use
``learn.baselines``         trivial and classical baselines per task
``learn.augment``           the robust touch recipe's augmentation
``learn.distributed``       DDP set-up (torchrun)
``learn.engine``            the epoch loops: train_one_epoch, evaluate
``learn.runfiles``          the files of a run directory (metrics.csv, config.json, ...)
``learn.tasks``             one class per task: model, loss, metrics, figures
``learn.touch_choice``      the touch model choice of a run (``--model auto`` / classical)
``learn.contact_classical`` a classical contact model (k-NN, ridge, trees, GP), ``model.skops``
``learn.contact_choice``    the contact model choice of a run (``--model auto`` / classical)
``learn.finetune``          ``--init-from RUN``: fine-tuning a trained run on another skin
``learn.train``             train / train_from_recording (TrainConfig), resume, DDP
``learn.evaluate``          evaluate_run: a run's test metrics, baselines and figures
==========================  ==============================================================
"""
