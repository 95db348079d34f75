"""Merge the boxes far_merge_record.py recorded in each way (issue 26d) and write one prediction file per variant:

    .venv/bin/python docs/experiments/far_merge_variants.py OUT_PREFIX.pkl P.jsonl PREFIX

writes PREFIX_<variant>.jsonl for `eval`: nms (class-aware NMS only), old (the rule of f0b74fb: any strip box of
the same place and size removes the band box), keepfar (shipped, strip boxes never removed), pP_cls / pP_any
(a strip box wins while scored >= P x the band box's; of one class / of any class; P 0, 0.5 (shipped: p0.5_cls), 1)."""
import sys, json, pickle
import numpy as np
from cone_perception.detector import farband
pkl, jl, pref = sys.argv[1:4]
rec = pickle.load(open(pkl, "rb"))
lines = [json.loads(l) for l in open(jl)]
assert len(lines) == len(rec), (len(lines), len(rec))
def old(b, f, iou=0.45):
    m = farband.same_cone(b, f, False).any(1)
    both = np.concatenate([b[~m], f])
    xywh = np.stack([both["u1"], both["v1"], both["u2"] - both["u1"], both["v2"] - both["v1"]], 1)
    return both[farband.nms_per_class(xywh, both["score"], both["class_id"], 0.0, iou)]
def nms(b, f, iou=0.45):
    both = np.concatenate([b, f])
    xywh = np.stack([both["u1"], both["v1"], both["u2"] - both["u1"], both["v2"] - both["v1"]], 1)
    return both[farband.nms_per_class(xywh, both["score"], both["class_id"], 0.0, iou)]
def keepfar(b, f, p=0.5, iou=0.45):
    bo, _ = farband.seen_by_far(b, f, p, True)
    both = np.concatenate([b[~bo], f])
    xywh = np.stack([both["u1"], both["v1"], both["u2"] - both["u1"], both["v2"] - both["v1"]], 1)
    return both[farband.nms_per_class(xywh, both["score"], both["class_id"], 0.0, iou)]
V = {"nms": nms, "old": old, "keepfar": keepfar}
for p in (0.0, 0.5, 1.0):
    for sc in (True, False):
        V[f"p{p}_{'cls' if sc else 'any'}"] = (lambda p, sc: lambda b, f: farband.merge_boxes(b, f, 0.45, p, sc))(p, sc)
for name, fn in V.items():
    with open(f"{pref}_{name}.jsonl", "w") as fo:
        for d, (b, f) in zip(lines, rec):
            m = fn(b, f) if len(f) else b
            m = m[np.argsort(-m["score"], kind="stable")]
            d = dict(d); d["boxes"] = [[round(float(x["u1"]), 2), round(float(x["v1"]), 2), round(float(x["u2"]), 2),
                                        round(float(x["v2"]), 2), round(float(x["score"]), 4), int(x["class_id"])] for x in m]
            fo.write(json.dumps(d) + "\n")
print(list(V))
