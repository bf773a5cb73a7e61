"""F12's Render Region traced alone: the rectangle traced around it (``preview.region``) and
the camera cropped to it (``scene.view_camera.crop_camera``)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from snapshots import translation

from voxgi.voxgi_addon.preview.region import ALIGN_CELLS, MARGIN_CELLS, traced_rect
from voxgi.voxgi_addon.scene.camera import camera_rays, image_points
from voxgi.voxgi_addon.scene.snapshot import CameraData
from voxgi.voxgi_addon.scene.view_camera import crop_camera


def _camera(kind: str, resolution=(64, 40)) -> CameraData:
    near, far = 0.1, 50.0
    p = np.zeros((4, 4))
    if kind == "ORTHO":
        p[0, 0], p[1, 1], p[0, 3], p[1, 3] = 0.5, 0.8, 0.1, -0.05
        p[2, 2], p[2, 3], p[3, 3] = -2 / (far - near), -(far + near) / (far - near), 1.0
    else:  # a lens shift both ways
        p[0, 0], p[1, 1], p[0, 2], p[1, 2] = 1.4, 2.24, 0.2, -0.1
        p[2, 2], p[2, 3], p[3, 2] = -(far + near) / (far - near), -2 * far * near / (far - near), -1.0
    return CameraData("cam", translation(0.5, -1.0, 4.0), p, resolution, kind,
                      clip_start=near, clip_end=far)


@pytest.mark.parametrize("kind", ["PERSP", "ORTHO"])
@pytest.mark.parametrize("size", [(64, 40), (50, 40)])  # the camera's aspect, and another
def test_a_cropped_camera_sees_exactly_its_pixels_of_the_frame(kind, size):
    """The region's rays are the frame's rays through the region's pixels (perspective with a
    lens shift, orthographic; a frame of another aspect than the camera's fitted by its Sensor
    Fit first), and a point lands on the same pixel of the crop as of the frame."""
    camera = _camera(kind)
    width, height = size
    origins, directions = (a.reshape(height, width, 3) for a in camera_rays(camera, width, height))
    rect = (9, 5, 23, 17)  # (x0, y0, w, h) from the bottom left
    crop = crop_camera(camera, rect, width, height)
    assert crop.resolution == (23, 17)
    o, d = (a.reshape(17, 23, 3) for a in camera_rays(crop))
    rows = slice(height - 5 - 17, height - 5)  # rays' rows top first
    np.testing.assert_allclose(d, directions[rows, 9:32], atol=1e-12)
    np.testing.assert_allclose(o, origins[rows, 9:32], atol=1e-12)
    points = origins[rows, 9:32].reshape(-1, 3) + 3.0 * directions[rows, 9:32].reshape(-1, 3)
    x, y, front = image_points(crop, points, 23, 17)
    fx, fy, _ = image_points(camera, points, width, height)
    assert front.all()
    np.testing.assert_allclose(x, fx - 9, atol=1e-9)
    np.testing.assert_allclose(y, fy - (height - 5 - 17), atol=1e-9)
    assert dataclasses.replace(crop, projection_matrix=camera.projection_matrix,
                               resolution=camera.resolution) == dataclasses.replace(camera)


@pytest.mark.parametrize("stride", [1, 2, 3])
def test_the_traced_rectangle_holds_the_region_its_margin_and_the_frames_lattice(stride):
    width, height = 640, 480
    for region in [(300, 200, 40, 30), (0, 0, 17, 9), (630, 470, 10, 10), (100, 5, 1, 1),
                   (0, 0, 640, 480)]:
        x0, y0, w, h = region
        left, bottom, tw, th = traced_rect(region, width, height, stride)
        top = height - bottom - th  # rows from the top
        margin = MARGIN_CELLS * stride
        # inside the frame, around the region with the margin (or to the frame's edge)
        assert 0 <= left and 0 <= bottom and left + tw <= width and bottom + th <= height
        assert left <= max(0, x0 - margin) and bottom == max(0, y0 - margin)
        assert left + tw == min(width, x0 + w + margin)
        assert top <= max(0, height - y0 - h - margin)
        # the top-left corner on the whole frame's lattice, at most one step of it further out
        assert left % (ALIGN_CELLS * stride) == 0 and top % (ALIGN_CELLS * stride) == 0
        assert left > x0 - margin - ALIGN_CELLS * stride
        assert top > height - y0 - h - margin - ALIGN_CELLS * stride
    assert traced_rect((0, 0, 640, 480), width, height, stride) == (0, 0, 640, 480)


def test_a_region_outside_the_frame_is_refused():
    for region in [(600, 0, 50, 10), (0, 0, 0, 5), (-1, 0, 5, 5)]:
        with pytest.raises(ValueError, match="not inside"):
            traced_rect(region, 640, 480, 1)
