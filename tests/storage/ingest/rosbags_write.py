"""Writing small ROS 1 / ROS 2 bags for the import tests (rosbags' own writers, synthetic frames)."""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

W, H = 160, 120
K = (200.0, 0.0, 80.0, 0.0, 201.0, 60.0, 0.0, 0.0, 1.0)
D = [0.1, -0.05, 0.001, 0.002, 0.01]
T0 = 1_700_000_000


@dataclass
class BagSpec:
    kind: str = "ros1"  # ros1 | sqlite3 | mcap
    frames: int = 4
    colour: str = "rgb8"  # rgb8 | bgr8 | mono8 | jpeg | png | yuv422 (unsupported)
    depth: str | None = "16UC1"  # 16UC1 | 32FC1 | cd16 | cd32 (compressedDepth) | None
    info: bool = True
    gt: str | None = None  # pose | transform | tf
    rgb_topic: str = "/camera/rgb/image_raw"
    depth_topic: str = "/camera/depth_registered/image_raw"
    repeat_stamp: int | None = None  # this frame's colour image carries the previous frame's header stamp


def colour_frame(i: int) -> np.ndarray:
    """RGB uint8 (H, W, 3): a textured pattern shifted with the frame."""
    y, x = np.mgrid[0:H, 0:W]
    r = ((x * 3 + i * 5) % 256).astype(np.uint8)
    g = ((y * 4) % 256).astype(np.uint8)
    b = (((x // 8 + y // 8) % 2) * 200 + i).astype(np.uint8)
    return np.dstack([r, g, b])


def depth_frame(i: int) -> np.ndarray:
    """Metres, float32 (H, W): a ramp from 0.5 m to ~3 m, a 0 (invalid) corner."""
    y, x = np.mgrid[0:H, 0:W]
    d = (0.5 + 2.5 * x / W + 0.01 * i + 0.001 * y).astype(np.float32)
    d[:4, :4] = 0.0
    return d


def _stamp(ts: Any, i: int, offset_ns: int = 0) -> Any:
    ns = i * 33_333_333 + offset_ns
    return ts.types["builtin_interfaces/msg/Time"](sec=T0 + ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def _header(ts: Any, ros1: bool, i: int, frame: str = "camera", offset_ns: int = 0) -> Any:
    hdr = ts.types["std_msgs/msg/Header"]
    stamp = _stamp(ts, i, offset_ns)
    return hdr(seq=i, stamp=stamp, frame_id=frame) if ros1 else hdr(stamp=stamp, frame_id=frame)


def _colour_msg(ts: Any, ros1: bool, i: int, enc: str, stamp_of: int | None = None) -> tuple[str, Any]:
    rgb = colour_frame(i)
    i = i if stamp_of is None else stamp_of
    if enc in ("jpeg", "png"):
        ok, buf = cv2.imencode("." + ("jpg" if enc == "jpeg" else "png"), rgb[..., ::-1])
        assert ok
        msg = ts.types["sensor_msgs/msg/CompressedImage"](
            header=_header(ts, ros1, i), format=f"rgb8; {enc} compressed bgr8",
            data=np.frombuffer(buf.tobytes(), np.uint8))
        return "sensor_msgs/msg/CompressedImage", msg
    arr = {"rgb8": rgb, "bgr8": rgb[..., ::-1], "mono8": rgb[..., 1], "yuv422": rgb[..., :2]}[enc]
    arr = np.ascontiguousarray(arr)
    channels = 1 if arr.ndim == 2 else arr.shape[2]
    msg = ts.types["sensor_msgs/msg/Image"](header=_header(ts, ros1, i), height=H, width=W, encoding=enc,
                                            is_bigendian=0, step=W * channels, data=arr.reshape(-1).view(np.uint8))
    return "sensor_msgs/msg/Image", msg


def _depth_msg(ts: Any, ros1: bool, i: int, enc: str) -> tuple[str, Any]:
    metres = depth_frame(i)
    hdr = _header(ts, ros1, i, offset_ns=2_000_000)  # 2 ms after colour: associated by time
    if enc == "16UC1":
        mm = np.rint(metres * 1000).astype(np.uint16)
        return "sensor_msgs/msg/Image", ts.types["sensor_msgs/msg/Image"](
            header=hdr, height=H, width=W, encoding="16UC1", is_bigendian=0, step=W * 2,
            data=mm.reshape(-1).view(np.uint8))
    if enc == "32FC1":
        m = metres.copy()
        m[m == 0] = np.nan
        return "sensor_msgs/msg/Image", ts.types["sensor_msgs/msg/Image"](
            header=hdr, height=H, width=W, encoding="32FC1", is_bigendian=0, step=W * 4,
            data=m.reshape(-1).view(np.uint8))
    if enc == "cd16":
        mm = np.rint(metres * 1000).astype(np.uint16)
        ok, buf = cv2.imencode(".png", mm)
        data = struct.pack("<iff", 0, 0.0, 0.0) + buf.tobytes()
        fmt = "16UC1; compressedDepth png"
    else:  # cd32: compressed_depth_image_transport's inverse depth, depth_quantization 100, depth_max 10 m
        quant_a = np.float32(100.0 * (100.0 + 1.0))
        quant_b = np.float32(1.0 - quant_a / 10.0)
        inv = np.zeros_like(metres, dtype=np.uint16)
        valid = metres > 0
        inv[valid] = np.rint(quant_a / metres[valid] + quant_b).astype(np.uint16)
        ok, buf = cv2.imencode(".png", inv)
        data = struct.pack("<iff", 0, float(quant_a), float(quant_b)) + buf.tobytes()
        fmt = "32FC1; compressedDepth png"
    assert ok
    return "sensor_msgs/msg/CompressedImage", ts.types["sensor_msgs/msg/CompressedImage"](
        header=hdr, format=fmt, data=np.frombuffer(data, np.uint8))


def _info_msg(ts: Any, ros1: bool, i: int) -> Any:
    cls = ts.types["sensor_msgs/msg/CameraInfo"]
    roi = ts.types["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    arrays = {"D": np.array(D), "K": np.array(K), "R": np.eye(3).reshape(-1), "P": np.zeros(12)}
    if not ros1:
        arrays = {k.lower(): v for k, v in arrays.items()}
    return cls(header=_header(ts, ros1, i), height=H, width=W, distortion_model="plumb_bob", binning_x=0,
               binning_y=0, roi=roi, **arrays)


def gt_pose(i: int) -> tuple[list[float], list[float]]:
    return [0.01 * i, 0.02 * i, -0.005 * i], [0.0, 0.0, 0.0998334, 0.9950042]


def _gt_msg(ts: Any, ros1: bool, i: int, how: str) -> tuple[str, Any]:
    pos, quat = gt_pose(i)
    vec = ts.types["geometry_msgs/msg/Vector3"](x=pos[0], y=pos[1], z=pos[2])
    q = ts.types["geometry_msgs/msg/Quaternion"](x=quat[0], y=quat[1], z=quat[2], w=quat[3])
    if how == "pose":
        point = ts.types["geometry_msgs/msg/Point"](x=pos[0], y=pos[1], z=pos[2])
        pose = ts.types["geometry_msgs/msg/Pose"](position=point, orientation=q)
        return "geometry_msgs/msg/PoseStamped", ts.types["geometry_msgs/msg/PoseStamped"](
            header=_header(ts, ros1, i, "world"), pose=pose)
    tr = ts.types["geometry_msgs/msg/Transform"](translation=vec, rotation=q)
    stamped = ts.types["geometry_msgs/msg/TransformStamped"](header=_header(ts, ros1, i, "world"),
                                                              child_frame_id="camera", transform=tr)
    if how == "transform":
        return "geometry_msgs/msg/TransformStamped", stamped
    other = ts.types["geometry_msgs/msg/TransformStamped"](header=_header(ts, ros1, i, "odom"),
                                                            child_frame_id="base", transform=tr)
    return "tf2_msgs/msg/TFMessage", ts.types["tf2_msgs/msg/TFMessage"](transforms=[stamped, other])


def write_bag(path: Path, spec: BagSpec) -> Path:
    """Write the bag ``spec`` describes at ``path`` (a .bag file, a ROS 2 folder); returns the path to import."""
    from rosbags.typesys import Stores, get_typestore

    ros1 = spec.kind == "ros1"
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.LATEST)
    msgs: list[tuple[str, str, int, Any]] = []  # topic, type, time ns, message
    for i in range(spec.frames):
        t_ns = T0 * 1_000_000_000 + i * 33_333_333
        typ, msg = _colour_msg(ts, ros1, i, spec.colour, i - 1 if i == spec.repeat_stamp else None)
        msgs.append((spec.rgb_topic, typ, t_ns, msg))
        if spec.depth:
            typ, msg = _depth_msg(ts, ros1, i, spec.depth)
            msgs.append((spec.depth_topic, typ, t_ns + 2_000_000, msg))
        if spec.info:
            msgs.append(("/camera/rgb/camera_info", "sensor_msgs/msg/CameraInfo", t_ns, _info_msg(ts, ros1, i)))
        if spec.gt:
            typ, msg = _gt_msg(ts, ros1, i, spec.gt)
            msgs.append(({"tf": "/tf"}.get(spec.gt, "/groundtruth/pose"), typ, t_ns, msg))
    return _write(path, spec.kind, ts, msgs)


def _write(path: Path, kind: str, ts: Any, msgs: list[tuple[str, str, int, Any]]) -> Path:
    """Write ``msgs`` (topic, type, time ns, message; in time order) as a ``kind`` bag (ros1 | sqlite3 | mcap)."""
    if kind == "ros1":
        from rosbags.rosbag1 import Writer as Writer1

        with Writer1(path) as w1:
            conns: dict[str, Any] = {}
            for topic, typ, t_ns, msg in msgs:
                if topic not in conns:
                    conns[topic] = w1.add_connection(topic, typ, typestore=ts)
                w1.write(conns[topic], t_ns, ts.serialize_ros1(msg, typ))
        return path
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2

    plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
    with Writer2(path, version=9, storage_plugin=plugin) as w2:
        conns = {}
        for topic, typ, t_ns, msg in msgs:
            if topic not in conns:
                conns[topic] = w2.add_connection(topic, typ, typestore=ts)
            w2.write(conns[topic], t_ns, ts.serialize_cdr(msg, typ))
    return path


def folder_to_bag(src: Path, out: Path, n: int, depth_enc: str = "32FC1", kind: str = "ros1",
                  colour: str = "compressed") -> Path:
    """The first ``n`` colour frames of a TUM-layout folder (depth PNG at 5000/m, JPEG or PNG colour) as a ``kind``
    bag (ros1 | sqlite3 | mcap): colour as CompressedImage (the file's own bytes) or, with ``colour`` "rgb8", as a
    raw Image of the decoded pixels; depth as ``depth_enc`` Image, ground truth as PoseStamped on
    /groundtruth/pose; no CameraInfo (the caller's camera preset applies)."""
    from rosbags.typesys import Stores, get_typestore

    ros1 = kind == "ros1"
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.LATEST)
    types = ts.types

    def rows(name: str) -> list[list[str]]:
        return [line.split() for line in (src / name).read_text().splitlines() if line.strip()
                and not line.startswith("#")]

    def stamp(s: str) -> Any:
        sec, _, frac = s.partition(".")
        return types["builtin_interfaces/msg/Time"](sec=int(sec), nanosec=int((frac + "000000000")[:9]))

    def header(s: str, i: int, frame: str = "camera") -> Any:
        hdr = types["std_msgs/msg/Header"]
        return hdr(seq=i, stamp=stamp(s), frame_id=frame) if ros1 else hdr(stamp=stamp(s), frame_id=frame)

    def ns(s: str) -> int:
        st = stamp(s)
        return int(st.sec) * 1_000_000_000 + int(st.nanosec)

    rgb = rows("rgb.txt")[:n]
    t_end = float(rgb[-1][0]) + 0.1
    msgs: list[tuple[str, str, int, Any]] = []
    for i, (t, rel) in enumerate(rgb):
        if colour == "rgb8":
            pix = cv2.imread(str(src / rel), cv2.IMREAD_COLOR)
            assert pix is not None, rel
            pix = np.ascontiguousarray(pix[..., ::-1])
            msgs.append(("/camera/rgb/image_color", "sensor_msgs/msg/Image", ns(t), types["sensor_msgs/msg/Image"](
                header=header(t, i), height=pix.shape[0], width=pix.shape[1], encoding="rgb8", is_bigendian=0,
                step=pix.shape[1] * 3, data=pix.reshape(-1))))
            continue
        msgs.append(("/camera/rgb/image_color/compressed", "sensor_msgs/msg/CompressedImage", ns(t),
                     types["sensor_msgs/msg/CompressedImage"](header=header(t, i), format="bgr8; jpeg compressed bgr8",
                                                              data=np.frombuffer((src / rel).read_bytes(), np.uint8))))
    for i, (t, rel) in enumerate(r for r in rows("depth.txt") if float(r[0]) <= t_end):
        png = cv2.imread(str(src / rel), cv2.IMREAD_UNCHANGED)
        assert png is not None, rel
        h, w = png.shape
        if depth_enc == "32FC1":
            arr: np.ndarray = png.astype(np.float32) / np.float32(5000.0)
            arr[png == 0] = np.nan
        else:
            arr = np.rint(png / 5.0).astype(np.uint16)
        msgs.append(("/camera/depth/image", "sensor_msgs/msg/Image", ns(t), types["sensor_msgs/msg/Image"](
            header=header(t, i), height=h, width=w, encoding=depth_enc, is_bigendian=0, step=w * arr.itemsize,
            data=np.ascontiguousarray(arr).reshape(-1).view(np.uint8))))
    for i, g in enumerate(r for r in rows("groundtruth.txt") if float(r[0]) <= t_end):
        v = [float(x) for x in g[1:8]]
        pose = types["geometry_msgs/msg/Pose"](
            position=types["geometry_msgs/msg/Point"](x=v[0], y=v[1], z=v[2]),
            orientation=types["geometry_msgs/msg/Quaternion"](x=v[3], y=v[4], z=v[5], w=v[6]))
        msgs.append(("/groundtruth/pose", "geometry_msgs/msg/PoseStamped", ns(g[0]),
                     types["geometry_msgs/msg/PoseStamped"](header=header(g[0], i, "world"), pose=pose)))
    msgs.sort(key=lambda m: m[2])
    return _write(out, kind, ts, msgs)
