"""The sparse map (points, keyframes, covisibility), local BA, culling, loop closure and the dense map."""
