"""The limits of what the verbs and the CLI accept, in one light module: the CLI checks its options
against them before numba or a kernel loads."""

# The largest image a verb renders: the camera takes up to MAX_CAMERA_SIDE, but 4096² already
# takes 200 MB of float RGBA; larger is nearly always a typo.
MAX_IMAGE_SIDE = 8192
# The camera's own bound on an image side (gatun_py.raycast.camera.Camera).
MAX_CAMERA_SIDE = 16384
# A zoom factor lies in [1 / MAX_ZOOM, MAX_ZOOM].
MAX_ZOOM = 1.0e4
# The ray caster's sampling modes: uniform samples every step, or one sample per tet at its faces.
MODES = ("volume", "face")
# How a render runs: one streaming pass, or decode-all-then-render (the paper's baseline).
PIPELINES = ("streaming", "generic")

# The PLOT3D Q-file quantities a reader derives (gatun_py.mesh.plot3d; the CLI's --q-var choices).
Q_VARIABLES = (
    "density",
    "momentum-x",
    "momentum-y",
    "momentum-z",
    "energy",
    "velocity-x",
    "velocity-y",
    "velocity-z",
    "velocity-magnitude",
    "momentum-magnitude",
    "pressure",
)
