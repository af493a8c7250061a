"""`vtdslam train-vocab --out FILE`: train the ORB vocabulary tree used for place recognition."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer


def register(app: typer.Typer) -> None:
    app.command("train-vocab")(train_vocab_command)


def train_vocab_command(
    out: Annotated[Path, typer.Option("--out", help="Vocabulary file to write (.npz).")],
    images: Annotated[list[Path] | None, typer.Option(
        "--images", help="Folder of training images (recursive; repeatable). Default: COCO128 and CCP persons "
                         "from VTD_SHARED_DIR. Evaluation-only data (bonn_crowd_dev, davis_movers_dev) is refused.")
    ] = None,
    every: Annotated[int, typer.Option(help="Use every n-th image of each folder.")] = 1,
    k: Annotated[int, typer.Option(help="Children per node.")] = 10,
    levels: Annotated[int, typer.Option(help="Tree depth (at most k^levels words).")] = 4,
    max_descriptors: Annotated[int, typer.Option(help="Descriptors clustered at most (random subset).")] = 400_000,
    seed: Annotated[int, typer.Option(help="Random seed (subset, k-means++ seeding).")] = 0,
) -> None:
    """Hierarchical k-majority clustering of the images' ORB descriptors (the runtime's extractor) into a
    k-ary tree of binary words with idf weights; see worker/slam/features/data/VOCABULARY.md."""
    from storage.settings import get_settings
    from worker.slam.vocab_train.train import VocabTrainConfig, image_paths, train_vocabulary

    if images is None:
        shared = Path(get_settings().shared_dir) / "data"
        images = [shared / "coco128_seg" / "images", shared / "ccp_persons" / "images"]
    try:
        paths = image_paths(images, every)
    except (ValueError, FileNotFoundError) as exc:
        raise typer.BadParameter(str(exc), param_hint="--images") from exc
    if not paths:
        raise typer.BadParameter("no images found", param_hint="--images")
    cfg = VocabTrainConfig(k=k, levels=levels, max_descriptors=max_descriptors, seed=seed)
    res = train_vocabulary(paths, cfg, progress=typer.echo)
    out.parent.mkdir(parents=True, exist_ok=True)
    res.vocabulary.save(out)
    typer.echo(f"wrote {out} ({out.stat().st_size / 1e6:.2f} MB): {res.vocabulary.n_words} words, "
               f"{len(res.vocabulary.centres)} nodes, from {res.n_images} images, {res.n_clustered} of "
               f"{res.n_descriptors} descriptors clustered, {res.seconds:.0f} s")
