"""The robot co-worker safety product: keypoints -> lifter -> calibration -> hazard zones -> commands on the arm's link."""
