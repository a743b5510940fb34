"""Stage 2 (storage): lossless cut-border compression, the streaming decoder, the ``.tetc`` container."""
