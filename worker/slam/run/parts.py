"""The SLAM back end of a run, built once: sensor model, map, tracker, local mapper and loop closer."""
from __future__ import annotations

from dataclasses import dataclass

from worker.slam.camera import Camera
from worker.slam.config import PipelineConfig
from worker.slam.features.bow_database import KeyframeDatabase
from worker.slam.features.vocabulary import Vocabulary
from worker.slam.map.map import Map
from worker.slam.mapping.local_mapping import LocalMapper
from worker.slam.mapping.loop_closure import LoopCloser
from worker.slam.sensor import SensorModel
from worker.slam.tracking.tracker import Tracker


@dataclass(frozen=True)
class SlamParts:
    """One map and one sensor model, shared by the tracker, the local mapper and the loop closer."""

    sensor: SensorModel
    map: Map
    tracker: Tracker
    mapper: LocalMapper
    closer: LoopCloser | None
    """None when `loop.enabled` is off."""


def build_slam(camera: Camera, config: PipelineConfig) -> SlamParts:
    """Each part gets only its own config sections (the tracker: `tracking`, `features` and two numbers)."""
    sensor = SensorModel.build(camera, config.features, config.tracking)
    slam_map = Map()
    tracker = Tracker(sensor, slam_map, config.tracking, config.features, config.mapping.new_point_max_depth_m,
                      config.dense.stride)
    mapper = LocalMapper(slam_map, config.mapping, sensor, config.tracking.huber_px)
    vocab = Vocabulary.load(config.loop.vocabulary) if config.loop.vocabulary else Vocabulary.load()
    places = KeyframeDatabase(vocab)  # relocalisation and loop closure share the keyframes' vectors
    tracker.places = places
    closer = LoopCloser(slam_map, config.loop, sensor, places) if config.loop.enabled else None
    return SlamParts(sensor, slam_map, tracker, mapper, closer)
