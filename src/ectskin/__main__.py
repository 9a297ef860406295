"""``python -m ectskin`` runs the console script."""

import sys

from ectskin.cli import main

sys.exit(main())
