"""Read OptiTrack Motive CSV exports: marker trajectories in mm, NaN where a marker was occluded.

A Motive export (format versions 1.2x) looks like this (see ``docs/instrument-import.md``)::

    Format Version,1.23,Take Name,touch_017,...,Export Frame Rate,120.000000,...,Length Units,Meters
    <blank>
    ,Type,Rigid Body,...,Marker,Marker,Marker
    ,Name,Body,...,Skin:M1,Skin:M1,Skin:M1
    ,ID,1,...,2,2,2
    ,,Rotation,...,Position,Position,Position
    Frame,Time (Seconds),X,Y,Z,W,...,X,Y,Z
    0,0.000000,...
    1,0.008333,...

An occluded marker leaves its three cells empty. By default the reader keeps the labelled columns
of Type ``Marker`` (Motive's "Unlabeled …" markers are left out); ``marker_names`` selects markers
by name instead (any Type, e.g. ``Rigid Body Marker``), in the order given. Positions are converted
from the file's ``Length Units`` (Meters, Centimeters, Millimeters) to mm.

Modules: :mod:`~ectskin.io.motive.header` (metadata row, header rows, marker columns),
:mod:`~ectskin.io.motive.read` (the reader and its data rows), :mod:`~ectskin.io.motive.data`
(the result types); text and numbers through :mod:`ectskin.io.text`.
"""

from __future__ import annotations

from ectskin.io.motive.data import MarkerOcclusion, MocapData
from ectskin.io.motive.header import LENGTH_UNITS
from ectskin.io.motive.read import read_motive_csv

__all__ = ["LENGTH_UNITS", "MarkerOcclusion", "MocapData", "read_motive_csv"]
