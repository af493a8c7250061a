"""RGB-D camera tracking: motion model, projection search, PnP-RANSAC, motion-only BA, relocalisation."""
