"""Exact optical flow and relative pose in the loaders: the .flo files, crops that move the
flow, and the pose of view 2 in view 1's camera."""

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

import paircast  # noqa: E402
from paircast.torch import (LivePairs, ShardLoader, ShardPairs, crop_flow,  # noqa: E402
                             relative_pose)
from conftest import RESOLUTION, ROOM, run_tool  # noqa: E402


def read_flo(path):
    """A small .flo reader of its own: magic 202021.25, width, height, then (u, v) float32."""
    raw = path.read_bytes()
    magic = np.frombuffer(raw[:4], "<f4")[0]
    width, height = np.frombuffer(raw[4:12], "<i4")
    assert magic == np.float32(202021.25)
    assert len(raw) == 12 + 8 * width * height
    return np.frombuffer(raw[12:], "<f4").reshape(height, width, 2)


def project(camera, points):
    """Pixel coordinates (x, y) of world points [N, 3] in a camera dict, and their z-depth."""
    r, t = np.asarray(camera["R_cam2world"]), np.asarray(camera["t_cam2world"])
    cam = (points - t) @ r
    uvw = cam @ np.asarray(camera["camera_intrinsics"]).T
    return uvw[:, :2] / uvw[:, 2:], cam[:, 2]


def lift(camera, depth):
    """World points of every pixel centre [H * W, 3] at its z-depth."""
    h, w = depth.shape
    v, u = np.mgrid[0:h, 0:w]
    pix = np.stack([u + 0.5, v + 0.5, np.ones_like(u, dtype=float)], -1).reshape(-1, 3)
    cam = pix @ np.linalg.inv(np.asarray(camera["camera_intrinsics"])).T * depth.reshape(-1, 1)
    return cam @ np.asarray(camera["R_cam2world"]).T + np.asarray(camera["t_cam2world"])


def test_croco_layout_flow_lands_where_the_depth_and_cameras_say(flow_shards):
    scene = flow_shards / "room"
    for stem in sorted(scene.glob("*_1.jpeg"))[:2]:
        idx = stem.name[:8]
        cams = [json.loads((scene / f"{idx}_{k}_camera_params.json").read_text()) for k in (1, 2)]
        for cam in cams:
            cam.update(width=RESOLUTION, height=RESOLUTION)
        for k, (src, dst) in ((1, (0, 1)), (2, (1, 0))):
            flow = read_flo(scene / f"{idx}_{k}_flow.flo")
            path = scene / f"{idx}_{k}_depth.exr"
            depth = paircast.decode_exr(path.read_bytes(), str(path))
            depth = depth.reshape(depth.shape[:2])
            points = lift(cams[src], depth)
            xy, z = project(cams[dst], points)
            h, w = depth.shape
            v, u = np.mgrid[0:h, 0:w]
            centres = np.stack([u + 0.5, v + 0.5], -1).reshape(-1, 2)
            known = (depth.reshape(-1) > 0) & (z > 0)
            f = flow.reshape(-1, 2)
            assert known.sum() > 100
            np.testing.assert_allclose(f[known], (xy - centres)[known], atol=2e-3)
            assert np.isinf(f[~known]).all()


def test_crop_flow_moves_by_the_offset_between_the_crops():
    flow = np.zeros((8, 8, 2), np.float32)
    flow[..., 0] = np.arange(8)[None, :]  # u grows with x
    flow[0, 0] = np.inf
    out, valid = crop_flow(flow, (1, 2), (3, 1), (4, 4))
    # Pixel (x=2, y=1) moves by 2 in view 2; in crop coordinates (0, 0) -> (0 + 2 + 2 - 1, 1 - 3).
    assert out.shape == (2, 4, 4)
    assert out[0, 0, 0] == pytest.approx(2 + 2 - 1)
    assert out[1, 0, 0] == pytest.approx(1 - 3)
    assert valid.all()
    out, valid = crop_flow(flow, (0, 0), (0, 0), (4, 4))
    assert not valid[0, 0] and valid.sum() == 15


def test_shard_pairs_give_cropped_flow_valid_masks_and_pose(flow_shards):
    items = list(ShardPairs(str(flow_shards / "pairs-*.tar"), crop=48, flow=True,
                            return_dict=True))
    assert len(items) == 3
    for item in items:
        full = item["flows"][0]
        (t1, l1), (t2, l2) = item["crop1"], item["crop2"]
        expected = full[t1:t1 + 48, l1:l1 + 48] + np.array([l1 - l2, t1 - t2], np.float32)
        got = item["flow1"].permute(1, 2, 0).numpy()
        known = np.isfinite(expected).all(-1)
        np.testing.assert_array_equal(item["valid1"].numpy(), known)
        np.testing.assert_allclose(got[known], expected[known], atol=1e-5)
        pose = item["pose"].numpy()
        c1, c2 = item["cameras"]
        world = np.array([[0.3, -0.2, 1.7]])
        in2 = (world - c2["t_cam2world"]) @ np.asarray(c2["R_cam2world"])
        in1 = (world - c1["t_cam2world"]) @ np.asarray(c1["R_cam2world"])
        np.testing.assert_allclose(in2 @ pose[:3, :3].T + pose[:3, 3], in1, atol=1e-9)
    image1, image2, flow1, valid1, pose = next(iter(ShardPairs(
        str(flow_shards / "pairs-*.tar"), crop=48, flow=True)))
    assert flow1.shape == (2, 48, 48) and valid1.dtype == torch.bool and pose.shape == (4, 4)


def test_live_pairs_give_the_same_flow_as_the_shards_of_the_same_pairs(flow_shards):
    shards = {item["index"]: item for item in ShardPairs(str(flow_shards / "pairs-*.tar"),
                                                           flow=True, return_dict=True)}
    live = next(iter(LivePairs([ROOM], seed=3, resolution=RESOLUTION, threads=1, flow=True,
                               return_dict=True, length=1)))
    shard = shards[live["index"]]
    np.testing.assert_array_equal(live["flows"], shard["flows"])
    torch.testing.assert_close(live["pose"], shard["pose"])


def test_flow_from_shards_without_it_is_an_error(croco_pairs):
    with pytest.raises(paircast.Error, match="no flow"):
        next(iter(ShardPairs(str(croco_pairs / "pairs-*.tar"), flow=True)))


@pytest.fixture(scope="module")
def three_view_flow_shards(tmp_path_factory):
    """Shards of 3 views with flow: a pair with flow is views 1 and 2, with no view drawn."""
    out = tmp_path_factory.mktemp("flow3")
    run_tool("generate_pairs", "--scenes", ROOM, "--out", out, "--pairs-per-scene", 3,
             "--resolution", RESOLUTION, "--seed", 4, "--jobs", 1, "--views", 3,
             "--save-depth", "--save-flow")
    return out


@pytest.mark.parametrize("normalize,views", [(True, 2), (False, 2), (True, 3)])
def test_shard_loader_flow_batches_are_those_of_shard_pairs(flow_shards, three_view_flow_shards,
                                                            normalize, views):
    pattern = str((flow_shards if views == 2 else three_view_flow_shards) / "pairs-*.tar")
    pairs = ShardPairs(pattern, crop=48, flow=True, seed=5, normalize=normalize)
    pairs.set_epoch(2)
    expected = list(pairs)
    loader = ShardLoader(pattern, batch_size=2, crop=48, flow=True, seed=5, threads=2,
                         normalize=normalize, keep=2)
    loader.set_epoch(2)
    batches = [tuple(t.clone() for t in batch) for batch in loader]
    assert [len(b[0]) for b in batches] == [2, 1]
    got = [tuple(b[k][j] for k in range(5)) for b in batches for j in range(len(b[0]))]
    assert len(got) == len(expected) == 3
    for (i1, i2, f1, v1, pose), (e1, e2, g1, w1, epose) in zip(got, expected):
        assert torch.equal(i1, e1) and torch.equal(i2, e2)
        assert torch.equal(v1, w1) and v1.any() and v1.dtype == torch.bool
        assert torch.equal(f1[:, v1], g1[:, w1])  # bit for bit where known
        assert torch.isinf(f1[:, ~v1]).all()
        torch.testing.assert_close(pose, epose, rtol=0, atol=1e-12)
        assert pose.dtype == torch.float64


def test_shard_loader_flow_from_shards_without_it_is_an_error(croco_pairs):
    loader = ShardLoader(str(croco_pairs / "pairs-*.tar"), batch_size=2, crop=32, flow=True)
    with pytest.raises(paircast.Error, match="no flow"):
        next(iter(loader))


def test_relative_pose_of_a_camera_with_itself_is_the_identity():
    cam = {"R_cam2world": np.eye(3)[[1, 2, 0]], "t_cam2world": [1.0, 2.0, 3.0]}
    np.testing.assert_allclose(relative_pose(cam, cam).numpy(), np.eye(4), atol=1e-12)
