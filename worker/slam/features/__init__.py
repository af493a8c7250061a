"""ORB features with a scale pyramid, grid-balanced distribution and per-keypoint depth."""
from worker.slam.features.orb import OrbExtractor
from worker.slam.features.types import Features

__all__ = ["Features", "OrbExtractor"]
