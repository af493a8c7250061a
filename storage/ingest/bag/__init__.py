"""Importing a ROS recording (ROS 1 ``.bag``, ROS 2 ``.db3``/``.mcap`` file or bag folder) as a TUM-layout
sequence, without a ROS installation (the pure-Python ``rosbags`` reader).

Topics are found automatically (``sensor_msgs/Image`` or ``CompressedImage``: depth by encoding, then by name;
``CameraInfo`` nearest the colour topic) or named by the caller. Colour: raw ``rgb8``/``bgr8``/``rgba8``/
``bgra8``/``mono8`` (written as PNG) or compressed JPEG/PNG (written as received). Depth: raw ``16UC1``/``mono16``
(millimetres) or ``32FC1`` (metres), or ``compressedDepth`` (12-byte header + PNG), written as 16-bit PNG at
:data:`DEPTH_SCALE` units per metre (NaN, 0 and depths beyond the PNG's range become 0, invalid). Each image
keeps its header stamp; colour and depth are then paired by time as TUM's lists are. ``camera.json`` comes from
CameraInfo (fx fy cx cy, width, height, plumb_bob distortion k1 k2 p1 p2 k3), ``groundtruth.txt`` from an
optional PoseStamped / TransformStamped / tf topic.

Everything is written to a staging folder beside ``out``, checked as an upload is
(:func:`storage.ingest.sequence.validate_sequence`) and renamed into place: a bag that fails leaves nothing.
``rosbags``, numpy and OpenCV are imported when a bag is read, never when this package is.

Modules: :mod:`.sniff` (is it a bag), :mod:`.reader` (opening one), :mod:`.topics` (which topics to read),
:mod:`.decode` (messages to images, camera and poses), :mod:`.writer` (the staging folder's files),
:mod:`.convert` (the import itself).
"""

from storage.ingest.bag.convert import import_bag, import_uploaded_bag
from storage.ingest.bag.decode import DEPTH_SCALE
from storage.ingest.bag.sniff import MAGIC, find_bag_folder, is_ros1_bag, sniff_bag
from storage.ingest.bag.types import BagImport, BagLimits

__all__ = [
    "DEPTH_SCALE",
    "MAGIC",
    "BagImport",
    "BagLimits",
    "find_bag_folder",
    "import_bag",
    "import_uploaded_bag",
    "is_ros1_bag",
    "sniff_bag",
]
