"""Stage 4: object-space ray casting with bidirectional segments, camera and transfer functions."""

from .camera import Camera, FittedCamera
from .raycast import MODES, RenderResult, StreamingRaycaster, default_step, render_mesh
from .transfer import TransferFunction, load_transfer_function, preset_names

__all__ = ["Camera", "FittedCamera", "MODES", "RenderResult", "StreamingRaycaster", "default_step", "render_mesh",
           "TransferFunction", "load_transfer_function", "preset_names"]
