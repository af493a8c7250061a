"""What crosses process boundaries: TUM lists and association, trajectories, PLY, run-artifact names and the
frame-stats schema. The ground floor every package may import; pure Python + numpy, imports none of ours."""
