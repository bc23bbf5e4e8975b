#!/usr/bin/env python3
"""An independent CroCo forward pass in plain PyTorch, written from the formulas (not from
naver/croco's code), used by the tests and by bench_model to check paircast's LibTorch model.

  croco_ref.py forward CKPT INPUTS OUT   # OUT <- OrderedDict(pred=..., loss=...)
  croco_ref.py bench --preset tiny --batch 8 --threads 2 [--croco-dir DIR]

CKPT is a paircast checkpoint ({'model': state_dict, 'args': {...}}); INPUTS a dict with img1,
img2 [B,3,S,S] and mask [B,N] bool.
"""
import argparse
import collections
import math
import sys
import time

import torch
import torch.nn.functional as F


def layer_norm(x, sd, name):
    return F.layer_norm(x, x.shape[-1:], sd[name + ".weight"], sd[name + ".bias"], eps=1e-6)


def linear(x, sd, name):
    return F.linear(x, sd[name + ".weight"], sd[name + ".bias"])


def heads_split(x, h):
    b, n, c = x.shape
    return x.reshape(b, n, h, c // h).permute(0, 2, 1, 3)


def attend(q, k, v):
    a = torch.softmax(q @ k.transpose(-2, -1) / math.sqrt(q.shape[-1]), dim=-1)
    b, h, n, d = q.shape
    return (a @ v).transpose(1, 2).reshape(b, n, h * d)


def self_attention(x, sd, name, h):
    b, n, c = x.shape
    qkv = linear(x, sd, name + ".qkv").reshape(b, n, 3, h, c // h).permute(2, 0, 3, 1, 4)
    return linear(attend(qkv[0], qkv[1], qkv[2]), sd, name + ".proj")


def cross_attention(x, y, sd, name, h):
    q = heads_split(linear(x, sd, name + ".projq"), h)
    k = heads_split(linear(y, sd, name + ".projk"), h)
    v = heads_split(linear(y, sd, name + ".projv"), h)
    return linear(attend(q, k, v), sd, name + ".proj")


def mlp(x, sd, name):
    return linear(F.gelu(linear(x, sd, name + ".fc1")), sd, name + ".fc2")


def block(x, sd, name, h):
    x = x + self_attention(layer_norm(x, sd, name + ".norm1"), sd, name + ".attn", h)
    return x + mlp(layer_norm(x, sd, name + ".norm2"), sd, name + ".mlp")


def patchify(img, p):
    b, c, s, _ = img.shape
    g = s // p
    return img.reshape(b, c, g, p, g, p).permute(0, 2, 4, 3, 5, 1).reshape(b, g * g, p * p * c)


def forward(sd, a, img1, img2, mask):
    p = a["patch_size"]

    def encode(img, m):
        x = F.conv2d(img, sd["patch_embed.proj.weight"], sd["patch_embed.proj.bias"], stride=p)
        x = x.flatten(2).transpose(1, 2) + sd["enc_pos_embed"][None]
        b, n, c = x.shape
        if m is not None:
            x = x[~m].reshape(b, -1, c)
        for i in range(a["enc_depth"]):
            x = block(x, sd, f"enc_blocks.{i}", a["enc_num_heads"])
        return layer_norm(x, sd, "enc_norm")

    f1 = linear(encode(img1, mask), sd, "decoder_embed")
    f2 = linear(encode(img2, None), sd, "decoder_embed")
    b, n = mask.shape
    full = sd["mask_token"].repeat(b, n, 1)
    full[~mask] = f1.reshape(-1, f1.shape[-1])
    x, y = full + sd["dec_pos_embed"], f2 + sd["dec_pos_embed"]
    h = a["dec_num_heads"]
    for i in range(a["dec_depth"]):
        nm = f"dec_blocks.{i}"
        x = x + self_attention(layer_norm(x, sd, nm + ".norm1"), sd, nm + ".attn", h)
        mem = layer_norm(y, sd, nm + ".norm_y") if (nm + ".norm_y.weight") in sd else y
        x = x + cross_attention(layer_norm(x, sd, nm + ".norm2"), mem, sd, nm + ".cross_attn", h)
        x = x + mlp(layer_norm(x, sd, nm + ".norm3"), sd, nm + ".mlp")
    pred = linear(layer_norm(x, sd, "dec_norm"), sd, "prediction_head")
    target = patchify(img1, p)
    t = (target - target.mean(-1, keepdim=True)) / (target.var(-1, keepdim=True) + 1e-6) ** 0.5
    per = ((pred - t) ** 2).mean(-1)
    loss = (per * mask).sum() / mask.sum()
    return pred, loss


PRESETS = {
    "tiny": dict(enc_embed_dim=192, enc_depth=6, enc_num_heads=3, dec_embed_dim=128, dec_depth=2, dec_num_heads=4),
    "small": dict(enc_embed_dim=384, enc_depth=12, enc_num_heads=6, dec_embed_dim=256, dec_depth=4, dec_num_heads=8),
    "base": dict(enc_embed_dim=768, enc_depth=12, enc_num_heads=12, dec_embed_dim=512, dec_depth=8, dec_num_heads=16),
}


def bench(args):
    """Times the official CroCoNet (from --croco-dir) at a preset: forward, and the train step
    (forward and backward, plus AdamW's step with --optimizer, as CroCo's pretrain.py sets it up:
    betas (0.9, 0.95), weight decay 0.05 except on biases and 1-D parameters; torch's default
    implementation, foreach on CUDA). On CUDA each time is the median over --repeat steps."""
    torch.set_num_threads(args.threads)
    if not args.croco_dir:
        print("SUMMARY croco_ref bench skipped: no --croco-dir")
        return 0
    sys.path.insert(0, args.croco_dir)
    from models.croco import CroCoNet  # noqa: E402  (the user's checkout of naver/croco)
    from models.criterion import MaskedMSE  # noqa: E402
    torch.manual_seed(0)
    dev = torch.device(args.device)
    cuda = dev.type == "cuda"
    net = CroCoNet(**PRESETS[args.preset]).to(dev)
    crit = MaskedMSE(norm_pix_loss=True)
    img1 = torch.randn(args.batch, 3, 224, 224, device=dev)
    img2 = torch.randn(args.batch, 3, 224, 224, device=dev)
    amp = {"bf16": torch.bfloat16, "fp16": torch.float16}.get(args.amp)
    opt = None
    if args.optimizer:
        decay = [p for n, p in net.named_parameters() if p.ndim > 1 and not n.endswith(".bias")]
        no_decay = [p for n, p in net.named_parameters() if p.ndim <= 1 or n.endswith(".bias")]
        opt = torch.optim.AdamW([{"params": decay, "weight_decay": 0.05},
                                 {"params": no_decay, "weight_decay": 0.0}],
                                lr=1.5e-4, betas=(0.9, 0.95))
    if cuda:
        torch.backends.cuda.matmul.allow_tf32 = True
        torch.backends.cudnn.allow_tf32 = True

    clock = time.process_time if args.cpu_time else time.perf_counter

    def sync():
        if cuda:
            torch.cuda.synchronize()

    def best(fn):
        fn()
        fn()
        sync()
        times = []
        for _ in range(args.repeat):
            t = clock()
            fn()
            sync()
            times.append(clock() - t)
        times.sort()
        return times[len(times) // 2] if cuda else times[0]

    def autocast():
        # CPU autocast takes bf16 only (torch 1.13 refuses fp16 there).
        return torch.autocast(dev.type, dtype=amp,
                              enabled=amp is not None and (cuda or amp == torch.bfloat16))

    def fwd():
        with torch.no_grad(), autocast():
            net(img1, img2)

    def fwdbwd():
        with autocast():
            out, mask, target = net(img1, img2)
            loss = crit(out, mask, target)
        if opt is None:
            net.zero_grad()
        loss.backward()
        if opt is not None:
            opt.step()
            opt.zero_grad(set_to_none=True)

    print("SUMMARY croco_ref bench preset=%s batch=%d threads=%d device=%s amp=%s optimizer=%d "
          "torch=%s forward_s=%.4f train_s=%.4f"
          % (args.preset, args.batch, args.threads, args.device, args.amp, int(bool(opt)),
             torch.__version__, best(fwd), best(fwdbwd)))
    return 0


def main():
    ap = argparse.ArgumentParser()
    sub = ap.add_subparsers(dest="cmd", required=True)
    f = sub.add_parser("forward")
    f.add_argument("ckpt")
    f.add_argument("inputs")
    f.add_argument("out")
    b = sub.add_parser("bench", help="time forward and forward+backward")
    b.add_argument("--preset", default="tiny")
    b.add_argument("--batch", type=int, default=8)
    b.add_argument("--threads", type=int, default=2)
    b.add_argument("--repeat", type=int, default=3)
    b.add_argument("--croco-dir", default="", help="a checkout of naver/croco: time its CroCoNet")
    b.add_argument("--cpu-time", action="store_true", help="process CPU seconds, not wall-clock")
    b.add_argument("--device", default="cpu", help="cpu or cuda")
    b.add_argument("--amp", default="none", choices=["none", "bf16", "fp16"],
                   help="autocast dtype (on the CPU: bf16 only)")
    b.add_argument("--optimizer", action="store_true", help="the train step includes AdamW's step")
    o = sub.add_parser("officialize", help="re-save CKPT laid out as official CroCo checkpoints")
    o.add_argument("ckpt")
    o.add_argument("out")
    args = ap.parse_args()
    if args.cmd == "bench":
        return bench(args)
    if args.cmd == "officialize":
        import argparse as ap_mod
        ck = torch.load(args.ckpt, map_location="cpu")
        sd = collections.OrderedDict((k, v.clone()) for k, v in ck["model"].items())
        first = next(iter(sd))
        torch.save({"model": sd, "args": ap_mod.Namespace(**ck["args"]), "epoch": 5,
                    "optimizer": {"state": {0: {"step": torch.tensor(3.0), "exp_avg": torch.ones(2, 2)}},
                                  "param_groups": [{"lr": 1e-4, "params": [0]}]},
                    "scaler": {"scale": 65536.0}}, args.out)
        print("SUMMARY croco_ref officialize ok first=%s" % first)
        return 0
    ck = torch.load(args.ckpt, map_location="cpu")
    inp = torch.load(args.inputs, map_location="cpu")
    with torch.no_grad():
        pred, loss = forward(ck["model"], ck["args"], inp["img1"], inp["img2"], inp["mask"])
    torch.save(collections.OrderedDict(pred=pred, loss=loss.reshape(1)), args.out)
    print("SUMMARY croco_ref forward ok keys=%d" % len(ck["model"]))


if __name__ == "__main__":
    sys.exit(main())
