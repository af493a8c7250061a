"""The exclusion band around the dynamic pixels."""
import cv2
import numpy as np


def test_exclusion_band_matches_a_full_image_dilation():
    from worker.slam.dynamic.culling import dilate_disc

    rng = np.random.default_rng(0)
    for _ in range(10):
        mask = np.zeros((120, 160), bool)
        for _ in range(rng.integers(0, 3)):
            y, x = rng.integers(0, 120), rng.integers(0, 160)
            mask[y:y + rng.integers(1, 60), x:x + rng.integers(1, 60)] = True
        for px in (0, 3, 15):
            k = 2 * px + 1
            full = cv2.dilate(mask.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))) > 0
            assert np.array_equal(dilate_disc(mask, px), full)
