"""Augmented-real dynamic sequences: real COCO people (or animals, vehicles, objects) composited into a real static
RGB-D sequence in 3D, with exact truth."""
