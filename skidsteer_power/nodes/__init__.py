"""Thin rclpy shells around the pure layers: des_driver, power_estimator, energy_monitor, suite."""
