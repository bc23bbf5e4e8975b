#!/usr/bin/env python3
"""Does a small CroCo learn a global translation from scratch? naver/croco's own classes.

    /usr/bin/python3 bench/flow_translation_probe.py --croco-dir CROCO \\
        --train 'pilot/flow-train-many/pairs-*.tar' --heldout 'pilot/flow-heldout/pairs-*.tar' \\
        [--patch 16] [--pos-embed cosine] [--steps 1000] [--lr 3e-4]

The easiest flow there is: view 2 is view 1 shifted by one integer (dx, dy) in [-R, R]^2
(replicate padding), so the flow is that shift everywhere. naver/croco's
CroCoDownstreamBinocular (tiny: encoder 192 x 6, decoder 128 x 2, 64 px) with a linear head
(2 values a patch pixel, flow / 4 px, MSE), AdamW at a constant rate, batch 8, from random
weights, trained on the views 1 of --train and measured every 250 steps on 100 views 1 of
--heldout: AEPE inside the R-pixel border, against zero flow's. It runs naver/croco's code from
--croco-dir (not part of paircast), as bench/croco_flow_step.py does.
"""
import argparse
import itertools
import os
import sys
import time

import torch

R = 6


def shifted(image, gen):
    d = torch.randint(-R, R + 1, (2,), generator=gen)
    pad = torch.nn.functional.pad(image[None], (R,) * 4, mode="replicate")[0]
    size = image.shape[-1]
    return pad[:, R - d[1]:R - d[1] + size, R - d[0]:R - d[0] + size], d.float()  # x2(p) = x1(p - d)


def batch(images, gen):
    pairs = [shifted(x, gen) for x in images]
    return (torch.stack(images), torch.stack([p for p, _ in pairs]),
            torch.stack([d for _, d in pairs]))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--croco-dir", required=True)
    ap.add_argument("--train", required=True)
    ap.add_argument("--heldout", required=True)
    ap.add_argument("--patch", type=int, default=16)
    ap.add_argument("--pos-embed", default="cosine")
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--lr", type=float, default=3e-4)
    a = ap.parse_args()
    sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "build", "python"))
    sys.path.insert(0, a.croco_dir)
    from paircast.torch import ShardPairs
    from models.croco_downstream import CroCoDownstreamBinocular
    torch.set_num_threads(2)
    torch.manual_seed(0)
    train = [x for x, *_ in itertools.islice(ShardPairs(a.train, flow=True), 1500)]
    heldout = [x for x, *_ in itertools.islice(ShardPairs(a.heldout, flow=True), 100)]
    size, p = train[0].shape[-1], a.patch

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
    opt = torch.optim.AdamW(net.parameters(), lr=a.lr, betas=(0.9, 0.95), weight_decay=0.05)
    gen = torch.Generator().manual_seed(1)
    test = batch(heldout, torch.Generator().manual_seed(2))

    def evaluate():
        net.eval()
        with torch.no_grad():
            x1, x2, d = test
            err = (net(x1, x2) * 4 - d[:, :, None, None]).norm(dim=1)[:, R:-R, R:-R].mean()
        net.train()
        return err.item(), d.norm(dim=1).mean().item()

    start = time.time()
    print(f"patch {p}, {a.pos_embed}, lr {a.lr}: step, train loss, held-out AEPE, zero flow's")
    for step in range(1, a.steps + 1):
        picks = torch.randint(0, len(train), (8,), generator=gen)
        x1, x2, d = batch([train[i] for i in picks], gen)
        loss = ((net(x1, x2) - d[:, :, None, None] / 4) ** 2)[:, :, R:-R, R:-R].mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        if step % 250 == 0 or step == a.steps:
            aepe, zero = evaluate()
            print(f"{step:6d} {loss.item():8.3f} {aepe:7.3f} {zero:7.3f}  ({time.time() - start:.0f} s)",
                  flush=True)


if __name__ == "__main__":
    main()
