"""Transfer-function presets (JSON files read with importlib.resources by ``gatun_py.raycast.transfer``)."""
