"""Electrostatics: capacitance of conductors by the method of moments (paper Eq. 1).

* :mod:`~ectskin.electrostatics.panels` — flat parallelogram panels (:class:`Panels`).
* :mod:`~ectskin.electrostatics.meshing` — builders of panels for plates, strips (wires),
  spheres and cylinders, with the edge correction of coarse strips.
* :mod:`~ectskin.electrostatics.mom` — potential coefficients with exact near-field integrals,
  the Maxwell capacitance matrix by Cholesky, the ECT pair readout ``C_ij = −K_ij``, and the
  first-order sensitivity of K to a permittivity change in a volume (``dielectric_sensitivity``).
* :mod:`~ectskin.electrostatics.schur` — build once, solve many: conductors that stay put
  factored once (:class:`FixedConductors`), panels added to them through the Schur complement.
* :mod:`~ectskin.electrostatics.dielectric` — conductors with dielectric bodies (boundary
  elements), near-exact panel fields, and per-voxel ECT Jacobians.
* :mod:`~ectskin.electrostatics.reconstruct` — ECT images: LBP, Tikhonov, projected Landweber.

Units: mm, pF, V, pC.
"""

from ectskin.electrostatics.dielectric import (
    box_panels,
    conductor_jacobian,
    dielectric_capacitance,
    panel_field,
    panel_potential,
    permittivity_jacobian,
)
from ectskin.electrostatics.meshing import (
    STRIP_PANEL_LENGTH_MM,
    STRIP_PANELS_ACROSS,
    cylinder_panels,
    cylinder_quads,
    edge_correction_factor,
    graded_nodes,
    grid_1d,
    grid_quads,
    rectangle_panels,
    rectangle_quads,
    sphere_panels,
    sphere_quads,
    strip_panels,
    strip_quads,
)
from ectskin.electrostatics.mom import (
    EPS0_PF_PER_MM,
    NEAR_FACTOR,
    dielectric_sensitivity,
    ect_readout,
    field_at,
    maxwell_capacitance,
    potential_integral,
    potential_matrix,
    two_terminal_capacitance,
)
from ectskin.electrostatics.panels import Panels
from ectskin.electrostatics.reconstruct import (
    METHODS,
    Reconstructor,
    centroid_location,
    collapse_layers,
    landweber,
    normalise_sensitivity,
    peak_location,
)
from ectskin.electrostatics.schur import FixedConductors, potential_block

__all__ = [
    "METHODS",
    "Reconstructor",
    "box_panels",
    "centroid_location",
    "collapse_layers",
    "conductor_jacobian",
    "dielectric_capacitance",
    "landweber",
    "normalise_sensitivity",
    "panel_field",
    "panel_potential",
    "peak_location",
    "permittivity_jacobian",
    "EPS0_PF_PER_MM",
    "FixedConductors",
    "NEAR_FACTOR",
    "STRIP_PANELS_ACROSS",
    "STRIP_PANEL_LENGTH_MM",
    "Panels",
    "cylinder_panels",
    "cylinder_quads",
    "dielectric_sensitivity",
    "ect_readout",
    "edge_correction_factor",
    "field_at",
    "graded_nodes",
    "grid_1d",
    "grid_quads",
    "maxwell_capacitance",
    "potential_integral",
    "potential_block",
    "potential_matrix",
    "rectangle_panels",
    "rectangle_quads",
    "sphere_panels",
    "sphere_quads",
    "strip_panels",
    "strip_quads",
    "two_terminal_capacitance",
]
