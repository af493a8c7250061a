"""The map model: keyframes, map points and the map that holds them."""
