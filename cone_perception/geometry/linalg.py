"""Inverses of small matrices without LAPACK's call overhead (the per-frame filters' 2x2 and 3x3)."""

from __future__ import annotations

import numpy as np


def inv3(A: np.ndarray) -> np.ndarray:
    """Inverse of a 3x3 matrix (adjugate over determinant)."""
    (a, b, c), (d, e, f), (g, h, i) = A.tolist()
    adj = np.array([[e * i - f * h, c * h - b * i, b * f - c * e],
                    [f * g - d * i, a * i - c * g, c * d - a * f],
                    [d * h - e * g, b * g - a * h, a * e - b * d]])
    return adj / (a * adj[0, 0] + b * adj[1, 0] + c * adj[2, 0])


def inv2(A: np.ndarray) -> np.ndarray:
    """Inverse of a 2x2 matrix, or of each of a stack ``(N, 2, 2)``."""
    if A.ndim == 2:
        a, b, c, d = A.ravel().tolist()
        det = a * d - b * c
        return np.array([[d, -b], [-c, a]]) / det
    a, b, c, d = A[:, 0, 0], A[:, 0, 1], A[:, 1, 0], A[:, 1, 1]
    det = a * d - b * c
    out = np.empty_like(A)
    out[:, 0, 0], out[:, 0, 1], out[:, 1, 0], out[:, 1, 1] = d / det, -b / det, -c / det, a / det
    return out
