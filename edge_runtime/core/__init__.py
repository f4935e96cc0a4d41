"""What every product on the box shares: the model manifest, ONNX sessions, the skeleton and frames, serial-line specs. Imports no feature."""
