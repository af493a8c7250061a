"""The class vocabulary of the segmenters: PASCAL VOC's 20 object classes (the teacher's), how COCO's 80 map onto
them, and which of them are potentially dynamic by default.

A job names its potentially dynamic classes by class name or by group (`person`, `animal`, `vehicle`,
`object`); `resolve_dynamic` turns such a list into the names a given segmenter knows.
"""
from __future__ import annotations

from types import MappingProxyType

from formats.class_names import VOC_CLASSES
from worker.slam.errors import ConfigError

__all__ = ["COCO_TO_VOC", "DEFAULT_DYNAMIC", "DEFAULT_GROUPS", "DYNAMIC_GROUPS", "VOC_CLASSES", "resolve_dynamic"]

#: COCO-80 name -> VOC name, for the COCO classes VOC has (the other 60 count as background).
COCO_TO_VOC = MappingProxyType({
    "person": "person", "bicycle": "bicycle", "car": "car", "motorcycle": "motorbike", "airplane": "aeroplane",
    "bus": "bus", "train": "train", "boat": "boat", "bird": "bird", "cat": "cat", "dog": "dog", "horse": "horse",
    "sheep": "sheep", "cow": "cow", "bottle": "bottle", "chair": "chair", "couch": "sofa",
    "potted plant": "pottedplant", "dining table": "diningtable", "tv": "tvmonitor",
})

#: Groups of potentially dynamic classes: what moves by itself, is ridden or driven, or is moved by people.
DYNAMIC_GROUPS = MappingProxyType({
    "person": ("person",),
    "animal": ("bird", "cat", "cow", "dog", "horse", "sheep"),
    "vehicle": ("aeroplane", "bicycle", "boat", "bus", "car", "motorbike", "train"),
    "object": ("chair",),
})

#: The groups a multi-class segmenter marks potentially dynamic by default: people, animals and vehicles. Chairs
#: (`object`) are opt-in: mostly parked, and culling does not yet keep the features of a marked object that stays
#: put, so marking them cost the static scene its chairs' features (augmented 7-Scenes seeds 0-7 `no-restoration`
#: 0.0345 m with them, 0.0259 without; the people-free kitchen 1.52 % marked, all chairs, against 0.00 %; Bonn and
#: the synthetic rooms unchanged; docs/results/dynamic.md, 2026-12-06). Bottles, tables, sofas, plants and screens
#: are static furniture for SLAM (moved rarely, and then not while filmed).
DEFAULT_GROUPS: tuple[str, ...] = ("person", "animal", "vehicle")
DEFAULT_DYNAMIC: tuple[str, ...] = tuple(c for group in DEFAULT_GROUPS for c in DYNAMIC_GROUPS[group])


def resolve_dynamic(names: tuple[str, ...] | list[str], classes: tuple[str, ...]) -> tuple[str, ...]:
    """Class names and group names -> the class names among `classes` they cover, in `classes` order.

    An unknown name (neither a group nor any known class) is a ConfigError; a known class the segmenter lacks
    (e.g. `car` for a person-only checkpoint) is simply not covered."""
    known = set(VOC_CLASSES) | set(classes)
    wanted: set[str] = set()
    for name in names:
        if name in DYNAMIC_GROUPS:
            wanted.update(DYNAMIC_GROUPS[name])
        elif name in known:
            wanted.add(name)
        else:
            raise ConfigError(f"unknown potentially dynamic class {name!r}",
                              detail={"groups": list(DYNAMIC_GROUPS), "classes": list(classes)})
    return tuple(c for c in classes if c in wanted and c != "background")
