"""The Segmenter protocol, the factory and both backends."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.worker.slam.segmentation.test_msnet_model import TINY
from worker.slam.errors import ConfigError
from worker.slam.segmentation import SegmentationError, Segmenter, SegmenterConfig, available_backends, make_segmenter
from worker.slam.segmentation.base import SegmentationResult, labels_of
from worker.slam.segmentation.msnet import build_msnet
from worker.slam.segmentation.msnet.checkpoint import default_checkpoint, load_model, save_model


@pytest.fixture()
def tiny_checkpoint(tmp_path: Path) -> Path:
    path = tmp_path / "tiny.pt"
    save_model(path, build_msnet(TINY), {"note": "test"})
    return path


def test_backends_registered() -> None:
    assert set(available_backends()) >= {"msnet", "tflite-teacher"}
    assert SegmenterConfig().backend == "msnet"


def test_unknown_backend_and_missing_files() -> None:
    with pytest.raises(ConfigError):
        make_segmenter(SegmenterConfig(backend="nope"))
    with pytest.raises(ConfigError):
        make_segmenter(SegmenterConfig(checkpoint="/nonexistent/msnet.pt"))
    with pytest.raises(ConfigError):
        make_segmenter(SegmenterConfig(backend="tflite-teacher"))


def test_msnet_backend_outputs_at_input_resolution(tiny_checkpoint: Path) -> None:
    seg = make_segmenter(SegmenterConfig(checkpoint=str(tiny_checkpoint), device="cpu", with_probs=True))
    assert isinstance(seg, Segmenter)
    assert seg.classes == ("background", "person", "chair") and seg.dynamic_classes == ("person", "chair")
    rgb = np.random.default_rng(0).integers(0, 255, (75, 101, 3), dtype=np.uint8)
    res = seg.segment(rgb)
    assert res.labels.shape == (75, 101) and res.labels.dtype == np.uint8
    assert res.probs is not None and res.probs.shape == (75, 101, 3)
    np.testing.assert_allclose(res.probs.sum(-1), 1.0, atol=1e-4)
    assert res.dynamic_mask().shape == (75, 101)
    with pytest.raises(SegmentationError):
        seg.segment(rgb.astype(np.float32))


def test_msnet_backend_runs_a_trace_with_the_eager_models_outputs(tiny_checkpoint: Path) -> None:
    """The segmenter's traced forward gives the grid logits of the (BN-folded) eager model bit for bit, on frames
    unlike the zeros it was traced with; its probabilities are the softmax of the eager model's upsampled logits,
    and its labels (the fast path, from the grid) agree with their argmax but for a sliver along boundaries."""
    import torch

    from worker.slam.segmentation.msnet.segmenter import MsnetSegmenter

    seg = make_segmenter(SegmenterConfig(checkpoint=str(tiny_checkpoint), device="cpu"))
    assert isinstance(seg, MsnetSegmenter) and isinstance(seg._grid, torch.jit.ScriptModule)
    rng = np.random.default_rng(1)
    for _ in range(3):
        rgb = rng.integers(0, 255, (120, 160, 3), dtype=np.uint8)
        x = torch.rand(1, 3, *TINY.input_size).contiguous(memory_format=torch.channels_last)
        with torch.inference_mode():
            want, got = seg.model.forward_grid(x), seg._grid(x)
        assert torch.equal(want, got) and want.abs().max() > 0
        probs = seg.predict_probs(rgb)
        with torch.inference_mode():
            eager = seg.model(_input(rgb, TINY.input_size)).logits.softmax(1)[0].permute(1, 2, 0).numpy()
        np.testing.assert_array_equal(probs, eager)
        full = cv2.resize(probs, (160, 120), interpolation=cv2.INTER_LINEAR).argmax(-1)
        assert (seg.segment(rgb).labels == full).mean() > 0.97


def _input(rgb: np.ndarray, size: tuple[int, int]):
    import cv2
    import torch

    small = cv2.resize(rgb, (size[1], size[0]), interpolation=cv2.INTER_AREA)
    x = torch.from_numpy(small).permute(2, 0, 1)[None].float().div_(255.0)
    return x.contiguous(memory_format=torch.channels_last)


def test_checkpoint_roundtrip_and_foreign_file(tiny_checkpoint: Path, tmp_path: Path) -> None:
    model, meta = load_model(tiny_checkpoint)
    assert model.cfg == TINY and meta == {"note": "test"}
    bad = tmp_path / "bad.pt"
    import torch

    torch.save({"weights": 1}, bad)
    with pytest.raises(ConfigError):
        load_model(bad)


def test_shipped_checkpoint_exists_and_is_small() -> None:
    path = default_checkpoint()
    assert path.is_file(), f"shipped weights missing: {path}"
    assert path.stat().st_size <= 30 * 1024 * 1024


@pytest.mark.realdata
def test_tflite_teacher_backend(shared: Path) -> None:
    pytest.importorskip("ai_edge_litert")
    model = shared / "models" / "selfie_segmentation.tflite"
    if not model.is_file():
        pytest.skip(f"{model} not present")
    seg = make_segmenter(SegmenterConfig(backend="tflite-teacher", model_path=str(model)))
    res = seg.segment(np.zeros((48, 64, 3), np.uint8))
    assert res.classes == ("background", "person") and res.labels.shape == (48, 64)


def test_labels_of_is_numpys_argmax_and_dynamic_mask_its_classes():
    """Ties go to the first class, a NaN wins as in numpy; the dynamic mask marks exactly its classes."""
    rng = np.random.default_rng(0)
    probs = rng.random((40, 50, 3)).astype(np.float32)
    probs[:5] = probs[:5, :, :1]  # three equal scores: class 0
    probs[5:10, :, 1:] = probs[5:10, :, 1:2]  # classes 1 and 2 tie above 0 sometimes: class 1
    probs[10, 3, 2] = probs[11, 4, 0] = np.nan
    got = labels_of(probs)
    assert got.dtype == np.uint8 and np.array_equal(got, probs.argmax(-1))
    res = SegmentationResult(got, ("background", "person", "chair"), ("chair",))
    assert np.array_equal(res.dynamic_mask(), got == 2)
