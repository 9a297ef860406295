"""The hub carries the newest inversion fit on the frames after it (frames between are skipped)."""

import json

from ectskin.dashboard.hub import Hub
from ectskin.layout import default_layout

FIT = {"state": [0.0, 0.0, 0.0], "n_fingers": 0, "fingers": [], "bic_by_count": [1.0],
       "converged": True, "warm": False, "fit_ms": 0.5}


def frame(seq, inversion, **extra):
    return {"seq": seq, "inversion": inversion, **extra}


def sent(hub: Hub) -> dict:
    return json.loads(hub.encoded_latest()[1])


def test_frames_without_a_fit_carry_the_newest_fit():
    hub = Hub(default_layout())
    hub.publish(frame(1, None))
    assert "inversion_fit" not in sent(hub)  # no fit yet
    hub.publish(frame(2, FIT))
    assert sent(hub)["inversion"] == FIT and "inversion_fit" not in sent(hub)
    hub.publish(frame(3, None))
    hub.publish(frame(4, None))
    assert sent(hub)["inversion_fit"] == {"seq": 2, "inversion": FIT}
    newer = dict(FIT, n_fingers=1)
    hub.publish(frame(5, newer))
    hub.publish(frame(6, None))
    assert sent(hub)["inversion_fit"] == {"seq": 5, "inversion": newer}
    # a frame without the key (an engine from before the inversion) is sent as it came
    other = Hub(default_layout())
    other.publish({"seq": 1})
    assert sent(other) == {"seq": 1}
