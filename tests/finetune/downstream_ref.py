#!/usr/bin/env python3
"""An independent forward pass of CroCo's downstream models with the DPT head, in plain
PyTorch functions over a state_dict, written from the architecture's description (not from
naver/croco's code); the tests check paircast's LibTorch model against it.

  downstream_ref.py forward CKPT INPUTS OUT   # OUT <- OrderedDict(pred=...)

CKPT is a paircast fine-tuning checkpoint ({'model', 'croco_kwargs', 'task', 'head_kwargs'});
INPUTS a dict with img1 (and img2) [B, 3, S, S]. Cosine position embeddings only.
"""
import collections
import os
import sys

import torch
import torch.nn.functional as F

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "model"))
from croco_ref import block, cross_attention, layer_norm, linear, mlp, self_attention  # noqa: E402


def conv(x, sd, name, stride=1, padding=0):
    return F.conv2d(x, sd[name + ".weight"], sd.get(name + ".bias"), stride=stride,
                    padding=padding)


def up2(x):
    return F.interpolate(x, scale_factor=2, mode="bilinear", align_corners=True)


def encoder_blocks(sd, a, img):
    x = conv(img, sd, "patch_embed.proj", stride=a["patch_size"]).flatten(2).transpose(1, 2)
    x = x + sd["enc_pos_embed"][None]
    out = []
    for i in range(a["enc_depth"]):
        x = block(x, sd, f"enc_blocks.{i}", a["enc_num_heads"])
        out.append(x)
    out[-1] = layer_norm(out[-1], sd, "enc_norm")
    return out


def decoder_blocks(sd, a, f1, f2):
    x = linear(f1, sd, "decoder_embed") + sd["dec_pos_embed"]
    y = linear(f2, sd, "decoder_embed") + sd["dec_pos_embed"]
    h = a["dec_num_heads"]
    out = []
    for i in range(a["dec_depth"]):
        nm = f"dec_blocks.{i}"
        x = x + self_attention(layer_norm(x, sd, nm + ".norm1"), sd, nm + ".attn", h)
        mem = layer_norm(y, sd, nm + ".norm_y")
        x = x + cross_attention(layer_norm(x, sd, nm + ".norm2"), mem, sd, nm + ".cross_attn", h)
        x = x + mlp(layer_norm(x, sd, nm + ".norm3"), sd, nm + ".mlp")
        out.append(x)
    out[-1] = layer_norm(out[-1], sd, "dec_norm")
    return out


def residual(x, sd, name):
    return x + conv(F.relu(conv(F.relu(x), sd, name + ".conv1", padding=1)), sd, name + ".conv2",
                    padding=1)


def fuse(x, skip, sd, name):
    if skip is not None:
        x = x + residual(skip, sd, name + ".resConfUnit1")
    return conv(up2(residual(x, sd, name + ".resConfUnit2")), sd, name + ".out_conv")


def dpt(sd, blocks, hooks, size):
    g = size // 16
    maps = []
    for k, hook in enumerate(hooks):
        t = blocks[hook]
        x = t.transpose(1, 2).reshape(t.shape[0], t.shape[2], g, g)
        pre = f"head.dpt.act_{k + 1}_postprocess"
        x = conv(x, sd, pre + ".0")
        if k in (0, 1):
            x = F.conv_transpose2d(x, sd[pre + ".1.weight"], sd[pre + ".1.bias"], stride=4 - 2 * k)
        elif k == 3:
            x = conv(x, sd, pre + ".1", stride=2, padding=1)
        maps.append(conv(x, sd, f"head.dpt.scratch.layer{k + 1}_rn", padding=1))
    path = fuse(maps[3], None, sd, "head.dpt.scratch.refinenet4")
    for k in (2, 1, 0):
        path = fuse(path, maps[k], sd, f"head.dpt.scratch.refinenet{k + 1}")
    x = up2(conv(path, sd, "head.dpt.head.0", padding=1))
    x = F.relu(conv(x, sd, "head.dpt.head.2", padding=1))
    return conv(x, sd, "head.dpt.head.4")


def forward(ck, inputs):
    sd, a = ck["model"], ck["croco_kwargs"]
    hooks = list(ck["head_kwargs"]["hooks_idx"])
    img1 = inputs["img1"]
    if ck["task"] == "depth":
        return dpt(sd, encoder_blocks(sd, a, img1), hooks, img1.shape[-1])
    b = img1.shape[0]
    enc = encoder_blocks(sd, a, torch.cat([img1, inputs["img2"]]))
    enc1 = [t[:b] for t in enc]
    dec = decoder_blocks(sd, a, enc1[-1], enc[-1][b:])
    out = dpt(sd, enc1 + dec, hooks, img1.shape[-1])
    # The head regresses flow / flow_scale: pixels are its u, v times the checkpoint's scale.
    scale = float(ck.get("flow_scale", 1.0))
    return torch.cat([out[:, :2] * scale, out[:, 2:]], 1)


def main():
    if len(sys.argv) != 5 or sys.argv[1] != "forward":
        print(__doc__, file=sys.stderr)
        return 2
    ck = torch.load(sys.argv[2], map_location="cpu")
    inputs = torch.load(sys.argv[3], map_location="cpu")
    with torch.no_grad():
        pred = forward(ck, inputs)
    torch.save(collections.OrderedDict(pred=pred), sys.argv[4])
    return 0


if __name__ == "__main__":
    sys.exit(main())
