"""Plane geometry of electrodes on a skin: sampled wires, wire-to-wire distance, pad contact.

Everything is in surface coordinates (u, v) in mm. An electrode here is anything with
``polyline_mm`` ((n, 2) array), ``width_mm``, ``pad_centre_mm`` and ``pad_size_mm`` (a
:class:`~ectskin.layout.Electrode`). The layout's overlap check uses these functions.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np


def sample_polyline(poly: np.ndarray, *, step_mm: float | None = None, n: int | None = None):
    """Points along a polyline's segments: every ``step_mm`` (at least 2 per segment), or ``n``
    evenly spaced points per segment. Returns (m, 2); segment ends appear in both neighbours."""
    poly = np.asarray(poly, dtype=np.float64)
    pts = []
    for a, b in itertools.pairwise(poly):
        if n is not None:
            k = n
        elif step_mm is not None:
            k = max(2, int(np.ceil(np.linalg.norm(b - a) / step_mm)) + 1)
        else:
            raise TypeError("sample_polyline: give step_mm or n")
        pts.append(a + (b - a) * np.linspace(0, 1, k)[:, None])
    return np.concatenate(pts)


def polyline_distance(points: np.ndarray, poly: np.ndarray) -> float:
    """Smallest distance (mm) from any of ``points`` (m, 2) to the polyline ``poly`` (k, 2)."""
    best = np.inf
    for a, b in itertools.pairwise(np.asarray(poly, dtype=np.float64)):
        ab = b - a
        t = np.clip(((points - a) @ ab) / (ab @ ab), 0, 1)
        d = np.linalg.norm(points - (a + t[:, None] * ab), axis=1)
        best = min(best, float(d.min()))
    return best


def pad_touches(e: Any, other: Any) -> bool:
    """Does the pad of ``e`` touch the pad or the wire of ``other``?

    Pads are axis-aligned rectangles; the wire is sampled and the pad inflated by half the wire's
    width. A wire may start at its own pad, so only another electrode's pad counts.
    """
    c = np.asarray(e.pad_centre_mm)
    h = np.asarray(e.pad_size_mm) / 2
    oc = np.asarray(other.pad_centre_mm)
    oh = np.asarray(other.pad_size_mm) / 2
    if np.all(np.abs(c - oc) < h + oh):
        return True
    pts = sample_polyline(other.polyline_mm, n=50)
    inside = np.all(np.abs(pts - c) < h + other.width_mm / 2, axis=1)
    return bool(inside.any())


def on_skin_distance(face_a: str, uv_a, face_b: str, uv_b, width_mm: float, thickness_mm: float):
    """Distance (mm) between two surface points over the body's skin.

    Same face: the straight distance in (u, v). Front to back: the shortest path around a side
    edge (u = ±width/2), the faces and the side wall unfolded into one plane:
    ``√((|u_a − e| + thickness + |u_b − e|)² + (v_a − v_b)²)``, the smaller over e = ±width/2.
    Both faces use u = x, so the edges line up.
    """
    a = np.asarray(uv_a, dtype=np.float64)
    b = np.asarray(uv_b, dtype=np.float64)
    dv = a[..., 1] - b[..., 1]
    if face_a == face_b:
        return np.hypot(a[..., 0] - b[..., 0], dv)
    e = width_mm / 2
    right = np.abs(e - a[..., 0]) + thickness_mm + np.abs(e - b[..., 0])
    left = np.abs(e + a[..., 0]) + thickness_mm + np.abs(e + b[..., 0])
    return np.hypot(np.minimum(left, right), dv)
