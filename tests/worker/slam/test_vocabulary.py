"""The ORB vocabulary: the shipped tree loads and ranks views of one place above others; training runs on a
tiny image set; the keyframe database scores and matches through the tree."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from tests.worker.slam.synthetic_room import pose, render
from worker.slam.config import FeatureConfig
from worker.slam.features.bow_database import KeyframeDatabase
from worker.slam.features.orb import OrbExtractor
from worker.slam.features.vocabulary import DEFAULT_VOCABULARY, Vocabulary
from worker.slam.vocab_train.kmajority import kmajority
from worker.slam.vocab_train.train import VocabTrainConfig, image_paths, train_vocabulary


def _desc(T: np.ndarray) -> np.ndarray:
    rgb, _ = render(T)
    return OrbExtractor(FeatureConfig()).extract(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)).desc


@pytest.fixture(scope="module")
def views() -> list[np.ndarray]:
    """Descriptors of views at yaw 0, 90, 180, 270 degrees, then yaw 5 (near the first)."""
    return [_desc(pose([0.0, 0.0, 0.0], yaw)) for yaw in (0, 90, 180, 270, 5)]


def test_shipped_vocabulary_loads_with_the_documented_shape():
    voc = Vocabulary.load()
    assert DEFAULT_VOCABULARY.stat().st_size < 3e6
    assert voc.k == 10 and voc.levels == 4
    assert 5000 < voc.n_words <= 10**4
    assert np.isfinite(voc.idf).all() and (voc.idf >= 0).all() and voc.idf.max() > 1
    leaves = voc.word_of >= 0
    assert (voc.children[leaves] < 0).all()  # words are leaves
    assert sorted(voc.word_of[leaves]) == list(range(voc.n_words))


def test_a_frame_scores_itself_highest_and_a_near_view_above_other_places(views):
    db = KeyframeDatabase(Vocabulary.load())
    db.extend(views[:4])
    bow, _ = db.transform(views[0])
    scores, common = db.query(bow)
    assert scores[0] == pytest.approx(1.0, abs=1e-5)
    assert np.argmax(scores) == 0 and common[0] == len(bow.words)
    near, _ = db.transform(views[4])
    s = db.query(near)[0]
    assert np.argmax(s) == 0 and s[0] > 1.5 * np.max(s[1:])  # the revisit stands out
    assert s[0] == pytest.approx(near.score(db.bows[0]), abs=1e-5)  # inverted file == direct L1 score


def test_direct_index_matching_finds_the_same_descriptors(views):
    db = KeyframeDatabase(Vocabulary.load())
    db.extend(views[:1])
    d = views[0]
    ia, ib = db.match(None, d, 0, d, ratio=0.9)
    assert len(ia) > 0.6 * len(d)  # distinct descriptors of one image find themselves
    assert np.mean(ia == ib) > 0.95


def test_kmajority_centres_are_the_bitwise_majority_of_their_members():
    rng = np.random.default_rng(0)
    base = rng.integers(0, 256, (3, 32), dtype=np.uint8)
    noisy = np.repeat(base, 50, axis=0) ^ (rng.random((150, 32 * 8)) < 0.05).reshape(150, 32, 8).dot(
        1 << np.arange(8)[::-1]).astype(np.uint8)
    centres, labels = kmajority(noisy, 3, rng)
    assert len(centres) == 3 and len(set(labels[:50])) == len(set(labels[50:100])) == 1
    for c in range(3):
        bits = np.unpackbits(noisy[labels == c], axis=1).mean(0) > 0.5
        assert np.array_equal(np.unpackbits(centres[c]).astype(bool), bits)
    # the three clusters recover the three base descriptors
    assert {tuple(c) for c in centres} == {tuple(b) for b in base}


def test_training_runs_on_a_tiny_image_set(tmp_path):
    for i, yaw in enumerate((0, 60, 120, 180)):
        rgb, _ = render(pose([0.0, 0.0, 0.0], yaw))
        cv2.imwrite(str(tmp_path / f"{i}.png"), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    paths = image_paths([tmp_path])
    res = train_vocabulary(paths, VocabTrainConfig(k=4, levels=3, max_descriptors=2000))
    voc = res.vocabulary
    assert res.n_images == 4 and res.n_clustered == 2000 and voc.k == 4 and voc.levels == 3
    assert 32 < voc.n_words <= 64
    voc.save(tmp_path / "v.npz")
    again = Vocabulary.load(tmp_path / "v.npz")
    assert np.array_equal(again.words(views_of(paths[0])), voc.words(views_of(paths[0])))
    assert again.bow(views_of(paths[0])).score(again.bow(views_of(paths[0]))) == pytest.approx(1.0, abs=1e-5)


def views_of(path) -> np.ndarray:
    gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    assert gray is not None, path
    return OrbExtractor(FeatureConfig()).extract(gray).desc


def test_training_refuses_evaluation_only_data(tmp_path):
    (tmp_path / "bonn_crowd_dev").mkdir()
    with pytest.raises(ValueError, match="evaluation-only"):
        image_paths([tmp_path / "bonn_crowd_dev"])
