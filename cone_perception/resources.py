"""Where the package's shipped files are: ``calib/``, ``models/``, ``launch_configs/``.

Looked up in this order: the source checkout (editable install, tests), then
``share/cone_perception`` under the install prefix (pip) or under any parent of
the installed package (colcon: ``install/cone_perception/lib/pythonX.Y/site-packages``).
"""

from __future__ import annotations

import os
import sys
from functools import lru_cache
from pathlib import Path

PACKAGE_NAME = "cone_perception"
PACKAGE_DIR = Path(__file__).resolve().parent


@lru_cache(maxsize=1)
def share_dir() -> Path:
    """Directory holding ``calib/``, ``models/`` and ``launch_configs/``."""
    repo = PACKAGE_DIR.parent
    if (repo / "package.xml").is_file() and (repo / "calib").is_dir():
        return repo
    candidates = [Path(sys.prefix) / "share" / PACKAGE_NAME]
    # colcon installs the package under <prefix>/lib/pythonX.Y/site-packages
    for parent in PACKAGE_DIR.parents:
        candidates.append(parent / "share" / PACKAGE_NAME)
    for c in candidates:
        if (c / "calib").is_dir():
            return c
    raise FileNotFoundError(
        f"cannot find the {PACKAGE_NAME} share directory (calib/, models/); looked in {repo} and "
        + ", ".join(str(c) for c in candidates[:3])
    )


def calib_dir() -> Path:
    return share_dir() / "calib"


def models_dir() -> Path:
    return share_dir() / "models"


#: File name of the shipped default model under ``models/``.
DEFAULT_MODEL_NAME = "cone_detector.pt"
#: What an error about a missing or unreadable model file advises.
RESTORE_HINT = (
    "restore the shipped file with `git checkout models/` or train one with `cone-perception train` "
    "(see README)"
)


def default_model_path() -> Path:
    """``models/cone_detector.pt`` of the installed package (may not exist yet)."""
    return models_dir() / DEFAULT_MODEL_NAME


#: File name of the shipped far-strip model under ``models/`` (models/cone_detector_far.md).
DEFAULT_FAR_MODEL_NAME = "cone_detector_far.pt"
#: ``far_model`` / ``--far-model`` spellings: ``auto`` (the default) = the shipped far model; empty or ``band`` =
#: the band's own model; anything else is a model file.
FAR_MODEL_AUTO = "auto"
FAR_MODEL_BAND = ("", "band")
#: ``far_model`` when not given: the shipped far model (it finds more small cones; the image attitude reads its
#: boxes through its own box model, :func:`cone_perception.attitude.box_files.far_reading_for`: docs/benchmarks.md,
#: "The far model's box model (issue 26f)").
FAR_MODEL_DEFAULT = "auto"


def default_far_model_path() -> Path:
    """``models/cone_detector_far.pt`` of the installed package (may not exist)."""
    return models_dir() / DEFAULT_FAR_MODEL_NAME


def far_model_for(choice, band_model):
    """The far strip's model of ``far_model`` / ``--far-model`` ``choice`` (None: :data:`FAR_MODEL_DEFAULT`): ``auto`` -> the
    shipped far model (the band's model where it is not installed), ``""`` / ``band`` -> ``band_model``
    (whatever the caller uses for the band's: a path, or None), else ``Path(choice)``."""
    c = FAR_MODEL_DEFAULT if choice is None else str(choice).strip()
    if c.lower() == FAR_MODEL_AUTO:
        far = default_far_model_path()
        return far if far.exists() else band_model
    if c.lower() in FAR_MODEL_BAND:
        return band_model
    return Path(c)


def far_model_given(choice) -> bool:
    """Whether ``--far-model`` names a model file (not None, ``auto``, ``band`` or empty)."""
    return choice is not None and str(choice).strip().lower() not in (FAR_MODEL_AUTO, *FAR_MODEL_BAND)


def launch_dir() -> Path:
    return share_dir() / "launch_configs"


DDS_PROFILES = {"shm": "fastdds_shm.xml", "localhost": "fastdds_localhost_shm.xml"}


def dds_profile_path(kind: str = "localhost") -> Path:
    """A shipped Fast DDS profile: ``shm`` (64 MiB shared memory + the standard UDPv4) or
    ``localhost`` (64 MiB shared memory + UDPv4 on 127.0.0.1 only); see :mod:`.ros_env`."""
    return PACKAGE_DIR / "config" / DDS_PROFILES[kind]


def resolve_in(directory: Path, name_or_path: str | os.PathLike, suffixes: tuple[str, ...]) -> Path:
    """An existing path as given, else ``directory/name`` with one of ``suffixes``."""
    p = Path(name_or_path).expanduser()
    if p.is_file() or p.parent != Path("."):
        return p
    for suffix in ("",) + suffixes:
        cand = directory / f"{p.name}{suffix}"
        if cand.is_file():
            return cand
    return p


def user_cache_dir() -> Path:
    """This package's folder in the user's cache: ``$XDG_CACHE_HOME``, else ``~/.cache``, then ``cone_perception``
    (the TensorRT engines: :func:`~cone_perception.detector.backends.trt_cache_dir`; the ONNX graphs of the torch
    models: :func:`~cone_perception.detector.onnx_cache.onnx_cache_dir`; the DDS profiles of a restart after a
    crash: :func:`~cone_perception.ros_env.with_participant_id`)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / PACKAGE_NAME
