"""Labelled people from the project's own synthetic rooms: `vtdslam synth` sequences (rendered once into the cache
folder by `vtdslam train-msnet`), every n-th frame a training image whose walkers' exact masks are its person
labels.

The demo a new user runs first is such a room; these seeds (100 and up by default) are other rooms, paths and
walkers than the benchmark's seeds 0-3. The network's training code does not render them itself (the renderer
writes the pipeline's truth layout, a floor the network knows nothing of): the CLI does, before training."""
from __future__ import annotations

from pathlib import Path

from worker.slam.camera import load_camera_file
from worker.slam.errors import ConfigError
from worker.slam.segmentation.train.config import TrainConfig
from worker.slam.segmentation.train.datasets import LabelledImage


def synthetic_folder(cfg: TrainConfig, seed: int) -> Path:
    """Where the room of `seed` is (to be) rendered; complete once its `truth/truth.json` exists (written last)."""
    return Path(cfg.cache_dir) / f"synth-s{seed}-f{cfg.synth_frames}-p{cfg.synth_people}"


def synthetic_people(cfg: TrainConfig) -> list[LabelledImage]:
    """Every `synth_stride`-th frame of each `synth_seeds` room as a fully labelled person image."""
    items: list[LabelledImage] = []
    for seed in cfg.synth_seeds:
        folder = synthetic_folder(cfg, seed)
        if not (folder / "truth" / "truth.json").is_file():
            raise ConfigError(f"synthetic room {folder} is missing: `vtdslam train-msnet` renders it (or `vtdslam "
                              f"synth {folder} --frames {cfg.synth_frames} --people {cfg.synth_people} --seed {seed}`)")
        camera = load_camera_file(folder)
        if camera is None:
            raise ConfigError(f"synthetic room {folder} has no camera.json: render it again")
        for i in range(0, cfg.synth_frames, max(cfg.synth_stride, 1)):
            name = f"{i:06d}.png"
            items.append(LabelledImage(folder / "rgb" / name, (camera.height, camera.width),
                                       mask=folder / "truth" / "masks" / name, mask_label="person", mask_min=1))
    return items
