"""The simulated Sawyer: kinematics and IK, and its controller on a CAN or MAVLink link."""
