"""Synthetic dynamic RGB-D sequences with exact truth: a textured room, walking figures, a Kinect-like sensor."""
