"""Simulated devices and world (docs/design.md section 2).

* :mod:`firmware_sim.devices.wrist` -- the physically motivated right-wrist accelerometer
  of the dissertation's chapter 2 (kinematic arm chain, gravity projection, driving,
  vehicle acceleration, road vibration, sensor errors) and its simulated cohort;
* ``python -m firmware_sim drive|cohort`` -- command line (see ``__main__``).

``firmware_sim`` may import ``edge_runtime``; never the reverse.
"""
