"""The viewer's page: HTML, script and style sheet (package data, read with importlib.resources)."""
