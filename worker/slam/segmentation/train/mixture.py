"""The training sample stream: labelled images (hard + teacher labels) mixed with copy-paste composites on
unlabelled backgrounds (teacher labels + pasted masks). Each sample is a pure function of (seed, epoch, index)."""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import torch
from torch.utils.data import Dataset, Sampler

from worker.slam.io.images import read_rgb
from worker.slam.segmentation.train.augment import IGNORE, Cutout, color_jitter, paste, random_affine, soften, warp
from worker.slam.segmentation.train.config import TrainConfig
from worker.slam.segmentation.train.datasets import LabelledImage, semantic_mask


@dataclass(frozen=True)
class SoftSet:
    """Images with optional teacher probabilities ((N, h, w, K) uint8 on the teacher's grid, or None)."""

    images: list
    soft: np.ndarray | None


class MixtureDataset(Dataset):
    """Yields dicts: image (3, H, W) float in [0, 1], hard (H, W) int64 (255 = ignore), soft (K, H, W) float
    teacher probabilities and kd_mask (H, W) float (1 where a soft label exists)."""

    def __init__(self, cfg: TrainConfig, labelled: list[LabelledImage], labelled_soft: np.ndarray | None,
                 backgrounds: SoftSet, cutouts: list[Cutout], targets: SoftSet | None = None) -> None:
        self.cfg = cfg
        self.classes = cfg.model.classes
        self.out_hw = cfg.model.input_size
        self.labelled, self.labelled_soft = labelled, labelled_soft
        self.backgrounds, self.cutouts = backgrounds, cutouts
        self.people = [c for c in cutouts if c.label == self.classes.index("person")] if "person" in self.classes \
            else []
        self.chairs = [c for c in cutouts if c.label not in (0, self.classes.index("person"))] if cutouts else []
        self.distractors = [c for c in cutouts if c.label == 0]
        self.targets = targets if targets is not None and targets.images else None
        self.labelled_p = self._labelled_weights(cfg.person_free_weight)

    def _labelled_weights(self, person_free_weight: float) -> np.ndarray | None:
        """Sampling probabilities of the labelled images, or None for uniform (the draw older recipes made)."""
        if person_free_weight == 1.0 or not self.labelled:
            return None
        w = np.array([1.0 if "person" in item.labels else person_free_weight for item in self.labelled])
        return w / w.sum()

    def _pick_labelled(self, rng: np.random.Generator) -> int:
        if self.labelled_p is None:
            return int(rng.integers(len(self.labelled)))
        return int(rng.choice(len(self.labelled), p=self.labelled_p))

    def __len__(self) -> int:
        return self.cfg.samples_per_epoch

    def _soft(self, soft: np.ndarray | None, k: int, a: np.ndarray, src_hw: tuple[int, int]):
        if soft is None:
            return None
        grid = soft[k]
        scale = (src_hw[1] / grid.shape[1], src_hw[0] / grid.shape[0])
        return warp(np.ascontiguousarray(grid), a, self.out_hw, src_scale=scale)

    def _labelled(self, rng: np.random.Generator, k: int):
        item = self.labelled[k]
        rgb = read_rgb(item.image)
        a = random_affine(rng, rgb.shape[:2], self.out_hw, (0.8, 1.6))
        img = warp(rgb, a, self.out_hw)
        hard = warp(semantic_mask(item, self.classes), a, self.out_hw, nearest=True, border=IGNORE)
        if item.mask is not None and not item.partial:
            return img, hard, None, a  # an exact mask of every object (synthetic truth): nothing to distil
        soft = self._soft(self.labelled_soft, k, a, rgb.shape[:2])
        if item.partial and soft is not None:
            # Only the main subject is labelled: whatever else the teacher sees (a bystander, a car in a street
            # photo) is no certain background.
            hard[(hard == 0) & (soft[..., 0] < 128)] = IGNORE
        return img, hard, soft, a

    def _target(self, rng: np.random.Generator):
        """A target-domain frame with the teacher's labels (people kept): soft everywhere, hard where confident."""
        assert self.targets is not None, "called only when target-domain frames were given"
        k = int(rng.integers(len(self.targets.images)))
        rgb = read_rgb(self.targets.images[k])
        a = random_affine(rng, rgb.shape[:2], self.out_hw, self.cfg.target_scale)
        img = warp(rgb, a, self.out_hw)
        soft = self._soft(self.targets.soft, k, a, rgb.shape[:2])
        return img, self._confident(soft), soft

    def _confident(self, soft: np.ndarray) -> np.ndarray:
        hard = soft.argmax(-1).astype(np.uint8)
        hard[soft.max(-1) < self.cfg.target_confidence * 255] = IGNORE
        return hard

    def _composite(self, rng: np.random.Generator, pastes: bool = True):
        """A background frame with 0..max_pastes cut-outs; `pastes=False`: the frame alone (a hard negative)."""
        on_target = pastes and self.targets is not None and rng.random() < self.cfg.p_target_background
        source = self.targets if on_target else self.backgrounds
        assert source is not None, "backgrounds are always given"
        k = int(rng.integers(len(source.images)))
        rgb = read_rgb(source.images[k])
        a = random_affine(rng, rgb.shape[:2], self.out_hw, (1.0, 1.5))
        img = warp(rgb, a, self.out_hw)
        soft = self._soft(source.soft, k, a, rgb.shape[:2])
        if on_target:
            pass  # the teacher's people are real people here
        elif soft is None:
            soft = np.zeros((*self.out_hw, len(self.classes)), np.uint8)
            soft[..., 0] = 255
        elif "person" in self.classes:
            # Background frames contain no people: the teacher's person mass there is its error.
            p = self.classes.index("person")
            soft = soft.copy()
            soft[..., 0] = np.clip(soft[..., 0].astype(np.int32) + soft[..., p], 0, 255).astype(np.uint8)
            soft[..., p] = 0
        hard = self._confident(soft) if on_target else soft.argmax(-1).astype(np.uint8)
        for _ in range(int(rng.integers(0, self.cfg.max_pastes + 1)) if pastes else 0):
            if self.distractors and rng.random() < self.cfg.p_distractor_paste:
                cut = self.distractors[int(rng.integers(len(self.distractors)))]
                paste(rng, img, hard, soft, cut, self.cfg.distractor_height)
                continue
            use_chair = self.chairs and (not self.people or rng.random() < self.cfg.p_chair_paste)
            pool, frac = (self.chairs, self.cfg.chair_height) if use_chair else (self.people, self.cfg.person_height)
            if pool:
                paste(rng, img, hard, soft, pool[int(rng.integers(len(pool)))], frac)
        return img, hard, soft

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        # The sampler encodes the epoch in the index, so persistent workers need no state updates.
        epoch, index = divmod(index, len(self))
        rng = np.random.default_rng([self.cfg.seed, epoch, index])
        r = rng.random()
        p_target = self.cfg.p_target if self.targets is not None else 0.0
        target = r < p_target
        if target:
            img, hard, soft = self._target(rng)
        elif self.labelled and (not self.backgrounds.images or r < p_target + self.cfg.p_labelled):
            img, hard, soft, _ = self._labelled(rng, self._pick_labelled(rng))
        elif r < p_target + self.cfg.p_labelled + self.cfg.p_negative:
            img, hard, soft = self._composite(rng, pastes=False)
        else:
            img, hard, soft = self._composite(rng)
        if rng.random() < 0.5:
            img = soften(rng, img)
        elif rng.random() < 0.3:
            img = cv2.GaussianBlur(img, (3, 3), rng.uniform(0.3, 1.2))
        img = color_jitter(rng, img, self.cfg.target_jitter, channel_gain=0.12) if target else color_jitter(rng, img)
        k = len(self.classes)
        if soft is None:
            soft_t = torch.zeros(k, *self.out_hw)
            kd = torch.zeros(self.out_hw)
        else:
            soft_t = torch.from_numpy(soft).permute(2, 0, 1).float() / 255.0
            kd = (soft_t.sum(0) > 0.5).float()  # zero outside the warped image (border fill)
        return {
            "image": torch.from_numpy(img).permute(2, 0, 1).float() / 255.0,
            "hard": torch.from_numpy(hard.astype(np.int64)),
            "soft": soft_t,
            "kd_mask": kd,
        }


class EpochSampler(Sampler[int]):
    """Indices epoch * n + i for i in range(n); set `epoch` before each pass."""

    def __init__(self, n: int) -> None:
        self.n, self.epoch = n, 0

    def __len__(self) -> int:
        return self.n

    def __iter__(self):
        return iter(range(self.epoch * self.n, (self.epoch + 1) * self.n))
