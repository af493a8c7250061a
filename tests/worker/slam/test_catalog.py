"""The explicit catalog (sections, stages, presets) and the stage contracts it checks: no import fills a registry,
a snapshot loads in a fresh interpreter, wrong stage orders are refused, and each stage does what it declares."""
from __future__ import annotations

import ast
import dataclasses
import inspect
import json
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import pytest

from formats.catalog import PIPELINE_PRESETS, STAGE_CONTRACTS
from tests.worker.slam.synthetic_room import trajectory, write_sequence
from worker.slam.camera import parse_camera
from worker.slam.catalog import shipped_catalog
from worker.slam.config import PipelineConfig
from worker.slam.dynamic.stage import CullingStage
from worker.slam.errors import ConfigError
from worker.slam.inpainting.stage import RestorationStage
from worker.slam.io.sequence import Sequence
from worker.slam.pipeline import run_pipeline
from worker.slam.presets import get_preset
from worker.slam.segmentation.stage import SegmentationStage
from worker.slam.stages import FrameInputs
from worker.slam.synth.generator import SynthConfig, generate_synthetic

ROOT = Path(__file__).resolve().parents[3]
STAGE_CLASSES = (SegmentationStage, CullingStage, RestorationStage)
BOOKKEEPING = {"info", "prepared", "deferred", "deferred_delay"}
"""FrameInputs fields that carry no product between stages."""
SNAPSHOT_KEYS = ["name", "stages", "features", "tracking", "mapping", "loop", "dense", "eval",
                 "segmentation", "culling", "restoration"]


def test_a_fresh_interpreter_loads_a_full_snapshot_without_importing_the_presets(tmp_path: Path) -> None:
    overrides = {"culling.lag_frames": 7, "restoration.reference_margin_px": 9}
    snapshot = shipped_catalog().preset("full", overrides).to_dict()
    assert list(snapshot) == SNAPSHOT_KEYS
    path = tmp_path / "config.json"
    path.write_text(json.dumps(snapshot, indent=1))
    code = ("import json, sys\n"
            "from worker.slam.catalog import shipped_catalog\n"
            "cfg = shipped_catalog().config_from_dict(json.load(open(sys.argv[1])))\n"
            "assert 'worker.slam.presets' not in sys.modules\n"
            "print(json.dumps(cfg.to_dict()))\n")
    done = subprocess.run([sys.executable, "-c", code, str(path)], cwd=ROOT, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout) == snapshot


def test_the_bare_config_knows_the_core_sections_only_whatever_was_imported() -> None:
    snapshot = get_preset("full").to_dict()
    with pytest.raises(ConfigError, match="unknown config section 'segmentation'"):
        PipelineConfig.from_dict(snapshot)
    assert list(PipelineConfig().to_dict()) == SNAPSHOT_KEYS[:-3]
    assert list(shipped_catalog().base_config().to_dict()) == SNAPSHOT_KEYS


def test_the_catalog_holds_the_formats_presets_and_contracts() -> None:
    catalog = shipped_catalog()
    assert list(catalog.stages) == list(catalog.sections) == list(STAGE_CONTRACTS)
    assert catalog.describe_presets() == {p.name: p.description for p in PIPELINE_PRESETS}
    for cls in STAGE_CLASSES:
        assert cls.contract is STAGE_CONTRACTS[cls.name]
        assert catalog.stages[cls.name].contract is cls.contract and catalog.stages[cls.name].factory is cls
    products = {f.name for f in dataclasses.fields(FrameInputs)} - BOOKKEEPING
    for c in STAGE_CONTRACTS.values():
        assert {*c.needs, *c.uses, *c.provides} <= products, c


@pytest.mark.parametrize("cls", STAGE_CLASSES, ids=lambda c: c.name)
def test_a_stage_reads_only_what_its_contract_names(cls) -> None:
    """Every `inputs.<field>` its module reads is a product it needs, uses or provides itself."""
    tree = ast.parse(inspect.getsource(sys.modules[cls.__module__]))
    read = {n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute) and isinstance(n.value, ast.Name)
            and n.value.id == "inputs" and isinstance(n.ctx, ast.Load)} - BOOKKEEPING - {"track_inputs"}
    c = cls.contract
    assert read <= {*c.needs, *c.uses, *c.provides}, read - {*c.needs, *c.uses, *c.provides}


class _Watch:
    """Runs a stage and records which FrameInputs fields its `process` set."""

    def __init__(self, stage, seen: dict[str, set[str]]) -> None:
        self.stage, self.name, self.seen = stage, stage.name, seen

    def __getattr__(self, attr: str):
        return getattr(self.stage, attr)

    def process(self, frame, inputs, ctx):
        before = {f.name: getattr(inputs, f.name) for f in dataclasses.fields(inputs)}
        out = self.stage.process(frame, inputs, ctx)
        self.seen[self.name] |= {n for n, v in before.items() if getattr(out, n) is not v}
        return out


def test_each_stage_sets_only_what_it_provides(tmp_path: Path) -> None:
    generate_synthetic(tmp_path / "seq", SynthConfig(frames=6, people=2, trajectory="walk", seed=3,
                                                     shared_dir=tmp_path / "noshared"))
    seq = Sequence(tmp_path / "seq")
    catalog = shipped_catalog()
    cfg = catalog.preset("full", {"segmentation.source": "truth", "restoration.on_demand": False,
                                  "dense.enabled": False})
    seen: dict[str, set[str]] = defaultdict(set)
    run_pipeline(seq, cfg, stages=[_Watch(s, seen) for s in catalog.build_stages(cfg, seq.camera)])
    for name, contract in STAGE_CONTRACTS.items():
        assert seen[name] - BOOKKEEPING, name  # it did something
        assert seen[name] - BOOKKEEPING <= set(contract.provides), (name, seen[name])


@pytest.mark.parametrize("preset, overrides, uses", [
    ("geometry-only", None, False),
    ("geometry-only", {"culling.culling.use_segmentation": True}, False),  # an optional input: nothing provides it
    ("no-restoration", None, True),
    ("full", None, True),
])
def test_culling_uses_the_mask_when_an_earlier_stage_provides_it(preset, overrides, uses) -> None:
    assert CullingStage(get_preset(preset, overrides), parse_camera("tum3")).use_segmentation is uses


@pytest.mark.parametrize("stages", [["restoration"], ["segmentation", "restoration", "culling"]])
def test_the_pipeline_refuses_a_stage_whose_input_no_earlier_stage_provides(stages, tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="'restoration' needs dynamic_mask"):
        get_preset("full", {"stages": stages})
    cfg = shipped_catalog().base_config()
    cfg.stages = stages  # built by hand: the pipeline checks again when it builds the stages
    seq = Sequence(write_sequence(tmp_path / "room", trajectory(3)))
    with pytest.raises(ConfigError, match="'restoration' needs dynamic_mask"):
        run_pipeline(seq, cfg, max_frames=2)


@pytest.mark.parametrize("preset", PIPELINE_PRESETS, ids=lambda p: p.name)
def test_every_preset_builds_its_stages(preset) -> None:
    catalog = shipped_catalog()
    cfg = catalog.preset(preset.name, {"segmentation.source": "truth"})
    assert [s.name for s in catalog.build_stages(cfg, parse_camera("tum3"))] == list(preset.stages)
