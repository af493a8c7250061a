"""The `tflite-teacher` backend: a user-supplied TFLite segmenter run with ai-edge-litert (imported here only).

Understood model families, told apart by their output tensor:
- (1, h, w, 21) float: DeepLabV3 PASCAL-VOC logits -> background / person (VOC 15) / chair (VOC 9), or all 21
  VOC classes with `full_voc` (`SegmenterConfig.full_voc`; a multi-class MSNET's teacher);
- (1, h, w) integer: a VOC class map (the quantised DeepLabV3) -> same classes, one-hot probabilities;
- (1, h, w, 1) float: a person probability (MediaPipe selfie segmentation) -> background / person.
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from worker.slam.segmentation.base import SegmentationError, SegmentationResult, SegmenterConfig, check_rgb, labels_of
from worker.slam.segmentation.classes import DEFAULT_DYNAMIC
from worker.slam.segmentation.classes import VOC_CLASSES as VOC_NAMES

VOC_CLASSES = 21
# Our class -> PASCAL VOC index. Everything else in VOC counts as background.
VOC_TO_OURS = {"person": 15, "chair": 9}


class TfliteSegmenter:
    """Wraps one .tflite model; `predict_probs` gives probabilities over `classes` at the model's output size."""

    def __init__(self, model_path: Path, threads: int = 1, dynamic_classes: tuple[str, ...] | None = None,
                 full_voc: bool = False) -> None:
        from ai_edge_litert.interpreter import Interpreter

        try:
            self.interpreter = Interpreter(model_path=str(model_path), num_threads=threads)
            self.interpreter.allocate_tensors()
        except (ValueError, RuntimeError) as exc:
            raise SegmentationError(f"cannot load TFLite model {model_path}: {exc}") from exc
        inp = self.interpreter.get_input_details()[0]
        out = self.interpreter.get_output_details()[0]
        self._in_index, self._out_index = inp["index"], out["index"]
        self.input_hw = (int(inp["shape"][1]), int(inp["shape"][2]))
        self._in_dtype = inp["dtype"]
        shape = tuple(int(s) for s in out["shape"])
        if len(shape) == 3:
            self.kind = "voc-labels"
        elif len(shape) == 4 and shape[3] == VOC_CLASSES:
            self.kind = "voc-logits"
        elif len(shape) == 4 and shape[3] == 1:
            self.kind = "person-prob"
        else:
            raise SegmentationError(f"unsupported TFLite output shape {shape} in {model_path}")
        self.full_voc = full_voc and self.kind != "person-prob"
        self.classes: tuple[str, ...] = ("background", "person") if self.kind == "person-prob" else \
            VOC_NAMES if self.full_voc else ("background", "person", "chair")
        default_dyn = DEFAULT_DYNAMIC if self.full_voc else tuple(c for c in ("person", "chair") if c in self.classes)
        self.dynamic_classes = tuple(dynamic_classes) if dynamic_classes is not None else default_dyn
        self.name = Path(model_path).stem

    @classmethod
    def from_config(cls, config: SegmenterConfig) -> TfliteSegmenter:
        if config.model_path is None:
            from worker.slam.errors import ConfigError

            raise ConfigError("the tflite-teacher backend needs model_path (a .tflite file)")
        return cls(Path(config.model_path), config.threads or 1, config.dynamic_classes, config.full_voc)

    def _input(self, rgb: np.ndarray) -> np.ndarray:
        h, w = self.input_hw
        x = cv2.resize(rgb, (w, h), interpolation=cv2.INTER_AREA)
        if self._in_dtype == np.uint8:
            return x[None]
        x = x.astype(np.float32) / 255.0
        # DeepLab expects [-1, 1]; MediaPipe selfie expects [0, 1].
        return (x if self.kind == "person-prob" else x * 2.0 - 1.0)[None]

    def predict_probs(self, rgb: np.ndarray) -> np.ndarray:
        """rgb (H, W, 3) uint8 -> (h, w, K) float32 probabilities over `classes` at the model's output size."""
        self.interpreter.set_tensor(self._in_index, self._input(rgb))
        self.interpreter.invoke()
        out = self.interpreter.get_tensor(self._out_index)[0]
        if self.kind == "person-prob":
            p = np.clip(out[..., 0].astype(np.float32), 0.0, 1.0)
            return np.stack([1.0 - p, p], axis=-1)
        if self.kind == "voc-labels":
            voc = np.eye(VOC_CLASSES, dtype=np.float32)[np.clip(out, 0, VOC_CLASSES - 1)]
        else:
            z = out.astype(np.float32)
            z = np.exp(z - z.max(-1, keepdims=True))
            voc = z / z.sum(-1, keepdims=True)
        if self.full_voc:
            return voc
        person, chair = voc[..., VOC_TO_OURS["person"]], voc[..., VOC_TO_OURS["chair"]]
        return np.stack([1.0 - person - chair, person, chair], axis=-1)

    def segment(self, rgb: np.ndarray) -> SegmentationResult:
        """rgb: (H, W, 3) uint8 RGB -> labels and probabilities at (H, W)."""
        check_rgb(rgb)
        probs = cv2.resize(self.predict_probs(rgb), (rgb.shape[1], rgb.shape[0]), interpolation=cv2.INTER_LINEAR)
        return SegmentationResult(labels_of(probs), self.classes, self.dynamic_classes, probs)


def read_constants(model_path: Path) -> dict[str, np.ndarray]:
    """The tensors of a float .tflite model that are readable without running it, by name: its weights and
    biases, to start training from (`msnet.mobilenet.pretrained_state_dict`). Raises SegmentationError for an
    unreadable file."""
    from ai_edge_litert.interpreter import Interpreter

    try:
        interpreter = Interpreter(model_path=str(model_path))
        interpreter.allocate_tensors()
    except (ValueError, RuntimeError) as exc:
        raise SegmentationError(f"cannot load TFLite model {model_path}: {exc}") from exc
    out = {}
    for t in interpreter.get_tensor_details():
        try:
            out[t["name"]] = np.array(interpreter.tensor(t["index"])())  # weights stay readable after allocation
        except ValueError:  # an intermediate activation: not allocated outside invoke()
            continue
    return out
