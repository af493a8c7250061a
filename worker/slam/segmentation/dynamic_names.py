"""A job's potentially dynamic class names (`SegmenterConfig.dynamic_classes`): which names it may give, and
how they resolve against a segmenter's own classes (`classes.resolve_dynamic`, with COCO's spellings)."""
from __future__ import annotations

from formats.class_names import COCO_CLASSES
from worker.slam.segmentation.classes import COCO_TO_VOC, DYNAMIC_GROUPS, VOC_CLASSES, resolve_dynamic

#: Every name a job may list: a group, a VOC class or a COCO class (published for the api's check).
DYNAMIC_NAMES: tuple[str, ...] = tuple(dict.fromkeys((*DYNAMIC_GROUPS, *VOC_CLASSES[1:], *COCO_CLASSES)))


def resolve_for_segmenter(names: tuple[str, ...] | list[str], classes: tuple[str, ...]) -> tuple[str, ...]:
    """`resolve_dynamic` for a job's names: a COCO name the segmenter lacks but VOC has under its own name
    (`motorcycle`, `couch`, `tv`) means VOC's class; any other COCO class the segmenter lacks (`teddy bear` for a
    VOC model) is simply not covered, as a VOC class is. Unknown names are a ConfigError."""
    wanted = [n if n in classes or n in DYNAMIC_GROUPS else COCO_TO_VOC.get(n, n) for n in names]
    lacking = set(COCO_CLASSES) - set(VOC_CLASSES) - set(classes)
    return resolve_dynamic([n for n in wanted if n not in lacking], classes)
