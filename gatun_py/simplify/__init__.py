"""Stage 3: offline Van Gelder decimation (merge forest, pre-simplified levels) and the run-time filter."""
