"""C2DT: the capacitance-to-deformation transformer (paper §4.2, Fig. 8), as DESIGN.md reads it.

The original code is not public; this is the team's reading of the paper and of its reference
(D. Hu et al., Nat. Mach. Intell. 5:261, 2023), with the paper's prior knowledge (the first frame
of each trajectory):

* **Encoder**, one token per electrode pair p = (P, Q)::

      token_p = Linear_k→d( window of the last k calibrated frames of pair p )
                + emb(desc_P) + emb(desc_Q)

  ``emb`` is ONE MLP shared by P and Q over the electrode descriptors (paper Fig. 8: "P, Q share
  the same MLP"), so the pair embedding is order-invariant. The tokens go through a
  ``TransformerEncoder`` (self-attention over the pairs). With ``desc_dim = 0`` (a generic
  recording whose channels have no electrode geometry) a learned embedding per pair replaces it.
* **Decoder**, one query per marker: a learned marker embedding plus an MLP of the marker's
  initial coordinates (the "source sequence" of the paper); a ``TransformerDecoder``
  cross-attends to the encoder tokens.
* **Head**: a linear layer gives a displacement per marker, and the output is
  ``init + out_scale * head`` (mm). The head starts at zero, so an untrained model predicts the
  "markers do not move" baseline and training improves on it.

Transformer layers are pre-norm (``norm_first``), GELU, ``batch_first``; there is no positional
encoding: the pair identity comes only from the electrode embeddings, so the encoder is a
function of the *set* of pairs (tested).

``prior=False`` is the ablation without prior knowledge: the queries are the learned marker
embeddings alone and the output is absolute, ``out_mean + out_scale * head`` (``out_mean`` = mean
training coordinates per marker).

Scaling (for well-conditioned training, all held in buffers so a checkpoint restores them):
``x_mean``/``x_std`` per pair normalise the calibrated input; ``pos_mean``/``pos_scale`` the
coordinates fed to the decoder MLP; ``out_scale`` (mm) scales the head's output, so the head works
in units of the typical training displacement. See :func:`coordinate_stats`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import torch
from torch import nn

from ectskin._check import EctskinError


@dataclass
class C2DTConfig:
    """Hyper-parameters of :class:`C2DT` (defaults: 8 electrodes, 28 pairs, 5 markers, 10 frames)."""

    n_pairs: int = 28  # encoder tokens (electrode pairs = input channels)
    n_markers: int = 5  # decoder tokens
    window: int = 10  # k: calibrated frames per sample, oldest first
    desc_dim: int = 6  # electrode descriptor features; 0 = learned per-pair embedding instead
    n_electrodes: int = 8  # rows of the electrode descriptor buffer (unused when desc_dim = 0)
    d_model: int = 64
    n_heads: int = 4
    n_enc_layers: int = 2
    n_dec_layers: int = 2
    ff: int = 128  # feed-forward width inside each transformer layer
    dropout: float = 0.0
    prior: bool = True  # True: queries from initial coordinates, output = init + displacement

    def __post_init__(self) -> None:
        positive = ("n_pairs", "n_markers", "window", "d_model", "n_heads", "ff")
        non_negative = ("desc_dim", "n_electrodes", "n_enc_layers", "n_dec_layers")
        for name in positive + non_negative:
            v = getattr(self, name)
            low = 1 if name in positive else 0
            if not isinstance(v, int | np.integer) or isinstance(v, bool) or v < low:
                raise EctskinError(f"C2DTConfig.{name} must be an integer >= {low}, got {v!r}")
            setattr(self, name, int(v))
        if self.n_dec_layers < 1:
            raise EctskinError("C2DTConfig.n_dec_layers must be >= 1 (the markers are decoded)")
        if self.d_model % self.n_heads:
            raise EctskinError(
                f"C2DTConfig.d_model ({self.d_model}) must be divisible by n_heads ({self.n_heads})"
            )
        if self.desc_dim and self.n_electrodes < 2:
            raise EctskinError(
                f"C2DTConfig.n_electrodes must be >= 2 with electrode descriptors, "
                f"got {self.n_electrodes}"
            )
        if not 0.0 <= float(self.dropout) < 1.0:
            raise EctskinError(f"C2DTConfig.dropout must be in [0, 1), got {self.dropout!r}")
        self.dropout = float(self.dropout)
        if not isinstance(self.prior, bool | np.bool_):
            raise EctskinError(f"C2DTConfig.prior must be True or False, got {self.prior!r}")
        self.prior = bool(self.prior)


def _mlp(d_in: int, d: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(d_in, d), nn.GELU(), nn.Linear(d, d))


class C2DT(nn.Module):
    """Pairs' calibrated windows (+ initial marker coordinates) → marker coordinates, mm.

    Parameters
    ----------
    config : C2DTConfig
    desc : (n_electrodes, desc_dim) electrode descriptors (``layout.electrode_descriptors()``);
        ignored when ``config.desc_dim == 0``. Stored as a buffer.
    pairs : (n_pairs, 2) electrode indices of each pair (0-based). Stored as a buffer.
    """

    kind = "c2dt"
    #: stacks of layers in the state dict: config field → key prefix of its numbered layers
    layer_stacks: ClassVar[dict[str, str]] = {
        "n_enc_layers": "encoder.layers.",
        "n_dec_layers": "decoder.layers.",
    }

    @staticmethod
    def state_shapes(config: C2DTConfig) -> dict[str, tuple[str | int, ...]]:
        """The state-dict tensors whose shapes hold every size of ``config`` (with
        :attr:`layer_stacks`, the layer counts), each dimension named by its config field (or a
        fixed int): a checkpoint is checked against them before the model is built
        (:func:`ectskin.learn.checkpoint.load_checkpoint`)."""
        shapes: dict[str, tuple[str | int, ...]] = {
            "x_mean": ("n_pairs",),
            "x_std": ("n_pairs",),
            "out_mean": ("n_markers", 3),
            "marker_emb": ("n_markers", "d_model"),
            "value_proj.weight": ("d_model", "window"),
            "decoder.layers.0.linear1.weight": ("ff", "d_model"),
        }
        if config.desc_dim:
            shapes["desc"] = ("n_electrodes", "desc_dim")
            shapes["pairs"] = ("n_pairs", 2)
        else:
            shapes["pair_table.weight"] = ("n_pairs", "d_model")
        if config.n_enc_layers:
            shapes["encoder.layers.0.linear1.weight"] = ("ff", "d_model")
        return shapes

    def __init__(
        self,
        config: C2DTConfig | None = None,
        desc: np.ndarray | torch.Tensor | None = None,
        pairs: np.ndarray | torch.Tensor | None = None,
    ) -> None:
        super().__init__()
        self.config = c = config or C2DTConfig()
        d = c.d_model
        # ---- pair identity: electrode descriptors through one shared MLP, or a learned table
        if c.desc_dim:
            if desc is None:
                desc = torch.zeros(c.n_electrodes, c.desc_dim)
            if pairs is None:
                i, j = np.triu_indices(c.n_electrodes, k=1)
                pairs = np.stack([i, j], axis=1)
            desc = torch.as_tensor(np.asarray(desc, dtype=np.float32))
            pairs = torch.as_tensor(np.asarray(pairs, dtype=np.int64))
            self._check_geometry(desc, pairs)
            self.register_buffer("desc", desc.clone())  # (n_electrodes, desc_dim)
            self.register_buffer("pairs", pairs.clone())  # (n_pairs, 2)
            self.electrode_mlp = _mlp(c.desc_dim, d)
        else:
            self.pair_table = nn.Embedding(c.n_pairs, d)
        # ---- normalisation buffers (set from the training data)
        self.register_buffer("x_mean", torch.zeros(c.n_pairs))
        self.register_buffer("x_std", torch.ones(c.n_pairs))
        self.register_buffer("pos_mean", torch.zeros(3))
        self.register_buffer("pos_scale", torch.ones(()))
        self.register_buffer("out_mean", torch.zeros(c.n_markers, 3))
        self.register_buffer("out_scale", torch.ones(()))
        # ---- encoder over pair tokens
        self.value_proj = nn.Linear(c.window, d)
        enc_layer = nn.TransformerEncoderLayer(
            d, c.n_heads, c.ff, c.dropout, activation="gelu", batch_first=True, norm_first=True
        )
        self.encoder = (
            nn.TransformerEncoder(
                enc_layer, c.n_enc_layers, norm=nn.LayerNorm(d), enable_nested_tensor=False
            )
            if c.n_enc_layers
            else nn.LayerNorm(d)  # ablation without self-attention over the pairs
        )
        # ---- decoder over marker queries
        self.marker_emb = nn.Parameter(torch.randn(c.n_markers, d))  # N(0, 1) as nn.Embedding
        if c.prior:
            self.init_mlp = _mlp(3, d)
        dec_layer = nn.TransformerDecoderLayer(
            d, c.n_heads, c.ff, c.dropout, activation="gelu", batch_first=True, norm_first=True
        )
        self.decoder = nn.TransformerDecoder(dec_layer, c.n_dec_layers, norm=nn.LayerNorm(d))
        # ---- head: zero-initialised, so an untrained model predicts "markers do not move"
        # (prior) or the mean pose (no prior): training starts from the trivial baseline.
        self.head = nn.Linear(d, 3)
        nn.init.zeros_(self.head.weight)
        nn.init.zeros_(self.head.bias)

    # ------------------------------------------------------------------ helpers
    def _check_geometry(self, desc: torch.Tensor, pairs: torch.Tensor) -> None:
        c = self.config
        if tuple(desc.shape) != (c.n_electrodes, c.desc_dim):
            raise EctskinError(
                f"C2DT: electrode descriptors must have shape ({c.n_electrodes}, {c.desc_dim}), "
                f"got {tuple(desc.shape)}"
            )
        if tuple(pairs.shape) != (c.n_pairs, 2):
            raise EctskinError(
                f"C2DT: pairs must have shape ({c.n_pairs}, 2), got {tuple(pairs.shape)}"
            )
        if pairs.numel() and (int(pairs.min()) < 0 or int(pairs.max()) >= c.n_electrodes):
            raise EctskinError(
                f"C2DT: pair electrode indices must be in 0..{c.n_electrodes - 1}, got "
                f"{int(pairs.min())}..{int(pairs.max())}"
            )

    def set_normalization(
        self,
        x_mean: np.ndarray,
        x_std: np.ndarray,
        pos_mean: np.ndarray,
        pos_scale: float,
        out_mean: np.ndarray,
        out_scale: float,
    ) -> None:
        """Set the scaling buffers: ``x_mean``/``x_std`` (n_pairs,) of the calibrated input over
        training samples and frames, and the coordinate scales of :func:`coordinate_stats`."""
        for name, value in (
            ("x_mean", x_mean),
            ("x_std", x_std),
            ("pos_mean", pos_mean),
            ("pos_scale", pos_scale),
            ("out_mean", out_mean),
            ("out_scale", out_scale),
        ):
            buf = getattr(self, name)
            val = torch.as_tensor(np.asarray(value, dtype=np.float32))
            if val.shape != buf.shape:
                raise EctskinError(
                    f"C2DT.set_normalization: {name} must have shape {tuple(buf.shape)}, "
                    f"got {tuple(val.shape)}"
                )
            buf.copy_(val)

    def pair_embedding(
        self, desc: torch.Tensor | None = None, pairs: torch.Tensor | None = None
    ) -> torch.Tensor:
        """(n_pairs, d_model): emb(P) + emb(Q) with one shared MLP (or the learned table)."""
        if not self.config.desc_dim:
            return self.pair_table.weight
        desc = self.desc if desc is None else desc.to(self.desc)
        pairs = self.pairs if pairs is None else pairs.to(self.pairs.device, torch.long)
        e = self.electrode_mlp(desc)  # (n_electrodes, d)
        return e[pairs[:, 0]] + e[pairs[:, 1]]  # (n_pairs, d), symmetric in P and Q

    # ------------------------------------------------------------------ forward
    def forward(
        self,
        x: torch.Tensor,
        init: torch.Tensor | None = None,
        desc: torch.Tensor | None = None,
        pairs: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Marker coordinates from a window of calibrated readouts.

        x : (B, k, n_pairs) calibrated readouts (Eq. 2), oldest frame first.
        init : (B, n_markers, 3) initial marker coordinates, mm (required when ``prior``).
        desc, pairs : optional overrides of the electrode-descriptor / pair buffers.
        Returns (B, n_markers, 3) coordinates, mm.
        """
        c = self.config
        if x.ndim != 3 or x.shape[1] != c.window or x.shape[2] != c.n_pairs:
            raise EctskinError(
                f"C2DT expects x of shape (B, {c.window}, {c.n_pairs}), got {tuple(x.shape)}"
            )
        B = x.shape[0]
        x = (x - self.x_mean) / self.x_std  # (B, k, P)
        tok = self.value_proj(x.transpose(1, 2))  # (B, P, d)
        tok = tok + self.pair_embedding(desc, pairs)  # (B, P, d)
        memory = self.encoder(tok)  # (B, P, d)
        q = self.marker_emb.expand(B, -1, -1)  # (B, M, d)
        if c.prior:
            if init is None or tuple(init.shape) != (B, c.n_markers, 3):
                got = None if init is None else tuple(init.shape)
                raise EctskinError(
                    f"C2DT (prior) expects init of shape ({B}, {c.n_markers}, 3), got {got}"
                )
            q = q + self.init_mlp((init - self.pos_mean) / self.pos_scale)  # (B, M, d)
            base = init  # (B, M, 3)
        else:
            base = self.out_mean.expand(B, -1, -1)  # (B, M, 3)
        h = self.decoder(q, memory)  # (B, M, d)
        return base + self.head(h) * self.out_scale  # (B, M, 3) mm


def coordinate_stats(init: np.ndarray, y: np.ndarray, *, prior: bool) -> dict[str, Any]:
    """Coordinate scaling of :class:`C2DT` fitted on training arrays (never validation or test).

    init, y : (n, n_markers, 3) initial and target marker coordinates, mm.
    Returns ``pos_mean`` (3,) and ``pos_scale`` (RMS distance from it, mm) of the coordinates the
    decoder sees (``init`` with prior, else ``y``); ``out_mean`` (n_markers, 3): zeros with
    prior, else the mean target per marker; ``out_scale`` (mm): RMS per component of the target
    minus its base (``y - init`` with prior, ``y - out_mean`` without). Scales are floored at
    1e-3 mm (a data set whose markers never move).
    """
    coords = (init if prior else y).reshape(-1, 3)
    pos_mean = coords.mean(axis=0, dtype=np.float64)
    pos_scale = float(np.sqrt(np.mean(np.square(coords - pos_mean, dtype=np.float64)) * 3))
    if prior:
        out_mean = np.zeros(y.shape[1:], dtype=np.float64)
        resid = y - init
    else:
        out_mean = y.mean(axis=0, dtype=np.float64)
        resid = y - out_mean
    out_scale = float(np.sqrt(np.mean(np.square(resid, dtype=np.float64))))
    return {
        "pos_mean": pos_mean,
        "pos_scale": max(pos_scale, 1e-3),
        "out_mean": out_mean,
        "out_scale": max(out_scale, 1e-3),
    }
