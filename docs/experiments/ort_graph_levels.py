"""ONNX Runtime's graph optimisation levels on the shipped networks' forward, one thread (issue 43; docs/decisions.md,
"Why the defaults cannot reach 2x `n` with this network").

X
    cone-perception export --format onnx --imgsz 1920x96 --out strip.onnx           # the far strip's
    .venv/bin/python docs/experiments/ort_graph_levels.py band.onnx strip.onnx [--rounds 5] [--runs 20]

Per graph and level (ALL, the package's `backends.ort_session`; EXTENDED, without the NCHWc layout; BASIC) the median
over ``--rounds`` interleaved rounds of the mean forward of ``--runs`` runs on one random input, and the largest
difference of the outputs against ALL.
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("graphs", nargs="+", help="ONNX files (cone-perception export --format onnx)")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--runs", type=int, default=20)
    args = ap.parse_args()
    import onnxruntime as ort

    levels = {"ALL": ort.GraphOptimizationLevel.ORT_ENABLE_ALL, "EXTENDED": ort.GraphOptimizationLevel.ORT_ENABLE_EXTENDED,
              "BASIC": ort.GraphOptimizationLevel.ORT_ENABLE_BASIC}
    for graph in args.graphs:
        sessions = {}
        for name, level in levels.items():
            so = ort.SessionOptions()
            so.intra_op_num_threads, so.inter_op_num_threads, so.graph_optimization_level = 1, 1, level
            sessions[name] = ort.InferenceSession(graph, so, providers=["CPUExecutionProvider"])
        inp = sessions["ALL"].get_inputs()[0]
        x = {inp.name: np.random.default_rng(0).random(inp.shape, dtype=np.float32)}
        ms = {name: [] for name in sessions}
        for s in sessions.values():
            for _ in range(5):
                s.run(None, x)
        for _ in range(args.rounds):
            for name, s in sessions.items():
                t = time.perf_counter()
                for _ in range(args.runs):
                    s.run(None, x)
                ms[name].append((time.perf_counter() - t) / args.runs * 1e3)
        ref = sessions["ALL"].run(None, x)[0]
        print(f"{graph} {inp.shape}: " + ", ".join(
            f"{name} {np.median(v):.2f} ms (max diff {float(np.abs(sessions[name].run(None, x)[0] - ref).max()):.1e})"
            for name, v in ms.items()))


if __name__ == "__main__":
    main()
