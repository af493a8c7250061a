"""Augmented movers of other classes: exact masks with class ids, static instances that stay put and belong to
the background, the people default unchanged, and culling scored per instance."""
from __future__ import annotations

import json

import numpy as np
import pytest

from tests.worker.slam.test_augment import make_coco
from worker.slam.augment.generator import AugmentConfig, generate_augmented
from worker.slam.augment.instance_scores import InstanceCounts, InstanceLayers, InstanceTruth
from worker.slam.augment.movers import COCO80, is_people_only, parse_movers
from worker.slam.augment.sprites import load_sprites
from worker.slam.errors import ConfigError
from worker.slam.io.sequence import Sequence
from worker.slam.synth.generator import SynthConfig, generate_synthetic
from worker.slam.truth import load_truth

CHAIR = COCO80.index("chair")


@pytest.fixture(scope="module")
def static_source(tmp_path_factory):
    root = tmp_path_factory.mktemp("static")
    generate_synthetic(root, SynthConfig(frames=30, people=0, trajectory="circle", seed=2))
    return root


@pytest.fixture(scope="module")
def coco(tmp_path_factory):
    return make_coco(tmp_path_factory.mktemp("coco") / "coco", np.random.default_rng(1))


@pytest.fixture(scope="module")
def chairs(static_source, coco, tmp_path_factory):
    """One moving chair and one parked chair."""
    out = tmp_path_factory.mktemp("chairs") / "aug"
    generate_augmented(static_source, coco, out, AugmentConfig(frames=30, people=1, seed=4, movers="chair",
                                                               static=1))
    return out


def test_parse_movers_groups_names_and_errors():
    assert [m.name for m in parse_movers("person")] == ["person"] and is_people_only(parse_movers("person"))
    animals = parse_movers("animal")
    assert {"cat", "dog", "horse"} <= {m.name for m in animals} and "person" not in {m.name for m in animals}
    mixed = parse_movers("Suitcase, teddy bear,vehicle")
    assert {m.name for m in mixed} == {"suitcase", "teddy bear", "bicycle", "car", "motorcycle"}
    assert [m.coco_id for m in mixed] == sorted(m.coco_id for m in mixed)
    cat = next(m for m in animals if m.name == "cat")
    assert cat.height_m[1] < 0.5  # a cat is pasted at a cat's size
    for bad in ("dragon", " , "):
        with pytest.raises(ConfigError):
            parse_movers(bad)


def test_sprites_of_other_classes_carry_their_class(coco):
    assert [s.coco_id for s in load_sprites(coco)] == [0]  # the default: people only, as before
    chairs = load_sprites(coco, classes=(CHAIR,))
    assert [s.coco_id for s in chairs] == [CHAIR]  # the clipped polygon is class 0: never a chair


def test_moving_chair_has_an_exact_mask_and_class(chairs, static_source):
    seq, src, truth = Sequence(chairs), Sequence(static_source), load_truth(chairs)
    inst = InstanceTruth.of(chairs)
    assert inst is not None
    objects = truth.layout.objects
    assert objects == [{"id": 1, "class": "chair", "classes": ["chair"], "kind": "COCO billboard", "moving": True}]
    seen = 0
    for i in range(30):
        layers, a, s = inst[i], seq[i], src[i]
        pasted = layers.classes > 0
        assert set(np.unique(layers.classes)) <= {0, CHAIR + 1}
        assert np.array_equal(pasted, (layers.moving > 0) | (layers.static > 0))
        assert not np.any((layers.moving > 0) & (layers.static > 0))
        # outside the pasted pixels the frame is the source, byte for byte; the mover's pixels changed
        assert np.array_equal(a.rgb[~pasted], s.rgb[~pasted]) and np.array_equal(a.depth[~pasted], s.depth[~pasted])
        m = layers.moving > 0
        if m.sum() > 200:
            seen += 1
            assert np.mean(np.any(a.rgb[m] != s.rgb[m], axis=1)) > 0.9
    assert seen >= 3


def _world_points(seq: Sequence, index: int, mask: np.ndarray) -> np.ndarray:
    """(N, 3) world points of the pixels of `mask` with depth in frame `index`."""
    assert seq.groundtruth is not None
    f, cam, T = seq[index], seq.camera, seq.groundtruth.poses[index]
    v, u = np.nonzero(mask & (f.depth > 0))
    z = f.depth[v, u]
    pc = np.stack([(u - cam.cx) / cam.fx * z, (v - cam.cy) / cam.fy * z, z], 1)
    return pc @ T[:3, :3].T + T[:3, 3]


def test_static_instance_stays_put_and_belongs_to_the_background(chairs):
    seq, truth, inst = Sequence(chairs), load_truth(chairs), InstanceTruth.of(chairs)
    gen = truth.layout.generator
    assert [s["class"] for s in gen["static"]] == ["chair"] and gen["static"][0]["id"] == 2
    foot, facing = np.array(gen["static"][0]["floor_point"]), np.array(gen["static"][0]["facing"])
    static_pts, moving_pts = [], []
    for i in range(30):
        layers = inst[i]
        s = layers.static > 0
        assert not (truth.mask(i) & s).any()  # never in the moving truth
        bg = truth.background_rgb(i)
        assert np.array_equal(seq[i].rgb[s], bg[s])  # the parked chair is part of the static scene
        assert np.array_equal(seq[i].rgb[~truth.mask(i)], bg[~truth.mask(i)])
        if s.sum() > 500:
            pts = _world_points(seq, i, s)
            # a rigid plane, fixed in the world: a billboard turning to the camera would leave it by ~10 cm
            assert np.percentile(np.abs((pts - foot) @ facing), 95) < 0.01
            static_pts.append(pts.mean(axis=0))
        if (layers.moving > 0).sum() > 500:
            moving_pts.append(_world_points(seq, i, layers.moving > 0).mean(axis=0))
    assert len(static_pts) >= 5 and len(moving_pts) >= 3
    static_pts, moving_pts = np.array(static_pts), np.array(moving_pts)
    # the parked chair's visible surface stays within a cm or two in the world (unless a mover hides part of it);
    # the moving one crosses the room
    assert np.median(np.linalg.norm(static_pts - np.median(static_pts, axis=0), axis=1)) < 0.02
    assert np.linalg.norm(moving_pts.max(0) - moving_pts.min(0)) > 0.5


def test_people_default_writes_what_it_always_wrote(static_source, coco, tmp_path):
    cfg = AugmentConfig(frames=12, people=2, seed=3)
    assert cfg.movers == "person" and cfg.static == 0
    generate_augmented(static_source, coco, tmp_path / "a", cfg)
    generate_augmented(static_source, coco, tmp_path / "b", AugmentConfig(frames=12, people=2, seed=3, static=1))
    a = load_truth(tmp_path / "a")
    assert not (tmp_path / "a/truth/classes").exists() and not (tmp_path / "a/truth/static").exists()
    assert set(a.layout.generator) == {"name", "source", "seed", "people", "floor", "walks", "placement"}
    assert a.layout.objects == [{"id": k, "class": "person", "kind": "COCO billboard"} for k in (1, 2)]
    assert InstanceTruth.of(tmp_path / "a") is None
    # background files are the source's own bytes without static instances
    assert (tmp_path / "a/truth/background_rgb/000005.png").read_bytes() == \
        (static_source / "rgb/000005.png").read_bytes()
    # a static instance has its own random stream: the people walk exactly as before
    walks = lambda p: json.loads((p / "truth/truth.json").read_text())["generator"]["walks"]  # noqa: E731
    assert [{k: v for k, v in w.items() if k != "class"} for w in walks(tmp_path / "b")] == walks(tmp_path / "a")


def test_instance_counts_split_moving_static_and_scene():
    moving = np.zeros((60, 60), np.uint8)
    moving[5:15, 5:15] = 1
    static = np.zeros_like(moving)
    static[25:55, 25:55] = 2
    classes = np.where(moving > 0, COCO80.index("dog") + 1, 0) + np.where(static > 0, CHAIR + 1, 0)
    # moving: 2 (1 removed); static: an edge one removed, an interior one kept; scene: 2 (1 removed); (16, 10)
    # lies within 3 px of the dog: neither moving nor scene
    uv = np.array([[10, 10], [12, 8], [27, 30], [40, 40], [2, 35], [57, 3], [16, 10]], float)
    culled = np.array([True, False, True, False, True, False, True])
    counts = InstanceCounts()
    counts.add(InstanceLayers(moving, static, classes.astype(np.uint8)), uv, culled, border_px=3)
    s = counts.summary()
    assert s["moving_by_class"] == {"dog": {"removed": 0.5, "keypoints": 2}} and s["moving_removed"] == 0.5
    assert s["static_removed"] == 0.5 and s["static_interior_removed"] == 0.0 and s["scene_removed"] == 0.5
    assert s["keypoints"] == {"moving": 2, "static": 2, "static_interior": 1, "scene": 2}
