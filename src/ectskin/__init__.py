"""ectskin: touch and shape perception for soft robots from a sparse capacitive e-skin.

The package follows the data flow of the system (see ``docs/architecture.md``)::

    layout ─► viz ─► electrostatics ─► io (recordings, HDF5, Eq. 2, imports)
          ─► twin (mechanics, sensor, readout, protocol) ─► learn (tasks, training, evaluation)
          ─► report ─► pipeline ─► live (sources, engine, recorder) ─► dashboard ─► commands

Each sub-package imports only from the ones to its left (``tests/test_architecture.py``).
"""

from ectskin._check import EctskinError

__version__ = "0.1.0"

__all__ = ["EctskinError", "__version__"]
