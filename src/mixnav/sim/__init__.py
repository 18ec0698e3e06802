"""Simulation: trajectories from motion segments, IMU and GNSS measurements."""
