"""Cone classes in project (FSOCO) order, their colours and name mapping."""

from __future__ import annotations

from .errors import ConfigError

BLUE, YELLOW, ORANGE, LARGE_ORANGE, UNKNOWN = range(5)

#: Class names by project class id.
CLASS_NAMES: tuple[str, ...] = ("blue", "yellow", "orange", "large_orange", "unknown")
NUM_CLASSES = len(CLASS_NAMES)

#: Cone sizes by class id (FS rules; the synthetic cones are built to them): (height, base plate side,
#: radius of the flat tip) in metres. No entry for ``unknown`` (its size is not known).
CONE_SIZE_M: dict[int, tuple[float, float, float]] = {
    BLUE: (0.325, 0.228, 0.022),
    YELLOW: (0.325, 0.228, 0.022),
    ORANGE: (0.325, 0.228, 0.022),
    LARGE_ORANGE: (0.505, 0.285, 0.028),
}

#: Drawing colour per class id, BGR (OpenCV order).
CLASS_BGR: tuple[tuple[int, int, int], ...] = (
    (255, 90, 0),  # blue
    (0, 220, 255),  # yellow
    (0, 130, 255),  # orange
    (0, 60, 230),  # large orange
    (160, 160, 160),  # unknown
)

#: Drawing colour per class id, RGBA in 0..1 (rviz markers, matplotlib).
CLASS_RGBA: tuple[tuple[float, float, float, float], ...] = tuple(
    (r / 255.0, g / 255.0, b / 255.0, 1.0) for (b, g, r) in CLASS_BGR
)

# Names other tools use for the same classes (FSOCO, Roboflow exports, YOLO yamls).
_ALIASES = {
    "blue": BLUE,
    "blue_cone": BLUE,
    "bluecone": BLUE,
    "yellow": YELLOW,
    "yellow_cone": YELLOW,
    "yellowcone": YELLOW,
    "orange": ORANGE,
    "orange_cone": ORANGE,
    "small_orange": ORANGE,
    "small_orange_cone": ORANGE,
    "orangecone": ORANGE,
    "large_orange": LARGE_ORANGE,
    "large_orange_cone": LARGE_ORANGE,
    "big_orange": LARGE_ORANGE,
    "big_orange_cone": LARGE_ORANGE,
    "largeorangecone": LARGE_ORANGE,
    "unknown": UNKNOWN,
    "unknown_cone": UNKNOWN,
    "other": UNKNOWN,
    "other_cone": UNKNOWN,
}


def class_id_from_name(name: str) -> int:
    """Project class id of a class name used by this or another tool.

    Case, spaces and dashes are ignored (``"Large Orange-Cone"`` works).
    Raises ``KeyError`` naming the known names when the name does not map.
    """
    key = str(name).strip().lower().replace("-", "_").replace(" ", "_")
    if key in _ALIASES:
        return _ALIASES[key]
    raise KeyError(
        f"class name {name!r} does not map to a project class; known: "
        + ", ".join(sorted(_ALIASES))
    )


def class_map_from_names(names: list[str], source: str) -> list[int]:
    """Project class id per model class; :class:`ConfigError` names a name that does not map."""
    out = []
    for i, n in enumerate(names):
        try:
            out.append(class_id_from_name(n))
        except KeyError as e:
            raise ConfigError(source, f"class_names[{i}]", str(e.args[0])) from e
    return out
