"""Dynamic object culling (paper 4.1): epipolar geometry with an adaptive, entropy-guided threshold."""
