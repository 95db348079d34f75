"""rclpy message <-> core conversions (the only place message classes are built)."""

from __future__ import annotations

import numpy as np
from geometry_msgs.msg import Vector3Stamped
from sensor_msgs.msg import CameraInfo, Image, PointCloud2, PointField
from std_msgs.msg import Header
from visualization_msgs.msg import Marker, MarkerArray

from ..adapter import crop_raw_to_bgr, raw_frame_view
from ..attitude import attitude_vector
from ..classes import CLASS_RGBA, LARGE_ORANGE
from ..crop import CropSpec, camera_info_crop
from ..geometry import covariance_ellipses
from ..records import BOX_DTYPE, CONE_DTYPE, TRACKED_CONE_DTYPE, from_pointcloud2, to_pointcloud2

# FS cone sizes (m): small cones 228 mm base, 325 mm high; large orange 285 mm, 505 mm.
_CONE_DIAMETER_M = {LARGE_ORANGE: 0.285}
_CONE_HEIGHT_M = {LARGE_ORANGE: 0.505}


def copy_header(header: Header, frame_id: str | None = None) -> Header:
    h = Header()
    h.stamp = header.stamp
    h.frame_id = header.frame_id if frame_id is None else frame_id
    return h


def stamp_ns(header: Header) -> int:
    """Integer nanoseconds of a header's stamp."""
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def bgr_image(bgr: np.ndarray, header: Header) -> Image:
    """(h, w, 3) uint8 BGR -> sensor_msgs/Image bgr8 with the given header."""
    msg = Image()
    msg.header = header
    msg.height, msg.width = int(bgr.shape[0]), int(bgr.shape[1])
    msg.encoding = "bgr8"
    msg.is_bigendian = 0
    msg.step = msg.width * 3
    msg.data = np.ascontiguousarray(bgr).tobytes()
    return msg


def image_to_bgr(msg: Image) -> np.ndarray:
    """sensor_msgs/Image bgr8 -> (h, w, 3) view (used by detection on ``image_cropped``)."""
    name, view = raw_frame_view(msg.encoding, msg.width, msg.height, msg.step, msg.data)
    return crop_raw_to_bgr(name, view, CropSpec.full_image(msg.width, msg.height))


def camera_info(fields: dict, header: Header, camera_matrix: np.ndarray | None = None) -> CameraInfo:
    """CameraInfo for ``image_cropped``: full size, roi = crop, binning = downscale."""
    msg = CameraInfo()
    msg.header = header
    msg.width, msg.height = fields["width"], fields["height"]
    msg.binning_x, msg.binning_y = fields["binning_x"], fields["binning_y"]
    roi = fields["roi"]
    msg.roi.x_offset, msg.roi.y_offset = roi["x_offset"], roi["y_offset"]
    msg.roi.width, msg.roi.height = roi["width"], roi["height"]
    msg.roi.do_rectify = roi["do_rectify"]
    if camera_matrix is not None:
        msg.k = [float(x) for x in np.asarray(camera_matrix).ravel()]
    return msg


def crop_from_camera_info(msg: CameraInfo) -> CropSpec:
    """The validated crop of a ``camera_info`` (:func:`cone_perception.crop.camera_info_crop`;
    raises ``FrameError``)."""
    r = msg.roi
    return camera_info_crop(width=int(msg.width), height=int(msg.height), roi_x=int(r.x_offset),
                            roi_y=int(r.y_offset), roi_w=int(r.width), roi_h=int(r.height),
                            binning_x=int(msg.binning_x), binning_y=int(msg.binning_y))


def boxes_msg(records: np.ndarray, header: Header) -> PointCloud2:
    return to_pointcloud2(records.astype(BOX_DTYPE, copy=False), header, PointCloud2, PointField)


def boxes_from_msg(msg: PointCloud2) -> np.ndarray:
    return from_pointcloud2(msg, BOX_DTYPE)


def cones_msg(records: np.ndarray, header: Header) -> PointCloud2:
    return to_pointcloud2(records.astype(CONE_DTYPE, copy=False), header, PointCloud2, PointField)


def cones_from_msg(msg: PointCloud2) -> np.ndarray:
    return from_pointcloud2(msg, CONE_DTYPE)


def cone_markers(cones: np.ndarray, header: Header, ns: str = "cones") -> MarkerArray:
    """One coloured cylinder per cone, and (namespace ``<ns>_2sigma``) a flat disc of its 2-sigma
    position ellipse; a leading DELETEALL removes the previous frame's markers."""
    arr = MarkerArray()
    clear = Marker()
    clear.header = header
    clear.ns = ns
    clear.action = Marker.DELETEALL
    arr.markers.append(clear)
    for i, c in enumerate(cones):
        cid = int(c["class_id"])
        d = _CONE_DIAMETER_M.get(cid, 0.228)
        h = _CONE_HEIGHT_M.get(cid, 0.325)
        m = Marker()
        m.header = header
        m.ns = ns
        m.id = i
        m.type = Marker.CYLINDER
        m.action = Marker.ADD
        m.pose.position.x = float(c["x"])
        m.pose.position.y = float(c["y"])
        m.pose.position.z = h / 2.0
        m.pose.orientation.w = 1.0
        m.scale.x = m.scale.y = d
        m.scale.z = h
        r, g, b, a = CLASS_RGBA[cid]
        m.color.r, m.color.g, m.color.b, m.color.a = r, g, b, a
        arr.markers.append(m)
    major, minor, yaw = covariance_ellipses(cones, 2.0)
    for i, c in enumerate(cones):
        e = Marker()
        e.header = header
        e.ns = f"{ns}_2sigma"
        e.id = i
        e.type = Marker.CYLINDER
        e.action = Marker.ADD
        e.pose.position.x, e.pose.position.y, e.pose.position.z = float(c["x"]), float(c["y"]), 0.01
        e.pose.orientation.z, e.pose.orientation.w = float(np.sin(yaw[i] / 2)), float(np.cos(yaw[i] / 2))
        e.scale.x, e.scale.y, e.scale.z = max(float(major[i]), 0.01), max(float(minor[i]), 0.01), 0.02
        r, g, b, _ = CLASS_RGBA[int(c["class_id"])]
        e.color.r, e.color.g, e.color.b, e.color.a = r, g, b, 0.3
        arr.markers.append(e)
    return arr


def attitude_msg(att, header):
    """``geometry_msgs/Vector3Stamped`` of the attitude a frame was mapped with (x = roll, y = pitch, radians)."""
    m = Vector3Stamped()
    m.header = header
    m.vector.x, m.vector.y, m.vector.z = attitude_vector(att)
    return m


def tracked_msg(records: np.ndarray, header: Header) -> PointCloud2:
    """``TRACKED_CONE_DTYPE`` records -> ``/cones/tracked`` PointCloud2."""
    return to_pointcloud2(records.astype(TRACKED_CONE_DTYPE, copy=False), header, PointCloud2, PointField)


def tracked_from_msg(msg: PointCloud2) -> np.ndarray:
    return from_pointcloud2(msg, TRACKED_CONE_DTYPE)


def tracked_markers(tracked: np.ndarray, header: Header) -> MarkerArray:
    """Tracked cones as cylinders (marker id = track id) plus their id as text above each one."""
    arr = cone_markers(tracked, header, ns="tracked")
    for m, c in zip(arr.markers[1:], tracked):
        m.id = int(c["track_id"]) & 0x7FFFFFFF  # Marker.id is int32
    clear = Marker()
    clear.header, clear.ns, clear.action = header, "tracked_ids", Marker.DELETEALL
    arr.markers.append(clear)
    for c in tracked:
        t = Marker()
        t.header, t.ns, t.id = header, "tracked_ids", int(c["track_id"]) & 0x7FFFFFFF
        t.type, t.action = Marker.TEXT_VIEW_FACING, Marker.ADD
        t.pose.position.x, t.pose.position.y, t.pose.position.z = float(c["x"]), float(c["y"]), 0.7
        t.pose.orientation.w = 1.0
        t.scale.z = 0.3
        t.color.r = t.color.g = t.color.b = t.color.a = 1.0
        t.text = str(int(c["track_id"]))
        arr.markers.append(t)
    return arr
