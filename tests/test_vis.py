"""Pictures: labels that would cover each other are left out, the legend strip, the band."""

from __future__ import annotations

import numpy as np

from cone_perception.records import boxes_from_arrays
from cone_perception.vis import draw_band, draw_boxes, legend_strip


def test_crowded_labels_are_not_drawn_over_each_other():
    img = np.full((200, 400, 3), 128, np.uint8)
    one = boxes_from_arrays(np.array([[100, 100, 120, 130]], np.float32), np.array([0.9], np.float32), np.array([0]))
    two = boxes_from_arrays(np.array([[100, 100, 120, 130], [102, 101, 121, 131]], np.float32),
                            np.array([0.9, 0.8], np.float32), np.array([0, 1]))
    a, b = draw_boxes(img, one), draw_boxes(img, two)
    label_area = (slice(70, 98), slice(95, 240))
    # the second (smaller) box's label would cover the first's: only the first label is drawn
    assert np.array_equal(a[label_area], b[label_area])
    far = draw_boxes(img, two, min_label_height=50)
    assert np.array_equal(far[label_area], img[label_area])  # boxes under 50 px: no labels at all


def test_legend_strip_wraps_and_band_darkens_outside():
    strip = legend_strip(300, [("a long legend entry", (255, 0, 0)), ("another long entry", (0, 255, 0))])
    assert strip.shape[1] == 300 and strip.shape[0] == 2 * 34  # two rows: the items do not fit in one
    img = np.full((100, 200, 3), 200, np.uint8)
    out = draw_band(img, (40, 80))
    assert out[10, 100].mean() < 120 and out[72, 180].mean() == 200
