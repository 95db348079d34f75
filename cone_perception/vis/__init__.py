"""Pictures: boxes, bands, strips, legends and the bird's-eye plot (:mod:`.draw`); the nodes' debug image
(:mod:`.debug_image`).
"""

from __future__ import annotations

from .draw import birdseye_plot, draw_band, draw_boxes, frame_strip, legend_strip, outlined_text

__all__ = ["birdseye_plot", "draw_band", "draw_boxes", "frame_strip", "legend_strip", "outlined_text"]
