"""Trajectory accuracy: ATE and RPE computed with evo, the field's reference tool."""
