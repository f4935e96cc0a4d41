"""The wearable distraction product: IMU sources -> detector -> preprocessing -> classifier -> alert decisions -> CAN."""
