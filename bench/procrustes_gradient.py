#!/usr/bin/env python3
"""How well LibTorch's SVD gradient gives the Procrustes rotation's gradient near 2 I.

The pose head's rotation is the nearest rotation to 2 I + M. torch.linalg.svd's gradient divides
by differences of squared singular values, which vanish near 2 I; the rotation's own derivative
divides by their sums. This prints, for matrices 2 I + eps N(0, 1), the median gap between
singular values and the relative error of torch's gradient (float64 and float32) against the
closed form paircast's procrustesRotation uses (model/downstream.cpp).

    /usr/bin/python3 bench/procrustes_gradient.py [--count 4096] [--seed 0]
"""
import argparse

import torch


def closed_form_gradient(m, g):
    u, s, vh = torch.linalg.svd(m)
    d = torch.det(u @ vh)
    flip = torch.ones_like(s)
    flip[..., 2] = d
    u_flipped, s_flipped = u * flip.unsqueeze(-2), s * flip
    h = u_flipped.transpose(-1, -2) @ g @ vh.transpose(-1, -2)
    sums = (s_flipped.unsqueeze(-1) + s_flipped.unsqueeze(-2)).clamp_min(1e-300)
    return u_flipped @ ((h - h.transpose(-1, -2)) / sums) @ vh


def svd_gradient(m, g, dtype):
    m = m.to(dtype).clone().requires_grad_()
    u, _, vh = torch.linalg.svd(m)
    d = torch.det(u @ vh)
    ones = torch.ones_like(d)
    rotation = u @ torch.diag_embed(torch.stack([ones, ones, d], -1)) @ vh
    (rotation * g.to(dtype)).sum().backward()
    return m.grad.double()


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--count", type=int, default=4096)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    torch.manual_seed(args.seed)
    print("| eps | median gap | median |grad| | float64 max rel err | float32 max rel err | float32 non-finite |")
    print("| --- | --- | --- | --- | --- | --- |")
    for eps in (3e-1, 1e-1, 1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-8):
        m = 2 * torch.eye(3, dtype=torch.float64) + eps * torch.randn(args.count, 3, 3, dtype=torch.float64)
        g = torch.randn(args.count, 3, 3, dtype=torch.float64)
        ref = closed_form_gradient(m, g)
        s = torch.linalg.svdvals(m)
        gap = torch.minimum(s[:, 0] - s[:, 1], s[:, 1] - s[:, 2]).median().item()
        row = [f"{eps:.0e}", f"{gap:.1e}", f"{ref.norm(dim=(1, 2)).median().item():.2f}"]
        for dtype in (torch.float64, torch.float32):
            err = (svd_gradient(m, g, dtype) - ref).norm(dim=(1, 2)) / ref.norm(dim=(1, 2))
            finite = torch.isfinite(err)
            row.append(f"{err[finite].max().item():.1e}")
        row.append(str(int((~finite).sum())))
        print("| " + " | ".join(row) + " |")


if __name__ == "__main__":
    main()
