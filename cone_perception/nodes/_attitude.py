"""The attitude parameters (``attitude``, ``imu_rest_deg``, ``box_model``: :mod:`cone_perception.params`), the
IMU subscription and the attitude's ``/diagnostics`` values shared by the ``mapping`` and ``pipeline`` nodes (the
logic is in :mod:`cone_perception.attitude`; the nodes publish ``cones/attitude`` themselves:
:meth:`~cone_perception.nodes._common.PerceptionNode.publish_attitude`).
"""

from __future__ import annotations

from collections.abc import Mapping

from sensor_msgs.msg import Imu

from ..attitude import ImageAttitudeConfig, ImuAttitude, QUAT_NORM_TOL
from ..attitude.box_files import attitude_config_for
from . import _msgs
from ..errors import ConfigError, FrameError
from ..resources import default_model_path
from ._params import declare

#: IMU in: best effort (IMU drivers publish so), a short queue (100 Hz and more).
IMU_QUEUE = 50


def declare_attitude(node) -> tuple[str, ImuAttitude | None]:
    """Declare ``attitude`` and ``imu_rest_deg``; subscribe ``imu`` for modes imu / fused.
    Returns ``(requested mode or "", ImuAttitude or None)``."""
    mode = str(declare(node, "attitude"))
    rest = [float(v) for v in declare(node, "imu_rest_deg")]  # two numbers: checked by its spec
    imu = None
    if mode in ("imu", "fused"):
        imu = ImuAttitude((rest[0], rest[1]))

        def on_imu(msg: Imu) -> None:
            q = msg.orientation
            before = imu.counts.as_dict()
            if not imu.add(_msgs.stamp_ns(msg.header), (q.x, q.y, q.z, q.w)):
                cause = next(k for k, v in imu.counts.as_dict().items() if v != before[k])
                raise FrameError(f"imu_{cause.removeprefix('dropped_')}",
                                 f"IMU message not used ({cause}; quaternion norm tolerance {QUAT_NORM_TOL})")

        node.create_subscription(Imu, "imu", node.guarded(on_imu, "imu", frames=False), IMU_QUEUE)
    return mode, imu


def declare_box_model(node, calib, model_path, far_model_path=None, far_box_model: str = "band"
                      ) -> tuple[ImageAttitudeConfig, str]:
    """Declare ``box_model``; the image fit's config reading the boxes of the model file ``model_path``
    (None: the shipped default) that way, and those of the far strip's model ``far_model_path`` (None: no strip,
    or the band's model in it) as ``far_box_model`` (the pipeline node's parameter) says, and the box model in words (``attitude:box_model`` on
    ``/diagnostics``)."""
    choice = str(declare(node, "box_model"))
    try:
        return attitude_config_for(choice, model_path or default_model_path(), far_model_path, calib.camera == "synth",
                                   far_box_model)
    except ValueError as e:
        raise ConfigError("parameter", "box_model", str(e)) from None


class AttitudeCountsView(Mapping):
    """The attitude estimator's counts as they are now (read at each ``/diagnostics``): the image fit's
    (``fitted``, ``too_few_cones``, ``rejected_beyond_limit``, ``used_calibration``: frames mapped with the
    calibration's H; ``size_cones`` / ``size_followed``: cones whose heights were averaged over frames / followed
    from an earlier frame) and, with an IMU, ``imu_*``."""

    def __init__(self, estimator) -> None:
        self.estimator = estimator

    def _now(self) -> dict[str, int]:
        est = self.estimator
        d = dict(est.counts.as_dict())
        imu = getattr(est, "imu", None)
        if imu is not None:
            d.update({f"imu_{k}": v for k, v in imu.counts.as_dict().items()})
        return d

    def __getitem__(self, key: str) -> int:
        return self._now()[key]

    def __iter__(self):
        return iter(self._now())

    def __len__(self) -> int:
        return len(self._now())


def report_attitude(node, mode: str, estimator, box_model: str) -> None:
    """Put the attitude on the node's ``/diagnostics``: ``attitude:mode``, ``attitude:box_model`` and, with an
    estimator, its counts (:class:`AttitudeCountsView`, e.g. ``attitude:used_calibration``)."""
    node.health.info["attitude:mode"] = mode
    node.health.info["attitude:box_model"] = box_model if estimator is not None else "none (attitude fixed)"
    if estimator is not None:
        node.health.watch("attitude", AttitudeCountsView(estimator))
