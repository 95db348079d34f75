"""The figures of a soak (``cone-perception soak``, ROS-free): every frame sent accounted for by the
node's own counts, memory and latency over time, and the targets they are held to.

The node's counts come from its ``/diagnostics`` values (:mod:`cone_perception.stats`), taken once
before the first frame (``base``) and once after the last has been settled (``final``); the soak's
frames are the difference. ``uncounted`` = sent - (processed + dropped + replaced + missing + queued).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
from matplotlib.figure import Figure

#: RSS may grow by at most this share from the first window to the last.
RSS_GROWTH_LIMIT = 0.05


@dataclass
class SoakWindow:
    """One window of the run: ``t_s`` its end (s from the first frame)."""

    t_s: float
    sent: int = 0
    cones: int = 0  # /cones received for frames of this window's... arrival
    rss_mb: float = float("nan")
    latencies_ms: list = field(default_factory=list)

    def row(self, width_s: float) -> dict:
        lat = np.asarray(self.latencies_ms, dtype=float)
        return {"t_s": round(self.t_s, 1), "sent_per_s": self.sent / width_s, "cones_per_s": self.cones / width_s,
                "rss_mb": self.rss_mb, "latency_p50_ms": float(np.median(lat)) if lat.size else float("nan"),
                "latency_p99_ms": float(np.percentile(lat, 99)) if lat.size else float("nan")}


def stream_counts(values: dict[str, str], topic: str) -> dict[str, int]:
    """The counts of ``topic`` and the node's drops by cause from one ``/diagnostics`` status's values."""
    out = {}
    for k in ("received", "ok", "dropped", "arrived", "replaced", "queued", "missing", "lost", "silences"):
        out[k] = int(values.get(f"{topic}:{k}", 0))
    for k, v in values.items():
        if k.startswith("dropped_"):
            out[k] = int(v)
    return out


def _delta(final: dict[str, int], base: dict[str, int]) -> dict[str, int]:
    return {k: final.get(k, 0) - base.get(k, 0) for k in sorted(set(final) | set(base))}


def _window_stat(windows: list[SoakWindow], key: str, seconds: float, last: bool) -> float:
    """``key`` over the first (or last) ``seconds`` of windows: RSS median, latency p99 of all."""
    if not windows:
        return float("nan")
    t_end = windows[-1].t_s
    sel = [w for w in windows if (w.t_s > t_end - seconds if last else w.t_s <= windows[0].t_s + seconds - 1e-9)]
    if key == "rss_mb":
        vals = [w.rss_mb for w in sel if w.rss_mb == w.rss_mb]
        return float(np.median(vals)) if vals else float("nan")
    lat = [x for w in sel for x in w.latencies_ms]
    return float(np.percentile(lat, 99)) if lat else float("nan")


def summarize(sent: int, base: dict[str, str], final: dict[str, str], topic: str, windows: list[SoakWindow],
              window_s: float, rate_hz: float, seconds: float, wall_s: float, cones: int, died: int | None = None,
              compare_s: float | None = None) -> dict:
    """The soak's result: the accounting, the windows and the targets (``passed`` when all are met)."""
    d = _delta(stream_counts(final, topic), stream_counts(base, topic))
    drops = {k[len("dropped_"):]: v for k, v in d.items() if k.startswith("dropped_") and v}
    accounted = d["ok"] + sum(drops.values()) + d["replaced"] + d["missing"] + d["queued"]
    compare_s = compare_s or min(60.0, max(window_s, seconds / 4))
    rss0, rss1 = _window_stat(windows, "rss_mb", compare_s, False), _window_stat(windows, "rss_mb", compare_s, True)
    p99_0, p99_1 = _window_stat(windows, "lat", compare_s, False), _window_stat(windows, "lat", compare_s, True)
    growth = (rss1 - rss0) / rss0 if rss0 == rss0 and rss0 > 0 else float("nan")
    all_lat = [x for w in windows for x in w.latencies_ms]
    targets = {
        "uncounted_0": sent - accounted == 0,
        "rss_flat_5pct": abs(growth) <= RSS_GROWTH_LIMIT if growth == growth else False,
        "latency_p99_last_le_first": p99_1 <= p99_0 if p99_0 == p99_0 and p99_1 == p99_1 else False,
        "node_alive": died is None,
    }
    return {
        "topic": topic, "rate_hz": rate_hz, "seconds": seconds, "wall_s": wall_s,
        "sent": sent, "publish_rate_hz": sent / wall_s if wall_s > 0 else float("nan"),
        "processed": d["ok"], "dropped": drops, "replaced": d["replaced"], "missing": d["missing"],
        "queued": d["queued"], "uncounted": sent - accounted, "cones_received": cones,
        "node_received": d["received"], "node_arrived": d["arrived"], "middleware_lost": d["lost"],
        "processing_hz": d["ok"] / wall_s if wall_s > 0 else float("nan"),
        "rss_first_mb": rss0, "rss_last_mb": rss1, "rss_growth": growth, "compare_s": compare_s,
        "latency_p99_first_ms": p99_0, "latency_p99_last_ms": p99_1,
        "latency_p50_ms": float(np.median(all_lat)) if all_lat else float("nan"),
        "latency_p99_ms": float(np.percentile(all_lat, 99)) if all_lat else float("nan"),
        "windows": [w.row(window_s) for w in windows], "window_s": window_s,
        "died": died, "targets": targets, "passed": all(targets.values()),
    }


def format_report(r: dict, max_rows: int = 20) -> str:
    """The soak's table for the terminal and docs (markdown)."""
    drops = ", ".join(f"{k} {v}" for k, v in sorted(r["dropped"].items())) or "0"
    lines = [
        f"soak: {r['sent']} frames at {r['rate_hz']:g} Hz for {r['seconds']:g} s into {r['topic']} "
        f"(published {r['publish_rate_hz']:.1f} Hz over {r['wall_s']:.1f} s)",
        "",
        "| frames | count | share |",
        "|---|---:|---:|",
    ]
    for name, v in (("sent", r["sent"]), ("processed (/cones)", r["processed"]),
                    ("dropped by cause", sum(r["dropped"].values())), ("replaced in the queue", r["replaced"]),
                    ("missing (lost upstream)", r["missing"]), ("queued at the end", r["queued"]),
                    ("**uncounted**", r["uncounted"])):
        share = f"{100 * v / r['sent']:.1f} %" if r["sent"] else "-"
        lines.append(f"| {name} | {v} | {share} |")
    lines += ["", f"dropped by cause: {drops}; /cones received: {r['cones_received']}; "
                  f"processing {r['processing_hz']:.1f} frames/s; DDS-reported lost: {r['middleware_lost']}", ""]
    lines += ["| t (s) | sent/s | /cones/s | RSS (MiB) | latency p50 (ms) | p99 (ms) |", "|---:|---:|---:|---:|---:|---:|"]
    rows = r["windows"]
    step = max(1, -(-len(rows) // max_rows))
    for w in rows[step - 1::step] if len(rows) > max_rows else rows:
        lines.append(f"| {w['t_s']:.0f} | {w['sent_per_s']:.1f} | {w['cones_per_s']:.1f} | {w['rss_mb']:.0f} | "
                     f"{w['latency_p50_ms']:.0f} | {w['latency_p99_ms']:.0f} |")
    t = r["targets"]
    c = r["compare_s"]
    lines += ["",
              f"targets: uncounted 0: {_ok(t['uncounted_0'])} ({r['uncounted']}); "
              f"RSS flat within 5 %: {_ok(t['rss_flat_5pct'])} ({r['rss_first_mb']:.0f} -> {r['rss_last_mb']:.0f} MiB, "
              f"{100 * r['rss_growth']:+.1f} %, first vs last {c:g} s); "
              f"latency p99 last <= first: {_ok(t['latency_p99_last_le_first'])} "
              f"({r['latency_p99_first_ms']:.0f} -> {r['latency_p99_last_ms']:.0f} ms); "
              f"node alive: {_ok(t['node_alive'])}"]
    return "\n".join(lines)


def _ok(b: bool) -> str:
    return "yes" if b else "NO"


def plot(r: dict, path) -> None:
    """RSS, rates and latency over time (one PNG)."""
    w = r["windows"]
    t = [x["t_s"] for x in w]
    fig = Figure(figsize=(8, 7))
    ax = fig.subplots(3, 1, sharex=True)
    ax[0].plot(t, [x["sent_per_s"] for x in w], label="sent/s")
    ax[0].plot(t, [x["cones_per_s"] for x in w], label="/cones/s")
    ax[0].set_ylabel("frames/s")
    ax[0].legend(loc="lower right")
    ax[1].plot(t, [x["rss_mb"] for x in w])
    ax[1].set_ylabel("node RSS (MiB)")
    ax[2].plot(t, [x["latency_p50_ms"] for x in w], label="p50")
    ax[2].plot(t, [x["latency_p99_ms"] for x in w], label="p99")
    ax[2].set_ylabel("latency (ms)")
    ax[2].set_xlabel("s")
    ax[2].legend(loc="upper right")
    fig.suptitle(f"soak: {r['rate_hz']:g} Hz for {r['seconds']:g} s, {r['sent']} sent, {r['uncounted']} uncounted")
    fig.tight_layout()
    fig.savefig(path, dpi=90)


def to_json(r: dict) -> dict:
    return {k: (asdict(v) if hasattr(v, "__dataclass_fields__") else v) for k, v in r.items()}
