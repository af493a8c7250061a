"""Which frames' preview images a run keeps."""
from __future__ import annotations

import numpy as np


class PreviewPicker:
    """Keeps the preview images of a few frames spread over the run (bounded memory)."""

    def __init__(self, start: int, total: int, count: int = 6) -> None:
        """A run of `total` frames from frame index `start`; `count` frames wanted, evenly spaced."""
        step = max(1, total // (count + 1))
        self.wanted = {start + step * (i + 1) for i in range(count)}
        self.kept: dict[int, dict[str, np.ndarray]] = {}
        """RGB uint8 images by frame index, then by kind (e.g. 'rgb', 'classes', 'mask', 'restored')."""
        self.attached: dict[int, dict[str, np.ndarray]] = {}
        """Images of frames whose other previews come later (deferred work), merged into them by `keep`."""

    def wants(self, index: int) -> bool:
        """Whether a frame with previews at `index` would be kept."""
        return any(w <= index for w in self.wanted)

    def claim(self, index: int) -> bool:
        """Whether the previews of frame `index` are kept: the first frame with previews at or after each wanted
        index (frames claim in order; the images may come later, into `kept`)."""
        due = [w for w in self.wanted if w <= index]
        self.wanted -= set(due)
        return bool(due)

    def offer(self, index: int, images: dict[str, np.ndarray]) -> None:
        if self.claim(index):
            self.keep(index, images)

    def attach(self, index: int, images: dict[str, np.ndarray]) -> None:
        """Images of frame `index` to keep beside the previews a later `keep` of the same frame brings."""
        self.attached[index] = images

    def keep(self, index: int, images: dict[str, np.ndarray]) -> None:
        """Keep `images` of a claimed frame, with what was attached to it (the given images win a clash)."""
        merged = {**self.attached.pop(index, {}), **images}
        if merged:
            self.kept[index] = merged
