"""The wearable distraction product: IMU source -> loop -> detector -> classifier (capture in, probabilities out) -> alerts on CAN; ``command`` runs it."""
