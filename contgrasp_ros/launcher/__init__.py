"""The launcher: the graph's one description, its runs (processes, supervision, events,
summary) and the ROS 2 launch entities built from the same description."""
