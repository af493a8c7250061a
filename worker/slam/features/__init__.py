"""ORB features with a scale pyramid, grid-balanced distribution and per-keypoint depth; keypoint search.

Import the modules directly (`features.orb`, `features.types`, `features.search`): this package imports
nothing on its own, so the dynamic stages can use `types`/`search` without pulling in the pipeline config.
"""
