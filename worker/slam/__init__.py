"""The pure SLAM pipeline: knows nothing of databases or the web (imports none of our other packages)."""
