"""Import of recordings that did not come from the twin: a documented NPZ or CSV layout.

The format is described in ``docs/import-format.md``. In short, every file holds one row per frame
with its readouts (any number of channels), a group id (the frame's trial: splits are
trial-exclusive), and labels: a touch class per frame and/or marker coordinates per frame
(frames × markers × 3, mm); optionally a reference (per trial or per frame) and timestamps (s).

:func:`load_generic` returns a :class:`~ectskin.io.recording.Recording`. Its layout is either the
one passed in (``layout=``: the channels are then that layout's pairs in the fixed order), or a
*virtual* layout built from the data:

* n virtual electrodes ``V1..Vn`` with n the smallest integer such that n(n−1)/2 ≥ channels,
  parallel wires 10 mm apart on one virtual skin (their descriptors only tell the C2DT which
  channel is which);
* when the channel count is not n(n−1)/2 the last pairs have no data: they hold NaN and are listed
  in ``rec.meta["unmeasured_pairs"]``, which every data set of :mod:`ectskin.learn.data` leaves
  out (so 5 channels give a 4-electrode layout with 6 pairs, of which pair 5 is unmeasured);
* one region per touch class (1..max label) and one marker per tracked point
  (``rec.meta["virtual_layout"]`` is True: :func:`is_virtual_layout`).

A file with contact labels alone (no touch classes, no markers) takes its classes from them: 1
where a finger is on the skin, else 0. ``readouts="difference"`` imports readouts that are
already differences (difference imaging; ``rec.meta["readouts"]``).

The file's channel and marker names are kept in ``rec.meta["channel_names"]`` and
``rec.meta["marker_names"]``. Every problem is an :class:`~ectskin.EctskinError` naming the file,
the field or column, the line (CSV) or row (NPZ), what was expected and what was found.

Modules: :mod:`~ectskin.io.generic.npz` and :mod:`~ectskin.io.generic.csvfile` read the two
formats into the same :class:`~ectskin.io.generic.fields.Fields`;
:mod:`~ectskin.io.generic.build` turns them into the recording.
"""

from __future__ import annotations

from pathlib import Path

from ectskin._check import EctskinError, check_option
from ectskin.io.generic.build import READOUTS, build_recording, is_virtual_layout, virtual_layout
from ectskin.io.generic.csvfile import read_csv
from ectskin.io.generic.fields import NPZ_FIELDS
from ectskin.io.generic.npz import read_npz
from ectskin.io.recording import Recording
from ectskin.layout import SensorLayout, load_layout

__all__ = ["NPZ_FIELDS", "READOUTS", "is_virtual_layout", "load_generic", "virtual_layout"]


def load_generic(
    path: str | Path,
    *,
    frame_rate_hz: float | None = None,
    layout: SensorLayout | str | Path | None = None,
    readouts: str = "absolute",
) -> Recording:
    """Read a generic NPZ or CSV recording (see ``docs/import-format.md``).

    Parameters
    ----------
    path : str or Path
        ``*.npz`` or ``*.csv`` (by suffix).
    frame_rate_hz : float, optional
        Overrides the file's frame rate; otherwise the file's ``frame_rate_hz`` field (NPZ) or
        ``# frame_rate_hz: 30`` line (CSV), else the median step of the timestamps.
    layout : SensorLayout or path to a layout JSON, optional
        The skin the channels come from: the file must then hold exactly ``layout.n_pairs``
        channels in the fixed pair order, ``layout.n_markers`` markers and classes up to
        ``layout.n_regions``. Default: a virtual layout built from the data (module docstring).
    readouts : "absolute" (default) or "difference"
        "difference": the readouts are already differences (difference imaging): Eq. 2 is the
        identity on them, no reference is divided by (``rec.meta["readouts"]``, honoured by
        :mod:`ectskin.io.calibration`); a reference field is then refused.

    Returns
    -------
    Recording with one trial per group (in order of first appearance).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".npz", ".csv"):
        raise EctskinError(
            f"{path}: unknown generic recording type {path.suffix!r}; expected .npz or .csv "
            f"(see docs/import-format.md)"
        )
    check_option("readouts", readouts, READOUTS)
    if not path.is_file():
        raise EctskinError(f"{path}: file not found")
    fields = read_npz(path) if suffix == ".npz" else read_csv(path)
    if isinstance(layout, (str, Path)):
        layout = load_layout(layout)
    return build_recording(fields, layout, frame_rate_hz, fmt=suffix[1:], readouts=readouts)
