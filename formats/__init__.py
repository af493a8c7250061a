"""What crosses process boundaries: TUM lists and association, trajectories, PLY, run-artifact names and the
typed run-metrics (run_metrics) and frame-stats (frame_stats) schemas. The ground floor every package may import;
pure Python + numpy, imports none of ours."""
