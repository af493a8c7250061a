"""Augmented-real dynamic sequences: real COCO people composited into a real static RGB-D sequence in 3D."""
