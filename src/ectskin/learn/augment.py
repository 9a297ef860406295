"""The ``robust`` touch recipe's augmentation: the inflation shift, mixup and its loss.

* :func:`no_contact_means`: the mean calibrated frame of each no-contact trial of a split (one
  per inflation state in the paper's protocol).
* :func:`augment_touch_batch`: adds to each frame the difference between two drawn states'
  means ("the same touch seen at another inflation"), scales each value by a gain of its own,
  then mixes the batch up.
* :func:`mixup_cross_entropy`: the cross-entropy of a mixed batch, with label smoothing.

Every random draw comes from a numpy generator the caller seeds (from (seed, epoch, rank) in
training), so an epoch's augmentation is reproducible and a resumed run equals an uninterrupted
one.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
import torch.nn.functional as F


def no_contact_means(data: Any) -> np.ndarray:
    """The mean calibrated frame of each no-contact trial of ``data``: (n_states, n_pairs) float32.

    A no-contact trial is a group present in ``data.group`` whose ``data.group_region`` is 0; in
    the paper's protocol there is one per inflation state, so the rows are the inflation states
    of the data (the ``robust`` profile passes the training split). Returns an empty (0, n_pairs)
    array when ``group_region`` is missing or empty (e.g. generic imports without trial kinds).
    """
    x = np.asarray(data.x)
    region, group = getattr(data, "group_region", None), getattr(data, "group", None)
    region = np.zeros(0, np.int64) if region is None else np.asarray(region, np.int64).ravel()
    group = np.zeros(0, np.int64) if group is None else np.asarray(group, np.int64).ravel()
    if region.size == 0 or group.shape != (x.shape[0],):
        return np.zeros((0, x.shape[1]), np.float32)
    present = [g for g in np.unique(group) if 0 <= g < region.size and region[g] == 0]
    means = [x[group == g].mean(axis=0, dtype=np.float64) for g in present]
    return np.asarray(means, dtype=np.float32).reshape(len(means), x.shape[1])


def augment_touch_batch(
    x: torch.Tensor,
    y: torch.Tensor,
    rng: np.random.Generator,
    *,
    state_means: torch.Tensor | None = None,
    mixup_alpha: float = 0.0,
    mixup_pairs: str = "any",
    channel_gain: float = 0.0,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None, torch.Tensor | None]:
    """The ``robust`` recipe's augmentation of one touch batch.

    1. Inflation shift (when ``state_means`` (S, P) is given, S >= 2): frame i gets
       ``state_means[a_i] - state_means[b_i]`` added, a_i and b_i drawn uniformly and
       independently from the S states (a_i = b_i adds 0): the same touch seen at another
       inflation. The model normalises its input per pair with a fixed affine map, so adding
       the raw difference equals adding the difference of the normalised means.
    2. Gain per channel (when ``channel_gain`` > 0): every value x_ij is multiplied by its own
       exp(g_ij), g_ij ~ N(0, ``channel_gain``²): how much a touch changes each pair's readout
       varies with the inflation and the finger beyond what the calibration removes.
    3. Mixup (when ``mixup_alpha`` > 0) on the shifted, scaled batch: λ_i ~ Beta(α, α) per
       sample and a random partner j = perm(i) within the batch; x_i ← λ_i x_i + (1 − λ_i) x_j.
       ``mixup_pairs`` "class": the partner is drawn among the frames of the same class (a
       permutation within each class of the batch), so the mixed frame keeps its label: a touch
       of the same region between two training trials (other placements, states, fingers).

    Every draw comes from ``rng`` (numpy; the caller seeds it from (seed, epoch, rank)), in the
    order a, b (each (B,)), g (B, P), λ (B,), perm (B,; "class": one permutation per class
    present, in class order). Returns ``(x, y_a, y_b, lam)``: y_a = y and y_b = y[perm], lam
    (B,) float32, both None without mixup. Shapes: x (B, P), y (B,).
    """
    n = int(x.shape[0])
    if state_means is not None and len(state_means) >= 2:
        ab = torch.from_numpy(rng.integers(0, len(state_means), size=(2, n))).to(x.device)
        x = x + (state_means[ab[0]] - state_means[ab[1]])  # (B, P)
    if channel_gain > 0:
        gain = np.exp(rng.normal(0.0, channel_gain, size=tuple(x.shape))).astype(np.float32)
        x = x * torch.from_numpy(gain).to(x.device)  # (B, P)
    if mixup_alpha <= 0:
        return x, y, None, None
    lam = torch.from_numpy(rng.beta(mixup_alpha, mixup_alpha, size=n).astype(np.float32))
    if mixup_pairs == "class":
        labels = y.detach().cpu().numpy()
        order = np.arange(n)
        for c in np.unique(labels):
            idx = np.flatnonzero(labels == c)
            order[idx] = idx[rng.permutation(idx.size)]
        perm = torch.from_numpy(order).to(x.device)
    else:
        perm = torch.from_numpy(rng.permutation(n)).to(x.device)
    lam = lam.to(x.device)
    x = lam[:, None] * x + (1 - lam[:, None]) * x[perm]  # (B, P)
    return x, y, y[perm], lam


def mixup_cross_entropy(
    logits: torch.Tensor,
    y_a: torch.Tensor,
    y_b: torch.Tensor | None = None,
    lam: torch.Tensor | None = None,
    label_smoothing: float = 0.0,
) -> torch.Tensor:
    """Mean over the batch of λ_i CE(logits_i, y_a_i) + (1 − λ_i) CE(logits_i, y_b_i), each a
    cross-entropy with ``label_smoothing``; plain (smoothed) cross-entropy when ``y_b`` is None."""
    if y_b is None:
        return F.cross_entropy(logits, y_a, label_smoothing=label_smoothing)
    ce_a = F.cross_entropy(logits, y_a, reduction="none", label_smoothing=label_smoothing)
    ce_b = F.cross_entropy(logits, y_b, reduction="none", label_smoothing=label_smoothing)
    return (lam * ce_a + (1 - lam) * ce_b).mean()
