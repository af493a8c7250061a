"""An RGB-D camera attached to this machine as a `vtdslam stream` source (`camera:INDEX`), through OpenCV's
OpenNI2 capture backends (Kinect, Asus Xtion, Orbbec Astra and other OpenNI2 devices).

OpenCV opens such a camera with ``cv2.VideoCapture(index, cv2.CAP_OPENNI2)`` (or its Asus / Astra variants); one
``grab()`` takes a synchronised pair, ``retrieve(None, cv2.CAP_OPENNI_DEPTH_MAP)`` gives the depth map (uint16,
millimetres) and ``retrieve(None, cv2.CAP_OPENNI_BGR_IMAGE)`` the colour image (BGR uint8). Depth is registered
to the colour camera (``CAP_OPENNI_DEPTH_GENERATOR_REGISTRATION``), so the colour camera's intrinsics hold for
both; the depth generator's focal length gives them when the user names no camera preset. A frame's timestamp is
this machine's clock when it was grabbed. Frames are sent as the camera gives them: colour as JPEG, depth as
16-bit PNG in millimetres (depth scale 1000).

The capture is made by an injected ``open_capture(index, api_preference)`` (``cv2.VideoCapture`` by default), so
tests drive the source with a fake camera.
"""
from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from storage.errors import InvalidInput

PREFIX = "camera:"
DEPTH_SCALE = 1000.0
"""OpenNI depth maps are in millimetres."""
JPEG_QUALITY = 95


class Capture(Protocol):
    """What the source uses of ``cv2.VideoCapture``."""

    def isOpened(self) -> bool: ...  # noqa: N802 - OpenCV's names
    def grab(self) -> bool: ...
    def retrieve(self, image: Any = None, flag: int = 0) -> tuple[bool, Any]: ...
    def get(self, prop: int) -> float: ...
    def set(self, prop: int, value: float) -> bool: ...
    def release(self) -> None: ...


OpenCapture = Callable[[int, int], Capture]
"""``(camera index, OpenCV API preference) -> capture`` (``cv2.VideoCapture``)."""


class CameraError(InvalidInput):
    """No camera, or one without the streams a live session needs."""


def camera_index(source: str) -> int | None:
    """The index of a ``camera:INDEX`` source; None for anything else (a folder or a bag)."""
    if not source.startswith(PREFIX):
        return None
    text = source[len(PREFIX):]
    if not text.isdigit():
        raise InvalidInput(f"{source!r}: a camera source is camera:INDEX with INDEX a number, e.g. camera:0")
    return int(text)


def _backends() -> list[tuple[str, int]]:
    import cv2

    return [("OpenNI2 (cv2.CAP_OPENNI2)", cv2.CAP_OPENNI2),
            ("OpenNI2 Asus (cv2.CAP_OPENNI2_ASUS)", cv2.CAP_OPENNI2_ASUS),
            ("OpenNI2 Astra (cv2.CAP_OPENNI2_ASTRA)", cv2.CAP_OPENNI2_ASTRA)]


def _video_capture(index: int, api: int) -> Capture:
    import cv2

    cap: Capture = cv2.VideoCapture(index, api)
    return cap


@dataclass
class RgbdCamera:
    """An opened camera that gave a depth map and a colour image of the same size."""

    cap: Capture
    index: int
    backend: str
    width: int
    height: int
    focal_px: float
    """The depth generator's focal length in pixels (0: unknown)."""

    def camera_spec(self) -> dict[str, float] | None:
        """Pinhole intrinsics for the session (principal point at the centre, no distortion), or None when the
        camera reports no focal length."""
        if not self.focal_px > 0:
            return None
        return {"fx": self.focal_px, "fy": self.focal_px, "cx": self.width / 2, "cy": self.height / 2,
                "depth_scale": DEPTH_SCALE, "width": self.width, "height": self.height}

    def frames(self, max_frames: int | None = None,
               clock: Callable[[], float] = time.time) -> Iterator[tuple[float, bytes, bytes]]:
        """(timestamp s, colour JPEG, depth PNG) of each frame the camera gives, until it stops giving them or
        `max_frames` were taken; timestamps strictly increase (the api refuses any other order)."""
        import cv2

        last = -np.inf
        n = 0
        while max_frames is None or n < max_frames:
            pair = _grab(self.cap)
            if pair is None:
                return
            t = max(clock(), last + 1e-6)
            bgr, depth = pair
            ok_c, rgb_bytes = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
            ok_d, depth_bytes = cv2.imencode(".png", depth)
            if not (ok_c and ok_d):
                raise CameraError(f"camera {self.index}: frame {n} could not be encoded")
            yield round(t, 6), rgb_bytes.tobytes(), depth_bytes.tobytes()
            last = round(t, 6)
            n += 1

    def close(self) -> None:
        self.cap.release()


def _grab(cap: Capture) -> tuple[np.ndarray, np.ndarray] | None:
    """One synchronised (BGR (H,W,3) uint8, depth (H,W) uint16 mm) pair, or None when the camera gave none."""
    import cv2

    if not cap.grab():
        return None
    ok_d, depth = cap.retrieve(None, cv2.CAP_OPENNI_DEPTH_MAP)
    ok_c, bgr = cap.retrieve(None, cv2.CAP_OPENNI_BGR_IMAGE)
    if not (ok_d and ok_c) or depth is None or bgr is None:
        return None
    return bgr, depth


def open_rgbd_camera(index: int, open_capture: OpenCapture | None = None) -> RgbdCamera:
    """Camera `index` through the first OpenNI2 backend that opens it, checked by grabbing one frame: a depth
    map (uint16, mm) and a colour image of the same size. Raises :class:`CameraError` saying what was tried."""
    import cv2

    open_capture = open_capture or _video_capture
    tried = []
    for name, api in _backends():
        cap = open_capture(index, api)
        if cap.isOpened():
            return _checked(cap, index, name)
        cap.release()
        tried.append(name)
    plain = open_capture(index, cv2.CAP_ANY)
    colour_only = plain.isOpened()
    plain.release()
    if colour_only:
        raise CameraError(f"camera {index} opens through OpenCV's default backend but has no depth stream: "
                          f"tried {', '.join(tried)}; a live session needs an RGB-D camera that OpenNI2 drives")
    raise CameraError(f"no camera at index {index}: tried {', '.join(tried)} and OpenCV's default backend "
                      "(is it attached, and is OpenCV built with OpenNI2? see cv2.getBuildInformation())")


def _checked(cap: Capture, index: int, backend: str) -> RgbdCamera:
    import cv2

    cap.set(cv2.CAP_OPENNI_DEPTH_GENERATOR_REGISTRATION, 1)  # depth in the colour camera's pixels
    try:
        if not cap.get(cv2.CAP_OPENNI_DEPTH_GENERATOR_PRESENT):
            raise CameraError(f"camera {index} opened through {backend} but has no depth generator "
                              "(cv2.CAP_OPENNI_DEPTH_GENERATOR_PRESENT is 0)")
        if not cap.grab():
            raise CameraError(f"camera {index} opened through {backend} but gives no frame")
        ok_d, depth = cap.retrieve(None, cv2.CAP_OPENNI_DEPTH_MAP)
        if not ok_d or depth is None or depth.ndim != 2 or depth.dtype != np.uint16:
            raise CameraError(f"camera {index} opened through {backend} but gives no depth map "
                              "(cv2.CAP_OPENNI_DEPTH_MAP: a uint16 image in millimetres)")
        ok_c, bgr = cap.retrieve(None, cv2.CAP_OPENNI_BGR_IMAGE)
        if not ok_c or bgr is None or bgr.ndim != 3 or bgr.shape[:2] != depth.shape:
            raise CameraError(f"camera {index} opened through {backend} but gives no colour image of the depth "
                              f"map's size {depth.shape[1]}x{depth.shape[0]} (cv2.CAP_OPENNI_BGR_IMAGE)")
    except CameraError:
        cap.release()
        raise
    focal = float(cap.get(cv2.CAP_OPENNI_DEPTH_GENERATOR_FOCAL_LENGTH) or 0.0)
    return RgbdCamera(cap, index, backend, depth.shape[1], depth.shape[0], focal)
