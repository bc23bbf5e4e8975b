#!/usr/bin/env python3
"""Checks a finetune checkpoint against naver/croco's own downstream classes, as a user of
CroCo-Flow would load it: PixelwiseTaskWithDPT(**head_kwargs) in CroCoDownstreamBinocular (flow)
or CroCoDownstreamMonocularEncoder (depth) built with croco_kwargs, load_state_dict(strict=True);
then, given two images of the model's size and finetune --predict's output for them, the largest
difference between the official model's output and ours.

  check_downstream.py CKPT --croco-dir DIR [--image1 A --image2 B --ours OUT.flo|OUT.exr]

Prints one JSON line; exit 1 when the load or the comparison (> --tolerance) fails.
"""
import argparse
import json
import os
import sys

import numpy as np
import torch


def read_flo(path):
    raw = open(path, "rb").read()
    w, h = np.frombuffer(raw[4:12], "<i4")
    return np.frombuffer(raw[12:], "<f4").reshape(h, w, 2)


def read_exr(path):
    import OpenImageIO as oiio  # python3-openimageio
    return oiio.ImageInput.open(path).read_image("float")[..., 0]


def image_tensor(path):
    from PIL import Image
    rgb = np.asarray(Image.open(path).convert("RGB"), dtype=np.float32) / 255.0
    mean, std = np.array([0.485, 0.456, 0.406]), np.array([0.229, 0.224, 0.225])
    return torch.from_numpy(((rgb - mean) / std).transpose(2, 0, 1)).float()[None]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("ckpt")
    ap.add_argument("--croco-dir", required=True, help="a checkout of naver/croco")
    ap.add_argument("--image1")
    ap.add_argument("--image2")
    ap.add_argument("--ours", help="finetune --predict's output for the two images")
    ap.add_argument("--tolerance", type=float, default=1e-4)
    a = ap.parse_args()
    sys.path.insert(0, a.croco_dir)
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import einops_fallback  # noqa: E402
    einops_fallback.install()
    from models.croco_downstream import (CroCoDownstreamBinocular,  # noqa: E402
                                         CroCoDownstreamMonocularEncoder, croco_args_from_ckpt)
    from models.head_downstream import PixelwiseTaskWithDPT  # noqa: E402

    ck = torch.load(a.ckpt, map_location="cpu")
    head = PixelwiseTaskWithDPT(**ck["head_kwargs"])
    cls = CroCoDownstreamMonocularEncoder if ck["task"] == "depth" else CroCoDownstreamBinocular
    net = cls(head, **croco_args_from_ckpt(ck)).eval()
    net.load_state_dict(ck["model"], strict=True)
    out = {"task": ck["task"], "strict_load": True, "torch": torch.__version__,
           "params": sum(p.numel() for p in net.parameters())}
    ok = True
    if a.ours:
        img1 = image_tensor(a.image1)
        with torch.no_grad():
            pred = net(img1) if ck["task"] == "depth" else net(img1, image_tensor(a.image2))
        if ck["task"] == "depth":
            theirs, ours = torch.exp(pred[0, 0]).numpy(), read_exr(a.ours)
        else:
            theirs, ours = pred[0, :2].permute(1, 2, 0).numpy(), read_flo(a.ours)
        out["max_abs_diff"] = float(np.abs(theirs - ours).max())
        out["max_abs_value"] = float(np.abs(theirs).max())
        ok = out["max_abs_diff"] <= a.tolerance * max(1.0, out["max_abs_value"])
    print(json.dumps(out))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
