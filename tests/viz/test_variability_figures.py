"""The variability study's figures (ectskin.viz.variability): drawn from a hand-built results
document, into new figures or given axes, never saved by the plot function.

What each test catches: a curve drawn out of scale order or with a missing value as 0; a fault
case drawn on the curve instead of beside it; given axes ignored (a new figure opened).
"""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.figure import Figure

from ectskin._check import EctskinError
from ectskin.viz.variability import EVALUATION_LABELS, plot_degradation, plot_finetune


def _row(v, ft):
    return {**dict.fromkeys(EVALUATION_LABELS, v), "finetune": ft}


RESULTS = {
    "skin2": {
        "role": "sampled",
        "scale": 2.0,
        "touch": _row(0.5, {"0": 0.5, "100": 0.7}),
        "contact": _row(20.0, {"0": 20.0, "100": None}),
    },
    "nominal": {
        "role": "nominal",
        "scale": 0.0,
        "touch": _row(0.9, {"0": 0.9, "100": 0.9}),
        "contact": _row(5.0, {"0": 5.0, "100": 4.0}),
    },
    "dead": {
        "role": "fault",
        "scale": 0.0,
        "touch": _row(None, {"0": 0.1, "100": 0.2}),
        "contact": _row(40.0, {"0": 40.0, "100": 30.0}),
    },
}


def test_degradation_curves_in_scale_order_with_faults_beside():
    fig = plot_degradation(RESULTS)
    assert isinstance(fig, Figure) and len(fig.axes) == 2
    touch, contact = fig.axes
    curves = [ln for ln in touch.lines if ln.get_label() in EVALUATION_LABELS.values()]
    assert len(curves) == len(EVALUATION_LABELS)
    np.testing.assert_array_equal(curves[0].get_xdata(), [0.0, 2.0])  # sorted by scale
    np.testing.assert_array_equal(curves[0].get_ydata(), [0.9, 0.5])
    # the fault: no touch marker (None), one contact marker per evaluation at scale 2 + 0.5
    assert len(touch.lines) == len(EVALUATION_LABELS)
    fault = [ln for ln in contact.lines if ln.get_xdata()[0] == 2.5]
    assert len(fault) == len(EVALUATION_LABELS) and fault[0].get_ydata()[0] == 40.0
    assert [t.get_text() for t in contact.texts] == ["dead"]


def test_finetune_curves_into_given_axes_missing_values_as_gaps():
    fig = Figure()
    axes = fig.subplots(1, 2)
    assert plot_finetune(RESULTS, axes=axes) is fig
    contact = axes[1]
    skin2 = next(ln for ln in contact.lines if ln.get_label() == "skin2")
    np.testing.assert_array_equal(skin2.get_xdata(), [0, 100])
    assert skin2.get_ydata()[0] == 20.0 and np.isnan(skin2.get_ydata()[1])
    with pytest.raises(EctskinError, match="axes must hold 2 Axes"):
        plot_finetune(RESULTS, axes=[axes[0]])
