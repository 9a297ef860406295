"""The digital twin: the e-skin on the deforming pneumatic manipulator, with real electrostatics.

mechanics (bulge, bending, dimple) ─► sensor (panels, method of moments) ─► readout / motion capture
─► protocol + simulate (the paper's experiment) ─► characterize (paper Fig. 3, 4), live (a source).
"""

from ectskin.twin.ect import EctGrid, EctImager, ect_grid, sensitivity
from ectskin.twin.ect_metrics import ect_image_metrics
from ectskin.twin.mechanics import Manipulator, ManipulatorConfig, Touch
from ectskin.twin.protocol import Protocol, TrialPlan, plan_trials
from ectskin.twin.readout import MocapConfig, ReadoutConfig
from ectskin.twin.sensor import Discretisation, Finger, SensorModel
from ectskin.twin.simulate import simulate_experiment, simulate_trial

__all__ = [
    "EctGrid",
    "EctImager",
    "ect_grid",
    "ect_image_metrics",
    "sensitivity",
    "Discretisation",
    "Finger",
    "Manipulator",
    "ManipulatorConfig",
    "MocapConfig",
    "Protocol",
    "ReadoutConfig",
    "SensorModel",
    "Touch",
    "TrialPlan",
    "plan_trials",
    "simulate_experiment",
    "simulate_trial",
]
