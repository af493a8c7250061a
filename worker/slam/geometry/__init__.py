"""Geometry primitives: SE(3), reprojection residuals, PnP and pose optimisation (no map, no tracker)."""
