"""Stage 4: object-space ray casting with bidirectional segments, camera and transfer functions."""
