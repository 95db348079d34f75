"""Fuzzing the nodes: random and structured malformed messages through their subscription callbacks.

Each target is a node built in-process (as ``ros2 run`` builds it, with the shipped calibration and
model) whose guarded subscription callbacks are called directly with messages from a seeded
generator: random fields, lying sizes, short data, header bombs (:mod:`cone_perception.data.hostile`),
bit-flipped and truncated JPEGs, bad ``camera_info`` (zero sizes, roi outside, huge binning),
PointCloud2 with wrong fields, steps and lengths, stamps jumping back and forth, and a few valid
messages among them. A message that raises out of the callback is a crash; every message must be
counted on its topic (ok + dropped, + the one image the detection node keeps for its first
``camera_info``). Used by ``cone-perception fuzz`` (:func:`run_fuzz`) and the bounded fuzz tests.
"""

from __future__ import annotations

from ..nodes._common import PerceptionNode  # noqa: I001 (sets DDS env first)

import argparse
import json
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable, Iterator

import cv2
import numpy as np
import rclpy
from rclpy.parameter import Parameter
from sensor_msgs.msg import CameraInfo, CompressedImage, Image, PointCloud2, PointField
from tqdm import tqdm

from ..adapter import DriverAdapter, bgr_to_yuyv
from ..data import hostile
from ..data.outfiles import print_written, refuse_existing
from ..errors import ConfigError, FrameError
from ..geometry.calib import DEFAULT_CAMERA, load_calibration, resolve_calibration_path
from ..imageheader import declared_size
from ..nodes import _msgs
from ..nodes.detection import DetectionNode
from ..nodes.driver_adapter import DriverAdapterNode
from ..nodes.mapping import MappingNode
from ..nodes.pipeline import PipelineNode
from ..records import BOX_DTYPE, boxes_from_arrays
from ..timing import rss_mb

U32 = 2**32 - 1
TARGETS = ("driver_adapter_raw", "driver_adapter_compressed", "detection", "mapping", "pipeline_raw",
           "pipeline_compressed")
#: Kinds of message whose time is reported apart: they must be refused from the header alone.
BOMB_KINDS = ("bomb",)




@dataclass
class TargetReport:
    """What one node did with the fuzz messages."""

    target: str
    messages: int = 0
    crashes: int = 0
    crash_examples: list[str] = field(default_factory=list)
    counted: int = 0  # messages counted on the node's topics (ok + dropped + put aside)
    ok: int = 0
    dropped: dict[str, int] = field(default_factory=dict)
    kinds: dict[str, int] = field(default_factory=dict)
    wall_s: float = 0.0
    max_ms: float = 0.0
    bomb_max_ms: float = 0.0
    bomb_p50_ms: float = 0.0
    bomb_p99_ms: float = 0.0
    bombs: int = 0
    rss_start_mb: float = 0.0
    rss_end_mb: float = 0.0
    rss_max_mb: float = 0.0

    @property
    def all_counted(self) -> bool:
        return self.counted == self.messages

    def line(self) -> str:
        causes = ", ".join(f"{k}={v}" for k, v in sorted(self.dropped.items(), key=lambda kv: -kv[1]))
        return (f"{self.target}: {self.messages} messages, {self.crashes} crashes, {self.counted} counted "
                f"({self.ok} ok, {sum(self.dropped.values())} dropped: {causes}); {self.wall_s:.1f} s, "
                f"max {self.max_ms:.1f} ms/message; {self.bombs} header bombs: median {self.bomb_p50_ms:.3f} ms, "
                f"p99 {self.bomb_p99_ms:.3f}, max {self.bomb_max_ms:.2f}; "
                f"RSS {self.rss_start_mb:.0f} -> {self.rss_end_mb:.0f} MB (max {self.rss_max_mb:.0f})")


# -- message generators: (rng) -> (message, kind) ----------------------------------------------------

def _stamp(msg, rng: np.random.Generator, state: dict) -> None:
    """Mostly increasing stamps at 30 Hz, sometimes backwards, repeated or wild."""
    r = rng.random()
    if r < 0.05:
        t = int(rng.integers(0, 2**31)) * 10**9 + int(rng.integers(0, 10**9))
    elif r < 0.08:
        t = state.get("t", 10**18)  # repeated
    elif r < 0.11:
        t = max(0, state.get("t", 10**18) - int(rng.integers(1, 10**10)))  # backwards
    else:
        t = state.get("t", 1_700_000_000 * 10**9) + 33_333_333 * int(rng.integers(1, 4))
    state["t"] = t
    msg.header.stamp.sec, msg.header.stamp.nanosec = min(t // 10**9, 2**31 - 1), t % 10**9
    if rng.random() < 0.05:
        msg.header.frame_id = "".join(chr(int(c)) for c in rng.integers(32, 0x2FFF, int(rng.integers(0, 40))))


def _rand_bytes(rng: np.random.Generator, hi: int = 4096) -> bytes:
    return rng.integers(0, 256, int(rng.integers(0, hi)), dtype=np.uint8).tobytes()


def _dim(rng: np.random.Generator, good: int) -> int:
    return int(rng.choice([0, 1, 2, 3, good - 1, good, good + 2, 65_535, 1 << 20, U32,
                           int(rng.integers(0, 5000))]))


class Generators:
    """Message generators for one calibration, with the few valid payloads made once."""

    def __init__(self, calib, seed: int) -> None:
        self.calib = calib
        self.W, self.H = calib.image_width, calib.image_height
        rng = np.random.default_rng(seed)
        bgr = rng.integers(0, 256, (self.H, self.W, 3), dtype=np.uint8)
        self.yuyv = bgr_to_yuyv(bgr).tobytes()
        self.jpeg = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, 80])[1].tobytes()
        self.band = DriverAdapter(calib.crop, self.W, self.H).from_raw("yuv422_yuy2", self.W, self.H, 2 * self.W, self.yuyv)
        self.state: dict = {}

    def raw_image(self, rng: np.random.Generator) -> tuple[Image, str]:
        msg = Image()
        _stamp(msg, rng, self.state)
        r = rng.random()
        if r < 0.01:
            kind = "valid"
            msg.width, msg.height, msg.encoding, msg.step = self.W, self.H, "yuv422_yuy2", 2 * self.W
            msg.data = self.yuyv
        elif r < 0.3:
            kind = "short_data"  # right sizes, data cut short
            msg.width, msg.height = self.W, self.H
            msg.encoding = str(rng.choice(["yuv422_yuy2", "bgr8", "rgb8", "yuyv"]))
            msg.step = int(rng.choice([2 * self.W, 3 * self.W, 0, U32]))
            msg.data = _rand_bytes(rng, 8192)
        else:
            kind = "random"
            msg.width, msg.height = _dim(rng, self.W), _dim(rng, self.H)
            msg.encoding = str(rng.choice(["yuv422_yuy2", "bgr8", "rgb8", "mono16", "", "YUYV", "bgr8\x00",
                                           "\u2603" * 3, "a" * 300]))
            msg.step = int(rng.choice([0, 1, msg.width, 2 * msg.width % (U32 + 1), 3 * msg.width % (U32 + 1), U32]))
            msg.is_bigendian = int(rng.integers(0, 2))
            msg.data = _rand_bytes(rng)
        return msg, kind

    def compressed(self, rng: np.random.Generator) -> tuple[CompressedImage, str]:
        msg = CompressedImage()
        _stamp(msg, rng, self.state)
        msg.format = str(rng.choice(["jpeg", "png", "", "bgr8; jpeg compressed bgr8", "\u2603"]))
        r = rng.random()
        if r < 0.01:
            kind, data = "valid", self.jpeg
        elif r < 0.25:
            kind = "bomb"
            w, h = int(rng.integers(self.W + 1, 100_001)), int(rng.integers(self.H + 1, 100_001))
            make = str(rng.choice(["png", "jpeg", "bmp", "pnm"]))
            if make == "jpeg":  # 16-bit sizes
                w, h = min(w, 65_535), min(h, 65_535)
            data = {"png": hostile.png_bomb, "jpeg": hostile.jpeg_with_size, "bmp": hostile.bmp_bomb,
                    "pnm": hostile.pnm_bomb}[make](w, h)
        elif r < 0.35:
            kind = "truncated"
            data = self.jpeg[: int(rng.integers(0, len(self.jpeg)))]
        elif r < 0.45:
            kind = "bitflip"
            arr = np.frombuffer(self.jpeg, np.uint8).copy()
            idx = rng.integers(0, arr.size, int(rng.integers(1, 50)))
            arr[idx] ^= rng.integers(1, 256, idx.size, dtype=np.uint8)
            data = arr.tobytes()
        elif r < 0.6:
            kind = "header"  # a real header of a format with sizes around the calibration's, no pixels
            w, h = _dim(rng, self.W) % 70_000, _dim(rng, self.H) % 70_000
            data = (hostile.png_bomb, hostile.bmp_bomb, hostile.pnm_bomb)[int(rng.integers(0, 3))](w, h)
        elif r < 0.7:
            kind = "magic"  # a known format's first bytes, then garbage
            head = [b"\xff\xd8\xff", b"\x89PNG\r\n\x1a\n", b"BM", b"P6", b"P7\n", b"RIFF\0\0\0\0WEBPVP8 ", b"II*\0"]
            data = head[int(rng.integers(0, len(head)))] + _rand_bytes(rng, 256)
        else:
            kind, data = "random", _rand_bytes(rng)
        msg.data = data
        return msg, kind

    def camera_info(self, rng: np.random.Generator) -> tuple[CameraInfo, str]:
        fields = self.calib.crop.camera_info_fields(self.W, self.H)
        msg = _msgs.camera_info(fields, Image().header)
        _stamp(msg, rng, self.state)
        r = rng.random()
        if r < 0.5:
            return msg, "valid"
        if r < 0.55:  # another valid band: the node builds at most a few networks
            ds = int(rng.choice([1, 2, 4]))
            msg.binning_x = msg.binning_y = ds
            msg.roi.y_offset, msg.roi.height = self.H - 144 * ds * 2, 144 * ds * 2
            return msg, "other_band"
        for name in rng.choice(["width", "height", "binning_x", "binning_y", "roi.x_offset", "roi.y_offset",
                                "roi.width", "roi.height"], int(rng.integers(1, 4)), replace=False):
            obj, attr = (msg.roi, name[4:]) if name.startswith("roi.") else (msg, name)
            setattr(obj, attr, int(rng.choice([0, 1, 3, 1000, 65_535, U32, int(rng.integers(0, 5000))])))
        return msg, "random"

    def cropped_image(self, rng: np.random.Generator) -> tuple[Image, str]:
        r = rng.random()
        if r < 0.02:
            msg = _msgs.bgr_image(self.band, Image().header)
            _stamp(msg, rng, self.state)
            return msg, "valid"
        msg, kind = self.raw_image(rng)
        if r < 0.3:  # the band's size, another encoding or step, short data
            msg.width, msg.height = self.calib.crop.out_width, self.calib.crop.out_height
            kind = "band_size"
        return msg, kind

    def boxes(self, rng: np.random.Generator) -> tuple[PointCloud2, str]:
        n = int(rng.integers(0, 50))
        b = rng.uniform(-1e4, 1e4, (n, 4))
        if n and rng.random() < 0.3:
            b.ravel()[rng.integers(0, b.size, 3)] = rng.choice([np.nan, np.inf, -np.inf, 1e38])
        cls = rng.integers(-5, 300, n)
        try:
            rec = boxes_from_arrays(b, rng.uniform(-1, 2, n), np.clip(cls, 0, 255))
        except Exception:  # noqa: BLE001 - what the generator cannot build becomes an empty cloud
            rec = np.zeros(0, BOX_DTYPE)
        msg = _msgs.boxes_msg(rec, Image().header)
        _stamp(msg, rng, self.state)
        r = rng.random()
        if r < 0.3:
            return msg, "values"
        if r < 0.45:
            msg.data = _rand_bytes(rng, 2048)
            return msg, "data"
        if r < 0.6:
            msg.point_step = int(rng.choice([0, 1, 4, 255, U32]))
            msg.row_step = int(rng.choice([0, U32, msg.row_step]))
            return msg, "steps"
        if r < 0.75:
            msg.width, msg.height = int(rng.choice([0, 1, U32])), int(rng.choice([0, 1, 2, U32]))
            return msg, "dims"
        fields = list(msg.fields)
        if fields:
            f = fields[int(rng.integers(0, len(fields)))]
            f.offset = int(rng.choice([0, 3, 255, U32]))
            f.datatype = int(rng.choice([0, 1, 7, 8, 9, 255]))
            f.count = int(rng.choice([0, 1, 2, U32]))
            f.name = str(rng.choice([f.name, "", "x", "\u2603"]))
        msg.fields = fields + ([PointField(name="u1", offset=0, datatype=7, count=1)] if rng.random() < 0.3 else [])
        msg.is_bigendian = bool(rng.random() < 0.2)
        msg.is_dense = bool(rng.random() < 0.5)
        return msg, "fields"


# -- targets -----------------------------------------------------------------------------------------

def _callback(node, msgtype) -> Callable:
    subs = [s for s in node.subscriptions if s.msg_type is msgtype and not s.raw]  # not the counting path
    if len(subs) != 1:
        raise RuntimeError(f"{node.get_name()}: expected one {msgtype.__name__} subscription, found {len(subs)}")
    return getattr(subs[0].callback, "message_only", subs[0].callback)


def build_target(name: str, context, gen: Generators, params: dict | None = None):
    """The node of target ``name`` and its feeds: [(callback, generator)] with the mix of messages."""
    overrides = [Parameter(k, value=v) for k, v in (params or {}).items()]
    if name.startswith(("driver_adapter", "pipeline")):
        transport = name.rsplit("_", 1)[1]
        cls = DriverAdapterNode if name.startswith("driver_adapter") else PipelineNode
        if cls is DriverAdapterNode:
            overrides = [p for p in overrides if p.name == "calibration"]
        node = cls(context=context, parameter_overrides=overrides + [Parameter("input_transport", value=transport)])
        if transport == "raw":
            return node, [(_callback(node, Image), gen.raw_image)]
        return node, [(_callback(node, CompressedImage), gen.compressed)]
    if name == "detection":
        node = DetectionNode(context=context, parameter_overrides=[p for p in overrides if p.name != "calibration"])
        return node, [(_callback(node, CameraInfo), gen.camera_info), (_callback(node, Image), gen.cropped_image)]
    if name == "mapping":
        node = MappingNode(context=context, parameter_overrides=[p for p in overrides if p.name == "calibration"])
        return node, [(_callback(node, PointCloud2), gen.boxes)]
    raise ValueError(f"unknown fuzz target {name!r}; known: {', '.join(TARGETS)}")


def fuzz_target(name: str, n: int, seed: int = 0, params: dict | None = None,
                progress: Callable[[Iterator, int], Iterator] | None = None) -> TargetReport:
    """Send ``n`` fuzz messages through the callbacks of a fresh node of target ``name``."""
    calib = load_calibration((params or {}).get("calibration", DEFAULT_CAMERA))
    gen = Generators(calib, seed)
    rng = np.random.default_rng(seed + 1)
    context = rclpy.Context()
    rclpy.init(context=context)
    rep = TargetReport(name)
    node = None
    try:
        node, feeds = build_target(name, context, gen, params)
        assert isinstance(node, PerceptionNode)
        rep.rss_start_mb = rep.rss_max_mb = rss_mb()
        steps = range(n) if progress is None else progress(range(n), n)
        bomb_ms = []
        t_start = time.perf_counter()
        for _ in steps:
            cb, make = feeds[int(rng.integers(0, len(feeds)))]
            msg, kind = make(rng)
            rep.kinds[kind] = rep.kinds.get(kind, 0) + 1
            t0 = time.perf_counter()
            try:
                cb(msg)
            except BaseException as e:  # noqa: BLE001 - what escapes the callback would end the node
                rep.crashes += 1
                if len(rep.crash_examples) < 5:
                    rep.crash_examples.append(f"{kind}: {type(e).__name__}: {e}")
            ms = (time.perf_counter() - t0) * 1e3
            rep.max_ms = max(rep.max_ms, ms)
            if kind in BOMB_KINDS:
                bomb_ms.append(ms)
            rep.messages += 1
            if rep.messages % 256 == 0:
                rep.rss_max_mb = max(rep.rss_max_mb, rss_mb())
        rep.wall_s = time.perf_counter() - t_start
        if bomb_ms:
            rep.bombs = len(bomb_ms)
            rep.bomb_p50_ms, rep.bomb_p99_ms, rep.bomb_max_ms = (float(v) for v in np.percentile(bomb_ms, [50, 99, 100]))
        rep.rss_end_mb = rss_mb()
        rep.rss_max_mb = max(rep.rss_max_mb, rep.rss_end_mb)
        pending = 1 if getattr(node, "pending", None) is not None else 0
        rep.counted = sum(s.received for s in node.health.streams.values())
        counted_outcome = sum(s.ok + s.dropped for s in node.health.streams.values()) + pending
        if counted_outcome != rep.counted:  # every message that arrived: ok, dropped or put aside
            rep.crash_examples.append(f"counts do not add up: {counted_outcome} ok+dropped vs {rep.counted} received")
            rep.crashes += 1
        rep.ok = sum(s.ok for s in node.health.streams.values())
        rep.dropped = dict(node.stats.dropped)
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.shutdown(context=context)
    return rep


def bomb_timings(calib_name: str = DEFAULT_CAMERA, repeat: int = 20) -> dict[str, dict[str, float]]:
    """The issue's header bombs through the driver adapter (the nodes' and tools' decode path):
    per bomb the worst time (ms) of ``repeat`` refusals and the RSS growth (MB)."""
    calib = load_calibration(calib_name)
    adapter = DriverAdapter(calib.crop, calib.image_width, calib.image_height)
    out = {}
    for name, make in sorted(hostile.BOMBS.items()):
        data, worst, before = make(), 0.0, rss_mb()
        for _ in range(repeat):
            t0 = time.perf_counter()
            try:
                adapter.from_compressed(data)
            except FrameError:
                pass
            worst = max(worst, (time.perf_counter() - t0) * 1e3)
        out[name] = {"bytes": len(data), "max_ms": worst, "rss_growth_mb": rss_mb() - before,
                     "declared": "x".join(str(v) for v in hostile_size(data))}
    return out


def hostile_size(data: bytes) -> tuple[int, int]:
    return declared_size(data)[1:]


def run_fuzz(args: argparse.Namespace) -> int:
    """``cone-perception fuzz`` (its options ``args``): every target fuzzed, its line and crashes printed, then the
    header bombs timed; exit 1 on any crash or uncounted message."""
    targets = list(TARGETS) if args.targets == "all" else [t.strip() for t in args.targets.split(",") if t.strip()]
    unknown = [t for t in targets if t not in TARGETS]
    if unknown:
        raise ConfigError("--targets", None, f"unknown {', '.join(unknown)}; known: {', '.join(TARGETS)}")
    if args.n <= 0:
        raise ConfigError("--n", None, f"must be > 0, got {args.n}")
    if args.json:
        refuse_existing([args.json], args.force, "fuzz")
    params = {}
    if args.calib:
        params["calibration"] = str(resolve_calibration_path(args.calib))
    if args.model:
        params["model"] = str(Path(args.model).resolve())
    reports, bad = [], 0
    for t in targets:
        prog = (lambda it, total, t=t: tqdm(it, total=total, desc=t, unit="msg", file=sys.stderr,
                                             disable=args.no_progress))
        rep = fuzz_target(t, args.n, args.seed, params, prog)
        reports.append(rep)
        print(rep.line())
        for ex in rep.crash_examples:
            print(f"  crash: {ex}")
        bad += rep.crashes + (0 if rep.all_counted else 1)
    bombs = bomb_timings(args.calib or "example_mainhoop")
    print("header bombs through the adapter (worst of 20):")
    for name, b in bombs.items():
        print(f"  {name}: {b['bytes']} bytes declaring {b['declared']} px: {b['max_ms']:.3f} ms, "
              f"RSS {b['rss_growth_mb']:+.1f} MB")
    total = sum(r.messages for r in reports)
    print(f"fuzz: {total} messages, {sum(r.crashes for r in reports)} crashes, "
          f"{sum(r.counted for r in reports)} counted" + ("" if not bad else "  FAILED"))
    if args.json:
        doc = {"n": args.n, "seed": args.seed, "targets": [asdict(r) for r in reports], "bombs": bombs}
        args.json.write_text(json.dumps(doc, indent=1))
        print_written([args.json], "fuzz")
    return 1 if bad else 0
