"""Operator interfaces (terminal view of energy_monitor; the Foxglove bridge is in ``bridge``).

Not pure like ``estimator``: this layer may import rich (terminal drawing). No ROS import here
either; the rclpy shells live in ``skidsteer_power.nodes``.
"""
