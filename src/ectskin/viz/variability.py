"""Figures of the fabrication-variability study (:mod:`ectskin.design.variability`): the models'
metrics against the skins' perturbation scale, and against the frames fine-tuned on.

MNE style like :mod:`ectskin.viz.learning`: each function takes the study's per-skin results,
``axes=None, show=False``, and returns the :class:`matplotlib.figure.Figure`; the caller saves it.

``results`` maps a skin name to its evaluation: ``role`` ("nominal", "sampled", "fault"),
``scale``, and per task (``"touch"``, ``"contact"``) the metric of each evaluation of
:data:`EVALUATION_LABELS` (None where it is not defined) and ``finetune`` ({N as str: metric}).
:func:`plot_few_shot` draws the few-shot curves of :mod:`ectskin.study.fewshot`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from ectskin._check import EctskinError
from ectskin.viz.learning import _finish, _new_figure

#: the study's evaluations without fine-tuning, and their legend labels
EVALUATION_LABELS = {
    "baseline": "nominal model, nominal reference",
    "own_reference": "(b) own rest reference",
    "domain_randomisation": "(a) domain randomisation",
    "dr_own_reference": "(a) + (b)",
}
#: the tasks drawn (one panel each), and the y label of each task's metric
TASK_LABELS = {"touch": "touch accuracy", "contact": "contact loc_mm_mean (mm)"}


def _panels(axes: Sequence[Any] | None, show: bool) -> tuple[Figure, list[Any], bool]:
    """(figure, one Axes per task, whether the figure is new)."""
    if axes is None:
        fig = _new_figure(show, figsize=(11, 4.2))
        return fig, list(fig.subplots(1, len(TASK_LABELS))), True
    axs = list(axes)
    if len(axs) != len(TASK_LABELS):
        raise EctskinError(
            f"axes must hold {len(TASK_LABELS)} Axes ({', '.join(TASK_LABELS)}), got {len(axs)}"
        )
    return axs[0].figure, axs, False


def plot_degradation(
    results: Mapping[str, Mapping[str, Any]],
    *,
    axes: Sequence[Any] | None = None,
    show: bool = False,
) -> Figure:
    """Touch accuracy and contact error of every evaluation against the skins' perturbation
    scale (the nominal skin at 0; fault cases as separate markers at the right), one panel per
    task (``axes``: one Axes per task of :data:`TASK_LABELS`; a new figure otherwise)."""
    fig, axs, new = _panels(axes, show)
    pts = sorted(
        ((r["scale"], r) for r in results.values() if r["role"] in ("nominal", "sampled")),
        key=lambda p: p[0],
    )
    faults = [(k, r) for k, r in results.items() if r["role"] == "fault"]
    x_fault = (pts[-1][0] if pts else 1.0) + 0.5
    for ax, (task, ylabel) in zip(axs, TASK_LABELS.items()):
        x = [p[0] for p in pts]
        for name, label in EVALUATION_LABELS.items():
            y = [np.nan if p[1][task][name] is None else p[1][task][name] for p in pts]
            line = ax.plot(x, y, "o-", label=label)[0]
            for j, (_, r) in enumerate(faults):
                v = r[task][name]
                if v is not None:
                    ax.plot(x_fault + 0.25 * j, v, "s", color=line.get_color())
        for j, (fname, _) in enumerate(faults):
            ax.annotate(
                fname,
                (x_fault + 0.25 * j, 0),
                xycoords=("data", "axes fraction"),
                ha="center",
                va="bottom",
                fontsize=8,
            )
        ax.set_xlabel("perturbation scale (× the assumed spreads)")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
    axs[0].legend(fontsize=8)
    if new:
        fig.suptitle("Models trained on the nominal skin, on fabricated skins")
        fig.tight_layout()
    return _finish(fig, show)


def plot_finetune(
    results: Mapping[str, Mapping[str, Any]],
    *,
    axes: Sequence[Any] | None = None,
    show: bool = False,
) -> Figure:
    """Each skin's metric against the number N of labelled frames fine-tuned on, one panel per
    task (``axes`` as in :func:`plot_degradation`)."""
    fig, axs, new = _panels(axes, show)
    for ax, (task, ylabel) in zip(axs, TASK_LABELS.items()):
        for name, r in results.items():
            ft = r[task]["finetune"]
            ns = sorted(int(k) for k in ft)
            y = [np.nan if ft[str(n)] is None else ft[str(n)] for n in ns]
            ax.plot(ns, y, "o-", label=name, alpha=0.9)
        ax.set_xscale("symlog", linthresh=100)
        ax.set_xlabel("labelled frames of the new skin N")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
    axs[0].legend(fontsize=8)
    if new:
        fig.suptitle("Fine-tuning the nominal model on N frames of each skin")
        fig.tight_layout()
    return _finish(fig, show)


def plot_few_shot(
    curve: Mapping[str, Mapping[str, Mapping[str, Any]]],
    metrics: Mapping[str, str],
    *,
    axes: Sequence[Any] | None = None,
    show: bool = False,
) -> Figure:
    """Few-shot curves (:mod:`ectskin.study.fewshot`): each metric against the number N of
    labelled frames of the new skin, one line per method with its spread over the draws as
    error bars, one panel per metric.

    ``curve`` maps N (as str) → method → metric → ``{"mean", "std"}`` (a metric or a method
    absent at some N, or a None mean, is a gap); ``metrics`` maps metric key → axis label, in
    panel order; ``axes``: one Axes per metric (a new figure otherwise)."""
    if not metrics:
        raise EctskinError("plot_few_shot: metrics must name at least one metric")
    if axes is None:
        fig = _new_figure(show, figsize=(4.2 * len(metrics), 4.0))
        axs, new = list(np.atleast_1d(fig.subplots(1, len(metrics)))), True
    else:
        axs, new = list(axes), False
        if len(axs) != len(metrics):
            raise EctskinError(
                f"axes must hold {len(metrics)} Axes ({', '.join(metrics)}), got {len(axs)}"
            )
        fig = axs[0].figure
    ns = sorted(curve, key=int)
    methods = list(dict.fromkeys(m for n in ns for m in curve[n]))
    for ax, (key, label) in zip(axs, metrics.items()):
        for method in methods:
            mean, std = [], []
            for n in ns:
                v = curve[n].get(method, {}).get(key) or {}
                mean.append(np.nan if v.get("mean") is None else v["mean"])
                std.append(0.0 if v.get("std") is None else v["std"])
            x = [int(n) for n in ns]
            ax.errorbar(x, mean, yerr=std, fmt="o-", capsize=3, label=method)
        ax.set_xscale("symlog", linthresh=100)
        ax.set_xlabel("labelled frames of the new skin N")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axs[0].legend(fontsize=8)
    if new:
        fig.suptitle("Adapting to a new skin: N labelled frames")
        fig.tight_layout()
    return _finish(fig, show)
