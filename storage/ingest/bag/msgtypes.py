"""The ROS message types and image encodings a bag import reads."""

from __future__ import annotations

IMAGE = "sensor_msgs/msg/Image"
COMPRESSED = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
TRANSFORM_STAMPED = "geometry_msgs/msg/TransformStamped"
TF = "tf2_msgs/msg/TFMessage"
TF_OLD = "tf/msg/tfMessage"
GT_TYPES = (POSE_STAMPED, TRANSFORM_STAMPED, TF, TF_OLD)
IMAGE_TYPES = (IMAGE, COMPRESSED)
COLOUR_ENCODINGS = ("rgb8", "bgr8", "rgba8", "bgra8", "mono8", "8uc1", "8uc3", "8uc4")
DEPTH_ENCODINGS = ("16uc1", "mono16", "32fc1")
