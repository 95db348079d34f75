"""Real detector behaviour on rendered drives (issue 27, item 5): the shipped detectors draw boxes on rendered
cones within tenths of a pixel of the cones' outline, while on real frames their boxes are shorter than the
labelled cones (tops 1-3 % of the height low, heights 0.97-0.99x) and scatter (the top offset's spread, 7 % of
the height), as each model's measured box model says (``MODEL.box_model.yaml``, :mod:`cone_perception.attitude.boxes`).
:class:`BoxBehaviour` gives a detector's boxes that behaviour: each box is moved by the box model's medians
(:meth:`~cone_perception.attitude.boxes.BoxModel.detected`, the rendered box taken as the labelled cone's) and
its top (and, if asked, its bottom) scattered by a normal draw of ``top_jitter`` (``bottom_jitter``) times its
height, independently per box and frame. A network whose boxes do not sit on the rendered cones (the far model's
tops 0.3-0.6 px below the cones' tips, its rendered table, :data:`~cone_perception.attitude.boxes.RENDERED_TABLES`)
has that rendered offset taken out first (``rendered_table``): the box model, measured against labels, already holds
all of the network's offset on real frames, and adding it to the rendered one would count it twice.
:class:`BehavingDetector` wraps a detector so (``replay --box-behaviour real``). The sidecars measure the spread
of the top offset only (labelling noise included): bottoms keep their rendered scatter unless ``bottom_jitter`` is
set. Off unless asked; ``synth dataset`` and ``synth bag`` are unchanged by it.
"""

from __future__ import annotations

import numpy as np

from ..attitude.boxes import BoxModel, box_top_extra_px
from ..errors import ConfigError


class BoxBehaviour:
    """Moves and scatters a detector's boxes (``BOX_DTYPE`` records, full-image px) as ``box_model`` says the
    detector does on real frames (module doc); ``top_jitter`` / ``bottom_jitter``: 1-sigma of the top / bottom
    row as a fraction of the box height (None: the box model's ``sigma_rel`` for the top, 0 for the bottom);
    ``seed``: the draws' (same seed, same boxes); ``rendered_table``: the network's rendered box-top table ((box
    height px, px) pairs, the fit's reading of its boxes on rendered drives), taken out of each box top first (empty:
    its boxes taken as the rendered cones')."""

    def __init__(self, box_model: BoxModel, top_jitter: float | None = None, bottom_jitter: float = 0.0,
                 seed: int = 0, rendered_table: tuple = ()):
        self.box_model = box_model
        self.rendered_table = tuple(rendered_table)
        self.top_jitter = float(box_model.sigma_rel if top_jitter is None else top_jitter)
        self.bottom_jitter = float(bottom_jitter)
        if not (self.top_jitter >= 0 and self.bottom_jitter >= 0):
            raise ValueError(f"box jitter must be >= 0, got top {self.top_jitter}, bottom {self.bottom_jitter}")
        self.rng = np.random.default_rng(seed)

    def __call__(self, records: np.ndarray) -> np.ndarray:
        if len(records) == 0:
            return records
        out = records.copy()
        b = np.column_stack([records["u1"], records["v1"], records["u2"], records["v2"]]).astype(np.float64)
        b[:, 1] += box_top_extra_px(b[:, 3] - b[:, 1], self.rendered_table)  # the cone's top row, as the fit reads it
        h = b[:, 3] - b[:, 1]
        d = self.box_model.detected(b)
        d[:, 1] += self.rng.normal(0.0, 1.0, len(b)) * self.top_jitter * h
        d[:, 3] += self.rng.normal(0.0, 1.0, len(b)) * self.bottom_jitter * h
        d[:, 1] = np.minimum(d[:, 1], d[:, 3] - 1.0)  # a box keeps at least one pixel of height
        out["v1"], out["v2"] = d[:, 1], d[:, 3]
        return out


class BehavingDetector:
    """A detector whose boxes pass through a :class:`BoxBehaviour` (``detect``); everything else is the wrapped
    detector's (``timing``, ``source``, thresholds...)."""

    def __init__(self, detector, behaviour: BoxBehaviour):
        self.__dict__["_detector"] = detector
        self.__dict__["behaviour"] = behaviour

    def detect(self, *args, **kwargs) -> np.ndarray:
        return self.behaviour(self._detector.detect(*args, **kwargs))

    def __getattr__(self, name):
        return getattr(self._detector, name)

    def __setattr__(self, name, value) -> None:  # thresholds set at run time reach the wrapped detector
        setattr(self._detector, name, value)


def real_box_behaviour(detector, far, box_model: BoxModel, top_jitter: float | None = None,
                       far_box_model: BoxModel | None = None, seed: int = 0, far_rendered_table: tuple = ()):
    """``(detector, far)`` with their boxes given the real behaviour of ``box_model`` (:class:`BehavingDetector`;
    ``far``: a :class:`~cone_perception.detector.farband.FarBand` or None, its detector wrapped with the next seed,
    with ``far_box_model``'s behaviour: the far strip's own model's; None: ``box_model``'s; ``far_rendered_table``:
    the far model's rendered table, taken out of its boxes first, :class:`BoxBehaviour`)."""
    if top_jitter is not None and not top_jitter >= 0:
        raise ConfigError("--box-jitter", None, f"must be a fraction >= 0 of the box height, got {top_jitter}")
    detector = BehavingDetector(detector, BoxBehaviour(box_model, top_jitter, seed=seed))
    if far is not None:
        far.detector = BehavingDetector(far.detector, BoxBehaviour(far_box_model or box_model, top_jitter, seed=seed + 1,
                                                                          rendered_table=far_rendered_table))
    return detector, far
