"""A snapshot camera from a 3D view's matrices (numpy only).

Blender's viewport describes what it shows with two 4 × 4 matrices: the view matrix
(world → eye, ``RegionView3D.view_matrix``) and the window matrix (eye → OpenGL clip,
``RegionView3D.window_matrix``); a camera's own pair is ``matrix_world.inverted()`` and
``calc_matrix_camera``. ``camera_from_view`` turns either pair into the ``CameraData`` the
tracers take, perspective or orthographic, free view or camera view (the camera view's zoom
and offset are part of its window matrix). The clipping range is read back from the window
matrix, so rays and rasterization cover exactly what the view shows.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from .camera import projection
from .snapshot import CameraData

__all__ = ["border_rect", "camera_from_view", "clip_range", "crop_camera", "crop_window",
           "is_orthographic"]


def is_orthographic(window_matrix) -> bool:
    """True for an orthographic window matrix (its last row is (0, 0, 0, 1))."""
    w = np.asarray(window_matrix, np.float64)
    return abs(w[3, 3] - 1.0) < 1e-9 and abs(w[3, 2]) < 1e-9


def clip_range(window_matrix) -> tuple[float, float]:
    """(near, far) distances in front of the eye encoded by an OpenGL window matrix."""
    w = np.asarray(window_matrix, np.float64)
    a, b = w[2, 2], w[2, 3]
    if is_orthographic(w):  # a = −2/(f−n), b = −(f+n)/(f−n)
        return float((b + 1.0) / a), float((b - 1.0) / a)
    return float(b / (a - 1.0)), float(b / (a + 1.0))  # a = −(f+n)/(f−n), b = −2fn/(f−n)


def camera_from_view(view_matrix, window_matrix, width: int, height: int,
                     name: str = "View") -> CameraData:
    """The ``CameraData`` of a ``width`` × ``height`` image of a view.

    view_matrix : (4, 4) world → eye (rigid; the eye looks along its −Z).
    window_matrix : (4, 4) OpenGL projection for that image's aspect.
    The camera's ``resolution`` is (width, height), so ``scene.camera.view_projection`` gives
    back the window matrix (up to the clipping rows) and the rays go through its pixels.
    """
    view = np.asarray(view_matrix, np.float64).reshape(4, 4)
    window = np.asarray(window_matrix, np.float64).reshape(4, 4)
    if not (np.isfinite(view).all() and np.isfinite(window).all()):
        raise ValueError("view and window matrices must be finite")
    near, far = clip_range(window)
    ortho = is_orthographic(window)
    return CameraData(
        name=name,
        world_matrix=np.linalg.inv(view),
        projection_matrix=window.copy(),
        resolution=(int(width), int(height)),
        type="ORTHO" if ortho else "PERSP",
        angle_x=0.0 if ortho else float(2.0 * np.arctan(1.0 / window[0, 0])),
        angle_y=0.0 if ortho else float(2.0 * np.arctan(1.0 / window[1, 1])),
        ortho_scale=float(2.0 / min(window[0, 0], window[1, 1])) if ortho else 0.0,
        clip_start=near,
        clip_end=far,
    )


def border_rect(border, width: int, height: int) -> tuple[int, int, int, int]:
    """(x0, y0, w, h), pixels counted from the bottom left, of a ``width`` × ``height`` image's
    Render Region ``border`` (x0, y0, x1, y1 as fractions of the image, from the bottom left),
    cut as Blender cuts a render's region (its float32 corners times the size, truncated; at
    least one pixel each way). The border is clipped to the image first; w or h is 0 when
    nothing of it is inside."""
    x0, y0, x1, y1 = (min(max(float(v), 0.0), 1.0) for v in border)
    if x1 <= x0 or y1 <= y0:
        return 0, 0, 0, 0

    def cut(low, high, size):
        a, b = int(np.float32(low) * np.float32(size)), int(np.float32(high) * np.float32(size))
        a = min(a, size - 1)
        return a, max(b, a + 1) - a
    (px, pw), (py, ph) = cut(x0, x1, int(width)), cut(y0, y1, int(height))
    return px, py, pw, ph


def crop_window(window_matrix, rect, width: int, height: int) -> np.ndarray:
    """The window matrix of the pixels ``rect`` (x0, y0, w, h from the bottom left) of a
    ``width`` × ``height`` image seen through ``window_matrix``: a ``w`` × ``h`` image whose
    pixel (i, j) is the image's pixel (x0 + i, y0 + j). The crop scales and moves clip space
    (x' = s x + t w), so perspective and orthographic windows keep their kind and their
    clipping range."""
    x0, y0, w, h = rect
    if w < 1 or h < 1:
        raise ValueError(f"a crop of {w} × {h} pixels is empty")
    a, b = -1.0 + 2.0 * x0 / width, -1.0 + 2.0 * (x0 + w) / width
    c, d = -1.0 + 2.0 * y0 / height, -1.0 + 2.0 * (y0 + h) / height
    crop = np.eye(4)
    crop[0, 0], crop[0, 3] = 2.0 / (b - a), -(a + b) / (b - a)
    crop[1, 1], crop[1, 3] = 2.0 / (d - c), -(c + d) / (d - c)
    return crop @ np.asarray(window_matrix, np.float64).reshape(4, 4)



def crop_camera(camera: CameraData, rect, width: int, height: int) -> CameraData:
    """``camera`` as it sees the pixels ``rect`` (x0, y0, w, h from the bottom left) of a
    ``width`` × ``height`` image: a ``w`` × ``h`` image whose pixel (i, j) is that image's pixel
    (x0 + i, y0 + j), its rays and raster exactly those pixels' (F12's Render Region)."""
    window = crop_window(projection(camera, width, height), rect, width, height)
    return dataclasses.replace(camera, projection_matrix=window,
                               resolution=(int(rect[2]), int(rect[3])))
