"""Stage 5: decompress -> simplify -> render in one streaming pass; time budgets; image quality."""
