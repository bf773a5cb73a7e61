"""The film: what Cycles' film adds where camera samples miss every surface.

The tracers' passes are 0 where camera rays see no surface (as a film-transparent Cycles
render), with ``passes["Alpha"]`` the pixel's filtered share of camera samples that met a
surface (``passes.filter_coverage``). Cycles' Combined shows the world behind the geometry:

* ``background``: the world's radiance along the camera rays of each pixel, sampled at the
  anti-aliased preview's sub-pixel offsets (``camera.filter_samples``, bilinear in the map so
  the sky is not blurred beyond its own pixels) and taken through the same pixel filter as the
  passes — the background a pixel's filter window sees.
* ``film_combined``: RGBA Combined. Opaque film: RGB + (1 − coverage − holdout) × background,
  alpha 1 − holdout; Film › Transparent: RGB as traced (premultiplied) and alpha = coverage.
  ``holdout`` (``passes["_holdout"]``) is the filtered share of camera samples that met a
  holdout (object Holdout, Holdout shader): they show nothing, neither surface nor world.

Only images that leave the add-on go through it (F12's Combined, ``voxgi.render_preview``'s
Combined.A); the passes the tests compare against film-transparent references do not.
"""
from __future__ import annotations

import numpy as np

from ..scene.camera import DEFAULT_FILTER_WIDTH, camera_rays, filter_samples
from ..scene.equirect import sample_bilinear
from .passes import AA_SIDE, filter_coverage

__all__ = ["background", "film_combined", "world_along"]


def world_along(world, camera, width: int, height: int, offset=(0.0, 0.0)):
    """(H, W, 3) float32: the ``WorldData`` ``world`` along ``camera``'s ray through each
    pixel at ``offset`` (``camera.camera_rays``; bilinear in the map), or None for a black
    world (radiance None). ``background`` is this over the filter's sub-pixel offsets; the
    viewport adds one offset per sample (``preview.progressive.Accumulation``)."""
    radiance = getattr(world, "radiance", None)
    if radiance is None:
        return None
    _, directions = camera_rays(camera, width, height, offset)
    return sample_bilinear(radiance, directions)[:, :3].reshape(height, width, 3)


def background(world, camera, width: int, height: int,
               filter_width: float = DEFAULT_FILTER_WIDTH, cancel=None) -> np.ndarray | None:
    """(H, W, 3) float32: the ``WorldData`` ``world`` seen by ``camera`` through each pixel's
    filter (row 0 = top); zeros for a black world (radiance None). cancel : checked between
    the sub-pixel offsets (a worker's job: the Rendered view's world alone); None once it
    says True."""
    if width < 1 or height < 1:
        raise ValueError(f"image size must be positive, got {width}×{height}")
    if getattr(world, "radiance", None) is None:
        return np.zeros((height, width, 3), np.float32)
    offsets, weights = filter_samples(filter_width, AA_SIDE)
    total = np.zeros((height, width, 3))
    for offset, weight in zip(offsets, weights):
        if cancel is not None and cancel():
            return None
        total += weight * world_along(world, camera, width, height, offset)
    return filter_coverage(total / len(offsets), filter_width)


def film_combined(combined, alpha, back, transparent: bool, holdout=None) -> np.ndarray:
    """(H, W, 4) float32 RGBA Combined from the traced (H, W, 3) ``combined``, the (H, W)
    surface coverage ``alpha``, the (H, W, 3) ``back`` (``background``) and the (H, W)
    ``holdout`` share (None: no holdouts); ``transparent``: Film › Transparent (no background,
    alpha = coverage), else background behind the share no surface or holdout covers and
    alpha 1 − holdout."""
    combined = np.asarray(combined, np.float32)
    alpha = np.clip(np.asarray(alpha, np.float32), 0.0, 1.0)
    if combined.ndim != 3 or combined.shape[2] != 3 or alpha.shape != combined.shape[:2]:
        raise ValueError(f"film: Combined {combined.shape} and Alpha {alpha.shape} do not match")
    held = np.zeros_like(alpha) if holdout is None else \
        np.clip(np.asarray(holdout, np.float32), 0.0, 1.0 - alpha)
    if held.shape != alpha.shape:
        raise ValueError(f"film: holdout {held.shape} does not match Alpha {alpha.shape}")
    if transparent:
        return np.concatenate([combined, alpha[..., None]], axis=2)
    back = np.asarray(back, np.float32)
    if back.shape != combined.shape:
        raise ValueError(f"film: background {back.shape} does not match Combined {combined.shape}")
    rgb = combined + (1.0 - alpha - held)[..., None] * back
    return np.concatenate([rgb, (1.0 - held)[..., None]], axis=2)


def snapshot_combined(snapshot, passes, filter_width: float = DEFAULT_FILTER_WIDTH) -> np.ndarray:
    """(H, W, 4) float32 RGBA Combined of a render's ``passes`` (with ``"Alpha"``) as the
    ``snapshot``'s film shows it: its world behind the geometry unless its
    ``film_transparent``."""
    if "Alpha" not in passes:
        raise ValueError("film: the passes carry no Alpha (surface coverage)")
    combined = passes["Combined"]
    height, width = combined.shape[:2]
    transparent = bool(snapshot.film_transparent)
    back = None if transparent or snapshot.camera is None else \
        background(snapshot.world, snapshot.camera, width, height, filter_width)
    if back is None:
        back = np.zeros((height, width, 3), np.float32)
    return film_combined(combined, passes["Alpha"], back, transparent, passes.get("_holdout"))
