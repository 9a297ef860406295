"""Studies of the twin's reading of the paper, run by ``ectskin study`` (one module each)."""
