#!/usr/bin/env python3
"""What does a cross-view checkpoint take from its reference view? naver/croco's own CroCoNet.

    /usr/bin/python3 bench/croco_reference_probe.py --croco-dir CROCO --checkpoint CKPT \\
        --pairs 'pairs/pairs-*.tar' [--count 200]

The masked completion loss of a paircast pre-training checkpoint (cross-view completion, loaded
strictly into naver/croco's CroCoNet) on --count pairs, with the same masks, for four reference
views given in place of view 2:
  - view 2, the pair's own (what it was trained with);
  - another pair's view 2 (no information about view 1);
  - view 1 itself (all of view 1, unmasked: a model that matches content copies it);
  - zeros.
A model that learnt correspondence completes best from view 1 itself. One that memorised its
training scenes and reads the reference only to place view 1 in them does better with the
pair's own view 2, at the viewpoint change it was trained on, than with view 1 itself.
The loss is CroCo's, on per-patch normalised pixels (norm_pix_loss). It runs naver/croco's code
from --croco-dir (not part of paircast), as bench/croco_flow_step.py does.
"""
import argparse
import inspect
import itertools
import os
import sys

import torch


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--croco-dir", required=True)
    ap.add_argument("--checkpoint", required=True)
    ap.add_argument("--pairs", required=True, help="shards (a glob), as pretrain --data")
    ap.add_argument("--count", type=int, default=200)
    a = ap.parse_args()
    sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "build", "python"))
    sys.path.insert(0, a.croco_dir)
    from paircast.torch import ShardPairs
    from models.croco import CroCoNet
    torch.set_num_threads(2)
    ck = torch.load(a.checkpoint, map_location="cpu")
    if ck.get("task", "croco") != "croco":
        sys.exit(f"croco_reference_probe: {a.checkpoint}: a {ck['task']} checkpoint has no "
                 "reference view")
    args = dict(ck["args"])
    accepted = inspect.signature(CroCoNet.__init__).parameters
    net = CroCoNet(**{k: v for k, v in args.items() if k in accepted})
    net.load_state_dict(ck["model"], strict=True)
    net.eval()
    size = args.get("img_size", 224)
    pairs = list(itertools.islice(ShardPairs(a.pairs, crop=size), a.count))
    if not pairs:
        sys.exit(f"croco_reference_probe: no pairs in {a.pairs}")
    x1 = torch.stack([p[0] for p in pairs])
    x2 = torch.stack([p[1] for p in pairs])

    def loss(reference):
        torch.manual_seed(1)  # the same masks for every reference
        with torch.no_grad():
            out, mask, target = net(x1, reference)
            mean, var = target.mean(-1, keepdim=True), target.var(-1, keepdim=True)
            target = (target - mean) / (var + 1e-6) ** 0.5
            per_patch = ((out - target) ** 2).mean(-1)
            return ((per_patch * mask).sum() / mask.sum()).item()

    print(f"{a.checkpoint}: {len(pairs)} pairs of {a.pairs}, {size} px, masked completion loss")
    for name, reference in [("view 2 (its own)", x2), ("another pair's view 2", x2.roll(1, 0)),
                            ("view 1 itself", x1), ("zeros", torch.zeros_like(x2))]:
        print(f"  {name:24s} {loss(reference):.4f}")


if __name__ == "__main__":
    main()
