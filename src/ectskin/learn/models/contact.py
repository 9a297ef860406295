"""ContactNet: where, how hard and how many fingers, from a window of calibrated frames (ours).

Input: (B, k, n_pairs) calibrated readouts (paper Eq. 2), oldest frame first. A trunk turns the
window into a feature vector; heads read it out:

* ``count`` (B, max_fingers + 1) logits: 0, 1, … fingers on the skin;
* ``hover`` (B,) logit: a finger above the skin, none on it;
* per finger slot s: ``face`` (B, S, n_faces) logits, ``uv`` (B, S, 2) the point in units of
  the face's half extent (centred), ``log_var`` (B, S) the log variance of that point (same
  units; the model's own uncertainty, trained with a Gaussian likelihood), ``force`` (B, S) in
  units of ``force_scale`` N, and with ``force_sigma`` ``force_log_var`` (B, S) the log variance
  of that force (same units; the model's own, trained with a Gaussian likelihood on the
  training frames; :meth:`ContactNet.decode` multiplies its σ by the buffer
  ``force_sigma_scale``, fitted on the validation frames by the contact task's criterion).

``force_sigma`` is False in the files of runs made before the force had its uncertainty (their
stored config lacks the field, and their weights the head): they load as they were, and their
force's σ column is 0 (no σ). The contact task builds new models with it
(:meth:`~ectskin.learn.tasks.contact.ContactTask.build_model`).

Trunks (``arch``):

``mlp``       the window flattened → ``hidden`` units (ReLU, dropout): the paper's TouchMLP size
              (one hidden layer of 128) with a window of 1.
``temporal``  a small sequence model: two 1-D convolutions over the k frames (``channels``,
              kernel 3, ReLU), then the flattened sequence → ``hidden`` units (ReLU, dropout)
              → ``hidden`` units (ReLU).

Buffers ``x_mean``/``x_std`` (n_pairs,) normalise the input (set from the training data).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import torch
from torch import nn

from ectskin._check import EctskinError

ARCHS = ("mlp", "temporal")


@dataclass
class ContactNetConfig:
    """Hyper-parameters of :class:`ContactNet` (shape fields come from the data)."""

    n_pairs: int = 28
    window: int = 5
    n_faces: int = 2
    max_fingers: int = 2
    arch: str = "temporal"
    hidden: int = 128
    channels: int = 64  # temporal: convolution channels
    dropout: float = 0.1
    force_sigma: bool = False  # a head for the force's log variance (module docstring)

    def __post_init__(self) -> None:
        if not isinstance(self.force_sigma, bool | np.bool_):
            raise EctskinError(
                f"ContactNetConfig.force_sigma must be true or false, got {self.force_sigma!r}"
            )
        self.force_sigma = bool(self.force_sigma)
        for name in ("n_pairs", "window", "n_faces", "max_fingers", "hidden", "channels"):
            v = getattr(self, name)
            if not isinstance(v, int | np.integer) or isinstance(v, bool) or v < 1:
                raise EctskinError(f"ContactNetConfig.{name} must be a positive integer, got {v!r}")
            setattr(self, name, int(v))
        if self.arch not in ARCHS:
            raise EctskinError(
                f"ContactNetConfig.arch must be one of {', '.join(ARCHS)}, got {self.arch!r}"
            )
        if not 0.0 <= float(self.dropout) < 1.0:
            raise EctskinError(f"ContactNetConfig.dropout must be in [0, 1), got {self.dropout!r}")
        self.dropout = float(self.dropout)


class ContactNet(nn.Module):
    """See the module docstring. ``forward`` returns a dict of the heads' outputs."""

    kind = "contact_net"
    layer_stacks: ClassVar[dict[str, str]] = {}

    @staticmethod
    def state_shapes(config: ContactNetConfig) -> dict[str, tuple[str | int, ...]]:
        """State-dict tensors holding every size of ``config`` (checked before building)."""
        shapes: dict[str, tuple[str | int, ...]] = {
            "x_mean": ("n_pairs",),
            "x_std": ("n_pairs",),
            "uv_centre": ("n_faces", 2),
            "hover_head.weight": (1, "hidden"),
        }
        if config.arch == "temporal":
            shapes["conv.0.weight"] = ("channels", "n_pairs", 3)
        if config.force_sigma:
            shapes["force_var_head.weight"] = ("max_fingers", "hidden")
        return shapes

    def __init__(self, config: ContactNetConfig | None = None) -> None:
        super().__init__()
        self.config = c = config or ContactNetConfig()
        self.register_buffer("x_mean", torch.zeros(c.n_pairs))
        self.register_buffer("x_std", torch.ones(c.n_pairs))
        self.register_buffer("uv_centre", torch.zeros(c.n_faces, 2))
        self.register_buffer("uv_half", torch.ones(c.n_faces, 2))
        self.register_buffer("force_scale", torch.ones(()))
        if c.arch == "temporal":
            self.conv = nn.Sequential(
                nn.Conv1d(c.n_pairs, c.channels, 3, padding=1),
                nn.ReLU(),
                nn.Conv1d(c.channels, c.channels, 3, padding=1),
                nn.ReLU(),
            )
            self.trunk = nn.Sequential(
                nn.Linear(c.channels * c.window, c.hidden),
                nn.ReLU(),
                nn.Dropout(c.dropout),
                nn.Linear(c.hidden, c.hidden),
                nn.ReLU(),
            )
        else:
            self.conv = None
            self.trunk = nn.Sequential(
                nn.Linear(c.n_pairs * c.window, c.hidden), nn.ReLU(), nn.Dropout(c.dropout)
            )
        s = c.max_fingers
        self.count_head = nn.Linear(c.hidden, s + 1)
        self.hover_head = nn.Linear(c.hidden, 1)
        # per slot: face logits, (u, v), log variance, force
        self.slot_head = nn.Linear(c.hidden, s * 4)
        self.face_head = nn.Linear(c.hidden, s * c.n_faces)
        # per slot: the force's log variance
        self.force_var_head = nn.Linear(c.hidden, s) if c.force_sigma else None
        if c.force_sigma:  # the force σ's scale on held-out data (set by the validation pass)
            self.register_buffer("force_sigma_scale", torch.ones(()))

    def set_normalization(
        self,
        x_mean: np.ndarray,
        x_std: np.ndarray,
        uv_centre: np.ndarray,
        uv_half: np.ndarray,
        force_scale: float,
    ) -> None:
        """Set the input statistics and the target scales (faces × (u, v) mm, N)."""
        values = {
            "x_mean": x_mean,
            "x_std": x_std,
            "uv_centre": uv_centre,
            "uv_half": uv_half,
            "force_scale": force_scale,
        }
        for name, value in values.items():
            buf = getattr(self, name)
            val = torch.as_tensor(np.asarray(value, dtype=np.float32))
            if val.shape != buf.shape:
                raise EctskinError(
                    f"ContactNet.set_normalization: {name} must have shape {tuple(buf.shape)}, "
                    f"got {tuple(val.shape)}"
                )
            buf.copy_(val)

    def forward(self, x: torch.Tensor) -> dict[str, torch.Tensor]:
        """x: (B, k, n_pairs) → {count, hover, face, uv, log_var, force} and, with
        ``force_sigma``, ``force_log_var`` (see the docstring)."""
        c = self.config
        z = (x - self.x_mean) / self.x_std  # (B, k, P)
        if self.conv is not None:
            z = self.conv(z.transpose(1, 2))  # (B, channels, k)
        h = self.trunk(z.flatten(1))  # (B, hidden)
        s = c.max_fingers
        slots = self.slot_head(h).view(-1, s, 4)
        face = self.face_head(h).view(-1, s, c.n_faces)
        out = {
            "count": self.count_head(h),
            "hover": self.hover_head(h)[:, 0],
            "face": face,
            "uv": slots[..., :2],
            "log_var": slots[..., 2].clamp(-12.0, 6.0),
            "force": slots[..., 3],
        }
        if self.force_var_head is not None:
            out["force_log_var"] = self.force_var_head(h).clamp(-14.0, 6.0)  # (B, S)
        return out

    def decode(self, out: dict[str, torch.Tensor]) -> torch.Tensor:
        """(B, 3 + S · 6) physical predictions, columns as :data:`PRED_COLUMNS` and
        :data:`SLOT_COLUMNS` describe (``force_sigma_n`` 0 without the force's σ head)."""
        count_p = out["count"].softmax(-1)  # (B, S + 1)
        face = out["face"].argmax(-1)  # (B, S)
        centre = self.uv_centre[face]  # (B, S, 2)
        half = self.uv_half[face]
        uv = centre + out["uv"] * half  # mm
        sigma = out["log_var"].mul(0.5).exp()[..., None] * half  # (B, S, 2) mm
        sigma_mm = sigma.norm(dim=-1) / np.sqrt(2.0)  # per-axis RMS
        force = (out["force"] * self.force_scale).clamp_min(0.0)
        if "force_log_var" in out:
            scale = self.force_scale * self.force_sigma_scale
            force_sd = out["force_log_var"].mul(0.5).exp() * scale  # (B, S) N
        else:  # no σ: 0 (a NaN would fail the ONNX export's check against this model)
            force_sd = torch.zeros_like(force)
        count = count_p.argmax(-1).to(uv.dtype)
        p_contact = 1.0 - count_p[:, 0]
        p_hover = torch.sigmoid(out["hover"])
        slots = torch.cat(
            [
                face[..., None].to(uv.dtype),
                uv,
                sigma_mm[..., None],
                force[..., None],
                force_sd[..., None],
            ],
            -1,
        )
        return torch.cat(
            [count[:, None], p_contact[:, None], p_hover[:, None], slots.flatten(1)], 1
        )


#: columns of :meth:`ContactNet.decode` (and of the contact task's predictions): three per
#: frame, then six per finger slot: ``sigma_mm`` the point's standard deviation per axis (mm),
#: NaN where the model gives none; ``force_sigma_n`` the force's (N), 0 or NaN where the model
#: gives none
PRED_COLUMNS = ("count", "p_contact", "p_hover")
SLOT_COLUMNS = ("face", "u_mm", "v_mm", "sigma_mm", "force_n", "force_sigma_n")
