"""The models: the paper's :class:`TouchMLP` (touch class per frame) and :class:`C2DT` (marker
coordinates from a window of frames), and our :class:`ContactNet` (contact count, position,
force and hover from a window of frames). Each has a config dataclass, so a checkpoint that stores
``asdict(config)`` rebuilds the model from the file alone (see ``ectskin.learn.checkpoint``).
"""

from ectskin.learn.models.c2dt import C2DT, C2DTConfig
from ectskin.learn.models.contact import ContactNet, ContactNetConfig
from ectskin.learn.models.mlp import TouchMLP, TouchMLPConfig

#: checkpoint ``kind`` → (model class, config class)
MODELS = {
    TouchMLP.kind: (TouchMLP, TouchMLPConfig),
    C2DT.kind: (C2DT, C2DTConfig),
    ContactNet.kind: (ContactNet, ContactNetConfig),
}

__all__ = [
    "C2DT",
    "MODELS",
    "C2DTConfig",
    "ContactNet",
    "ContactNetConfig",
    "TouchMLP",
    "TouchMLPConfig",
]
