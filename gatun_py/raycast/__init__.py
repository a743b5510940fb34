"""Stage 4: object-space ray casting with bidirectional segments, camera and transfer functions.

The names below load on first use (PEP 562), so importing the package, or one light module of it
(the camera, the transfer functions), does not load numba and the ray caster's kernels.
"""

from .._lazy import attach

# public name -> the submodule that defines it
_LAZY = {
    "Camera": "camera", "FittedCamera": "camera",
    "to_rgb8": "image", "write_png": "image",
    "MODES": "caster", "RenderResult": "caster", "StreamingRaycaster": "caster", "render_mesh": "caster",
    "render_batches": "stream",
    "TransferFunction": "transfer", "load_transfer_function": "transfer", "preset_names": "transfer",
}


__getattr__, __dir__, __all__ = attach(__name__, _LAZY)
