"""ectskin: touch and shape perception for soft robots from a sparse capacitive e-skin.

The package follows the data flow of the system (see ``docs/architecture.md``)::

    layout ─► twin (mechanics ─► electrostatics ─► readout) ─► io (HDF5 recordings)
          ─► learn (calibration, datasets, models, training, evaluation) ─► report
          ─► live (sources, recorder, engine) ─► dashboard

Each sub-package imports only from the ones to its left.
"""

from ectskin._check import EctskinError

__version__ = "0.1.0"

__all__ = ["EctskinError", "__version__"]
