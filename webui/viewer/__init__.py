"""The viser 3D viewer of a finished run: map, trajectories, keyframes and per-frame overlays."""
