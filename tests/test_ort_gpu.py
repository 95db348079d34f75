"""ONNX Runtime on the car's GPU (docs/jetson.md, "Run it in the nodes"): with ``backend: onnx`` and ``device: cuda``
the session lists TensorRT first (its engine in fp16 with ``fp16``, cached), then CUDA, then the CPU, on the GPU the
device names; a GPU this ONNX Runtime cannot reach is refused naming ``device``, fp16 without TensorRT naming
``fp16``; the detector says where it runs. No GPU here: the wiring is checked against a stand-in ONNX Runtime
whose session reports the providers it was given, and the real CPU-only ONNX Runtime for the refusals."""

from __future__ import annotations

import sys
import types

import numpy as np
import pytest

from cone_perception.detector import Detector, default_model_path
from cone_perception.detector.backends import (CPU_PROVIDER, CUDA_PROVIDER, TRT_PROVIDER, OrtRunner, ort_providers,
                                               ort_session, trt_cache_dir)
from cone_perception.errors import ConfigError

from synthetic_cones import assert_same_cones, make_image


def test_cpu_asks_for_the_cpu_alone():
    assert ort_providers("cpu", False, [TRT_PROVIDER, CUDA_PROVIDER, CPU_PROVIDER], "m") == [CPU_PROVIDER]


def test_a_gpu_lists_tensorrt_then_cuda_then_the_cpu_on_its_device(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    got = ort_providers("cuda:1", True, [TRT_PROVIDER, CUDA_PROVIDER, CPU_PROVIDER], "m")
    (trt, trt_opts), (cuda, cuda_opts), cpu = got
    assert (trt, cuda, cpu) == (TRT_PROVIDER, CUDA_PROVIDER, CPU_PROVIDER)
    assert trt_opts["device_id"] == "1" and cuda_opts == {"device_id": "1"}
    assert trt_opts["trt_fp16_enable"] == "True" and trt_opts["trt_engine_cache_enable"] == "True"
    assert trt_opts["trt_engine_cache_path"] == str(tmp_path / "cone_perception" / "tensorrt") == str(trt_cache_dir())
    assert (tmp_path / "cone_perception" / "tensorrt").is_dir()  # made, so TensorRT can write its engines
    fp32 = ort_providers("cuda", False, [TRT_PROVIDER, CUDA_PROVIDER, CPU_PROVIDER], "m")
    assert fp32[0][1]["trt_fp16_enable"] == "False" and fp32[0][1]["device_id"] == "0"
    cuda_only = ort_providers("cuda", False, [CUDA_PROVIDER, CPU_PROVIDER], "m")
    assert cuda_only == [(CUDA_PROVIDER, {"device_id": "0"}), CPU_PROVIDER]


@pytest.mark.parametrize("device, fp16, available, field, words", [
    ("cuda", False, [CPU_PROVIDER], "device", "GPU provider"),
    ("cuda:x", False, [CUDA_PROVIDER, CPU_PROVIDER], "device", "cuda:N"),
    ("cuda", True, [CUDA_PROVIDER, CPU_PROVIDER], "fp16", "TensorrtExecutionProvider"),
])
def test_a_gpu_onnx_runtime_cannot_reach_is_refused_naming_the_parameter(device, fp16, available, field, words):
    with pytest.raises(ConfigError) as e:
        ort_providers(device, fp16, available, "models/m.pt")
    assert e.value.field == field and words in str(e.value) and "models/m.pt" in str(e.value)


class _FakeOrt(types.ModuleType):
    """A stand-in ``onnxruntime`` with TensorRT and CUDA: its session keeps the providers it is given and reports
    them as ONNX Runtime does (names; each one's options as strings)."""

    class GraphOptimizationLevel:
        ORT_ENABLE_ALL = 99

    class SessionOptions:
        def __init__(self):
            self.entries = {}

        def add_session_config_entry(self, key, value):
            self.entries[key] = value

    class InferenceSession:
        def __init__(self, model, sess_options=None, providers=()):
            self.providers = [p if isinstance(p, tuple) else (p, {}) for p in providers]

        def get_providers(self):
            return [name for name, _ in self.providers]

        def get_provider_options(self):
            return {name: dict(opts) for name, opts in self.providers}

        def get_inputs(self):
            return [types.SimpleNamespace(name="images", type="tensor(float)")]

        def run(self, outputs, feeds):
            assert feeds["images"].dtype == np.float32  # the graph's input type, whatever TensorRT computes in
            return [np.zeros((1, 9, 10), np.float32)]

    def __init__(self):
        super().__init__("onnxruntime")

    @staticmethod
    def get_available_providers():
        return [TRT_PROVIDER, CUDA_PROVIDER, CPU_PROVIDER]


def test_the_session_runs_tensorrt_fp16_first_and_the_runner_says_so(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.setitem(sys.modules, "onnxruntime", _FakeOrt())
    runner = OrtRunner(ort_session(b"graph", "cuda", 1, "m", fp16=True))
    assert runner.session.get_providers() == [TRT_PROVIDER, CUDA_PROVIDER, CPU_PROVIDER]
    assert runner.provider == TRT_PROVIDER and runner.fp16  # TensorRT's engine in fp16: the input stays float32
    assert runner(np.zeros((1, 3, 32, 32), np.float32)).shape == (9, 10)
    fp32 = OrtRunner(ort_session(b"graph", "cuda", 1, "m", fp16=False))
    assert fp32.provider == TRT_PROVIDER and not fp32.fp16
    cpu = OrtRunner(ort_session(b"graph", "cpu", 1, "m"))
    assert cpu.session.get_providers() == [CPU_PROVIDER] and not cpu.fp16


def test_the_detector_says_where_it_runs_and_a_cpu_only_runtime_refuses_a_gpu():
    import onnxruntime

    det = Detector.load(default_model_path(), backend="onnx")
    assert (det.runs_on, det.precision) == ("CPU", "fp32")
    assert Detector.load(default_model_path(), backend="torch").runs_on == "cpu"
    available = onnxruntime.get_available_providers()
    if TRT_PROVIDER in available or CUDA_PROVIDER in available:  # a GPU build of ONNX Runtime: it runs there
        gpu = Detector.load(default_model_path(), backend="onnx", device="cuda", fp16=TRT_PROVIDER in available)
        assert gpu.runs_on == ("TensorRT" if TRT_PROVIDER in available else "CUDA")
        img, _ = make_image(np.random.default_rng(3), 960, 288, 6)
        assert_same_cones(det, gpu, img, box_px=2.0, score_tol=0.05)  # fp16 moves boxes and scores a little
        return
    with pytest.raises(ConfigError) as e:  # not torch's "CUDA is not available": ONNX Runtime's providers decide
        Detector.load(default_model_path(), backend="onnx", device="cuda", fp16=True)
    assert e.value.field == "device" and "GPU provider" in str(e.value)
