"""Scene.render against render_view, and covisibility against the C++ generator."""

import numpy as np
import pytest

import paircast
from conftest import RESOLUTION, take


def decode(path):
    data = path.read_bytes()
    return paircast.decode_exr(data, str(path)) if path.suffix == ".exr" else \
        paircast.decode_image(data, str(path))


def test_render_matches_render_view(room, random_views):
    for camera, png, depth, normals in random_views:
        view = room.render(camera, normals=True)
        assert view["rgb"].dtype == np.uint8 and view["rgb"].shape == (RESOLUTION, RESOLUTION, 3)
        assert view["depth"].dtype == np.float32 and view["depth"].shape == (RESOLUTION,) * 2
        assert view["normals"].dtype == np.float32
        assert view["normals"].shape == (RESOLUTION, RESOLUTION, 3)
        np.testing.assert_array_equal(view["rgb"], decode(png))
        np.testing.assert_array_equal(view["depth"], decode(depth))
        np.testing.assert_array_equal(view["normals"], decode(normals))
        assert (view["depth"] > 0).mean() > 0.5


def test_render_returns_only_what_is_asked_and_owns_it(room, random_views):
    camera = random_views[0][0]
    view = room.render(camera, rgb=False, depth=True)
    assert set(view) == {"depth"}
    depth = view["depth"]
    depth[0, 0] = -1.0  # writable, and freed with the array (no view into C++ state)
    del view
    assert room.render(camera)["depth"][0, 0] != -1.0


def test_camera_accepts_numpy_and_lists(room, random_views):
    camera = random_views[0][0]
    as_numpy = {k: np.asarray(v) for k, v in camera.items()}
    np.testing.assert_array_equal(room.render(as_numpy)["depth"], room.render(camera)["depth"])


def test_covisibility_matches_the_generator():
    for sample in take(3):
        c = paircast.covisibility(sample["cameras"][0], sample["depths"][0],
                                  sample["cameras"][1], sample["depths"][1])
        assert c["covis"] == sample["covis"][0]
        assert c["covis"] == min(c["v12"], c["v21"])
        swapped = paircast.covisibility(sample["cameras"][1], sample["depths"][1],
                                        sample["cameras"][0], sample["depths"][0])
        assert (swapped["v12"], swapped["v21"]) == (c["v21"], c["v12"])


def test_covisibility_of_a_view_with_itself_is_one(room, random_views):
    camera = random_views[1][0]
    depth = room.render(camera, rgb=False)["depth"]
    c = paircast.covisibility(camera, depth, camera, depth)
    assert c["covis"] == pytest.approx(1.0)
