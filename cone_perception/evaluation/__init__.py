"""Evaluation of the detector and the whole chain against ground truth (``cone-perception eval``, ``replay --gt-topic``).

* :mod:`.metrics`: box metrics: COCO mAP (pycocotools), the operating point (P/R/F1), matching;
* :mod:`.groundtruth`: ground truth (YOLO labels, ``gt.jsonl``) paired with a prediction file;
* :mod:`.localisation`: cones in metres: matching, recall and error by distance, blue-yellow pairs;
* :mod:`.report`: ``eval``'s evaluation and report writer (metrics.json, report.md, the printed summary);
* :mod:`.plots`: ``eval``'s pictures (confusion, precision-recall, by distance, localisation, pairs, worst frames).

The names below are the face of the former module ``cone_perception.evaluation`` (now :mod:`.localisation`):
``from cone_perception.evaluation import LocalisationReport`` keeps working.
"""

from .localisation import (
    BANDS_MAX_M,
    DISTANCE_GROUPS,
    EXTRA_GROUPS,
    GT_MIN_VISIBLE,
    MAX_PAIR_M,
    LocalisationReport,
    PairDistanceReport,
    blue_yellow_pairs,
    distance_group,
    format_localisation,
    match_cones,
)

__all__ = [
    "BANDS_MAX_M", "DISTANCE_GROUPS", "EXTRA_GROUPS", "GT_MIN_VISIBLE", "MAX_PAIR_M", "LocalisationReport", "PairDistanceReport", "blue_yellow_pairs",
    "distance_group", "format_localisation", "match_cones",
]
