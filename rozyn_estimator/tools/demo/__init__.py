"""``rozyn demo``, the main job: the simulator, the estimator and a recorder as ROS 2 nodes in
one process on sim time, estimate against truth (``command``; what it prints and writes:
``output``)."""
