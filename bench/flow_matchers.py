#!/usr/bin/env python3
"""How much of a held-out set's flow do its images carry? Classical matchers against zero flow.

    /usr/bin/python3 bench/flow_matchers.py 'pilot/flow-heldout/pairs-*.tar' [--pairs 60]

For each pair (shards written with generate_pairs --save-flow) it scores, over the pixels
finetune's primary AEPE averages (known flow landing inside view 2's frame):
  zero     zero flow (finetune's baseline);
  global   the one integer shift within +-R px that best matches the grey images (least squares
           over those pixels), everywhere;
  block7, block15   per pixel, the integer shift within +-R px whose 7x7 or 15x15 window matches
           best (sum of squared differences).
No learning: a learnt model that does not beat these has not used the images. Needs the build's
Python module (build/python) on sys.path, which the script adds.
"""
import argparse
import os
import sys

import torch

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "build", "python"))
from paircast.torch import ShardPairs  # noqa: E402


def grey(x):
    return (x * torch.tensor([0.299, 0.587, 0.114]).view(3, 1, 1)).sum(0)


def shifted_costs(g1, g2, radius):
    """[D, H, W] squared differences of g1 against g2 shifted by each (dx, dy), and the shifts."""
    H, W = g1.shape
    pad = torch.nn.functional.pad(g2[None, None], (radius,) * 4, mode="replicate")[0, 0]
    shifts = [(dx, dy) for dy in range(-radius, radius + 1) for dx in range(-radius, radius + 1)]
    costs = torch.stack([(g1 - pad[radius + dy:radius + dy + H, radius + dx:radius + dx + W]) ** 2
                         for dx, dy in shifts])
    return costs, torch.tensor(shifts, dtype=torch.float32)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("pattern")
    ap.add_argument("--pairs", type=int, default=60)
    ap.add_argument("--radius", type=int, default=12)
    a = ap.parse_args()
    torch.set_num_threads(2)
    sums, n = {}, 0
    for image1, image2, flow, valid, _ in ShardPairs(a.pattern, normalize=False, flow=True):
        H, W = image1.shape[1:]
        ys, xs = torch.meshgrid(torch.arange(H), torch.arange(W), indexing="ij")
        lx, ly = xs + 0.5 + flow[0], ys + 0.5 + flow[1]
        scored = valid & (lx >= 0) & (lx < W) & (ly >= 0) & (ly < H)
        if not scored.any():
            continue
        costs, shifts = shifted_costs(grey(image1.float()), grey(image2.float()), a.radius)

        def aepe(u, v):
            return ((u - flow[0]) ** 2 + (v - flow[1]) ** 2).sqrt()[scored].mean().item()

        best = costs[:, scored].mean(1).argmin()
        result = {"zero": aepe(torch.zeros(H, W), torch.zeros(H, W)),
                  "global": aepe(shifts[best, 0].expand(H, W), shifts[best, 1].expand(H, W))}
        for window in (7, 15):
            pooled = torch.nn.functional.avg_pool2d(costs[None], window, 1, window // 2,
                                                    count_include_pad=False)[0]
            pick = pooled.argmin(0)
            result[f"block{window}"] = aepe(shifts[pick, 0], shifts[pick, 1])
        for k, v in result.items():
            sums[k] = sums.get(k, 0.0) + v
        n += 1
        if n >= a.pairs:
            break
    if n == 0:
        sys.exit(f"flow_matchers: {a.pattern}: no pair with flow landing in frame")
    print(f"{n} pairs, AEPE over in-frame known flow (px), and over zero flow's:")
    for k, v in sums.items():
        print(f"  {k:8s} {v / n:6.3f}  {v / sums['zero']:5.3f}")


if __name__ == "__main__":
    main()
