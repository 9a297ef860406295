"""Sensor layouts as data: electrodes, pairs, touch regions and markers (see ``layout.py``)."""

from ectskin.layout.layout import (
    Electrode,
    Marker,
    Region,
    SensorLayout,
    Skin,
    default_layout,
    load_layout,
)

__all__ = [
    "Electrode",
    "Marker",
    "Region",
    "SensorLayout",
    "Skin",
    "default_layout",
    "load_layout",
]
