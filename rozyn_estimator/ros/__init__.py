"""The ROS 2 nodes and their glue (rclpy): thin nodes around the online class and bag storage.

``estimator_node`` (:mod:`.estimator_node`), ``bag_recorder`` (:mod:`.recorder_node`);
:mod:`.glue` declares parameters from their descriptions and spins a node with an ordered
shutdown; :mod:`.stop` turns SIGINT/SIGTERM into a stop request (standard library only,
so the executables install it before their imports); :mod:`.messages` converts estimates
to messages. No algorithm lives here.
"""
