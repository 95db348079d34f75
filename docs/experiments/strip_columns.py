"""The far strip narrowed to its central columns (issue 26, helper "speed"): its cost and what it misses.

    .venv/bin/python docs/experiments/strip_columns.py WIDTH replay BAG --calib C --gt-topic /cones_gt --track --json F
    .venv/bin/python docs/experiments/strip_columns.py WIDTH bench pipeline --frames 200 --json

Runs one `cone-perception` command with every far strip cut to the central WIDTH columns of the image (rows as
the command says: the calibration's strip, moved with the attitude), by replacing `farband.far_band_crop`; WIDTH a
multiple of 32. A design measured, not shipped: docs/benchmarks.md, "Row-scaled band (issue 26)".
"""
import sys
from dataclasses import replace

from cone_perception.cli import main
from cone_perception.detector import farband

width = int(sys.argv[1])
whole = farband.far_band_crop


def central(rows, image_width, image_height, band, source="far_rows"):
    crop = whole(rows, image_width, image_height, band, source)
    u0 = (image_width - width) // 2 // 2 * 2
    return replace(crop, u0=u0, u1=u0 + width)


farband.far_band_crop = central
sys.exit(main(sys.argv[2:]))
