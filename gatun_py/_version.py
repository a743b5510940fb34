"""The package version, in a base module so that any layer can read it without importing the top."""

__version__ = "0.2.0"
