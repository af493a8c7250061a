"""Ground truth of a dynamic sequence (which pixels move, what lies behind them) and the scores that use it.

Layout inside a sequence folder (written by the synthetic and augmented-real generators)::

    truth/truth.json                 {"version": 1, "frames": N, "timestamps": [...], "depth_scale": s,
                                      "mask": "masks/{index:06d}.png", "background_rgb": "...",
                                      "background_depth": "...", "objects": [{"id", "class"}], "generator": {...}}
    truth/masks/000000.png           uint8 instance ids: 0 = static, k > 0 = dynamic object k (see "objects")
    truth/background_rgb/000000.png  colour of the static scene alone (8-bit; PNG, or the source JPEG's bytes)
    truth/background_depth/000000.png  uint16 depth of the static scene alone, value / depth_scale = metres

`index` is the frame's position in the sequence (the order of `rgb.txt`, which the generators write 1:1 with
`depth.txt`); `timestamps` repeat those of `rgb.txt` so a reader can check the pairing. By construction the
frame equals the background wherever the mask is 0, in colour and in depth (the background depth carries the
same simulated sensor noise and holes as the frame): it is what a perfect restoration would give.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from worker.slam.errors import SequenceFormatError

TRUTH_DIR = "truth"
TRUTH_FILE = "truth.json"
TRUTH_VERSION = 1


@dataclass(frozen=True)
class TruthFrame:
    """One frame's truth: `ids` uint8 (H, W) instance ids, `background_rgb` RGB uint8 (H, W, 3),
    `background_depth` float32 metres (H, W), 0 = invalid."""

    index: int
    ids: np.ndarray
    background_rgb: np.ndarray
    background_depth: np.ndarray

    @property
    def mask(self) -> np.ndarray:
        """bool (H, W): True where a dynamic object is visible."""
        return self.ids > 0


@dataclass(frozen=True)
class TruthLayout:
    """The contents of `truth/truth.json`; path templates are relative to the `truth/` folder."""

    frames: int
    timestamps: list[float]
    depth_scale: float
    mask: str = "masks/{index:06d}.png"
    background_rgb: str = "background_rgb/{index:06d}.png"
    background_depth: str = "background_depth/{index:06d}.png"
    objects: list[dict] = field(default_factory=list)
    generator: dict = field(default_factory=dict)
    version: int = TRUTH_VERSION

    def to_dict(self) -> dict:
        return {"version": self.version, "frames": self.frames, "timestamps": self.timestamps,
                "depth_scale": self.depth_scale, "mask": self.mask, "background_rgb": self.background_rgb,
                "background_depth": self.background_depth, "objects": self.objects, "generator": self.generator}


class Truth:
    """Lazy reader of a sequence's truth; files are decoded only when a frame is asked for."""

    def __init__(self, seq_root: Path | str, layout: TruthLayout) -> None:
        self.root = Path(seq_root) / TRUTH_DIR
        self.layout = layout

    def __len__(self) -> int:
        return self.layout.frames

    @property
    def timestamps(self) -> np.ndarray:
        return np.asarray(self.layout.timestamps, dtype=np.float64)

    def path(self, kind: str, index: int) -> Path:
        """Path of `kind` ("mask", "background_rgb", "background_depth") for frame `index`."""
        if not 0 <= index < len(self):
            raise IndexError(index)
        return self.root / getattr(self.layout, kind).format(index=index)

    def ids(self, index: int) -> np.ndarray:
        """uint8 (H, W) instance ids, 0 = static."""
        import cv2

        path = self.path("mask", index)
        img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED) if path.is_file() else None
        if img is None:
            raise SequenceFormatError("truth mask is missing or not an image", path=path)
        if img.ndim != 2 or img.dtype != np.uint8:
            raise SequenceFormatError("truth mask must be a single-channel 8-bit image", path=path)
        return img

    def mask(self, index: int) -> np.ndarray:
        """bool (H, W): True where a dynamic object is visible."""
        return self.ids(index) > 0

    def background_rgb(self, index: int) -> np.ndarray:
        """RGB uint8 (H, W, 3) of the static scene alone."""
        from worker.slam.io.images import read_rgb

        return read_rgb(self.path("background_rgb", index))

    def background_depth(self, index: int) -> np.ndarray:
        """float32 metres (H, W) of the static scene alone, 0 = invalid."""
        from worker.slam.io.images import read_depth

        return read_depth(self.path("background_depth", index), self.layout.depth_scale)

    def __getitem__(self, index: int) -> TruthFrame:
        return TruthFrame(index, self.ids(index), self.background_rgb(index), self.background_depth(index))


def load_truth(seq_root: Path | str) -> Truth | None:
    """The truth of a sequence folder, or None when it has none (a real, unlabelled sequence)."""
    path = Path(seq_root) / TRUTH_DIR / TRUTH_FILE
    if not path.is_file():
        return None
    try:
        d = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise SequenceFormatError(f"not valid JSON: {exc}", path=path) from None
    if d.get("version") != TRUTH_VERSION:
        raise SequenceFormatError(f"unsupported truth version {d.get('version')!r}", path=path)
    try:
        layout = TruthLayout(**d)
    except TypeError as exc:
        raise SequenceFormatError(f"invalid truth description: {exc}", path=path) from None
    if len(layout.timestamps) != layout.frames:
        raise SequenceFormatError("timestamps and frames disagree", path=path)
    return Truth(seq_root, layout)


def write_truth_json(seq_root: Path | str, layout: TruthLayout) -> Path:
    """Write `truth/truth.json` last, atomically, so a half-written truth is never loaded."""
    path = Path(seq_root) / TRUTH_DIR / TRUTH_FILE
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".part")
    tmp.write_text(json.dumps(layout.to_dict(), indent=1))
    tmp.replace(path)
    return path


def write_background_sequence(seq_root: Path | str, out: Path | str) -> Path:
    """A sequence folder `out` whose frames are `seq_root`'s truth backgrounds (the same frames without the
    dynamic objects), with its timestamps, `groundtruth.txt` and `camera.json`, and its `truth/` linked (the
    masks still say where the objects were). For references: the ATE without people, and with their pixels
    cut out. Raises SequenceFormatError when `seq_root` has no truth."""
    seq_root, out = Path(seq_root), Path(out)
    truth = load_truth(seq_root)
    if truth is None:
        raise SequenceFormatError("no truth to take the background frames from", path=seq_root / TRUTH_DIR)
    out.mkdir(parents=True, exist_ok=True)
    (out / TRUTH_DIR).symlink_to(truth.root.resolve(), target_is_directory=True)
    for name in ("groundtruth.txt", "camera.json"):
        if (seq_root / name).is_file():
            (out / name).write_bytes((seq_root / name).read_bytes())
    for kind, listing in (("background_rgb", "rgb.txt"), ("background_depth", "depth.txt")):
        lines = [f"{t:.6f} {TRUTH_DIR}/{getattr(truth.layout, kind).format(index=i)}"
                 for i, t in enumerate(truth.layout.timestamps)]
        (out / listing).write_text("# the truth's background frames\n" + "\n".join(lines) + "\n")
    return out


# ---- scores used by the evaluation of the dynamic stages ----------------------------------------------------

def mask_iou(pred: np.ndarray, truth: np.ndarray) -> float:
    """IoU of two bool (H, W) masks; 1.0 when both are empty (nothing to find, nothing found)."""
    if pred.shape != truth.shape:
        raise ValueError(f"mask shapes differ: {pred.shape} vs {truth.shape}")
    p, t = pred.astype(bool), truth.astype(bool)
    union = np.count_nonzero(p | t)
    return 1.0 if union == 0 else float(np.count_nonzero(p & t) / union)


@dataclass(frozen=True)
class PrecisionRecall:
    """Dynamic-feature culling scored against the truth mask. A removed keypoint on a dynamic pixel is a true
    positive, on a static pixel a false positive; a kept keypoint on a dynamic pixel is a false negative.
    precision (recall) is 1.0 when nothing was removed (nothing was dynamic)."""

    precision: float
    recall: float
    tp: int
    fp: int
    fn: int

    def to_dict(self) -> dict:
        return {"precision": self.precision, "recall": self.recall, "tp": self.tp, "fp": self.fp, "fn": self.fn}


def _on_mask(points: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """bool (N,): whether each (x, y) pixel keypoint lies on the mask (rounded, clipped to the image)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if len(pts) == 0:
        return np.zeros(0, dtype=bool)
    h, w = mask.shape
    x = np.clip(np.rint(pts[:, 0]).astype(int), 0, w - 1)
    y = np.clip(np.rint(pts[:, 1]).astype(int), 0, h - 1)
    return mask[y, x].astype(bool)


def feature_precision_recall(removed: np.ndarray, kept: np.ndarray, truth_mask: np.ndarray,
                             border_px: int = 0) -> PrecisionRecall:
    """Score culling: `removed`, `kept` (N, 2) / (M, 2) keypoints as (x, y) pixels; `truth_mask` bool (H, W).

    `border_px` > 0 also counts a removed keypoint within that distance of the mask as correct: ORB corners sit
    on silhouettes, and a keypoint whose patch straddles a moving object is unstable wherever its centre falls.
    Recall is always over keypoints on the mask itself."""
    return _precision_recall(_on_mask(removed, _near(truth_mask, border_px)), _on_mask(kept, truth_mask))


def _near(mask: np.ndarray, border_px: int) -> np.ndarray:
    """bool (H, W): `mask` grown by `border_px` pixels (a square), or `mask` itself for 0."""
    if border_px <= 0:
        return mask
    import cv2

    size = 2 * border_px + 1
    return cv2.dilate(mask.astype(np.uint8), np.ones((size, size), np.uint8)) > 0


def _precision_recall(removed_ok: np.ndarray, kept_dynamic: np.ndarray) -> PrecisionRecall:
    """From bool (N,) "removed keypoint is on or near the truth" and (M,) "kept keypoint is on the truth"."""
    tp, fp, fn = int(removed_ok.sum()), int((~removed_ok).sum()), int(kept_dynamic.sum())
    precision = tp / (tp + fp) if tp + fp else 1.0
    recall = tp / (tp + fn) if tp + fn else 1.0
    return PrecisionRecall(precision, recall, tp, fp, fn)


def restoration_psnr(restored: np.ndarray, background: np.ndarray, region: np.ndarray | None = None) -> float:
    """PSNR (dB, peak 255) of `restored` against the truth `background` (both RGB uint8 (H, W, 3) or grey
    (H, W)) over the bool (H, W) `region` (the filled hole; None = whole image). inf when identical, nan when
    the region is empty."""
    if restored.shape != background.shape:
        raise ValueError(f"image shapes differ: {restored.shape} vs {background.shape}")
    sel = np.ones(restored.shape[:2], bool) if region is None else region.astype(bool)
    if not sel.any():
        return float("nan")
    diff = restored[sel].astype(np.float64) - background[sel].astype(np.float64)
    mse = float(np.mean(diff * diff))
    return float("inf") if mse == 0 else float(10.0 * np.log10(255.0 ** 2 / mse))


class TruthScores:
    """Accumulates the per-frame scores of one run against a `Truth`; `summary()` goes into the run's metrics.

    Each `add_*` call scores one frame and returns that frame's value; the pipeline calls only those it has
    outputs for (a run without restoration never calls `add_restoration`)."""

    def __init__(self, truth: Truth) -> None:
        self.truth = truth
        self._iou: list[float] = []
        self._tp = self._fp = self._fn = 0
        self._fn_marked: int | None = None  # kept keypoints on the truth that segmentation had marked
        self._psnr: list[float] = []

    def add_mask(self, index: int, pred: np.ndarray) -> float:
        """Predicted dynamic mask, bool (H, W), of frame `index`."""
        iou = mask_iou(pred, self.truth.mask(index))
        self._iou.append(iou)
        return iou

    def add_features(self, index: int, removed: np.ndarray, kept: np.ndarray, border_px: int = 3,
                     marked: np.ndarray | None = None) -> PrecisionRecall:
        """Keypoints (N, 2) / (M, 2) as (x, y) that culling removed / kept in frame `index` (removed ones within
        `border_px` of the truth mask count as correct, see `feature_precision_recall`). `marked` bool (H, W),
        segmentation's potentially dynamic pixels, splits the kept dynamic keypoints into culling's misses (marked,
        judged still) and segmentation's (never marked)."""
        truth = self.truth.mask(index)
        kept_dynamic = _on_mask(kept, truth)  # looked up once: recall and the misses' split both need it
        pr = _precision_recall(_on_mask(removed, _near(truth, border_px)), kept_dynamic)
        self._tp, self._fp, self._fn = self._tp + pr.tp, self._fp + pr.fp, self._fn + pr.fn
        if marked is not None:
            self._fn_marked = (self._fn_marked or 0) + int((kept_dynamic & _on_mask(kept, marked)).sum())
        return pr

    def add_restoration(self, index: int, restored: np.ndarray, region: np.ndarray) -> float:
        """Restored RGB uint8 (H, W, 3) of frame `index` over the filled bool (H, W) `region`."""
        psnr = restoration_psnr(restored, self.truth.background_rgb(index), region)
        if not np.isnan(psnr):
            self._psnr.append(min(psnr, 100.0))  # identical pixels count as 100 dB, so the mean stays finite
        return psnr

    def summary(self) -> dict:
        """{"mask_iou": mean, "feature_precision", "feature_recall" (pooled over frames), "restoration_psnr": mean,
        "frames_scored": {...}}; a score with no frames is None. With segmentation also the dynamic keypoints'
        shares kept although marked (`feature_missed_by_culling`) and kept unmarked (`feature_missed_by_segmentation`),
        which add up to 1 - recall."""
        tp, fp, fn = self._tp, self._fp, self._fn
        split = {}
        if self._fn_marked is not None and tp + fn:
            split = {"feature_missed_by_culling": self._fn_marked / (tp + fn),
                     "feature_missed_by_segmentation": (fn - self._fn_marked) / (tp + fn)}
        return {**split,
            "mask_iou": float(np.mean(self._iou)) if self._iou else None,
            "feature_precision": (tp / (tp + fp) if tp + fp else 1.0) if tp + fp + fn else None,
            "feature_recall": (tp / (tp + fn) if tp + fn else 1.0) if tp + fp + fn else None,
            "restoration_psnr": float(np.mean(self._psnr)) if self._psnr else None,
            "frames_scored": {"mask": len(self._iou), "restoration": len(self._psnr)},
        }
