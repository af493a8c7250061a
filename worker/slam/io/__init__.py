"""Reading and writing sequences and trajectories on disk."""
