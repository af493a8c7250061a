"""Which COCO classes the augmenter pastes as movers, and how big each is in the real world.

`--movers` takes comma-separated groups (`person`, `animal`, `vehicle`, `object`) or COCO class names
(`dog`, `suitcase`, `teddy bear`); the default, `person`, is the people the augmenter always pasted. A class
is pasted as a billboard standing on the floor, `height_m` tall (the range real instances span), so a cat is
a cat's size next to the real furniture whatever its size in the COCO photo.
"""
from __future__ import annotations

from dataclasses import dataclass

from formats.class_names import COCO_CLASSES
from worker.slam.errors import ConfigError

#: COCO-80 class names in YOLO id order (id = index).
COCO80 = COCO_CLASSES

PERSON = 0


@dataclass(frozen=True)
class MoverClass:
    """A COCO class that can be pasted: its YOLO id, group and real height range (metres)."""

    coco_id: int
    group: str
    height_m: tuple[float, float]

    @property
    def name(self) -> str:
        return COCO80[self.coco_id]


def _c(name: str, group: str, lo: float, hi: float) -> MoverClass:
    return MoverClass(COCO80.index(name), group, (lo, hi))


#: The classes that can be pasted; people keep the height range the augmenter always used.
MOVER_CLASSES: dict[str, MoverClass] = {m.name: m for m in (
    _c("person", "person", 1.6, 1.85),
    _c("bird", "animal", 0.15, 0.3), _c("cat", "animal", 0.25, 0.35), _c("dog", "animal", 0.4, 0.75),
    _c("horse", "animal", 1.5, 1.7), _c("sheep", "animal", 0.7, 0.9), _c("cow", "animal", 1.3, 1.5),
    _c("bicycle", "vehicle", 0.95, 1.1), _c("motorcycle", "vehicle", 1.05, 1.25), _c("car", "vehicle", 1.4, 1.55),
    _c("backpack", "object", 0.4, 0.5), _c("umbrella", "object", 0.8, 1.0), _c("handbag", "object", 0.25, 0.35),
    _c("suitcase", "object", 0.55, 0.75), _c("sports ball", "object", 0.2, 0.24),
    _c("skateboard", "object", 0.1, 0.14), _c("chair", "object", 0.8, 1.0), _c("teddy bear", "object", 0.3, 0.5),
)}

GROUPS = ("person", "animal", "vehicle", "object")
DEFAULT_MOVERS = "person"


def parse_movers(spec: str) -> tuple[MoverClass, ...]:
    """The classes of a `--movers` spec (comma-separated groups or class names), in COCO id order.
    Raises ConfigError naming the choices for an unknown word or an empty spec."""
    chosen: set[str] = set()
    for word in (w.strip().lower() for w in spec.split(",")):
        if not word:
            continue
        if word in GROUPS:
            chosen |= {m.name for m in MOVER_CLASSES.values() if m.group == word}
        elif word in MOVER_CLASSES:
            chosen.add(word)
        else:
            raise ConfigError(f"unknown mover {word!r}: use a group ({', '.join(GROUPS)}) or one of "
                              f"{', '.join(MOVER_CLASSES)}")
    if not chosen:
        raise ConfigError("--movers needs at least one group or class")
    return tuple(sorted((MOVER_CLASSES[n] for n in chosen), key=lambda m: m.coco_id))


def is_people_only(classes: tuple[MoverClass, ...]) -> bool:
    """True for the augmenter's original movers (people alone), whose outputs stay as they always were."""
    return tuple(m.coco_id for m in classes) == (PERSON,)
