"""Training configuration: one dataclass, named presets, JSON files layered over a preset."""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from formats.class_names import COCO_CLASSES
from worker.slam.errors import ConfigError
from worker.slam.segmentation.classes import COCO_TO_VOC, DEFAULT_DYNAMIC, VOC_CLASSES
from worker.slam.segmentation.msnet.config import MsnetConfig


@dataclass(frozen=True)
class TrainConfig:
    """Everything a training run depends on; `{shared}` in paths expands to `shared_dir`."""

    model: MsnetConfig = field(default_factory=MsnetConfig)
    """Architecture of the network being trained."""
    shared_dir: str = "../shared"
    """Where the shared data and teacher models live (the CLI fills it from VTD_SHARED_DIR)."""
    yolo_dirs: tuple[str, ...] = ("{shared}/data/coco128_seg",)
    """YOLO-seg datasets (images/ + labels/ with normalised polygons)."""
    yolo_class_ids: dict[str, int] = field(default_factory=lambda: {"person": 0, "chair": 56})
    """Our class name -> YOLO (COCO-80) class id."""
    coco_json: tuple[tuple[str, str], ...] = ()
    """(instances JSON, image folder) pairs in COCO format; categories match by name."""
    coco_names: dict[str, str] = field(default_factory=lambda: {"person": "person", "chair": "chair"})
    """COCO category name -> our class name."""
    mask_dirs: tuple[tuple[str, str], ...] = ()
    """(folder, class) mask folders (`images/` + `masks/`, one labelled main subject per image: CCP). Split by
    `datasets.hash_split`: a fixed share of them is the test split and never trained on."""
    synth_seeds: tuple[int, ...] = ()
    """Seeds of synthetic rooms (`vtdslam synth`) whose walkers' exact masks are person training labels
    (`train.synthetic`); keep them apart from the benchmark's seeds 0-3."""
    synth_frames: int = 240
    """Frames rendered per synthetic room."""
    synth_people: int = 3
    """Walkers per synthetic room."""
    synth_stride: int = 4
    """Every n-th synthetic frame is a training image."""
    mask_test_fraction: float = 0.25
    """Share of each mask folder's images (by a seeded hash of the file name) held out as its test split."""
    mask_val_fraction: float = 0.1
    """Share of each mask folder's images held out as its validation split (checkpoint selection)."""
    split_seed: int = 0
    """Seed of the hash split; changing it changes the test split (never do that between runs you compare)."""
    holdout_every: int = 5
    """Every n-th labelled image (sorted by path) is held out as the test split and never trained on."""
    val_every: int = 0
    """Every n-th of the remaining (training) images is carved out as a validation split for checkpoint and
    AdaBN selection, so that the held-out test split is not used for selection; 0 validates on the held-out
    split (the old behaviour)."""
    backgrounds: tuple[str, ...] = ("{shared}/data/7scenes_redkitchen/data/*.color.jpg",)
    """Globs of unlabelled background frames for copy-paste and distillation (assumed free of people)."""
    background_stride: int = 2
    """Use every n-th background frame (neighbouring video frames are near-duplicates)."""
    target_frames: tuple[str, ...] = ()
    """Globs of unlabelled target-domain frames that may contain people (e.g. TUM walking_halfsphere). They are
    trained on with the teacher's soft labels (its person mass kept), with strong crops, zoom, flips and colour
    jitter; their teacher person masks also give person cut-outs. They are training frames, not held out."""
    p_target: float = 0.0
    """Probability that a sample is a target frame (teacher-labelled) rather than a labelled image or composite."""
    p_target_background: float = 0.0
    """Probability that a composite is built on a target frame (its teacher labels, people included) rather
    than on a people-free background."""
    target_scale: tuple[float, float] = (1.0, 2.5)
    """Zoom range of target-frame crops (1 = the whole frame fills the input)."""
    target_jitter: float = 0.4
    """Colour-jitter strength for target-frame samples (plus a per-channel gain: white balance)."""
    target_confidence: float = 0.8
    """Target frames get a hard label only where the teacher's top probability reaches this; elsewhere the
    soft label alone trains them."""
    forbidden: tuple[str, ...] = ("{shared}/data/tum_frames/fr3_walking_xyz",)
    """Folders (or globs of files) that must never feed training, validation or BN statistics (test frames); a
    config whose data reaches into them is rejected. `data.ALWAYS_FORBIDDEN` (the evaluation-only sets) is added to it
    whatever a config says."""
    bn_extra_frames: tuple[str, ...] = ()
    """Extra globs added to the AdaBN frames (e.g. the target frames). The trainer validates the EMA weights
    without AdaBN, with AdaBN on the backgrounds and with these added, and keeps the best on validation."""
    teacher: str | None = "{shared}/models/deeplabv3_257_mv_gpu.tflite"
    """TFLite teacher for soft labels; None trains on labels and pasted masks only."""
    extra_teachers: tuple[str, ...] = ()
    """More TFLite teachers whose probabilities (resampled to the first teacher's grid) are averaged with its
    own; classes a teacher lacks count as probability 0 in its vote."""
    cache_dir: str = "/tmp/msnet_cache"
    """Teacher soft labels are computed once and kept here."""
    init_weights: str | None = None
    """Start from the weights of this checkpoint (as saved by this trainer, e.g. an earlier run's `msnet.pt`)
    instead of a random initialisation: fine-tuning. Its architecture must equal `model`. Ignored on resume."""
    init_pretrained: str | None = None
    """A float DeepLabV3-MobileNetV2 .tflite (Apache-2.0) whose MobileNetV2 weights start the pyramid's CNN path
    when `model.cnn` is "mobilenetv2" (the rest starts random). Ignored with `init_weights` or on resume."""
    init_partial: str | None = None
    """Start every parameter whose name and shape match from this MSNET checkpoint (e.g. the shipped person network
    for a multi-class model: its backbone and guidance; the class-sized layers and whatever the architecture adds
    start as `init_pretrained` or random). Its CNN path then trains at `pretrained_lr_scale`. Ignored on resume."""
    pretrained_lr_scale: float = 1.0
    """Learning rate of the `init_pretrained` layers relative to `lr` (below 1 keeps them nearer their start)."""
    out_dir: str = "runs/msnet"
    """Checkpoints (`last.pt` for resume, `msnet.pt` weights) and `metrics.jsonl`."""
    epochs: int = 40
    """Passes over `samples_per_epoch` freshly drawn samples."""
    samples_per_epoch: int = 2000
    """Samples per epoch (composites are generated, so an epoch is a budget, not a dataset size)."""
    batch_size: int = 8
    lr: float = 1.5e-3
    """Peak AdamW learning rate (one-cycle: warm-up then cosine decay)."""
    weight_decay: float = 0.01
    warmup_fraction: float = 0.05
    ema_decay: float = 0.998
    """Exponential moving average of the weights (and BN statistics) that is validated and saved; smooths the
    epoch-to-epoch swings of a network trained from scratch on little data. 0 disables it."""
    bn_recalibration_stride: int = 5
    """After training, re-estimate BatchNorm statistics on every n-th background frame (AdaBN); 0 disables."""
    kd_weight: float = 1.0
    """Weight of the soft-label (teacher) cross-entropy against the hard-label cross-entropy."""
    query_weight: float = 0.1
    """Weight of the loss that keeps decoder query q predicting class q."""
    class_weights: tuple[float, ...] = (1.0, 2.0, 1.5)
    """Cross-entropy weight per class (people matter most to the SLAM pipeline)."""
    p_labelled: float = 0.4
    """Probability that a sample is a labelled image rather than a copy-paste composite."""
    person_free_weight: float = 1.0
    """Sampling weight of a labelled image with no person in it (a real photo of anything else: animals,
    furniture, streets) relative to one with people. Above 1 shows the network more real non-person textures
    as certain negatives (tried at 4 against held-out COCO's animals marked as person: MODEL_CARD.md)."""
    p_negative: float = 0.0
    """Probability that a sample is a people-free background frame with nothing pasted (a hard negative: its
    teacher person mass moved to background, every pixel labelled)."""
    max_pastes: int = 3
    """Up to this many cut-outs per composite (zero sometimes: pure background frames are distilled too)."""
    p_chair_paste: float = 0.3
    """Probability that a pasted cut-out is a chair rather than a person."""
    p_distractor_paste: float = 0.35
    """Probability that a pasted cut-out is another object (labelled background), so that being pasted is not
    itself a cue for person/chair."""
    distractor_height: tuple[float, float] = (0.15, 0.7)
    """Pasted distractor height as a fraction of the image height."""
    person_height: tuple[float, float] = (0.35, 1.1)
    """Pasted person height as a fraction of the image height."""
    chair_height: tuple[float, float] = (0.2, 0.6)
    time_budget_min: float | None = None
    """Wall-clock cap: the LR schedule runs on max(step fraction, time fraction) and training stops at the
    cap, so a run on a shared CPU still anneals and finishes. None = train all epochs."""
    seed: int = 0
    threads: int = 1
    """Torch CPU threads. On a shared, oversubscribed CPU one thread was 10x faster than two (OpenMP threads
    wait for each other when the scheduler parks one of them); raise it on a dedicated machine."""
    workers: int = 1
    """DataLoader worker processes generating samples."""
    device: str = "auto"
    """`auto` uses CUDA when present."""

    def path(self, value: str) -> Path:
        return Path(value.replace("{shared}", self.shared_dir)).expanduser()

    def to_dict(self) -> dict:
        return asdict(self)


def _from_dict(base: TrainConfig, data: dict) -> TrainConfig:
    known = {f.name for f in fields(TrainConfig)}
    unknown = set(data) - known - {"preset"}
    if unknown:
        raise ConfigError(f"unknown training config keys: {sorted(unknown)}")
    values: dict[str, Any] = {}
    for k, v in data.items():
        if k == "preset":
            continue
        if k == "model":
            values[k] = MsnetConfig.from_dict({**base.model.to_dict(), **v})
        elif isinstance(v, list):
            values[k] = tuple(tuple(x) if isinstance(x, list) else x for x in v)
        else:
            values[k] = v
    return replace(base, **values)


def presets() -> dict[str, TrainConfig]:
    """`cpu-real-mnv2`: `cpu-real-tum-ft`'s data on a pyramid whose CNN path starts from the teacher's
    MobileNetV2 (issue 20's allowed pretrained initialisation). `cpu-real-mnv2-neg`: a fine-tune of it (needs
    `init_weights`) on more person-free real photos.
    `cpu-real`: real people at scale (issue 20; the recipe for the next checkpoint, 3 h on this CPU).
    `cpu-real-tum-ft`: a `cpu-real` run fine-tuned with the TUM halfsphere frames (needs `init_weights`).
    `cpu-tum`: the recipe of the shipped checkpoint (adds teacher distillation on the TUM walking_halfsphere
    frames). `cpu-tum-ft`: a fine-tuning experiment on top of it (needs `init_weights`, a `cpu-tum` msnet.pt).
    `cpu`: the previous recipe (no TUM frames). `paper`: the paper's hyper-parameters (for a GPU).
    `smoke`: seconds-long run for tests."""
    cpu = TrainConfig(time_budget_min=58.0)
    halfsphere = "{shared}/data/tum_frames/fr3_walking_halfsphere/*.png"
    cpu_tum = replace(cpu, time_budget_min=75.0, epochs=100, val_every=6, target_frames=(halfsphere,),
                      p_target=0.3, p_labelled=0.3, p_target_background=0.3, bn_extra_frames=(halfsphere,))
    # Fine-tuning a `cpu-tum` run at a lower peak lr with more composites of COCO people on 7-Scenes backgrounds.
    # Measured and not shipped: better on held-out COCO, worse on walking_xyz (MODEL_CARD.md).
    cpu_tum_ft = replace(cpu_tum, time_budget_min=45.0, lr=5e-4, warmup_fraction=0.02, seed=1, p_target=0.25,
                         p_labelled=0.25, p_target_background=0.25, p_distractor_paste=0.3)
    # Real people at scale (issue 20): CCP (hash split) and COCO128 labelled samples, their full-body cut-outs
    # pasted on 7-Scenes frames 0-899 (900-999 are held out for the false-positive figure), people-free hard
    # negatives, and two DeepLabV3 teachers averaged on every image. 170 min of training leaves the teacher caches
    # and the AdaBN selection inside 3 h. Not yet trained to the end (MODEL_CARD.md).
    kitchen = "{shared}/data/7scenes_redkitchen/data"
    cpu_real = replace(cpu, time_budget_min=170.0, epochs=400, samples_per_epoch=2000, val_every=6,
                       mask_dirs=(("{shared}/data/ccp_persons", "person"),), p_labelled=0.45, p_negative=0.1,
                       backgrounds=(kitchen + "/frame-000[0-8]*.color.jpg",),
                       forbidden=(*cpu.forbidden, kitchen + "/frame-0009*"),
                       extra_teachers=("{shared}/models/deeplabv3_mnv2_pascal_quant.tflite",),
                       p_distractor_paste=0.3, p_chair_paste=0.15, person_height=(0.3, 1.1),
                       cache_dir="/tmp/msnet_cache_real")
    # Fine-tuning a `cpu-real` run (`--init` its msnet.pt) with the TUM walking_halfsphere frames distilled as in
    # `cpu-tum`: the `cpu-real` run found no one on walking_xyz and few of the synthetic room's people
    # (MODEL_CARD.md).
    cpu_real_tum_ft = replace(cpu_real, time_budget_min=30.0, lr=5e-4, warmup_fraction=0.02, seed=1,
                              target_frames=(halfsphere,), p_target=0.25, p_labelled=0.35, p_target_background=0.3,
                              bn_extra_frames=(halfsphere,))
    # `cpu-real-tum-ft`'s data from the start, the pyramid's CNN path a MobileNetV2 initialised from the 257
    # teacher's (Apache-2.0) and trained at a fifth of the rate of the layers that start random.
    cpu_real_mnv2 = replace(cpu_real_tum_ft, time_budget_min=80.0, lr=1e-3, warmup_fraction=0.03, seed=0,
                            model=replace(cpu.model, cnn="mobilenetv2", refine_rank=2),
                            init_pretrained=cpu.teacher, pretrained_lr_scale=0.2)
    # Fine-tuning a `cpu-real-mnv2` run (`--init` its msnet.pt) with the person-free labelled photos (COCO128's
    # animals, furniture, streets) drawn 4x as often, for its held-out COCO errors on animal photos. Measured
    # and not shipped: held-out COCO slightly worse (MODEL_CARD.md).
    cpu_real_mnv2_neg = replace(cpu_real_mnv2, time_budget_min=35.0, lr=3e-4, warmup_fraction=0.02, seed=1,
                                init_pretrained=None, person_free_weight=4.0)
    # Issue 57: the 21 PASCAL VOC classes (COCO128's polygons of the 20 VOC classes, both teachers' 21-class
    # probabilities, cut-outs of every class pasted on the kitchen), people of six synthetic rooms with their exact
    # masks, and class queries that decide per image which classes are present. Started (`--init-partial`) from
    # the `cpu-real-mnv2` person network: its backbone and guidance carry over, the class-sized layers start fresh.
    cpu_voc = replace(cpu_real_mnv2, time_budget_min=60.0, lr=8e-4, warmup_fraction=0.03, seed=0,
                      model=replace(cpu_real_mnv2.model, classes=VOC_CLASSES, dynamic_classes=DEFAULT_DYNAMIC,
                                    class_head="presence"),
                      yolo_class_ids={voc: COCO_CLASSES.index(coco) for coco, voc in COCO_TO_VOC.items()},
                      coco_names=dict(COCO_TO_VOC),
                      class_weights=tuple(2.0 if c == "person" else 1.0 for c in VOC_CLASSES), query_weight=0.5,
                      p_chair_paste=0.45, chair_height=(0.15, 0.7), synth_seeds=tuple(range(100, 106)),
                      synth_stride=8, cache_dir="/tmp/msnet_cache_voc")
    return {
        "cpu-voc": cpu_voc,
        "cpu-real-mnv2": cpu_real_mnv2,
        "cpu-real-mnv2-neg": cpu_real_mnv2_neg,
        "cpu-real": cpu_real,
        "cpu-real-tum-ft": cpu_real_tum_ft,
        "cpu-tum": cpu_tum,
        "cpu-tum-ft": cpu_tum_ft,
        "cpu": cpu,
        "paper": replace(cpu, lr=1e-3, epochs=64, batch_size=4, samples_per_epoch=20000, workers=4, threads=0,
                         time_budget_min=None, model=replace(cpu.model, dropout=0.56)),
        "smoke": replace(cpu, epochs=1, samples_per_epoch=8, batch_size=4, workers=0, teacher=None,
                         background_stride=50, time_budget_min=None),
    }


def load_train_config(spec: str, **overrides) -> TrainConfig:
    """A preset name, or a JSON file (optionally with "preset": NAME as its base, default `cpu`)."""
    table = presets()
    if spec in table:
        cfg = table[spec]
    else:
        path = Path(spec)
        if not path.is_file():
            raise ConfigError(f"{spec!r} is neither a preset ({', '.join(table)}) nor a config file")
        try:
            data = json.loads(path.read_text())
        except json.JSONDecodeError as exc:
            raise ConfigError(f"{path}: invalid JSON: {exc}") from exc
        base = data.get("preset", "cpu")
        if base not in table:
            raise ConfigError(f"{path}: unknown base preset {base!r}")
        cfg = _from_dict(table[base], data)
    return _from_dict(cfg, {k: v for k, v in overrides.items() if v is not None})
