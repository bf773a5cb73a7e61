"""The camera model: pixel rays and projection of a snapshot camera (numpy only).

* ``camera_rays`` — one ray per pixel centre of the scene camera, as Cycles shoots them
  (row 0 = top of the image, origins on the near clipping plane).
* ``camera_ray_lengths`` — distance along each ray from the near plane's origin to the eye.
* ``view_projection`` — the (4, 4) world → clip matrix that rasterizes the same pixels.
* ``camera_frame`` — the camera's orthonormal rotation and position.
* ``filter_offsets`` — sub-pixel offsets drawn by importance from Cycles' pixel filter
  within the pixel's own square (equal weights: the viewport's progressive samples).
* ``filter_samples`` — the same filter as a weighted grid (the one-shot image's sub-pixel
  passes, which one supersampled raster draws together).

Every ray function takes a sub-pixel ``offset`` (x right, y down, in pixels) that moves all
pixels' rays alike: the anti-aliased preview renders one pass per ``filter_samples`` entry.
"""
from __future__ import annotations

import dataclasses
import functools

import numpy as np

from ..errors import VoxGIError
from .short_axis import norm3
from .snapshot import CameraData

__all__ = ["DEFAULT_FILTER_WIDTH", "camera_frame", "camera_rays", "camera_ray_lengths",
           "filter_offsets", "filter_on_grid", "filter_samples",
           "image_points", "projection", "view_projection"]

DEFAULT_FILTER_WIDTH = 1.5  # pixels: Cycles' default Blackman-Harris Filter Size
_FILTER_TABLE = 4096  # entries of the filter's inverse CDF


def blackman_harris(offset, width: float):
    """Cycles' Blackman-Harris pixel filter (unnormalised) at ``offset`` pixels from the pixel
    centre for Filter Size ``width``: a window of total width 2 × ``width`` (Cycles doubles the
    width of this filter; measured: a straight edge through a pixel border gives the pixels
    beside it 0.117 and 0.035 coverage at sizes 1.5 and 3, the window's tails beyond 0.5 and
    1.5 pixels), 0 outside it."""
    x = np.asarray(offset, np.float64) / (2.0 * width) + 0.5
    a = 2.0 * np.pi * x
    value = 0.35875 - 0.48829 * np.cos(a) + 0.14128 * np.cos(2 * a) - 0.01168 * np.cos(3 * a)
    return np.where((x >= 0.0) & (x <= 1.0), value, 0.0)


def filter_offsets(width: float = DEFAULT_FILTER_WIDTH, side: int = 4) -> np.ndarray:
    """(side², 2) sub-pixel offsets (x right, y down, pixels) of the anti-aliased preview: the
    centres of a side × side stratified square warped through the inverse CDF of Cycles' pixel
    filter (``blackman_harris``, separable in x and y as Cycles samples it) over the pixel's
    own square (|x|, |y| ≤ ½), so that equal weights average the passes as the filter weights
    the pixel's own area; the filter's tails beyond it are the neighbours' share
    (``preview.passes.filter_passes``). Offset k is stratum (k // side, k % side) in (x, y).
    width ≤ 0 gives pixel centres. (Made once per size and width: the viewport asks for them
    at every slice.)"""
    return _filter_offsets(float(width), int(side)).copy()


@functools.lru_cache(maxsize=32)
def _filter_offsets(width: float, side: int) -> np.ndarray:
    u = (np.arange(side) + 0.5) / side
    if width <= 0.0:
        along = np.zeros(side)
    else:
        reach = min(width, 0.5)
        x = np.linspace(-reach, reach, _FILTER_TABLE)
        cdf = np.concatenate([[0.0], np.cumsum(0.5 * (blackman_harris(x[1:], width)
                                                     + blackman_harris(x[:-1], width)))])
        along = np.interp(u, cdf / cdf[-1], x)
    k = np.arange(side * side)
    return np.stack([along[k // side], along[k % side]], axis=1)


# How much worse than the importance-drawn offsets the weighted grid may cover a straight edge
# across the pixel (its worst place) and still be used: 1.24 × at Cycles' default Filter Size,
# where the grid's whole images read closer to Cycles' than the drawn offsets' (docs/
# gi_pipeline.md "Anti-aliasing": "One raster for the sixteen passes")
GRID_EDGE_SLACK = 1.3


def filter_samples(width: float = DEFAULT_FILTER_WIDTH, side: int = 4):
    """(offsets (side², 2), weights (side²,)): Cycles' pixel filter over the pixel's own square
    (|x|, |y| ≤ ½) as a weighted grid — offset k the centre of cell (k // side, k % side) in
    (x, y) of a side × side grid of equal cells, weighted by the filter's mass over that cell
    (``blackman_harris``, separable), the weights' mean 1. The offsets lie on a lattice, so a
    raster ``side`` times finer than the image draws all of them at once (render/
    gpu_preview.py ``supersampling``); ``filter_offsets`` draws the same filter by importance,
    equal weights, each offset on its own. Where the grid would cover a straight edge across
    the pixel worse than ``GRID_EDGE_SLACK`` × the drawn offsets' worst (a filter narrower
    than Cycles' default: its central cells hold most of it, 0.31 off at width 0.5 against
    0.11 drawn; at the default 1.5, 0.150 against 0.121) these are ``filter_offsets`` with
    equal weights (``filter_on_grid`` False). The filter's tails beyond the square are the
    neighbours' share (``preview.passes.filter_passes``). width ≤ 0: the pixel centre, weight
    1 each."""
    offsets, weights, _ = _filter_samples(float(width), int(side))
    return offsets.copy(), weights.copy()


def filter_on_grid(width: float = DEFAULT_FILTER_WIDTH, side: int = 4) -> bool:
    """Whether ``filter_samples(width, side)`` is the weighted grid (not the drawn offsets)."""
    return _filter_samples(float(width), int(side))[2]


@functools.lru_cache(maxsize=32)
def _filter_samples(width: float, side: int):
    k = np.arange(side * side)
    if width <= 0.0:
        return np.zeros((side * side, 2)), np.ones(side * side), False
    drawn = _filter_offsets(width, side)
    along = (np.arange(side) + 0.5) / side - 0.5
    # the filter's mass over each of the side cells along an axis (midpoint sums, fine steps)
    steps = ((np.arange(256) + 0.5) / 256 - 0.5) / side
    mass = np.array([blackman_harris(centre + steps, width).mean() for centre in along])
    mass /= mass.mean()
    # a straight edge across the pixel: the worst coverage of each arrangement against the
    # filter's own (the grid's weighted columns against the drawn equal ones)
    x = np.linspace(-0.5, 0.5, 2001)
    f = blackman_harris(x, width)
    cover = np.cumsum(f) / f.sum()
    edges = np.linspace(-0.5, 0.5, 81)
    truth = np.interp(edges, x, cover)
    grid_worst = np.abs((mass[None, :] * (along[None, :] < edges[:, None])).mean(axis=1)
                        - truth).max()
    drawn_worst = np.abs((drawn[::side, 0][None, :] < edges[:, None]).mean(axis=1)
                         - truth).max()
    if width < 0.5 or grid_worst > GRID_EDGE_SLACK * drawn_worst:
        return drawn, np.ones(side * side), False
    return (np.stack([along[k // side], along[k % side]], axis=1),
            mass[k // side] * mass[k % side], True)


def _frustum(camera: CameraData, width: int, height: int) -> tuple[float, float, float, float]:
    """(centre x, centre y, half width, half height) of the image on the camera's z = -1 plane
    (perspective) or in metres (orthographic), for a ``width`` × ``height`` image."""
    p = np.asarray(camera.projection_matrix, dtype=np.float64)
    hx, hy = 1.0 / p[0, 0], 1.0 / p[1, 1]
    if camera.type == "ORTHO":
        cx, cy = -p[0, 3] * hx, -p[1, 3] * hy
    else:
        cx, cy = p[0, 2] * hx, p[1, 2] * hy
    w0, h0 = camera.resolution
    if abs(w0 * height - h0 * width) > 1e-9 * w0 * height:
        # Another aspect than the projection's: the camera's Sensor Fit says which field of
        # view stays — Horizontal the width's, Vertical the height's (a glTF camera's: its
        # yfov), Auto the larger image dimension's (the shift, in camera units, is unchanged)
        fit = getattr(camera, "sensor_fit", "AUTO")
        if fit == "HORIZONTAL":
            hy = hx * height / width
        elif fit == "VERTICAL":
            hx = hy * width / height
        else:
            larger = hx if w0 >= h0 else hy
            if width >= height:
                hx, hy = larger, larger * height / width
            else:
                hx, hy = larger * width / height, larger
    return cx, cy, hx, hy


def camera_frame(camera: CameraData) -> tuple[np.ndarray, np.ndarray]:
    """(3, 3) orthonormal camera → world rotation (columns x, y, z) and (3,) position."""
    m = np.asarray(camera.world_matrix, dtype=np.float64)
    rotation = m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0, keepdims=True)
    return rotation, m[:3, 3].copy()


def camera_view(camera: CameraData, world_matrix, shift_delta: float,
                pixel_aspect=(1.0, 1.0)) -> CameraData:
    """``camera`` as one view of a stereo or multi-view render sees: placed at the view's
    ``world_matrix`` (4, 4) and its lens shifted by ``shift_delta`` more along x (Blender's
    per-view shift less the camera's own), as Blender shifts a view plane: by the shift times
    the sensor-fit side in pixels (the width, or the height × the pixel aspect's y / x), which
    moves the projection's x centre by twice that over the width."""
    width, height = camera.resolution
    ax, ay = (float(a) for a in pixel_aspect)
    fit = getattr(camera, "sensor_fit", "AUTO")
    if fit == "AUTO":
        fit = "HORIZONTAL" if ax * width >= ay * height else "VERTICAL"
    side = 1.0 if fit == "HORIZONTAL" else (ay / ax) * height / width
    projection = np.array(camera.projection_matrix, np.float64)
    if camera.type == "ORTHO":
        projection[0, 3] -= 2.0 * shift_delta * side
    else:
        projection[0, 2] += 2.0 * shift_delta * side
    return dataclasses.replace(camera, world_matrix=np.asarray(world_matrix, np.float64),
                               projection_matrix=projection)


def check_camera_type(camera: CameraData) -> None:
    """Raise a VoxGIError that says what to change unless ``camera`` is perspective or
    orthographic (what the tracers and the G-buffer's projection draw; a panoramic camera is
    Cycles' alone)."""
    if camera.type not in ("PERSP", "ORTHO"):
        kind = "panoramic" if camera.type == "PANO" else f"of type {camera.type}"
        raise VoxGIError(f"the camera '{camera.name}' is {kind}: VoxGI renders perspective and "
                         "orthographic cameras (Camera properties > Lens > Type)")


def camera_rays(camera: CameraData, width: int | None = None, height: int | None = None,
                offset=(0.0, 0.0)):
    """Rays through the pixel centres of a ``width`` × ``height`` image of ``camera``.

    Parameters
    ----------
    camera : the scene camera (PERSP or ORTHO; PANO is refused).
    width, height : image size in pixels; default ``camera.resolution``.
    offset : (x, y) sub-pixel offset of every ray from its pixel centre (x right, y down).

    Returns
    -------
    origins : (H·W, 3) float64 world space, on the near clipping plane (as Cycles clips).
    directions : (H·W, 3) float64 unit vectors.
    Pixel (row j, column i) is ray ``j·W + i``; row 0 is the **top** of the image, and pixel
    centres sit at (i + ½, j + ½) as in Cycles. A frame whose aspect differs from the camera's
    resolution is fitted as the camera's Sensor Fit fits it (``_frustum``).
    """
    check_camera_type(camera)
    width = int(width or camera.resolution[0])
    height = int(height or camera.resolution[1])
    cx, cy, hx, hy = _frustum(camera, width, height)
    x = cx + hx * (2.0 * (np.arange(width) + 0.5 + float(offset[0])) / width - 1.0)
    y = cy + hy * (1.0 - 2.0 * (np.arange(height) + 0.5 + float(offset[1])) / height)
    gx, gy = np.meshgrid(x, y)  # (H, W), row 0 on top
    rotation, position = camera_frame(camera)
    near = float(camera.clip_start)
    if camera.type == "ORTHO":
        local_origins = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, -near)], axis=1)
        local_dirs = np.tile([0.0, 0.0, -1.0], (gx.size, 1))
    else:
        local_dirs = np.stack([gx.ravel(), gy.ravel(), -np.ones(gx.size)], axis=1)
        local_origins = local_dirs * near  # the point on the near plane z = -near
        local_dirs /= norm3(local_dirs)[:, None]
    return local_origins @ rotation.T + position, local_dirs @ rotation.T


def image_points(camera: CameraData, points: np.ndarray, width: int, height: int):
    """(x, y, in front) of world ``points`` (N, 3) on a ``width`` × ``height`` image of
    ``camera``, in pixels as ``camera_rays`` places them (pixel (row j, column i) has its centre
    at x = i + ½, y = j + ½, row 0 on top); in front (N,) bool: the point lies ahead of the
    camera's eye (always for an orthographic camera), where x and y are meaningful."""
    cx, cy, hx, hy = _frustum(camera, width, height)
    rotation, position = camera_frame(camera)
    local = (np.asarray(points, np.float64).reshape(-1, 3) - position) @ rotation
    x, y = local[:, 0], local[:, 1]
    if camera.type == "ORTHO":
        front = np.ones(len(local), bool)
    else:
        depth = -local[:, 2]
        front = depth > 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            x, y = x / depth, y / depth
    return (((x - cx) / hx + 1.0) * (0.5 * width), (1.0 - (y - cy) / hy) * (0.5 * height),
            front)


def camera_ray_lengths(camera: CameraData, directions: np.ndarray) -> np.ndarray:
    """(N,) distance from the near to the far clipping plane along each camera ray."""
    rotation, _ = camera_frame(camera)
    depth = float(camera.clip_end) - float(camera.clip_start)
    if camera.type == "ORTHO":
        return np.full(len(directions), depth)
    cos = -(np.asarray(directions, dtype=np.float64) @ rotation[:, 2])
    return depth / np.maximum(cos, 1e-12)



def view_projection(camera: CameraData, width: int, height: int,
                    offset=(0.0, 0.0)) -> np.ndarray:
    """(4, 4) float64 world → OpenGL clip matrix whose pixel centres are ``camera_rays``'
    (NDC y up, so GL row 0 is the image's bottom row); depth spans the clipping range.
    offset : as ``camera_rays``' (the image slides the other way under the pixel centres)."""
    rotation, position = camera_frame(camera)
    view = np.eye(4)
    view[:3, :3] = rotation.T
    view[:3, 3] = -rotation.T @ position
    shift = np.eye(4)  # NDC translation (× w in clip space): the offset ray lands on the centre
    shift[0, 3] = -2.0 * float(offset[0]) / width
    shift[1, 3] = 2.0 * float(offset[1]) / height
    return shift @ projection(camera, width, height) @ view


def projection(camera: CameraData, width: int, height: int) -> np.ndarray:
    """(4, 4) float64 eye → OpenGL clip matrix of a ``width`` × ``height`` image of
    ``camera`` (fitted as ``camera_rays`` fits it); depth spans the clipping range."""
    cx, cy, hx, hy = _frustum(camera, width, height)
    near, far = float(camera.clip_start), float(camera.clip_end)
    proj = np.zeros((4, 4))
    if camera.type == "ORTHO":
        proj[0] = (1.0 / hx, 0.0, 0.0, -cx / hx)
        proj[1] = (0.0, 1.0 / hy, 0.0, -cy / hy)
        proj[2] = (0.0, 0.0, -2.0 / (far - near), -(far + near) / (far - near))
        proj[3] = (0.0, 0.0, 0.0, 1.0)
    else:
        proj[0] = (1.0 / hx, 0.0, cx / hx, 0.0)
        proj[1] = (0.0, 1.0 / hy, cy / hy, 0.0)
        proj[2] = (0.0, 0.0, -(far + near) / (far - near), -2.0 * far * near / (far - near))
        proj[3] = (0.0, 0.0, -1.0, 0.0)
    return proj
