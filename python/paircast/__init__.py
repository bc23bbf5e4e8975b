"""paircast: render CroCo pre-training pairs from mesh scenes, from Python.

    scene = paircast.load_scene("scenes/room/room.obj")
    view = scene.render(camera)              # {"rgb": uint8 [H,W,3], "depth": float32 [H,W]}
    paircast.covisibility(cam1, d1, cam2, d2)  # {"v12", "v21", "covis", ...}
    for sample in paircast.PairStream(["scenes/"], seed=0, resolution=256):
        sample["images"]                      # uint8 [V,H,W,3], view 0 is the reference

Cameras are dicts with CroCo's keys: camera_intrinsics (3x3), R_cam2world (3x3), t_cam2world (3),
width, height (OpenCV axes: x right, y down, z forward). Bad input raises paircast.Error (a
ValueError) whose message names what is wrong. paircast.torch has the PyTorch datasets.
"""

from ._paircast import (Error, PairStream, Scene, ShardReader, ShardSet, covisibility,
                        decode_exr, decode_image, encode_image, load_scene)

__all__ = [
    "Error",
    "PairStream",
    "Scene",
    "ShardReader",
    "ShardSet",
    "covisibility",
    "decode_exr",
    "decode_image",
    "encode_image",
    "load_scene",
]
__version__ = "0.1.0"
