"""The colour gain of a reference to the target (`worker.slam.inpainting.gain`)."""
import numpy as np
import pytest

from worker.slam.inpainting.gain import colour_gain


def test_colour_gain_from_a_subsample_of_a_large_region():
    """Exposure ratio 0.8 with per-pixel noise over a large shared region: the gain from an even subsample
    matches the full median closely, and below `max_pixels` every pixel is used."""
    rng = np.random.default_rng(4)
    h, w = 300, 400
    target = rng.integers(40, 220, (h, w, 3)).astype(np.uint8)
    noise = rng.normal(1.0, 0.03, (h, w, 3))
    ref = np.clip(target / 0.8 * noise, 0, 255).astype(np.uint8)
    yy, xx = np.mgrid[0:h, 0:w]
    landed = np.stack([yy, xx], -1)
    hole = np.zeros((h, w), bool)
    hole[100:200, 150:250] = True
    region = (0, h, 0, w)
    every = colour_gain(target, hole, ref, landed, region, max_pixels=h * w)
    some = colour_gain(target, hole, ref, landed, region, max_pixels=5000)
    assert np.allclose(every, 0.8, atol=0.01) and np.allclose(some, every, atol=0.005)
    assert not np.array_equal(some, every)  # a subsample was taken
    small = (0, 100, 0, 150)  # 15 000 shared pixels: under the default 20 000, all of them count
    assert np.array_equal(colour_gain(target, hole, ref, landed[:100, :150], small),
                          colour_gain(target, hole, ref, landed[:100, :150], small, max_pixels=10**9))


@pytest.mark.parametrize("max_pixels", [10**9, 20_000, 3_000])
def test_colour_gain_is_the_median_of_the_stated_subsample(max_pixels):
    """The compiled pass against numpy's statement of the rule: shared pixels of the region (landed, outside
    the hole) in row-major order, every step-th of them, the bright ones' ratios, the per-channel median."""
    rng = np.random.default_rng(7)
    h, w = 240, 320
    target = rng.integers(0, 256, (h, w, 3)).astype(np.uint8)  # dark pixels included: they must drop out
    ref = rng.integers(0, 256, (h, w, 3)).astype(np.uint8)
    region = (30, 230, 20, 300)
    rh, rw = region[1] - region[0], region[3] - region[2]
    landed = np.stack([rng.integers(0, h, (rh, rw)), rng.integers(0, w, (rh, rw))], -1)
    landed[rng.random((rh, rw)) < 0.3] = -1  # the reference does not see there
    hole = np.zeros((h, w), bool)
    hole[80:180, 100:200] = True
    ys, xs = np.nonzero(~hole[30:230, 20:300] & (landed[..., 0] >= 0))
    step = -(-len(ys) // max_pixels) if len(ys) > max_pixels else 1
    ys, xs = ys[::step], xs[::step]
    t = target[30 + ys, 20 + xs].astype(np.float64)
    r = ref[landed[ys, xs, 0], landed[ys, xs, 1]].astype(np.float64)
    bright = (t.min(1) > 16) & (r.min(1) > 16)
    want = np.clip(np.median(t[bright] / r[bright], axis=0), 0.7, 1.4)
    assert np.array_equal(colour_gain(target, hole, ref, landed, region, max_pixels=max_pixels), want)
    assert not np.allclose(want, 1.0)
    few = np.full_like(landed, -1)
    few[:10, :10] = landed[:10, :10]  # under min_pixels shared: no gain
    assert np.array_equal(colour_gain(target, hole, ref, few, region), np.ones(3))
