"""`vtdslam train-msnet` and `vtdslam eval-msnet`: train MSNET and measure a segmenter (mIoU, MPA, latency)."""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path
from typing import Annotated

import typer


def register(app: typer.Typer) -> None:
    app.command("train-msnet")(train_command)
    app.command("eval-msnet")(eval_command)
    app.command("export-msnet")(export_command)
    app.command("compress-msnet")(compress_command)


def _shared_default() -> str:
    return os.environ.get("VTD_SHARED_DIR", "../shared")


def render_synthetic_rooms(cfg) -> None:
    """Render the recipe's synthetic rooms (`synth_seeds`) that its cache folder lacks: about a minute each."""
    from worker.slam.segmentation.train.synthetic import synthetic_folder
    from worker.slam.synth.generator import SynthConfig, generate_synthetic

    shared = cfg.path("{shared}")
    for seed in cfg.synth_seeds:
        folder = synthetic_folder(cfg, seed)
        if not (folder / "truth" / "truth.json").is_file():
            typer.echo(f"rendering synthetic room {seed} into {folder}")
            generate_synthetic(folder, SynthConfig(frames=cfg.synth_frames, people=cfg.synth_people, seed=seed,
                                                   shared_dir=shared if shared.is_dir() else None))


def train_command(
    config: Annotated[str, typer.Option(help="Preset (cpu-tum = the shipped recipe, cpu-real = real people at scale, "
                                             "cpu-real-mnv2 = its data on a pretrained MobileNetV2 path, "
                                             "cpu-voc = the 21 VOC classes with class-presence queries (with "
                                             "--init-partial a person checkpoint), "
                                             "cpu-tum-ft, cpu-real-tum-ft and cpu-real-mnv2-neg = fine-tunes "
                                             "needing --init, "
                                             "cpu, paper, smoke) or a JSON "
                                             "file (keys of TrainConfig; optional \"preset\" base).")] = "cpu-tum",
    out: Annotated[Path | None, typer.Option(help="Output folder (checkpoints, metrics.jsonl).")] = None,
    resume: Annotated[bool, typer.Option(help="Continue from OUT/last.pt.")] = False,
    init: Annotated[Path | None, typer.Option(help="Fine-tune: start from this checkpoint's weights (e.g. the "
                                                   "msnet.pt of a cpu-tum run for cpu-tum-ft).")] = None,
    init_partial: Annotated[Path | None, typer.Option(
        help="Start every tensor whose name and shape match from this checkpoint (e.g. a person MSNET for a "
             "multi-class model); the rest starts pretrained or random.")] = None,
    epochs: Annotated[int | None, typer.Option(help="Override the number of epochs.")] = None,
    batch_size: Annotated[int | None, typer.Option(help="Override the batch size.")] = None,
    lr: Annotated[float | None, typer.Option(help="Override the peak learning rate.")] = None,
    samples_per_epoch: Annotated[int | None, typer.Option(help="Override samples per epoch.")] = None,
    time_budget_min: Annotated[float | None, typer.Option(help="Override the wall-clock cap (minutes).")] = None,
    shared_dir: Annotated[str | None, typer.Option(help="Shared data folder (default $VTD_SHARED_DIR or "
                                                         "../shared).")] = None,
    export: Annotated[Path | None, typer.Option(help="Copy the final weights here (e.g. the package's "
                                                     "weights/msnet_default.pt).")] = None,
    progress: Annotated[bool, typer.Option(help="Show a progress bar.")] = True,
) -> None:
    """Train MSNET: labelled YOLO-seg / COCO images, copy-paste composites, teacher distillation."""
    from worker.slam.segmentation.train.config import load_train_config
    from worker.slam.segmentation.train.trainer import train

    base = {"cpu-tum-ft": "cpu-tum", "cpu-real-tum-ft": "cpu-real", "cpu-real-mnv2-neg": "cpu-real-mnv2"}
    if config in base and init is None and not resume:
        raise typer.BadParameter(f"{config} continues a {base[config]} run: pass --init RUN/msnet.pt",
                                 param_hint="--init")
    cfg = load_train_config(config, out_dir=str(out) if out else None, epochs=epochs, batch_size=batch_size, lr=lr,
                            samples_per_epoch=samples_per_epoch, time_budget_min=time_budget_min,
                            init_weights=str(init) if init else None,
                            init_partial=str(init_partial) if init_partial else None,
                            shared_dir=shared_dir or _shared_default())
    render_synthetic_rooms(cfg)
    weights = train(cfg, resume=resume, progress=progress)
    if export is not None:
        export.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(weights, export)
    typer.echo(f"weights: {export or weights}")


def export_command(
    src: Annotated[Path, typer.Argument(help="A trained checkpoint (a run's msnet.pt).")],
    dest: Annotated[Path, typer.Argument(help="Where to write it (e.g. worker/slam/segmentation/weights/"
                                              "msnet_default.pt).")],
    dynamic_classes: Annotated[str | None, typer.Option(
        help="Comma-separated classes the pipeline treats as potentially dynamic (default: as trained). A class "
             "without held-out IoU >= 0.5 on real images is not shipped as dynamic (MODEL_CARD.md).")] = None,
    note: Annotated[str, typer.Option(help="Why, recorded in the checkpoint's metadata.")] = "",
) -> None:
    """Copy a trained MSNET checkpoint, optionally narrowing its potentially dynamic classes."""
    from worker.slam.errors import ConfigError
    from worker.slam.segmentation.msnet.checkpoint import export_model

    classes = tuple(c.strip() for c in dynamic_classes.split(",") if c.strip()) if dynamic_classes else None
    try:
        export_model(src, dest, classes, note)
    except ConfigError as exc:
        raise typer.BadParameter(exc.message) from exc
    typer.echo(f"weights: {dest}" + (f" (potentially dynamic: {', '.join(classes)})" if classes else ""))


def compress_command(
    src: Annotated[Path, typer.Argument(help="A checkpoint with the dense refinement (e.g. the shipped "
                                             "worker/slam/segmentation/weights/msnet_default.pt).")],
    dest: Annotated[Path, typer.Argument(help="Where to write the factorised checkpoint.")],
    rank: Annotated[int, typer.Option(help="Rank of the factorised refinement (1-9; 1 is cheapest).")] = 1,
    recipe: Annotated[str, typer.Option(help="Training preset whose image mixture (and validation split) is "
                                             "used; its teachers are not needed.")] = "cpu-real-tum-ft",
    samples: Annotated[int, typer.Option(help="Mixture samples cached (1/8 held back for the agreement).")] = 1200,
    local_steps: Annotated[int, typer.Option(help="Steps fitting the layer's output.")] = 1000,
    steps: Annotated[int, typer.Option(help="Then steps fitting the logits.")] = 2000,
    threads: Annotated[int, typer.Option(help="CPU threads (0 = the library default).")] = 0,
    shared_dir: Annotated[str | None, typer.Option(help="Shared data folder (default $VTD_SHARED_DIR or "
                                                         "../shared).")] = None,
) -> None:
    """Make MSNET cheaper: factorise its 3x3 refinement and distil it from the dense network (CPU, minutes)."""
    from dataclasses import replace

    import torch

    from worker.slam.errors import ConfigError
    from worker.slam.segmentation.msnet.checkpoint import load_model, save_model
    from worker.slam.segmentation.train.compress import CompressConfig, distil_refine, factorise_refine, mixture_images
    from worker.slam.segmentation.train.config import load_train_config
    from worker.slam.segmentation.train.data import build_training_data
    from worker.slam.segmentation.train.trainer import validate

    try:
        cfg = CompressConfig(rank=rank, samples=samples, local_steps=local_steps, steps=steps)
        teacher, meta = load_model(src)
        train_cfg = load_train_config(recipe, shared_dir=shared_dir or _shared_default())
        # the mixture's images only: no teacher labels are needed, so none are computed
        train_cfg = replace(train_cfg, teacher=None, extra_teachers=(), target_frames=(), bn_extra_frames=(),
                            model=teacher.cfg)
        student = factorise_refine(teacher, cfg.rank)
    except ConfigError as exc:
        raise typer.BadParameter(exc.message) from exc
    if threads:
        torch.set_num_threads(threads)
    data = build_training_data(train_cfg)
    typer.echo(f"caching {cfg.samples} samples of the {recipe} mixture ...")
    result = distil_refine(teacher, student, mixture_images(data.train, cfg.samples), cfg, progress=typer.echo)
    val = {}  # person IoU on the recipe's validation split (selection data, never a test image)
    if data.selection and "person" in teacher.cfg.classes:
        for name, model in (("dense", teacher), ("factorised", student)):
            val[name] = validate(model, data.selection, torch.device("cpu"))["val_iou"]["person"]
    record = {**result.to_dict(), "val_person_iou": val, "rank": cfg.rank, "samples": cfg.samples,
              "local_steps": cfg.local_steps, "steps": cfg.steps, "recipe": recipe}
    save_model(dest, student.eval(), {**meta, "compressed_from": str(src), "compress": record})
    typer.echo(json.dumps(record, indent=2))
    typer.echo(f"weights: {dest}")


def eval_command(
    data: Annotated[Path | None, typer.Option(help="YOLO-seg folder (default: shared coco128_seg).")] = None,
    split: Annotated[str, typer.Option(help="held-out (every n-th image, as in training) or all.")] = "held-out",
    holdout_every: Annotated[int, typer.Option(help="n of the held-out split.")] = 5,
    backend: Annotated[str, typer.Option(help="Segmenter backend: msnet or tflite-teacher.")] = "msnet",
    checkpoint: Annotated[Path | None, typer.Option(help="msnet checkpoint (default: shipped).")] = None,
    model_path: Annotated[Path | None, typer.Option(help="tflite-teacher: .tflite model.")] = None,
    threads: Annotated[int, typer.Option(help="CPU threads.")] = 2,
    guided_radius: Annotated[int, typer.Option(
        help="msnet: guided-upsampling radius on the network's output grid, e.g. 13; 0 = bilinear.")] = 0,
    as_json: Annotated[bool, typer.Option("--json", help="Print the metrics as JSON.")] = False,
) -> None:
    """Per-class IoU and pixel accuracy, mIoU, MPA and latency of a segmenter on a labelled set."""
    from worker.slam.segmentation.base import SegmenterConfig, make_segmenter
    from worker.slam.segmentation.evaluate import evaluate_segmenter, labelled_samples
    from worker.slam.segmentation.train.datasets import load_yolo_seg, split_holdout

    if split not in ("held-out", "all"):
        raise typer.BadParameter("split must be held-out or all")
    if guided_radius < 0:
        raise typer.BadParameter("must be >= 0", param_hint="--guided-radius")
    seg = make_segmenter(SegmenterConfig(backend=backend, checkpoint=str(checkpoint) if checkpoint else None,
                                         model_path=str(model_path) if model_path else None, threads=threads,
                                         guided_radius=guided_radius))
    root = data or Path(_shared_default()) / "data" / "coco128_seg"
    classes = ("background", "person", "chair")
    items = load_yolo_seg(root, {0: "person", 56: "chair"})
    if split == "held-out":
        items = split_holdout(items, holdout_every)[1]
    m = evaluate_segmenter(seg, labelled_samples(items, classes), classes)
    if as_json:
        typer.echo(json.dumps(m.to_dict(), indent=2))
        return
    typer.echo(f"{len(items)} images  mIoU {m.miou:.3f}  MPA {m.mpa:.3f}  latency {m.latency_ms:.1f} ms/image")
    for c in classes:
        iou, acc = m.iou[c], m.pixel_acc[c]
        typer.echo(f"  {c:<12} IoU {'n/a' if iou is None else f'{iou:.3f}'}  "
                   f"PA {'n/a' if acc is None else f'{acc:.3f}'}")
