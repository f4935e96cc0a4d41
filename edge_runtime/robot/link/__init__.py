"""The runtime's link to the arm: the wire protocol (which the simulated controller also imports), the link template, CAN and MAVLink."""
