"""Design a skin before making one: score and search electrode layouts in the twin.

* :mod:`~ectskin.design.family`: a parameterised family of wire layouts and the manufacturing
  rules (``build_layout``, ``check_manufacturable``);
* :mod:`~ectskin.design.information`: the information score (Cramér–Rao bound maps, the
  ambiguity; no training, deterministic);
* :mod:`~ectskin.design.score`: one layout scored (simulate, train, evaluate, sensor metrics);
* :mod:`~ectskin.design.stats`: trained scores over seeds (t-intervals, the paired comparison);
* :mod:`~ectskin.design.cluster`: Dask distributed (a local cluster or a scheduler);
* :mod:`~ectskin.design.sweep`: many layouts scored, resumable (``ectskin design score``);
* :mod:`~ectskin.design.search`: the Optuna study (``ectskin design search``);
* :mod:`~ectskin.design.report`: ``design.md`` / ``design.html`` and the figures;
* :mod:`~ectskin.design.variability`: fabrication variability, degradation and recoveries
  (``ectskin variability``).

The submodules are imported on use (dask, optuna and torch take seconds to import).
"""
