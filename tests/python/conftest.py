"""Shared fixtures of the Python tests: where the build is, the shipped room scene, and views of
it made by the command-line tools (the references the Python side must match)."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

SOURCE_DIR = Path(os.environ.get("PAIRCAST_SOURCE_DIR", Path(__file__).resolve().parents[2]))
BINARY_DIR = Path(os.environ.get("PAIRCAST_BINARY_DIR", SOURCE_DIR / "build"))
sys.path.insert(0, str(BINARY_DIR / "python"))

import paircast  # noqa: E402  (after the path is set)

ROOM = SOURCE_DIR / "scenes" / "room" / "room.obj"
RESOLUTION = 64  # small images keep the suite fast


def tool(name):
    path = BINARY_DIR / "tools" / name
    if not path.exists():
        pytest.fail(f"{path} is missing: build the '{name}' target first")
    return str(path)


def run_tool(name, *args):
    result = subprocess.run([tool(name), *map(str, args)], capture_output=True, text=True,
                            env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert result.returncode == 0, f"{name} failed: {result.stderr}"
    return result


@pytest.fixture(scope="session")
def room():
    return paircast.load_scene(str(ROOM))


@pytest.fixture(scope="session")
def random_views(tmp_path_factory):
    """Three random views of the room by render_view: [(camera dict, png, depth exr, normals)]."""
    out = tmp_path_factory.mktemp("views")
    run_tool("render_view", "--scene", ROOM, "--random", 3, "--resolution", RESOLUTION,
             "--seed", 5, "--out", out)
    views = []
    for i in range(3):
        stem = out / f"{i:06d}"
        camera = json.loads(Path(f"{stem}.json").read_text())
        views.append((camera, Path(f"{stem}.png"), Path(f"{stem}_depth.exr"),
                      Path(f"{stem}_normals.exr")))
    return views


@pytest.fixture(scope="session")
def croco_pairs(tmp_path_factory):
    """generate_pairs' croco layout and shards, with depth and cameras: 3 pairs of the room, seed 3,
    JPEG quality 100."""
    out = tmp_path_factory.mktemp("croco")
    run_tool("generate_pairs", "--scenes", ROOM, "--out", out, "--pairs-per-scene", 3,
             "--resolution", RESOLUTION, "--seed", 3, "--jobs", 1, "--format", "both",
             "--save-depth", "--shard-size", 2, "--jpeg-quality", 100)
    return out


@pytest.fixture(scope="session")
def multiview_shards(tmp_path_factory):
    """generate_pairs' shards of 3-view samples with depth: 3 samples of the room, seed 3."""
    out = tmp_path_factory.mktemp("views3")
    run_tool("generate_pairs", "--scenes", ROOM, "--out", out, "--pairs-per-scene", 3,
             "--resolution", RESOLUTION, "--seed", 3, "--jobs", 1, "--format", "shards",
             "--save-depth", "--views", 3)
    return out


def stream(**kwargs):
    options = dict(seed=3, resolution=RESOLUTION, threads=1)
    options.update(kwargs)
    return paircast.PairStream([str(ROOM)], **options)


def take(n, **kwargs):
    with stream(**kwargs) as s:
        return [next(s) for _ in range(n)]


@pytest.fixture(scope="session")
def flow_shards(tmp_path_factory):
    """generate_pairs' shards and croco layout with flow and depth: 3 pairs of the room, seed 3."""
    out = tmp_path_factory.mktemp("flow")
    run_tool("generate_pairs", "--scenes", ROOM, "--out", out, "--pairs-per-scene", 3,
             "--resolution", RESOLUTION, "--seed", 3, "--jobs", 1, "--format", "both",
             "--save-depth", "--save-flow")
    return out
