"""Architecture config of the detector: one plain dataclass, and the named sizes.

Channels are given per stage, already scaled (no hidden width multiplier at build
time), so a config reads as what is built. ``n`` matches YOLO11n in width and
depth (16-32-64-128-256 channels, one bottleneck per CSP block); ``t`` ("tiny")
and ``p`` ("pico") are cone-sized: few channels at high resolution (8 in the
stem), a lighter head and fewer DFL bins (7 bins x stride 32 = 224 px
from a cell centre to each side is enough for cones). Measured forward speed:
docs/benchmarks.md, "Forward alone per detector size"; ``cone-perception speed`` measures it.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields

from ..classes import NUM_CLASSES

#: ImageNet-pretrained backbone families (modules and weights: :mod:`.pretrained`)
PRETRAINED_BACKBONES: tuple[str, ...] = ("efficientnet_lite0", "mobilenet_v2")
#: neck and head size a pretrained family gets when the model name gives none (``mobilenet_v2`` = ``mobilenet_v2-p``)
DEFAULT_NECK_SIZE = "p"


@dataclass(frozen=True)
class ModelConfig:
    """What :class:`~cone_perception.model.yolo.ConeYOLO` builds.

    ``channels``: output channels of stem (stride 2) and the stages at strides
    4, 8, 16, 32. ``depths``: bottlenecks per CSP block at strides 4, 8, 16, 32
    (the neck's blocks use ``neck_depth``). ``head_reg_ch``/``head_cls_ch``:
    width of the box and class branches of the head (0 = YOLOv8 rule).
    ``reg_max``: DFL bins per box side. ``head_dw``: depth-wise class branch
    (YOLO11 style). ``backbone``: ``csp`` (the package's own, built from
    ``channels`` and ``depths``) or an ImageNet-pretrained one of
    :data:`~cone_perception.model.pretrained.BACKBONES`; with a pretrained
    backbone only ``channels[2:]`` are used, as the neck's widths at strides
    8/16/32 (``depths`` are unused). ``strides``: (8, 16, 32), or (4, 8, 16, 32)
    for a stride-4 output level (P2, ``csp`` backbone only) fed by the stride-4
    stage: a light side branch of neck and head, ``head_p2_ch`` channels wide, so
    the 8/16/32 levels are exactly the 3-level model's (same names and weights).
    """

    name: str = "n"
    channels: tuple[int, int, int, int, int] = (16, 32, 64, 128, 256)
    depths: tuple[int, int, int, int] = (1, 1, 1, 1)
    neck_depth: int = 1
    head_reg_ch: int = 0
    head_cls_ch: int = 0
    head_dw: bool = True
    reg_max: int = 16
    num_classes: int = NUM_CLASSES
    strides: tuple[int, ...] = field(default=(8, 16, 32))
    backbone: str = "csp"
    head_p2_ch: int = 16

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "ModelConfig":
        """Inverse of :meth:`to_dict`; raises ``ValueError`` naming unknown or bad keys."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(f"unknown architecture keys {unknown}; known: {sorted(known)}")
        kw = {k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items()}
        cfg = cls(**kw)
        cfg.validate()
        return cfg

    @property
    def has_p2(self) -> bool:
        """Whether the model has a stride-4 output level."""
        return 4 in tuple(self.strides)

    def validate(self) -> None:
        if len(self.channels) != 5 or any(int(c) <= 0 for c in self.channels):
            raise ValueError(f"channels must be 5 positive ints, got {self.channels}")
        if len(self.depths) != 4 or any(int(d) < 0 for d in self.depths):
            raise ValueError(f"depths must be 4 ints >= 0, got {self.depths}")
        if tuple(self.strides) not in ((8, 16, 32), (4, 8, 16, 32)):
            raise ValueError(f"strides must be (8, 16, 32) or (4, 8, 16, 32), got {self.strides}")
        if self.has_p2 and self.backbone != "csp":
            raise ValueError(f"a stride-4 level needs the csp backbone, not {self.backbone!r} (it gives strides 8/16/32 only)")
        if self.head_p2_ch < 1:
            raise ValueError(f"head_p2_ch must be >= 1, got {self.head_p2_ch}")
        if not 1 <= self.reg_max <= 32:
            raise ValueError(f"reg_max must be 1..32, got {self.reg_max}")
        if self.backbone != "csp" and self.backbone not in PRETRAINED_BACKBONES:
            raise ValueError(f"unknown backbone {self.backbone!r}; known: csp, {', '.join(PRETRAINED_BACKBONES)}")
        if self.num_classes < 1:
            raise ValueError(f"num_classes must be >= 1, got {self.num_classes}")


#: Named sizes. ``n``: YOLO11n width/depth. ``t``: in between (about half the FLOPs of ``n``).
#: ``p``: the smallest and fastest (a quarter of the FLOPs of ``n``). ``p2``: ``p`` with a stride-4 level.
MODEL_SIZES: dict[str, ModelConfig] = {
    "n": ModelConfig(name="n", channels=(16, 32, 64, 128, 256), depths=(1, 1, 1, 1), neck_depth=1, reg_max=16),
    "t": ModelConfig(name="t", channels=(8, 24, 48, 96, 192), head_reg_ch=32, head_cls_ch=48, reg_max=8),
    "p": ModelConfig(name="p", channels=(8, 16, 32, 64, 128), head_reg_ch=32, head_cls_ch=32, reg_max=8),
    # ``p`` with a stride-4 output level (issue 26, far cones): 16 channels at stride 4
    "p2": ModelConfig(name="p2", channels=(8, 16, 32, 64, 128), head_reg_ch=32, head_cls_ch=32, reg_max=8,
                      strides=(4, 8, 16, 32), head_p2_ch=16),
}


def model_names() -> list[str]:
    """Every name :func:`model_config` takes: the sizes, each pretrained family, each family-size pair."""
    return list(MODEL_SIZES) + [f"{b}{s}" for b in PRETRAINED_BACKBONES for s in [""] + [f"-{k}" for k in MODEL_SIZES if not MODEL_SIZES[k].has_p2]]


def is_model_name(name: str) -> bool:
    """Whether ``name`` is a model name (rather than a checkpoint path)."""
    return name in model_names()


def model_config(size: str, num_classes: int = NUM_CLASSES) -> ModelConfig:
    """The named model with ``num_classes`` classes; ``KeyError`` names the known names.

    ``size``: a size (``n``, ``t``, ``p``), a pretrained family (``mobilenet_v2``,
    ``efficientnet_lite0``: neck and head of size :data:`DEFAULT_NECK_SIZE`) or
    ``<family>-<size>`` (that size's neck and head on the pretrained backbone)."""
    family, _, neck = size.partition("-")
    if family in PRETRAINED_BACKBONES:
        neck = neck or DEFAULT_NECK_SIZE
        necks = sorted(k for k, c in MODEL_SIZES.items() if not c.has_p2)  # pretrained backbones give strides 8/16/32
        if neck not in necks:
            raise KeyError(f"unknown neck size {neck!r} in {size!r}; known: {necks}")
        d = MODEL_SIZES[neck].to_dict()
        d.update(name=f"{family}-{neck}", backbone=family)
    elif size in MODEL_SIZES:
        d = MODEL_SIZES[size].to_dict()
    else:
        raise KeyError(f"unknown model {size!r}; known: {', '.join(model_names())}")
    d["num_classes"] = int(num_classes)
    return ModelConfig.from_dict(d)
