"""A perspective camera that follows VTK's conventions, so our images line up with VTK/ParaView.

The sequence is VTK's: default camera (looking down -z, view-up +y, 30 degree view angle),
``ResetCamera`` (focal point at the bounding-box centre, distance = radius / sin(angle / 2) with the
radius of the bounding sphere), ``Azimuth``, ``Elevation``, ``OrthogonalizeViewUp``, ``ResetCamera``
again, then ``Zoom`` (view angle / zoom).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import OptionError
from ..limits import MAX_CAMERA_SIDE as MAX_SIZE, MAX_ZOOM  # noqa: F401  (MAX_ZOOM: the viewer's too)


@dataclass(frozen=True)
class Camera:
    """What the user asks for: image size and view angles; fitted to a mesh with :meth:`fit`.

    Parameters
    ----------
    width, height : int
        Image size in pixels.
    azimuth, elevation : float
        Degrees, VTK's ``Azimuth`` then ``Elevation`` about the focal point.
    zoom : float
        VTK's ``Zoom`` (the view angle is divided by it).
    view_angle : float
        Vertical view angle in degrees before zooming (VTK's default 30).
    pan_x, pan_y : float
        Shift of the focal point (and the camera with it) along the view's right and up vectors,
        in radii of the bounding sphere, applied after the fit (the viewer's pan; 0 for VTK's view).
    """

    width: int = 256
    height: int = 256
    azimuth: float = 0.0
    elevation: float = 0.0
    zoom: float = 1.0
    view_angle: float = 30.0
    pan_x: float = 0.0
    pan_y: float = 0.0

    def __post_init__(self):
        for name in ("width", "height"):
            v = getattr(self, name)
            if not isinstance(v, (int, np.integer)) or not 1 <= v <= MAX_SIZE:
                raise OptionError(f"image {name} must be an integer in 1..{MAX_SIZE}, got {v!r}")
        for name in ("azimuth", "elevation", "zoom", "view_angle", "pan_x", "pan_y"):
            if not math.isfinite(float(getattr(self, name))):
                raise OptionError(f"camera {name} must be a finite number")
        if not (1.0 / MAX_ZOOM <= self.zoom <= MAX_ZOOM):
            raise OptionError(f"zoom must lie in [{1 / MAX_ZOOM:g}, {MAX_ZOOM:g}], got {self.zoom:g}")
        if not 0.0 < self.view_angle / self.zoom < 179.0:
            raise OptionError("the view angle divided by the zoom must lie in (0, 179) degrees")

    def fit(self, lo, hi) -> "FittedCamera":
        """Place the camera for the bounding box ``lo``..``hi`` as VTK would."""
        lo = np.asarray(lo, dtype=np.float64)
        hi = np.asarray(hi, dtype=np.float64)
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            raise OptionError("cannot place the camera: the bounding box is not finite")
        aspect = self.width / self.height
        position = np.array([0.0, 0.0, 1.0])
        focal = np.zeros(3)
        up = np.array([0.0, 1.0, 0.0])
        position, focal, up = _reset(position, focal, up, lo, hi, self.view_angle, aspect)
        position, up = _azimuth(position, focal, up, self.azimuth)
        position, up = _elevation(position, focal, up, self.elevation)
        up = _orthogonal_up(position, focal, up)
        position, focal, up = _reset(position, focal, up, lo, hi, self.view_angle, aspect)
        if self.pan_x or self.pan_y:
            fwd = (focal - position) / np.linalg.norm(focal - position)
            right = np.cross(fwd, up)
            right = right / np.linalg.norm(right)
            radius = 0.5 * math.sqrt(float(np.sum((hi - lo) ** 2)) or 1.0)
            shift = radius * (self.pan_x * right + self.pan_y * np.cross(right, fwd))
            position, focal = position + shift, focal + shift
        return FittedCamera(self.width, self.height, position, focal, up, self.view_angle / self.zoom)


@dataclass(frozen=True)
class FittedCamera:
    """A camera with a position: it generates the pixel rays.

    Pixel (row ``j`` from the top, column ``i``) looks through the centre of its square on the
    image plane, as in VTK with display y flipped.
    """

    width: int
    height: int
    position: np.ndarray
    focal_point: np.ndarray
    view_up: np.ndarray
    view_angle: float

    def basis(self):
        """(forward, right, up) unit vectors of the view."""
        fwd = self.focal_point - self.position
        fwd = fwd / np.linalg.norm(fwd)
        right = np.cross(fwd, self.view_up)
        right = right / np.linalg.norm(right)
        up = np.cross(right, fwd)
        return fwd, right, up

    def ray_offsets(self):
        """(xs (W,), ys (H,)): pixel ray (col, row) points along fwd + xs[col] right + ys[row] up."""
        t = math.tan(math.radians(self.view_angle) / 2.0)
        w, h = self.width, self.height
        xs = (2.0 * (np.arange(w) + 0.5) / w - 1.0) * t * (w / h)
        ys = (1.0 - 2.0 * (np.arange(h) + 0.5) / h) * t
        return xs, ys

    def ray_directions(self) -> np.ndarray:
        """Unit direction (H * W, 3) float64 of every pixel ray, row-major from the top row."""
        fwd, right, up = self.basis()
        xs, ys = self.ray_offsets()
        d = fwd[None, None, :] + xs[None, :, None] * right[None, None, :] + ys[:, None, None] * up[None, None, :]
        d = d.reshape(-1, 3)
        return d / np.linalg.norm(d, axis=1)[:, None]

    def project(self, pts) -> np.ndarray:
        """Continuous pixel coordinates (column, row-from-top) of points in front of the camera."""
        fwd, right, up = self.basis()
        rel = np.asarray(pts, dtype=np.float64) - self.position
        z = rel @ fwd
        t = math.tan(math.radians(self.view_angle) / 2.0)
        w, h = self.width, self.height
        x = (rel @ right) / (z * t * (w / h))
        y = (rel @ up) / (z * t)
        return np.stack([(x + 1.0) * w / 2.0, (1.0 - y) * h / 2.0], axis=-1)


def _rotate(v, axis, degrees):
    """Rotate vector v about a unit axis through the origin (right-handed, degrees)."""
    axis = axis / np.linalg.norm(axis)
    a = math.radians(degrees)
    c, s = math.cos(a), math.sin(a)
    return v * c + np.cross(axis, v) * s + axis * np.dot(axis, v) * (1.0 - c)


def _reset(position, focal, up, lo, hi, view_angle, aspect):
    """vtkRenderer::ResetCamera(bounds): keep the direction, refit the distance."""
    vn = position - focal
    vn = vn / np.linalg.norm(vn)
    center = (lo + hi) / 2.0
    r2 = float(np.sum((hi - lo) ** 2))
    radius = math.sqrt(r2 if r2 > 0 else 1.0) * 0.5
    angle = math.radians(view_angle)
    if aspect < 1.0:  # VTK fits a tall window by its horizontal angle
        angle = 2.0 * math.atan(math.tan(angle * 0.5) * aspect)
    distance = radius / math.sin(angle * 0.5)
    if abs(np.dot(up, vn)) > 0.999:
        up = np.array([-up[2], up[0], up[1]])
    return center + distance * vn, center, up


def _azimuth(position, focal, up, degrees):
    return focal + _rotate(position - focal, up, degrees), up


def _elevation(position, focal, up, degrees):
    fwd = focal - position
    fwd = fwd / np.linalg.norm(fwd)
    right = np.cross(fwd, up)
    right = right / np.linalg.norm(right)
    # VTK rotates about minus the first row of the view transform (the camera's right vector)
    # and keeps the view-up until OrthogonalizeViewUp.
    return focal + _rotate(position - focal, -right, degrees), up


def _orthogonal_up(position, focal, up):
    fwd = focal - position
    fwd = fwd / np.linalg.norm(fwd)
    right = np.cross(fwd, up)
    right = right / np.linalg.norm(right)
    return np.cross(right, fwd)
