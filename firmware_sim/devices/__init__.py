"""Simulated devices: the wrist IMU and its MAVLink firmware, the CAN hub, the camera and its 2D detector model."""
