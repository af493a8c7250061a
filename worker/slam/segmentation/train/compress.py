"""A cheaper MSNET from a trained one: the guidance's dense 3x3 refinement (about a third of the forward on one
CPU core) factorised to rank r per input channel (`MsnetConfig.refine_rank`), then distilled from the dense
network on training images, every other weight unchanged. The student is judged by how often its masks agree
with the dense network's (`CompressResult`) and, like any checkpoint, on the held-out sets (bench_msnet.py)."""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import cast

import torch
import torch.nn.functional as F
from torch import nn

from worker.slam.errors import ConfigError
from worker.slam.segmentation.msnet.heads import grid_logits
from worker.slam.segmentation.msnet.model import MSNet, build_msnet


@dataclass(frozen=True)
class CompressConfig:
    rank: int = 1
    """Rank of the factorised refinement (1: ~4 ms less per frame on one core; 2: ~3 ms, closer to the dense)."""
    samples: int = 1200
    """Training-mixture samples whose refinement inputs are cached (~2.5 MB each at 192x256); 1/8 is held back
    to report agreement."""
    local_steps: int = 1000
    """Steps fitting the factorised layer's output to the dense layer's (MSE after the ReLU)."""
    steps: int = 2000
    """Then steps fitting the logits (KL to the dense network's per-pixel class distribution, plus the local
    MSE), with the pixel embedding's 1x1 `embed` free too."""
    batch: int = 16
    lr: float = 1e-3
    """Adam's learning rate of the local fit; the logit fit uses half of it (cosine decay in both)."""
    seed: int = 0

    def __post_init__(self) -> None:
        checks = {"rank": 1 <= self.rank <= 9, "samples": self.samples >= 2, "local_steps": self.local_steps >= 0,
                  "steps": self.steps >= 0, "batch": self.batch >= 1, "lr": 0 < self.lr <= 1}
        bad = [k for k, ok in checks.items() if not ok]
        if bad:
            raise ConfigError(f"invalid compression settings: {', '.join(bad)} (rank 1-9, samples >= 2, steps >= 0, "
                              "batch >= 1, 0 < lr <= 1)", detail={k: getattr(self, k) for k in bad})


@dataclass(frozen=True)
class CompressResult:
    """Agreement with the dense network on the held-back samples (argmax at the stride-4 grid), before the fit
    (the SVD initialisation), after the local fit and at the end."""

    agreement_svd: float
    agreement_local: float
    agreement: float
    kl_svd: float
    kl: float
    """Mean per-pixel KL divergence (nats) of the student's class distribution from the dense network's."""

    def to_dict(self) -> dict:
        return {k: round(float(v), 5) for k, v in self.__dict__.items()}


def factorise_refine(model: MSNet, rank: int) -> MSNet:
    """A copy of the dense-refinement `model` with `refine_rank = rank`, every other weight copied; the depthwise
    and 1x1 weights from the truncated SVD of each input channel's (out, 9) kernel slice, BatchNorm copied.
    At rank 9 (the most a 3x3 slice has) it is the same function up to float rounding."""
    if model.cfg.refine_rank:
        raise ConfigError(f"the refinement is already factorised (rank {model.cfg.refine_rank})")
    if rank > min(model.cfg.embed_dim, 9):
        raise ConfigError(f"rank {rank} exceeds what a ({model.cfg.embed_dim}, 9) kernel slice has")
    student = build_msnet(replace(model.cfg, refine_rank=rank))
    state = {k: v for k, v in model.state_dict().items() if not k.startswith("guidance.refine.")}
    missing, unexpected = student.load_state_dict(state, strict=False)
    assert not unexpected and all(k.startswith("guidance.refine.") for k in missing), (missing, unexpected)
    dense, bn = cast(nn.Conv2d, model.guidance.refine[0]), cast(nn.BatchNorm2d, model.guidance.refine[1])
    refine = student.guidance.refine
    dw, pw, bn_new = cast(nn.Conv2d, refine[-4]), cast(nn.Conv2d, refine[-3]), cast(nn.BatchNorm2d, refine[-2])
    w = dense.weight.detach()  # (out, in, 3, 3)
    c_out, c_in = w.shape[:2]
    with torch.no_grad():
        u, s, vh = torch.linalg.svd(w.permute(1, 0, 2, 3).reshape(c_in, c_out, 9), full_matrices=False)
        for r in range(rank):  # channel r * c_in + i of the copies carries input channel i's r-th component
            dw.weight[r * c_in:(r + 1) * c_in, 0] = vh[:, r].reshape(c_in, 3, 3)
            pw.weight[:, r * c_in:(r + 1) * c_in, 0, 0] = (u[:, :, r] * s[:, r:r + 1]).T
        bn_new.load_state_dict(bn.state_dict())
    return student.eval()


@dataclass
class _Cache:
    """Per sample: the refinement's input (N, D, h, w), the dense refinement's output, the decoder's mask
    embeddings (N, Q, D) and class distributions (N, Q, K), and the dense network's logits (N, K, h, w)."""

    inputs: torch.Tensor
    refined: torch.Tensor
    mask_embed: torch.Tensor
    class_probs: torch.Tensor
    logits: torch.Tensor


@torch.inference_mode()
def _cache(teacher: MSNet, images: torch.Tensor, batch: int) -> _Cache:
    seen: list[tuple[torch.Tensor, torch.Tensor]] = []
    hook = teacher.guidance.refine.register_forward_hook(lambda m, i, o: seen.append((i[0].clone(), o.clone())))
    parts: dict[str, list[torch.Tensor]] = {"me": [], "cp": [], "lg": []}
    try:
        for b in range(0, len(images), batch):
            f = teacher.forward_features(images[b:b + batch])
            cp = f.class_logits.softmax(-1)
            parts["me"].append(f.mask_embed)
            parts["cp"].append(cp)
            parts["lg"].append(grid_logits(f.pixel, cp, f.mask_embed))
    finally:
        hook.remove()
    return _Cache(torch.cat([s[0] for s in seen]), torch.cat([s[1] for s in seen]), torch.cat(parts["me"]),
                  torch.cat(parts["cp"]), torch.cat(parts["lg"]))


def _kl(target: torch.Tensor, logits: torch.Tensor) -> torch.Tensor:
    """Mean per-pixel KL(target || student) of (B, K, h, w) logits."""
    return F.kl_div(F.log_softmax(logits, 1), F.log_softmax(target, 1), log_target=True,
                    reduction="none").sum(1).mean()


def distil_refine(teacher: MSNet, student: MSNet, images: torch.Tensor, cfg: CompressConfig,
                  progress: Callable[[str], None] | None = None) -> CompressResult:
    """Fit `student`'s factorised refinement (and, in the second stage, its `embed`) to `teacher` on `images`
    (N, 3, H, W) RGB in [0, 1], in place; both models stay in eval mode (BatchNorm as the affine map it is at
    inference). Returns the agreement on the last eighth of `images`, which is never fitted on."""
    teacher, student = teacher.eval(), student.eval()
    gen = torch.Generator().manual_seed(cfg.seed)
    data = _cache(teacher, images, cfg.batch)
    n_val = max(len(images) // 8, 1)
    n_fit = len(images) - n_val
    if n_fit < 1:
        raise ConfigError(f"need at least 2 samples to distil, got {len(images)}")
    refine, embed = student.guidance.refine, student.guidance.embed

    def predict(idx: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        refined = refine(data.inputs[idx])
        return refined, grid_logits(embed(refined), data.class_probs[idx], data.mask_embed[idx])

    val_idx = torch.arange(n_fit, len(images))

    def agreement() -> tuple[float, float]:
        with torch.no_grad():
            _, logits = predict(val_idx)
            same = (logits.argmax(1) == data.logits[val_idx].argmax(1)).float().mean()
            return float(same), float(_kl(data.logits[val_idx], logits))

    def fit(steps: int, params: list[torch.nn.Parameter], lr: float, with_logits: bool, stage: str) -> None:
        if not steps:
            return
        opt = torch.optim.Adam(params, lr=lr)
        sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, steps)
        for step in range(steps):
            idx = torch.randint(0, n_fit, (min(cfg.batch, n_fit),), generator=gen)
            refined, logits = predict(idx)
            loss = F.mse_loss(refined, data.refined[idx])
            if with_logits:
                loss = loss + _kl(data.logits[idx], logits)
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            if progress and (step + 1) % max(steps // 8, 1) == 0:
                agree, kl = agreement()
                progress(f"{stage} {step + 1}/{steps}: loss {loss.item():.5f}, held-back agreement {agree:.4f}, "
                         f"KL {kl:.5f}")

    with torch.enable_grad():
        agree_svd, kl_svd = agreement()
        fit(cfg.local_steps, list(refine.parameters()), cfg.lr, False, "local")
        agree_local, _ = agreement()
        fit(cfg.steps, [*refine.parameters(), *embed.parameters()], cfg.lr / 2, True, "logits")
    agree, kl = agreement()
    return CompressResult(agree_svd, agree_local, agree, kl_svd, kl)


def mixture_images(dataset, n: int) -> torch.Tensor:
    """(n, 3, H, W) the first n samples of a training mixture (`MixtureDataset`: deterministic per index)."""
    if len(dataset) == 0:
        raise ConfigError("the training mixture is empty")
    return torch.stack([dataset[i]["image"] for i in range(n)])  # past len(dataset): the next epochs' draws
