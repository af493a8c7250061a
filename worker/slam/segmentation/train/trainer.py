"""The training loop: seeded, resumable, with a progress bar, a JSONL metrics log and per-epoch checkpoints."""
from __future__ import annotations

import json
import logging
import random
import time
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import cast

import cv2
import numpy as np
import torch
from torch.optim.swa_utils import AveragedModel, get_ema_multi_avg_fn
from tqdm import tqdm

from worker.slam.errors import ConfigError
from worker.slam.io.images import read_rgb
from worker.slam.segmentation.evaluate import confusion, metrics_from_confusion
from worker.slam.segmentation.msnet.checkpoint import load_model, save_model
from worker.slam.segmentation.msnet.mobilenet import pretrained_state_dict
from worker.slam.segmentation.msnet.model import MSNet, build_msnet
from worker.slam.segmentation.msnet.segmenter import pick_device
from worker.slam.segmentation.tflite_teacher import read_constants
from worker.slam.segmentation.train.bn_recalibration import recalibrate_bn
from worker.slam.segmentation.train.config import TrainConfig
from worker.slam.segmentation.train.data import TrainingData, build_training_data, expand, find_backgrounds
from worker.slam.segmentation.train.datasets import LabelledImage, semantic_mask
from worker.slam.segmentation.train.losses import msnet_loss
from worker.slam.segmentation.train.mixture import EpochSampler, MixtureDataset, SoftSet

_log = logging.getLogger(__name__)


def seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)


def init_worker(seed: int, worker_id: int) -> None:
    """Data workers: one OpenCV thread each, so they do not fight the training threads for the cores.
    Samples are seeded by their index; this only covers library code that draws from global RNGs."""
    cv2.setNumThreads(1)
    seed_everything(seed + worker_id)


def lr_factor(progress: float, warmup_fraction: float) -> float:
    """One-cycle shape over training progress in [0, 1]: linear warm-up, then cosine decay to 2 %."""
    if progress < warmup_fraction:
        return max(progress / warmup_fraction, 0.01)
    t = min((progress - warmup_fraction) / max(1.0 - warmup_fraction, 1e-9), 1.0)
    return 0.02 + 0.98 * 0.5 * (1 + np.cos(np.pi * t))


def progress_of(step: int, total_steps: int, seconds: float, budget_min: float | None) -> float:
    by_steps = step / max(total_steps, 1)
    return max(by_steps, seconds / (60.0 * budget_min)) if budget_min else by_steps


@torch.inference_mode()
def validate(model: MSNet, items: list[LabelledImage], device: torch.device) -> dict:
    """Per-class IoU / pixel accuracy on held-out images, predicted at the model's input size."""
    model.eval()
    classes, (h, w) = model.cfg.classes, model.cfg.input_size
    cm = np.zeros((len(classes), len(classes)), dtype=np.int64)
    for item in items:
        rgb = cv2.resize(read_rgb(item.image), (w, h), interpolation=cv2.INTER_AREA)
        gt = cv2.resize(semantic_mask(item, classes), (w, h), interpolation=cv2.INTER_NEAREST)
        x = torch.from_numpy(rgb).permute(2, 0, 1)[None].float().div(255).to(device)
        pred = model(x).logits.argmax(1)[0].cpu().numpy()
        cm += confusion(pred, gt, len(classes))
    model.train()
    m = metrics_from_confusion(cm, classes, len(items))
    return {"val_miou": m.miou, "val_mpa": m.mpa, "val_iou": m.iou, "val_acc": m.pixel_acc}


@torch.inference_mode()
def target_agreement(model: MSNet, targets: SoftSet | None, device: torch.device) -> dict:
    """Person IoU (pooled) between the model and the teacher's argmax on the target frames, at the model's
    input size. These frames are training data when `target_frames` is set: a training-set figure."""
    if targets is None or targets.soft is None or "person" not in model.cfg.classes:
        return {}
    model.eval()
    p, (h, w) = model.cfg.classes.index("person"), model.cfg.input_size
    inter = union = 0
    for path, soft in zip(targets.images, targets.soft):
        rgb = cv2.resize(read_rgb(path), (w, h), interpolation=cv2.INTER_AREA)
        teacher = cv2.resize(np.ascontiguousarray(soft), (w, h), interpolation=cv2.INTER_LINEAR).argmax(-1) == p
        x = torch.from_numpy(rgb).permute(2, 0, 1)[None].float().div(255).to(device)
        pred = model(x).logits.argmax(1)[0].cpu().numpy() == p
        inter += int(np.logical_and(pred, teacher).sum())
        union += int(np.logical_or(pred, teacher).sum())
    model.train()
    return {"train_target_agreement": inter / union if union else 1.0}


def selection_score(record: dict) -> float:
    """Validation person IoU (the pipeline's main class), else validation mIoU."""
    iou = record.get("val_iou", {}).get("person")
    return float(iou if iou is not None else record.get("val_miou", 0.0))


def evaluate_all(model: MSNet, data, device: torch.device) -> dict:
    record = validate(model, data.selection, device) if data.selection else {}
    if record and data.val:
        record["val_split"] = "val"
    elif record:
        record["val_split"] = "held-out"
    record.update(target_agreement(model, data.targets, device))
    return record


def load_pretrained_cnn(model: MSNet, tflite: Path) -> None:
    """The MobileNetV2 stages of a "mobilenetv2" pyramid from a DeepLabV3-MobileNetV2 .tflite (its BN folded)."""
    if model.cfg.cnn != "mobilenetv2":
        raise ConfigError("init_pretrained needs model.cnn = 'mobilenetv2'", detail={"cnn": model.cfg.cnn})
    try:
        state = pretrained_state_dict(read_constants(tflite))
    except KeyError as exc:
        raise ConfigError(f"{tflite} holds no DeepLabV3-MobileNetV2 (width 0.5) weights: {exc} missing") from exc
    model.backbone.cnn_stages().load_state_dict(state)


def param_groups(model: MSNet, cfg: TrainConfig) -> list[dict]:
    """The pretrained CNN path at `pretrained_lr_scale` x the rate (when it starts pretrained), the rest at 1x."""
    if not (cfg.init_pretrained or cfg.init_partial) or cfg.init_weights or cfg.pretrained_lr_scale == 1.0:
        return [{"params": list(model.parameters()), "lr_scale": 1.0}]
    cnn = {id(p) for p in model.backbone.cnn_stages().parameters()}
    return [{"params": [p for p in model.parameters() if id(p) in cnn], "lr_scale": cfg.pretrained_lr_scale},
            {"params": [p for p in model.parameters() if id(p) not in cnn], "lr_scale": 1.0}]


@dataclass(frozen=True)
class _Run:
    """One training run's fixed parts: its config, output folder and device, its data, the model and its
    optimiser, the EMA of the model's weights (None when `ema_decay` is 0), the per-class loss weights
    (num_classes,) float32 on `device`, and the planned number of optimiser steps."""
    cfg: TrainConfig
    out: Path
    device: torch.device
    data: TrainingData
    model: MSNet
    opt: torch.optim.Optimizer
    ema: AveragedModel | None
    class_weights: torch.Tensor
    total_steps: int


@dataclass(frozen=True)
class _Clock:
    """Where training stands: epochs done, training seconds spent, optimiser steps taken."""
    epoch: int
    elapsed_s: float
    step: int


def train(cfg: TrainConfig, resume: bool = False, progress: bool = True) -> Path:
    """Train MSNET as `cfg` says; returns the path of the weights-only checkpoint (`out_dir/msnet.pt`)."""
    out = Path(cfg.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    seed_everything(cfg.seed)
    if cfg.threads:
        torch.set_num_threads(cfg.threads)
        cv2.setNumThreads(cfg.threads)
    device = pick_device(cfg.device)
    run, clock = _start(cfg, resume, out, device, build_training_data(cfg))
    sampler = EpochSampler(len(run.data.train))
    loader = _loader(cfg, run.data.train, sampler)
    elapsed, step = clock.elapsed_s, clock.step
    for epoch in range(clock.epoch, cfg.epochs):
        t0 = time.time()
        sampler.epoch = epoch
        sums, n, step = _train_epoch(run, loader, _Clock(epoch, elapsed, step), t0, progress)
        elapsed += time.time() - t0
        _save_epoch(run, _Clock(epoch + 1, elapsed, step), {k: v / max(n, 1) for k, v in sums.items()})
        if progress_of(step, run.total_steps, elapsed, cfg.time_budget_min) >= 1.0:
            break
    finals = {"ema": cast(MSNet, run.ema.module), "raw": run.model} if run.ema is not None else {"raw": run.model}
    finish(cfg, finals, run.data, device, out, {"train_config": cfg.to_dict(), "train_seconds": round(elapsed, 1),
                                                 "epoch": state_epoch(out)})
    return out / "msnet.pt"


def _start(cfg: TrainConfig, resume: bool, out: Path, device: torch.device,
           data: TrainingData) -> tuple[_Run, _Clock]:
    """The model (fresh, fine-tuned from `init_weights` or pretrained), its optimiser and EMA, restored from
    `out/last.pt` when resuming; writes `out/config.json`."""
    model = _initial_model(cfg, resume, device)
    opt = torch.optim.AdamW(param_groups(model, cfg), lr=cfg.lr, weight_decay=cfg.weight_decay)
    steps_per_epoch = max(cfg.samples_per_epoch // cfg.batch_size, 1)
    total_steps = steps_per_epoch * cfg.epochs
    ema = AveragedModel(model, multi_avg_fn=get_ema_multi_avg_fn(cfg.ema_decay), use_buffers=True) \
        if cfg.ema_decay > 0 else None
    state_path = out / "last.pt"
    clock = _restore(state_path, model, ema, opt) if resume and state_path.is_file() else _Clock(0, 0.0, 0)
    (out / "config.json").write_text(json.dumps(cfg.to_dict(), indent=2))
    weights = torch.tensor(cfg.class_weights[:cfg.model.num_classes], dtype=torch.float32, device=device)
    return _Run(cfg, out, device, data, model, opt, ema, weights, total_steps), clock


def _initial_model(cfg: TrainConfig, resume: bool, device: torch.device) -> MSNet:
    """A new model on `device`, with the weights of `init_weights` or the pretrained CNN path unless resuming
    (a resumed run loads its own weights later)."""
    model = build_msnet(cfg.model).to(device)
    if cfg.init_weights and not (resume and (Path(cfg.out_dir) / "last.pt").is_file()):
        start, _ = load_model(cfg.path(cfg.init_weights))
        # Which classes count as dynamic is inference metadata (an exported checkpoint may narrow it), not shape.
        if replace(start.cfg, dynamic_classes=cfg.model.dynamic_classes) != cfg.model:
            raise ConfigError(f"init_weights {cfg.init_weights}: its architecture differs from the config's model")
        model.load_state_dict(start.state_dict())
        model.train()
    elif not (resume and (Path(cfg.out_dir) / "last.pt").is_file()):
        if cfg.init_pretrained:
            load_pretrained_cnn(model, cfg.path(cfg.init_pretrained))
        if cfg.init_partial:
            load_matching(model, cfg.path(cfg.init_partial))
    return model


def load_matching(model: MSNet, checkpoint: Path) -> list[str]:
    """Copy into `model` every tensor of `checkpoint` whose name and shape match; returns the names of the model's
    tensors left as they were (logged in the run's config as what starts fresh)."""
    start, _ = load_model(checkpoint)
    theirs = start.state_dict()
    ours = model.state_dict()
    matched = {k: v for k, v in theirs.items() if k in ours and ours[k].shape == v.shape}
    model.load_state_dict(matched, strict=False)
    fresh = sorted(k for k in ours if k not in matched)
    _log.info("init_partial: %d tensors from %s, %d start fresh: %s", len(matched), checkpoint.name, len(fresh),
              ", ".join(sorted({k.rsplit(".", 2)[0] for k in fresh})))
    return fresh


def _restore(state_path: Path, model: MSNet, ema: AveragedModel | None, opt: torch.optim.Optimizer) -> _Clock:
    """Load the model, EMA, optimiser and torch RNG state of an interrupted run from `state_path`."""
    state = torch.load(state_path, map_location="cpu", weights_only=False)
    model.load_state_dict(state["model"])
    if ema is not None and state.get("ema"):
        ema.load_state_dict(state["ema"])
    elif ema is not None:  # a run started without EMA begins averaging from its current weights
        ema.module.load_state_dict(state["model"])
    opt.load_state_dict(state["optimizer"])
    torch.set_rng_state(state["torch_rng"])
    return _Clock(state["epoch"], state["elapsed_s"], state["step"])


def _loader(cfg: TrainConfig, dataset: MixtureDataset, sampler: EpochSampler) -> torch.utils.data.DataLoader:
    # spawn, not fork: forking after OpenCV/OpenMP thread pools exist can deadlock the workers.
    return torch.utils.data.DataLoader(
        dataset, batch_size=cfg.batch_size, sampler=sampler, drop_last=True, num_workers=cfg.workers,
        persistent_workers=cfg.workers > 0, multiprocessing_context="spawn" if cfg.workers > 0 else None,
        worker_init_fn=partial(init_worker, cfg.seed))


def _train_epoch(run: _Run, loader: torch.utils.data.DataLoader, clock: _Clock, t0: float,
                 progress: bool) -> tuple[dict[str, float], int, int]:
    """Epoch `clock.epoch + 1`: one pass over `loader` from `clock` (it started at time `t0`), stopping when the
    steps or the time budget run out: the loss parts summed over the batches, the batches drawn (counting the one
    that found the budget spent), and the step reached."""
    cfg, step = run.cfg, clock.step
    run.model.train()
    sums: dict[str, float] = {}
    n = 0
    bar = tqdm(loader, desc=f"epoch {clock.epoch + 1}/{cfg.epochs}", disable=not progress, unit="batch")
    for n, batch in enumerate(bar, 1):
        done = progress_of(step, run.total_steps, clock.elapsed_s + time.time() - t0, cfg.time_budget_min)
        if done >= 1.0:
            break
        lr = cfg.lr * lr_factor(done, cfg.warmup_fraction)
        for group in run.opt.param_groups:
            group["lr"] = lr * group.get("lr_scale", 1.0)  # absent in the optimiser state of older runs
        step += 1
        parts = _train_step(run, batch)
        for k, v in parts.items():
            sums[k] = sums.get(k, 0.0) + v
        bar.set_postfix(loss=f"{sums['loss'] / n:.3f}")
    return sums, n, step


def _train_step(run: _Run, batch: dict[str, torch.Tensor]) -> dict[str, float]:
    """One optimiser step (gradients clipped to norm 5) and EMA update on `batch`; returns the loss parts."""
    cfg = run.cfg
    batch = {k: v.to(run.device) for k, v in batch.items()}
    loss, parts = msnet_loss(run.model(batch["image"]), batch["hard"], batch["soft"], batch["kd_mask"],
                             run.class_weights, cfg.kd_weight, cfg.query_weight)
    run.opt.zero_grad(set_to_none=True)
    loss.backward()
    torch.nn.utils.clip_grad_norm_(run.model.parameters(), 5.0)
    run.opt.step()
    if run.ema is not None:
        run.ema.update_parameters(run.model)
    return parts


def _save_epoch(run: _Run, clock: _Clock, means: dict[str, float]) -> None:
    """After epoch `clock.epoch`: its record (mean loss parts `means`, validation) appended to `metrics.jsonl`,
    the resumable state in `last.pt`, and the weights (the EMA's when there is one) in `msnet.pt` and
    `epochNNN.pt`."""
    out, model, opt, ema = run.out, run.model, run.opt, run.ema
    record = {"epoch": clock.epoch, "step": clock.step, "lr": opt.param_groups[0]["lr"],
              "elapsed_s": round(clock.elapsed_s, 1), **means}
    final = cast(MSNet, ema.module if ema is not None else model)
    record.update(evaluate_all(final, run.data, run.device))
    with open(out / "metrics.jsonl", "a") as f:
        f.write(json.dumps(record) + "\n")
    state_path = out / "last.pt"
    torch.save({"model": model.state_dict(), "optimizer": opt.state_dict(), "torch_rng": torch.get_rng_state(),
                "epoch": clock.epoch, "step": clock.step, "elapsed_s": clock.elapsed_s,
                "ema": ema.state_dict() if ema is not None else None}, state_path.with_suffix(".tmp"))
    state_path.with_suffix(".tmp").replace(state_path)
    meta = {"epoch": clock.epoch, "train_seconds": round(clock.elapsed_s, 1), "train_config": run.cfg.to_dict(),
            **{k: v for k, v in record.items() if k.startswith(("val_", "train_target"))}}
    save_model(out / "msnet.pt", final, meta)
    save_model(out / f"epoch{clock.epoch:03d}.pt", final, meta)  # for later inspection and selection


def state_epoch(out: Path) -> int | None:
    lines = (out / "metrics.jsonl").read_text().splitlines() if (out / "metrics.jsonl").is_file() else []
    return json.loads(lines[-1])["epoch"] if lines else None


def finish(cfg: TrainConfig, weights: dict[str, MSNet], data, device: torch.device, out: Path, meta: dict) -> dict:
    """Candidates: each of `weights` (the EMA and the raw final weights) as trained, with BN statistics
    re-estimated (AdaBN) on the backgrounds, and on the backgrounds plus `bn_extra_frames`. Each is validated
    (never on the test split when a `val` split exists); the best by `selection_score` becomes `msnet.pt`.
    The old recipe (no val split, no extra BN frames) keeps its rule: the first weights with AdaBN on the
    backgrounds. Returns the candidates' records (also written to `adabn.json`)."""
    frames = find_backgrounds(replace(cfg, background_stride=1))[::max(cfg.bn_recalibration_stride, 1)]
    frames = frames if cfg.bn_recalibration_stride > 0 else []
    extra = expand(cfg, cfg.bn_extra_frames) if frames else []
    candidates, n_bn = {}, {}
    for name, model in weights.items():
        candidates[f"{name}"], n_bn[f"{name}"] = model, 0
        if frames:
            candidates[f"{name}+adabn"], n_bn[f"{name}+adabn"] = recalibrate_bn(model, frames), len(frames)
        if extra:
            key = f"{name}+adabn-extra"
            candidates[key], n_bn[key] = recalibrate_bn(model, frames + extra), len(frames) + len(extra)
    records = {name: evaluate_all(m, data, device) for name, m in candidates.items()}
    first = next(iter(weights))
    if (cfg.bn_extra_frames or cfg.val_every) and any(records.values()):
        best = max(records, key=lambda k: selection_score(records[k]))
    else:
        best = f"{first}+adabn" if frames else first
    (out / "adabn.json").write_text(json.dumps({"chosen": best, "candidates": records}, indent=2))
    save_model(out / "msnet.pt", candidates[best].eval(), {**meta, "weights": best, "bn_recalibrated_on": n_bn[best],
                                                           **records[best]})
    return records
