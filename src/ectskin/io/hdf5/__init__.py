"""HDF5 recordings: one file per experiment holding the layout and every trial.

The schema (``format = "ectskin.recording"``, ``format_version = 4``; files of versions 1 to 3
are still read, see below) is documented in ``docs/recording-format.md``. In short, all frames of
all trials are stored back to back in one set of resizable datasets under ``/frames`` and a trial
index under ``/trials`` says where each trial starts; ``/committed`` records how many frames,
trials and events are part of the recording. The fingers are an axis (K: as wide as the trial
with the most fingers; ``/trials/n_fingers`` says how many columns of it each trial uses)::

    /                attrs format, format_version, complete, frame_rate_hz, created_utc,
                           ectskin_version, writer, meta_json
    /layout          attrs json (SensorLayout.to_json()), name
    /committed       (3,) int64: n_frames, n_trials, n_events
    /frames/capacitance  (n_frames, n_pairs) float64, pF
    /frames/timestamps   (n_frames,) float64, s
    /frames/labels       (n_frames,) int16
    /frames/markers      (n_frames, n_markers, 3) float64, mm   [if any trial has markers]
    /frames/force        (n_frames, K) float64, N               [if any trial has force]
    /frames/contact      (n_frames, K) bool                     [if any trial has it]
    /frames/finger_uv_mm (n_frames, K, 2) float64, mm           [if any trial has it]
    /frames/finger_height_mm  (n_frames, K) float64, mm         [if any trial has it]
    /trials/{name, start, region, inflation_ml, has_markers, has_force, has_contact,
             has_finger_uv_mm, has_finger_height_mm, n_fingers, meta_json}   (n_trials,)
    /trials/{finger_surface, finger_radius_mm, finger_modulus_mpa}       (n_trials, K)
    /events/{t_s, trial, text}                                           (n_events,)

Older files: version 1 has no finger ground truth; versions 1 to 3 store one finger without the
axis, and version 3 a second one in suffixed datasets (``contact2``, ``finger2_uv_mm``,
``force2``, ``/trials/finger2_surface``), which the reader puts on the axis as finger 1.

Why one set of datasets rather than a group per trial: the live :class:`RecordingWriter` uses
HDF5 SWMR (single writer, multiple readers), whose on-disk file stays consistent while it is
written, so a process killed with SIGKILL leaves a readable file. SWMR only supports appending to
datasets that exist when it is switched on; a new group per trial would break that guarantee. One
schema serves both writers, so the reader has a single code path.

Modules, by job:

* :mod:`~ectskin.io.hdf5.schema`: names, versions, the dataset layout, the metadata's JSON;
* :mod:`~ectskin.io.hdf5.write`: :func:`write_recording`, a whole recording at once, atomically
  (temp file, fsync, ``os.replace``);
* :mod:`~ectskin.io.hdf5.append`: :class:`RecordingWriter`, frames appended as they arrive (SWMR),
  with the checks of each appended batch in :mod:`~ectskin.io.hdf5.frame_args`;
* :mod:`~ectskin.io.hdf5.read` (with :mod:`~ectskin.io.hdf5.reader`): :func:`read_recording`
  checks the schema and returns a ``Recording`` (bit-exact arrays); :func:`read_layout` and
  :func:`list_trials` read metadata only, for big files;
* :mod:`~ectskin.io.hdf5._swmr`: the ``ctypes`` call that bounds a SWMR reader's retries.

Every problem with a file is reported as one :class:`~ectskin.EctskinError` naming the file and
the field; no h5py or OS traceback escapes for bad input.
"""

from __future__ import annotations

from ectskin.io.hdf5.append import RecordingWriter
from ectskin.io.hdf5.read import list_trials, read_layout, read_recording
from ectskin.io.hdf5.schema import EVENTS_KEY, FORMAT, FORMAT_VERSION
from ectskin.io.hdf5.write import write_recording

__all__ = [
    "EVENTS_KEY",
    "FORMAT",
    "FORMAT_VERSION",
    "RecordingWriter",
    "list_trials",
    "read_layout",
    "read_recording",
    "write_recording",
]
