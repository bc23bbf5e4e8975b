"""Bad input raises paircast.Error (a ValueError) with a message that says what is wrong."""

import math

import numpy as np
import pytest

import paircast
from conftest import ROOM, RESOLUTION


def test_missing_scene(tmp_path):
    missing = str(tmp_path / "nowhere.obj")
    with pytest.raises(paircast.Error, match="nowhere.obj"):
        paircast.load_scene(missing)
    with pytest.raises(paircast.Error, match="nowhere.obj"):
        paircast.PairStream([missing])
    assert issubclass(paircast.Error, ValueError)


def test_bad_up_axis():
    with pytest.raises(paircast.Error, match="up"):
        paircast.load_scene(str(ROOM), up="x")


def test_bad_camera_dicts(room, random_views):
    camera = random_views[0][0]
    missing = {k: v for k, v in camera.items() if k != "R_cam2world"}
    with pytest.raises(paircast.Error, match="R_cam2world"):
        room.render(missing)
    with pytest.raises(paircast.Error, match="t_cam2world"):
        room.render({**camera, "t_cam2world": [0.0, 1.0]})
    with pytest.raises(paircast.Error, match="not an object"):
        room.render([1, 2, 3])
    with pytest.raises(paircast.Error, match="unsupported value"):
        room.render({**camera, "width": object()})


def test_nan_in_a_pose(room, random_views):
    camera = random_views[0][0]
    t = list(camera["t_cam2world"])
    t[1] = math.nan
    with pytest.raises(paircast.Error, match="finite"):
        room.render({**camera, "t_cam2world": t})
    R = np.array(camera["R_cam2world"])
    R[0, 0] = np.nan
    with pytest.raises(paircast.Error, match="finite"):
        room.render({**camera, "R_cam2world": R})


def test_depth_that_does_not_fit_its_camera(random_views):
    camera = random_views[0][0]
    good = np.ones((RESOLUTION, RESOLUTION), np.float32)
    with pytest.raises(paircast.Error, match="depth1"):
        paircast.covisibility(camera, np.ones((3, 4), np.float32), camera, good)


def test_bad_stream_options():
    with pytest.raises(paircast.Error, match="covis band"):
        paircast.PairStream([str(ROOM)], min_covis=0.8, max_covis=0.2)
    # The same rule as generate_pairs' (PairOptions::validate), in keyword terms, no flags.
    with pytest.raises(paircast.Error, match=r"^resolution must be in 16\.\.4096 pixels, got 8$"):
        paircast.PairStream([str(ROOM)], resolution=8)
    with pytest.raises(paircast.Error, match=r"^hfov must be in \[1, 179\] degrees"):
        paircast.PairStream([str(ROOM)], hfov=0.5)
    with pytest.raises(paircast.Error, match="part"):
        paircast.PairStream([str(ROOM)], start=2, step=2)


def test_corrupt_shard(tmp_path):
    bad = tmp_path / "pairs-000000.tar"
    bad.write_bytes(b"not a tar file" * 100)
    with pytest.raises(paircast.Error, match="pairs-000000.tar"):
        list(paircast.ShardReader(str(bad)))
