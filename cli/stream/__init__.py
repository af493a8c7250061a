"""`vtdslam stream`: send a recorded sequence (TUM folder or ROS bag) to a live session at its recorded rate."""
