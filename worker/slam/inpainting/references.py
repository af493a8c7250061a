"""Reference-frame selection (paper 4.2): enough shared information with the target and enough motion."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.slam.config import valid
from worker.slam.features.matching import cross_checked
from worker.slam.geometry.se3 import pose_distance


@dataclass(frozen=True)
class ReferenceSelectionConfig:
    """How the reference library of a target frame is chosen."""

    window: int = valid(15, 1, 1_000, at_most="far_window")
    """Candidates are the frames up to `window` before (and, both-sided, after) the target."""
    far_window: int = valid(30, 1, 1_000)
    """Second-chance references come from frames farther than `window` but at most this far from the target."""
    far_refs: int = valid(2, 0, 16)
    """Up to this many second-chance references, chosen by the same tests among the far frames and placed after
    the near ones: a hole pixel takes the first references that see it (`blend_refs` of them), so they fill
    pixels no near reference sees (a person who lingers hides some background from every frame within +-15) and
    join the average only where a single near one does. Far frames warp worse (pose and colour/depth
    registration errors grow with the baseline), so they come second, never first. 0: none.
    Measured: docs/results/settings.md#restoration-far_refs"""
    min_match_ratio: float = valid(0.15, 0.0, 1.0)
    """Information test: ORB matches with the target / target's features."""
    min_translation_m: float = valid(0.01, 0.0001, 10.0)
    """Motion test τ: camera displacement to the target."""
    min_rotation_deg: float = valid(0.5, 0.0, 180.0)
    """Motion test γ: camera rotation to the target."""
    min_refs: int = valid(2, 1, 16, at_most="max_refs")
    max_refs: int = valid(4, 1, 16)
    candidate_stride: int = valid(2, 1, 100)
    """Only every n-th frame of the window is a candidate: neighbours see nearly the same background, and the
    information test (a brute-force match per candidate) dominated the stage's time at stride 1."""
    alternate_sides: bool = True
    """Both-sided: alternate the best past and the best future frame. A person walking across the view uncovers
    one side of the hole in earlier frames and the other side in later ones, so a past + future pair sees more
    of the hole than the two best-scored frames of one side."""
    min_gap_frames: int = valid(5, 0, 1_000)
    """References at least this many frames apart (as long as enough candidates are left): two neighbouring
    frames see nearly the same background, so the second would add little that the first does not."""
    max_target_descriptors: int = valid(256, 8, 100_000)
    """The information test matches at most this many of the target's descriptors (evenly picked): the
    matched fraction is an estimate, and the cost grows with target × candidate descriptors."""

    @property
    def reach(self) -> int:
        """How many frames on each side of the target may be references."""
        return self.far_window if self.far_refs else self.window


@dataclass(frozen=True)
class Candidate:
    """A frame that may serve as a reference: its index, pose T_WC (4x4) and ORB descriptors (M, 32) uint8."""

    index: int
    T_WC: np.ndarray
    descriptors: np.ndarray | None


@dataclass(frozen=True)
class Selection:
    indices: list[int]
    match_ratio: dict[int, float]
    relaxed: bool
    """True when fewer than `min_refs` passed both tests and the best informative frames were taken anyway."""
    far: tuple[int, ...] = ()
    """The second-chance references among `indices` (they come last)."""


def match_ratio(desc_target: np.ndarray | None, desc_cand: np.ndarray | None,
                max_target: int | None = None) -> float:
    """Cross-checked Hamming matches / target features (the paper's information estimate), from at most
    `max_target` of the target's descriptors."""
    if desc_target is None or desc_cand is None or len(desc_target) == 0 or len(desc_cand) == 0:
        return 0.0
    if max_target is not None and len(desc_target) > max_target:
        desc_target = desc_target[np.linspace(0, len(desc_target) - 1, max_target).astype(int)]
    return len(cross_checked(desc_target, desc_cand, 63)[0]) / len(desc_target)


def select_references(target: Candidate, candidates: list[Candidate],
                      config: ReferenceSelectionConfig = ReferenceSelectionConfig(),
                      both_sided: bool = False) -> Selection:
    """Pick 2-4 references: informative (match ratio) and displaced (Δp > τ and Δθ > γ), best score first;
    from the `window` frames before the target, and after it too when `both_sided`; then up to `far_refs`
    second-chance references the same way from the frames beyond `window` up to `far_window`, after the others.

    Score = match ratio × (1 + translation / τ): shared content matters, and more baseline shows more of the
    background behind a moving object.
    """
    near = [c for c in candidates if abs(c.index - target.index) <= config.window]
    chosen, ratios, relaxed = _choose(target, near, config, config.max_refs, config.min_refs, both_sided)
    far: list[int] = []
    if config.far_refs:
        rest = [c for c in candidates if config.window < abs(c.index - target.index) <= config.far_window]
        far, far_ratios, _ = _choose(target, rest, config, config.far_refs, min(config.min_refs, config.far_refs),
                                     both_sided)
        ratios |= far_ratios
    return Selection(chosen + far, ratios, relaxed, tuple(far))


def _choose(target: Candidate, candidates: list[Candidate], config: ReferenceSelectionConfig, max_refs: int,
            min_refs: int, both_sided: bool) -> tuple[list[int], dict[int, float], bool]:
    """`select_references`' choice among `candidates` (past ones, and future ones when `both_sided`): the indices,
    their match ratios and whether the tests were relaxed."""
    scored = []
    for c in candidates:
        if c.index == target.index or (c.index > target.index and not both_sided) \
                or (target.index - c.index) % config.candidate_stride:
            continue
        ratio = match_ratio(target.descriptors, c.descriptors, config.max_target_descriptors)
        if ratio < config.min_match_ratio:
            continue
        dt, dr_rad = pose_distance(target.T_WC, c.T_WC)
        dr = np.degrees(dr_rad)
        moved = dt >= config.min_translation_m and dr >= config.min_rotation_deg
        scored.append((moved, ratio * (1 + dt / config.min_translation_m), c.index, ratio))
    scored.sort(key=lambda s: (s[0], s[1]), reverse=True)
    passing = [s for s in scored if s[0]]
    relaxed = len(passing) < min_refs
    pool = scored if relaxed else passing
    if both_sided and config.alternate_sides:
        pool = _alternate([s for s in pool if s[2] < target.index], [s for s in pool if s[2] > target.index])
    chosen: list[tuple[bool, float, int, float]] = []
    for cand in pool:  # spread out first, then fill up with the rest in score order
        if len(chosen) < max_refs and all(abs(cand[2] - c[2]) >= config.min_gap_frames for c in chosen):
            chosen.append(cand)
    for cand in pool:
        if len(chosen) < min_refs and cand not in chosen:
            chosen.append(cand)
    return [s[2] for s in chosen], {s[2]: s[3] for s in chosen}, relaxed


def _alternate(a: list, b: list) -> list:
    """Interleave two best-first lists, starting with the better head: [a0, b0, a1, b1, ...] + the rest."""
    if b and (not a or (b[0][0], b[0][1]) > (a[0][0], a[0][1])):
        a, b = b, a
    out = [x for pair in zip(a, b) for x in pair]
    n = min(len(a), len(b))
    return out + a[n:] + b[n:]
