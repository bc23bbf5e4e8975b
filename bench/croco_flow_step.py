#!/usr/bin/env python3
"""Times naver/croco's CroCo-Flow train step on the CPU: CroCoDownstreamBinocular with
PixelwiseTaskWithDPT (3 channels), stereoflow's LaplacianLossBounded and AdamW (betas 0.9, 0.95,
weight decay 0.05 but on biases and 1-D parameters), from a checkout of naver/croco.

  croco_flow_step.py --croco-dir DIR --preset tiny --img-size 224 --batch 8 --threads 2 \
      --hooks 5 5 6 7 [--amp bf16]
--amp bf16 runs the forward and the loss under torch.autocast("cpu", dtype=torch.bfloat16).
Prints one line: SUMMARY croco_flow_step ... train_s=<median seconds per step>
minflt_per_step=<minor page faults per timed step>.
"""
import argparse
import os
import resource
import sys
import time

import torch

PRESETS = {
    "tiny": dict(enc_embed_dim=192, enc_depth=6, enc_num_heads=3, dec_embed_dim=128, dec_depth=2,
                 dec_num_heads=4),
    "small": dict(enc_embed_dim=384, enc_depth=12, enc_num_heads=6, dec_embed_dim=256,
                  dec_depth=4, dec_num_heads=8),
    "base": dict(enc_embed_dim=768, enc_depth=12, enc_num_heads=12, dec_embed_dim=512,
                 dec_depth=8, dec_num_heads=16),
}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--croco-dir", required=True)
    ap.add_argument("--preset", default="tiny", choices=sorted(PRESETS))
    ap.add_argument("--img-size", type=int, default=224)
    ap.add_argument("--batch", type=int, default=8)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--hooks", type=int, nargs=4, required=True)
    ap.add_argument("--amp", default="none", choices=["none", "bf16"])
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    sys.path.insert(0, a.croco_dir)
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "scripts"))
    import einops_fallback  # noqa: E402  (naver/croco's DPT block imports einops)
    einops_fallback.install()
    from models.croco_downstream import CroCoDownstreamBinocular  # noqa: E402
    from models.head_downstream import PixelwiseTaskWithDPT  # noqa: E402
    from stereoflow.criterion import LaplacianLossBounded  # noqa: E402

    torch.manual_seed(0)
    head = PixelwiseTaskWithDPT(hooks_idx=a.hooks, num_channels=3)
    net = CroCoDownstreamBinocular(head, img_size=a.img_size, **PRESETS[a.preset])
    crit = LaplacianLossBounded()
    decay = [p for n, p in net.named_parameters() if p.ndim > 1 and not n.endswith(".bias")]
    rest = [p for n, p in net.named_parameters() if p.ndim <= 1 or n.endswith(".bias")]
    opt = torch.optim.AdamW([{"params": decay, "weight_decay": 0.05},
                             {"params": rest, "weight_decay": 0.0}], lr=1e-4, betas=(0.9, 0.95))
    s = a.img_size
    img1, img2 = torch.randn(a.batch, 3, s, s), torch.randn(a.batch, 3, s, s)
    gt = 5 * torch.randn(a.batch, 2, s, s)

    def step():
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=a.amp == "bf16"):
            out = net(img1, img2)
            loss = crit(out[:, :2].float(), gt, out[:, 2:3].float())
        loss.backward()
        opt.step()
        opt.zero_grad(set_to_none=True)

    step()
    times = []
    faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(a.repeat):
        t = time.perf_counter()
        step()
        times.append(time.perf_counter() - t)
    faults = (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - faults) / a.repeat
    times.sort()
    print("SUMMARY croco_flow_step preset=%s batch=%d threads=%d img=%d amp=%s torch=%s "
          "train_s=%.4f minflt_per_step=%d" % (a.preset, a.batch, a.threads, s, a.amp,
                                               torch.__version__, times[len(times) // 2], faults))
    return 0


if __name__ == "__main__":
    sys.exit(main())
