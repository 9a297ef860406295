"""The base of the learning data sets, :class:`SampleData`, and the helpers their builders share.

A data set (:class:`~ectskin.learn.data.touch.TouchData`,
:class:`~ectskin.learn.data.track.TrackData`, :class:`~ectskin.learn.data.contact.ContactData`)
holds three kinds of fields, and each class declares which of its fields is which:

====================  ==========================================================================
``SAMPLE_FIELDS``     arrays with one row per sample (first axis n_samples): ``x``, the targets,
                      ``group`` (index into ``group_names`` of the sample's trial), ...
``GROUP_FIELDS``      arrays with one row per group (trial): ``group_region``; empty when the
                      builder did not record them
everything else       shared by every sample: channel names, class count, layout geometry
====================  ==========================================================================

The constructor checks that every per-sample array has n_samples rows and every per-group array
n_groups rows (or none), naming the field. :meth:`~SampleData.select` (samples of some groups),
:meth:`~SampleData.take` (samples by index) and :meth:`~SampleData.concat` (several data sets as
one) work on the declared fields only.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any, ClassVar, Self

import numpy as np

from ectskin._check import EctskinError
from ectskin.io.recording import Recording, Trial

#: what a data-set builder does with a frame holding a non-finite readout
NONFINITE_OPTIONS = ("raise", "drop")

__all__ = ["NONFINITE_OPTIONS", "SampleData", "finite_rows", "select_trials"]


class SampleData:
    """Samples of a learning task (see the module docstring). Subclasses are dataclasses that
    declare :attr:`SAMPLE_FIELDS` (with ``x`` first and ``group``) and may extend
    :attr:`GROUP_FIELDS` and :attr:`MATCH_FIELDS`."""

    #: per-sample array fields (first axis: sample)
    SAMPLE_FIELDS: ClassVar[tuple[str, ...]] = ("x", "group")
    #: per-group array fields (first axis: group, in ``group_names`` order; may be empty)
    GROUP_FIELDS: ClassVar[tuple[str, ...]] = ("group_region",)
    #: shared fields that must be equal in the data sets :meth:`concat` joins
    MATCH_FIELDS: ClassVar[tuple[str, ...]] = ("pair_names",)

    x: np.ndarray
    group: np.ndarray
    group_names: list[str]

    def __post_init__(self) -> None:
        n = self._rows("x", "sample")
        for field in self.SAMPLE_FIELDS:
            rows = self._rows(field, "sample")
            if rows != n:
                raise EctskinError(
                    f"{type(self).__name__}.{field} must have one row per sample ({n}, the rows "
                    f"of x), got shape {getattr(self, field).shape}"
                )
        n_groups = len(self.group_names)
        for field in self.GROUP_FIELDS:
            rows = self._rows(field, "group")
            if rows not in (0, n_groups):
                raise EctskinError(
                    f"{type(self).__name__}.{field} must have one row per group ({n_groups}, "
                    f"the length of group_names) or none, got {rows}"
                )

    def _rows(self, field: str, per: str) -> int:
        value = getattr(self, field)
        if not isinstance(value, np.ndarray) or value.ndim == 0:
            raise EctskinError(
                f"{type(self).__name__}.{field} must be a numpy array with one row per {per}, "
                f"got {type(value).__name__} of shape {np.shape(value)}"
            )
        return int(value.shape[0])

    @property
    def n_samples(self) -> int:
        return int(self.x.shape[0])

    @property
    def n_groups(self) -> int:
        return len(self.group_names)

    def group_ids(self, names: Sequence[str], *, source: str = "data") -> np.ndarray:
        """(len(names),) int64 ids of the groups (trials) called ``names``, in that order; a
        name that is not a group of the data is an error naming it (``source`` says where)."""
        index = {g: i for i, g in enumerate(self.group_names)}
        missing = [g for g in names if g not in index]
        if missing:
            raise EctskinError(
                f"{source}: lacks trial(s) {missing[:3]} ({self.n_groups} trials, e.g. "
                f"{self.group_names[:3]})"
            )
        return np.array([index[g] for g in names], dtype=np.int64)

    def select(self, groups: Sequence[int] | np.ndarray) -> Self:
        """The samples of the given group ids (e.g. ``split["train"]``), in their order in the
        data; group ids, group names and per-group fields are kept."""
        ids = np.asarray(groups)
        n = self.n_groups
        if ids.size and (ids.dtype.kind not in "iu" or ids.min() < 0 or ids.max() >= n):
            raise EctskinError(f"group ids must be integers in 0..{n - 1}, got {ids.tolist()[:10]}")
        return self._with_rows(np.isin(self.group, ids))

    def take(self, rows: Sequence[int] | np.ndarray) -> Self:
        """The samples ``rows`` (indices into the samples, in the order given); groups kept."""
        idx = np.asarray(rows)
        n = self.n_samples
        if idx.size and (idx.dtype.kind not in "iu" or idx.min() < 0 or idx.max() >= n):
            raise EctskinError(
                f"sample indices must be integers in 0..{n - 1}, got {idx.tolist()[:10]}"
            )
        return self._with_rows(idx.astype(np.int64, copy=False))

    def aligned_to(self, other: Self) -> Self:
        """These samples made joinable to ``other``'s (:meth:`concat`): as they are here; a
        data set whose samples index a list that may differ between recordings (contact's
        inflation states) maps them onto ``other``'s."""
        return self

    def _with_rows(self, index: np.ndarray) -> Self:
        return replace(self, **{f: getattr(self, f)[index] for f in self.SAMPLE_FIELDS})

    @classmethod
    def concat(cls, parts: Sequence[Self]) -> Self:
        """One data set of ``parts`` (of this class, with equal :attr:`MATCH_FIELDS`, e.g. the
        same channels): per-sample and per-group arrays concatenated in order, the groups of part
        i renumbered after those of the parts before it and named ``"i/<name>"`` (the same trial
        of two recordings stays two groups). The other shared fields are the first part's."""
        if not parts:
            raise EctskinError(f"{cls.__name__}.concat: no data sets to join")
        first = parts[0]
        for i, p in enumerate(parts):
            if type(p) is not cls:
                raise EctskinError(
                    f"{cls.__name__}.concat: part {i} is a {type(p).__name__}, not a {cls.__name__}"
                )
            for f in cls.MATCH_FIELDS:
                if not _equal(getattr(p, f), getattr(first, f)):
                    raise EctskinError(
                        f"{cls.__name__}.concat: part {i} differs from part 0 in {f!r}; only data "
                        f"sets with the same {', '.join(cls.MATCH_FIELDS)} can be joined"
                    )
            for f in cls.SAMPLE_FIELDS:
                shape, want = getattr(p, f).shape[1:], getattr(first, f).shape[1:]
                if shape != want:
                    raise EctskinError(
                        f"{cls.__name__}.concat: part {i} has {f} samples of shape {shape}, part "
                        f"0 {want}"
                    )
        changes: dict[str, Any] = {}
        offsets = np.cumsum([0] + [p.n_groups for p in parts[:-1]])
        for f in cls.SAMPLE_FIELDS:
            if f == "group":
                changes[f] = np.concatenate([p.group + o for p, o in zip(parts, offsets)])
            else:
                changes[f] = np.concatenate([getattr(p, f) for p in parts])
        for f in cls.GROUP_FIELDS:
            changes[f] = np.concatenate([getattr(p, f) for p in parts])
        changes["group_names"] = [f"{i}/{g}" for i, p in enumerate(parts) for g in p.group_names]
        return replace(first, **changes)


def _equal(a: Any, b: Any) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return bool(np.array_equal(a, b))
    return bool(a == b)


def select_trials(rec: Recording, trials: Any) -> list[Trial]:
    """The trials of ``rec`` named or indexed by ``trials`` (a name, or a sequence of names and
    indices; None: all, in recording order); an unknown one is an error naming it."""
    if trials is None:
        return list(rec.trials)
    if isinstance(trials, str):
        trials = [trials]
    out = []
    for t in trials:
        if isinstance(t, (int, np.integer)) and not isinstance(t, bool):
            if not 0 <= int(t) < rec.n_trials:
                raise EctskinError(f"trial index {t} out of range 0..{rec.n_trials - 1}")
            out.append(rec.trials[int(t)])
        else:
            out.append(rec.trial(str(t)))
    return out


def finite_rows(c: np.ndarray) -> np.ndarray:
    """(n,) bool: which rows of ``c`` (n, P) are finite in every column."""
    return np.all(np.isfinite(c), axis=1)
