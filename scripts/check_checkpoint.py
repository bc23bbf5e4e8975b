#!/usr/bin/env python3
"""Checks a paircast checkpoint in Python, as a user of naver/croco would load it: torch.load
(weights_only=True first, the default of torch >= 2.6), then the official CroCoNet built from the
checkpoint's args, load_state_dict(strict=True), and one forward pass that must be finite.

  check_checkpoint.py CKPT --croco-dir DIR     # prints one JSON line; exit 1 on failure
"""
import argparse
import inspect
import json
import sys

import torch


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("ckpt")
    ap.add_argument("--croco-dir", required=True, help="a checkout of naver/croco")
    a = ap.parse_args()
    sys.path.insert(0, a.croco_dir)
    from models.croco import CroCoNet  # noqa: E402

    out = {"torch": torch.__version__}
    try:
        ck = torch.load(a.ckpt, map_location="cpu", weights_only=True)
        out["weights_only_load"] = True
    except Exception as e:  # older torch, or a global the safe unpickler refuses
        out["weights_only_load"] = False
        out["weights_only_error"] = str(e).splitlines()[0][:200]
        ck = torch.load(a.ckpt, map_location="cpu")
    args = dict(ck["args"])
    accepted = inspect.signature(CroCoNet.__init__).parameters
    net = CroCoNet(**{k: v for k, v in args.items() if k in accepted})
    missing, unexpected = net.load_state_dict(ck["model"], strict=True)
    out.update({"strict_load": True, "params": sum(p.numel() for p in net.parameters()),
                "step": int(ck.get("step", -1)), "epoch": int(ck.get("epoch", -1))})
    s = args.get("img_size", 224)
    torch.manual_seed(0)
    with torch.no_grad():
        pred, mask, target = net(torch.randn(1, 3, s, s), torch.randn(1, 3, s, s))
    out["forward_finite"] = bool(torch.isfinite(pred).all())
    out["ok"] = out["forward_finite"]
    print(json.dumps(out))
    return 0 if out["ok"] else 1


if __name__ == "__main__":
    try:
        sys.exit(main())
    except Exception as e:
        print(json.dumps({"ok": False, "error": str(e).splitlines()[0][:300]}))
        sys.exit(1)
