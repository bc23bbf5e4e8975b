"""PairStream: determinism, parity with generate_pairs, disjoint parts."""

import json
from pathlib import Path

import numpy as np
import pytest

import paircast
from conftest import RESOLUTION, ROOM, take


def same(a, b):
    assert (a["scene"], a["index"]) == (b["scene"], b["index"])
    np.testing.assert_array_equal(a["images"], b["images"])
    np.testing.assert_array_equal(a["depths"], b["depths"])
    np.testing.assert_array_equal(a["covis"], b["covis"])
    for ca, cb in zip(a["cameras"], b["cameras"]):
        for key in ca:
            np.testing.assert_array_equal(ca[key], cb[key])


def test_sample_layout():
    s = take(1)[0]
    assert s["images"].dtype == np.uint8 and s["images"].shape == (2, RESOLUTION, RESOLUTION, 3)
    assert s["depths"].dtype == np.float32 and s["depths"].shape == (2, RESOLUTION, RESOLUTION)
    assert len(s["cameras"]) == 2 and s["cameras"][0]["width"] == RESOLUTION
    assert s["covis"].shape == (1,) and 0.5 <= s["covis"][0] <= 1.0
    assert s["scene"] == "room" and s["index"] == 0


def test_stream_is_deterministic_whatever_the_threads():
    first, again = take(4), take(4)
    for a, b in zip(first, again):
        same(a, b)
    threaded = take(6, threads=2)  # order may differ between threads; the pairs may not
    keys = [(s["scene"], s["index"]) for s in threaded]
    assert len(set(keys)) == len(keys), keys  # each index is made once, by one of the threads
    # One thread hands the pairs out in index order, and a pair is a pure function of its index, so
    # the first last + 1 single-thread pairs hold every index up to the threaded run's last: each
    # threaded pair is compared with its single-thread twin, whether or not it is among `first`.
    indices = [s["index"] for s in first]
    assert indices == sorted(set(indices)), indices
    last = max(s["index"] for s in threaded)
    by_key = {(s["scene"], s["index"]): s for s in take(last + 1)}
    for s, key in zip(threaded, keys):
        assert key in by_key, f"{key} is not in the single-thread stream's first {last + 1} pairs"
        same(s, by_key[key])


def test_stream_gives_generate_pairs_pixels(croco_pairs):
    """Same cameras and depth as generate_pairs, and the images its JPEGs encode: all bit for
    bit (our images through the same encoder give the same JPEG bytes)."""
    for s in take(3):
        for k in range(2):
            stem = croco_pairs / "room" / f"{s['index']:08d}_{k + 1}"
            depth = paircast.decode_exr(Path(f"{stem}_depth.exr").read_bytes(), "depth.exr")
            np.testing.assert_array_equal(s["depths"][k], depth)
            camera = json.loads(Path(f"{stem}_camera_params.json").read_text())
            for key in ("camera_intrinsics", "R_cam2world", "t_cam2world"):
                np.testing.assert_allclose(s["cameras"][k][key], camera[key], rtol=0, atol=1e-12)
            jpeg = Path(f"{stem}.jpeg").read_bytes()
            assert paircast.encode_image(s["images"][k], "jpg", quality=100) == jpeg


def test_parts_are_disjoint_and_cover_the_stream():
    whole = {s["index"] for s in take(6)}
    even = {s["index"] for s in take(3, start=0, step=2)}
    odd = {s["index"] for s in take(3, start=1, step=2)}
    assert not even & odd
    assert even | odd == whole


def test_offset_resumes_the_stream():
    same(take(3)[2], take(1, offset=2)[0])


def test_multi_view_samples():
    for s in take(2, views=3):
        assert s["images"].shape == (3, RESOLUTION, RESOLUTION, 3)
        assert s["depths"].shape == (3, RESOLUTION, RESOLUTION)
        assert len(s["cameras"]) == 3 and s["covis"].shape == (2,)
        assert s["visibility"].shape == (3, 3)
        for k in (1, 2):  # each view against the reference, as the generator computed it
            c = paircast.covisibility(s["cameras"][0], s["depths"][0], s["cameras"][k],
                                      s["depths"][k])
            assert c["covis"] == s["covis"][k - 1] and 0.5 <= c["covis"] <= 1.0
            assert (c["v12"], c["v21"]) == (s["visibility"][0, k], s["visibility"][k, 0])


def test_views_out_of_range():
    for views in (0, 100):
        with pytest.raises(ValueError, match="views"):
            paircast.PairStream([str(ROOM)], views=views)


def test_scenes_may_be_paths_or_one_path(tmp_path):
    with paircast.PairStream(ROOM, seed=3, resolution=RESOLUTION, threads=1) as one:
        same(next(one), take(1)[0])
    listing = tmp_path / "scenes.txt"
    listing.write_text(f"{ROOM}\n")
    with paircast.PairStream([listing], seed=3, resolution=RESOLUTION, threads=1) as listed:
        same(next(listed), take(1)[0])
    assert paircast.load_scene(ROOM).name == "room"
