"""Stage 4: object-space ray casting with bidirectional segments, camera and transfer functions."""

from .camera import Camera, FittedCamera
from .image import to_rgb8, write_png
from .raycast import MODES, RenderResult, StreamingRaycaster, render_mesh
from .stream import render_batches
from .transfer import TransferFunction, load_transfer_function, preset_names

__all__ = ["Camera", "FittedCamera", "MODES", "RenderResult", "StreamingRaycaster", "render_mesh",
           "TransferFunction", "load_transfer_function", "preset_names", "to_rgb8", "write_png",
           "render_batches"]
