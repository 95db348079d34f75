"""Record the band's and the strip's boxes of each frame of `detect` (issue 26d), to merge them offline each way
with far_merge_variants.py (the same boxes as `detect` gives with that merge):

    .venv/bin/python docs/experiments/far_merge_record.py OUT_PREFIX -- detect IMAGES --crop ... --far-rows ... --far-model band --conf 0.001 --out P.jsonl

writes OUT_PREFIX.pkl (a list of (band boxes, strip boxes) per image, in the order of P.jsonl)."""
import pickle
import sys

import numpy as np
from cone_perception.cli import main
from cone_perception.detector import farband
pref = sys.argv[1]; args = sys.argv[3:]
rec = []
orig = farband.FarBand.merged
def merged(self, band, strip_bgr, crop=None):
    far = self.detect(strip_bgr, crop)
    rec.append((band.copy(), far.copy()))
    return farband.merge_boxes(band, far, getattr(self.detector, "iou", 0.45))
farband.FarBand.merged = merged
rc = main(args)
pickle.dump(rec, open(pref + ".pkl", "wb"))
print("recorded", len(rec), "rc", rc)
