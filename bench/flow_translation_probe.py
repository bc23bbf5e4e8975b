#!/usr/bin/env python3
"""Does a small CroCo learn a global translation from scratch? naver/croco's own classes.

    /usr/bin/python3 bench/flow_translation_probe.py --croco-dir CROCO \\
        --train 'pilot/flow-train-many/pairs-*.tar' --heldout 'pilot/flow-heldout/pairs-*.tar' \\
        [--patch 16] [--pos-embed cosine] [--steps 1000] [--lr 3e-4] [--size 64] \\
        [--max-shift 6] [--flow-scale 4] [--init CKPT]

The easiest flow there is: view 2 is view 1 shifted by one integer (dx, dy) in [-R, R]^2
(R: --max-shift), so the flow is that shift everywhere. Both are --size crops of one view of the
shards, whose side must be at least --size + 2 R: view 1 the centre crop, view 2 the crop moved
by -(dx, dy), so every pixel's flow is exact and lands inside view 2. naver/croco's
CroCoDownstreamBinocular (tiny: encoder 192 x 6, decoder 128 x 2) with a linear head (2 values a
patch pixel, flow / --flow-scale px, MSE), AdamW at a constant rate, batch 8, from random
weights or a paircast pre-training checkpoint (--init: its encoder and decoder), trained on the views 1 of --train and measured every 250 steps on 100 views 1 of
--heldout: AEPE against zero flow's. It runs naver/croco's code from --croco-dir (not part of
paircast), as bench/croco_flow_step.py does.
"""
import argparse
import itertools
import os
import sys
import time

import torch


def shifted(image, size, r, gen):
    """View 1, the centre crop, and view 2, moved so that x2(p + d) = x1(p); d in [-r, r]^2."""
    d = torch.randint(-r, r + 1, (2,), generator=gen)
    o = (image.shape[-1] - size) // 2
    x1 = image[:, o:o + size, o:o + size]
    x2 = image[:, o - d[1]:o - d[1] + size, o - d[0]:o - d[0] + size]
    return x1, x2, d.float()


def batch(images, size, r, gen):
    views = [shifted(x, size, r, gen) for x in images]
    return tuple(torch.stack([v[k] for v in views]) for k in range(3))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--croco-dir", required=True)
    ap.add_argument("--train", required=True)
    ap.add_argument("--heldout", required=True)
    ap.add_argument("--patch", type=int, default=16)
    ap.add_argument("--pos-embed", default="cosine")
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--lr", type=float, default=3e-4)
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--max-shift", type=int, default=6)
    ap.add_argument("--flow-scale", type=float, default=4.0)
    ap.add_argument("--init", help="a pretrain checkpoint: its encoder and decoder (default: random)")
    a = ap.parse_args()
    sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "build", "python"))
    sys.path.insert(0, a.croco_dir)
    from paircast.torch import ShardPairs
    from models.croco_downstream import CroCoDownstreamBinocular
    torch.set_num_threads(2)
    torch.manual_seed(0)
    train = [x for x, *_ in itertools.islice(ShardPairs(a.train, flow=True), 1500)]
    heldout = [x for x, *_ in itertools.islice(ShardPairs(a.heldout, flow=True), 100)]
    size, p, r, scale = a.size, a.patch, a.max_shift, a.flow_scale
    if train[0].shape[-1] < size + 2 * r or heldout[0].shape[-1] < size + 2 * r:
        sys.exit(f"flow_translation_probe: views of {train[0].shape[-1]} and "
                 f"{heldout[0].shape[-1]} px, need {size + 2 * r} (--size + 2 --max-shift)")

    class LinearHead(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.proj = torch.nn.Linear(128, p * p * 2)

        def setup(self, croconet):
            pass

        def forward(self, tokens, info):
            y = self.proj(tokens)
            B, G = y.shape[0], size // p
            return y.view(B, G, G, p, p, 2).permute(0, 5, 1, 3, 2, 4).reshape(B, 2, size, size)

    net = CroCoDownstreamBinocular(LinearHead(), img_size=size, patch_size=p, enc_embed_dim=192,
                                   enc_depth=6, enc_num_heads=3, dec_embed_dim=128, dec_depth=2,
                                   dec_num_heads=4, pos_embed=a.pos_embed)
    if a.init:
        ck = torch.load(a.init, map_location="cpu")
        missing, unexpected = net.load_state_dict(ck["model"], strict=False)
        trunk_missing = [k for k in missing if not k.startswith("head.")]
        if trunk_missing:
            sys.exit(f"flow_translation_probe: {a.init} lacks {trunk_missing[:3]}...")
        print(f"init {a.init}: {len(ck['model']) - len(unexpected)} tensors loaded, "
              f"left out {sorted(unexpected)}")
    opt = torch.optim.AdamW(net.parameters(), lr=a.lr, betas=(0.9, 0.95), weight_decay=0.05)
    gen = torch.Generator().manual_seed(1)
    test = batch(heldout, size, r, torch.Generator().manual_seed(2))

    def evaluate():
        net.eval()
        with torch.no_grad():
            x1, x2, d = test
            err = (net(x1, x2) * scale - d[:, :, None, None]).norm(dim=1).mean()
        net.train()
        return err.item(), d.norm(dim=1).mean().item()

    start = time.time()
    print(f"{size} px, patch {p}, shifts to {r} px, flow / {scale} px, {a.pos_embed}, lr {a.lr}: "
          "step, train loss, held-out AEPE, zero flow's")
    for step in range(1, a.steps + 1):
        picks = torch.randint(0, len(train), (8,), generator=gen)
        x1, x2, d = batch([train[i] for i in picks], size, r, gen)
        loss = ((net(x1, x2) - d[:, :, None, None] / scale) ** 2).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        if step % 250 == 0 or step == a.steps:
            aepe, zero = evaluate()
            print(f"{step:6d} {loss.item():8.3f} {aepe:7.3f} {zero:7.3f}  ({time.time() - start:.0f} s)",
                  flush=True)


if __name__ == "__main__":
    main()
