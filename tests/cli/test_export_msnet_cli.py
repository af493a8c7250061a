"""`vtdslam export-msnet`: a trained checkpoint copied with a narrower set of potentially dynamic classes."""
from typer.testing import CliRunner

from cli.main import app
from worker.slam.segmentation.msnet.checkpoint import load_model, save_model
from worker.slam.segmentation.msnet.config import MsnetConfig
from worker.slam.segmentation.msnet.model import build_msnet

TINY = MsnetConfig(input_size=(32, 32), stem_channels=8, widths=(8, 8, 8), embed_dim=8, heads=2,
                   filters_per_class=2, decoder_layers=1)


def test_export_narrows_dynamic_classes_and_keeps_weights(tmp_path):
    src, dest = tmp_path / "run.pt", tmp_path / "out" / "shipped.pt"
    save_model(src, build_msnet(TINY).eval(), {"epoch": 3})
    out = CliRunner().invoke(app, ["export-msnet", str(src), str(dest), "--dynamic-classes", "person",
                                   "--note", "chair IoU 0.1 < 0.5"])
    assert out.exit_code == 0, out.output
    model, meta = load_model(dest)
    original, _ = load_model(src)
    assert model.cfg.dynamic_classes == ("person",) and model.cfg.classes == TINY.classes
    assert meta["epoch"] == 3 and meta["export_note"] == "chair IoU 0.1 < 0.5"
    assert all((a == b).all() for a, b in zip(model.state_dict().values(), original.state_dict().values()))


def test_export_refuses_a_class_the_network_does_not_have(tmp_path):
    src = tmp_path / "run.pt"
    save_model(src, build_msnet(TINY).eval())
    out = CliRunner().invoke(app, ["export-msnet", str(src), str(tmp_path / "x.pt"), "--dynamic-classes", "dog"])
    assert out.exit_code == 2 and "subset" in out.output
    assert not (tmp_path / "x.pt").exists()
