"""How good the attitude of a replay was (:class:`AttitudeReport`, its table) and its picture
(:func:`attitude_plot`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..attitude import Attitude
from .localisation import DISTANCE_GROUPS, distance_group


@dataclass
class AttitudeReport:
    """How good the attitude of a replay was: per frame the attitude used against the true one (where
    the bag has it), and per distance group whether the cones' covariance (attitude uncertainty
    included) matches their actual error."""

    err_pitch: list = None  # per frame with truth, degrees (estimate - truth)
    err_roll: list = None
    sources: dict = None
    pair_range: list = None  # per matched cone: true range (m), error (m), predicted 1-sigma (m)
    pair_err: list = None
    pair_sigma: list = None

    def __post_init__(self):
        for k in ("err_pitch", "err_roll", "pair_range", "pair_err", "pair_sigma"):
            setattr(self, k, [])
        self.sources = {}

    def add_frame(self, att: Attitude, truth_deg: tuple[float, float] | None, cones: np.ndarray,
                  truth: np.ndarray | None = None, pairs: list | None = None) -> None:
        """``truth_deg`` (pitch, roll) or None; ``pairs`` from :meth:`LocalisationReport.add_frame`."""
        self.sources[att.source] = self.sources.get(att.source, 0) + 1
        if truth_deg is not None:
            self.err_pitch.append(att.pitch_deg - truth_deg[0])
            self.err_roll.append(att.roll_deg - truth_deg[1])
        for i, j, d in pairs or ():
            c = cones[i]
            cov = np.array([[c["cov_xx"], c["cov_xy"]], [c["cov_xy"], c["cov_yy"]]], dtype=np.float64)
            self.pair_range.append(float(np.hypot(truth["x"][j], truth["y"][j])))
            self.pair_err.append(float(d))
            self.pair_sigma.append(float(np.sqrt(max(np.trace(cov), 0.0))))

    def summary(self) -> dict:
        out: dict = {"frames_by_source": dict(self.sources)}
        if self.err_pitch:
            ep, er = np.abs(self.err_pitch), np.abs(self.err_roll)
            out.update(frames_with_truth=len(ep), median_abs_err_pitch_deg=float(np.median(ep)),
                       median_abs_err_roll_deg=float(np.median(er)), p90_abs_err_pitch_deg=float(np.percentile(ep, 90)),
                       p90_abs_err_roll_deg=float(np.percentile(er, 90)))
        groups = {}
        if self.pair_range:
            g = distance_group(np.array(self.pair_range))
            e, s = np.array(self.pair_err), np.array(self.pair_sigma)
            for k, (name, _, _) in enumerate(DISTANCE_GROUPS):
                sel = g == k
                if sel.any():
                    groups[name] = {"n": int(sel.sum()), "median_err_m": float(np.median(e[sel])),
                                    "median_sigma_m": float(np.median(s[sel])),
                                    "within_2sigma": float(np.mean(e[sel] <= 2 * s[sel]))}
        out["groups"] = groups
        return out


def format_attitude_report(summary: dict) -> str:
    """Plain text of :meth:`AttitudeReport.summary`."""
    lines = ["attitude: frames by source " + ", ".join(f"{k} {v}" for k, v in sorted(summary["frames_by_source"].items()))]
    if "median_abs_err_pitch_deg" in summary:
        lines.append(f"attitude error vs truth ({summary['frames_with_truth']} frames): median |pitch| "
                     f"{summary['median_abs_err_pitch_deg']:.3f} deg (p90 {summary['p90_abs_err_pitch_deg']:.3f}), "
                     f"median |roll| {summary['median_abs_err_roll_deg']:.3f} deg (p90 {summary['p90_abs_err_roll_deg']:.3f})")
    if summary["groups"]:
        lines.append(f"{'group':<16}{'matched':>8}{'med err':>9}{'med 1-sigma':>12}{'err<=2sigma':>12}  (sigma: sqrt trace of the cone covariance, attitude included)")
        for name, s in summary["groups"].items():
            lines.append(f"{name:<16}{s['n']:>8}{s['median_err_m']:>9.3f}{s['median_sigma_m']:>12.3f}{s['within_2sigma']:>12.2f}")
    return "\n".join(lines)



# -- IMU --------------------------------------------------------------------------------------------
def attitude_plot(path, stamps_ns: list[int], used: list[Attitude], truth: dict[int, tuple[float, float]] | None = None,
                  title: str = ""):
    """PNG of the attitude used per frame (pitch and roll, degrees, with its 1-sigma band) against
    time, and the true attitude where known (``stamp -> (pitch, roll)``). Returns the path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t0 = stamps_ns[0] if stamps_ns else 0
    t = (np.asarray(stamps_ns, dtype=np.float64) - t0) / 1e9
    fig, axes = plt.subplots(2, 1, figsize=(11, 6), sharex=True)
    for ax, k, name in ((axes[0], 0, "pitch (+ nose down)"), (axes[1], 1, "roll (+ right side down)")):
        v = np.array([(a.pitch_deg, a.roll_deg)[k] for a in used])
        sd = np.array([(a.sigma_pitch_deg, a.sigma_roll_deg)[k] for a in used])
        ax.fill_between(t, v - sd, v + sd, color="tab:blue", alpha=0.2, lw=0, label="used +- 1 sigma")
        ax.plot(t, v, color="tab:blue", lw=1.2, label="used")
        if truth:
            tt = [(s - t0) / 1e9 for s in stamps_ns if s in truth]
            ax.plot(tt, [truth[s][k] for s in stamps_ns if s in truth], color="k", lw=1, ls="--", label="true")
        hold = np.array([a.source == "hold" for a in used])
        if hold.any():
            ax.plot(t[hold], v[hold], "x", color="tab:red", ms=4, label="held (no fit)")
        ax.set_ylabel(f"{name}, deg")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    axes[1].set_xlabel("time, s")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
