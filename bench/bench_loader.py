#!/usr/bin/env python3
"""bench_loader: paircast's shard loaders against naver/croco's official PairsDataset, side by side.

One run makes the pairs (generate_pairs: --pairs-per-scene pairs of each shipped scene at --resolution,
written once as 12 shards, once as 1 shard, and in CroCo's folder layout), then times on those
same pairs, one after the other, repeated --rounds times (best round kept):
  - paircast.torch.ShardPairs(crop=224) through a DataLoader with W workers, 12 shards and 1;
  - the official PairsDataset('habitat_release', trfs='crop224') (PIL decode, RandomCropPair,
    ToTensor, Normalize) through the same DataLoader, on the CroCo layout of those pairs;
  - the C++ trainer's batch loader alone (bench_trainer_loader), in pairs/s per thread.
ShardPairs makes its batches itself (batch_size=B, DataLoader batch_size=None: decoded straight into
shared memory); it is also timed per pair, collated by the DataLoader as the official loader is.
Each DataLoader pass is timed from the iterator's creation (workers started) to its last batch.
Target: ShardPairs at least 2.0x the official loader with 2 workers, with 12 shards and with 1.
It also prints the cores a GPU that consumes 2,000 pairs/s would need with each loader.

    /usr/bin/python3 bench/bench_loader.py --croco-dir ~/src/croco
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--croco-dir", required=True, help="a checkout of naver/croco")
    p.add_argument("--build", default=str(ROOT / "build"), help="CMake build folder")
    p.add_argument("--scenes", nargs="+", default=[str(ROOT / "scenes")])
    p.add_argument("--pairs-per-scene", type=int, default=200)
    p.add_argument("--resolution", type=int, default=256)
    p.add_argument("--crop", type=int, default=224)
    p.add_argument("--workers", type=int, default=2, help="DataLoader workers (W)")
    p.add_argument("--batch-size", type=int, default=64)
    p.add_argument("--rounds", type=int, default=3, help="timed passes of each loader")
    p.add_argument("--gpu-rate", type=float, default=2000.0,
                   help="pairs/s a GPU consumes, for the cores figure")
    p.add_argument("--out", help="keep the pairs here (default: a temporary folder)")
    return p.parse_args()


def generate(args, out, shard_size, fmt):
    cmd = [str(Path(args.build) / "tools" / "generate_pairs"), "--scenes", *args.scenes,
           "--out", str(out), "--pairs-per-scene", str(args.pairs_per_scene), "--resolution",
           str(args.resolution), "--seed", "0", "--format", fmt, "--shard-size", str(shard_size)]
    subprocess.run(cmd, check=True, capture_output=True, text=True)


def loader_rate(dataset, args, rounds, batched=False):
    """Best pairs/s over `rounds` passes of a DataLoader over `dataset` (which makes its own
    batches when `batched`)."""
    import torch
    from torch.utils.data import DataLoader

    best = 0.0
    for r in range(rounds):
        if hasattr(dataset, "set_epoch"):
            dataset.set_epoch(r)
        loader = DataLoader(dataset, batch_size=None if batched else args.batch_size,
                            num_workers=args.workers)
        start = time.perf_counter()
        pairs = 0
        for image1, image2 in loader:
            assert image1.shape[1:] == (3, args.crop, args.crop) and image1.dtype == torch.float32
            pairs += image1.shape[0]
        best = max(best, pairs / (time.perf_counter() - start))
    return best, pairs


def official_dataset(args, croco_layout, data_dir):
    """naver/croco's PairsDataset over `croco_layout`, as its pretrain.py builds it."""
    sys.path.insert(0, args.croco_dir)
    from datasets.pairs_dataset import PairsDataset  # naver/croco

    link = Path(data_dir) / "habitat_release"
    link.parent.mkdir(parents=True, exist_ok=True)
    if not link.exists():
        link.symlink_to(Path(croco_layout).resolve(), target_is_directory=True)
    return PairsDataset("habitat_release", trfs=f"crop{args.crop}", data_dir=str(data_dir))


def trainer_loader(args, shards, workers):
    cmd = [str(Path(args.build) / "bench" / "bench_trainer_loader"), "--shards", *shards,
           "--workers", str(workers), "--batch-size", str(args.batch_size), "--img-size",
           str(args.crop), "--batches", str(max(4, 9 * args.pairs_per_scene // args.batch_size))]
    result = subprocess.run(cmd, check=True, capture_output=True, text=True)
    return json.loads(result.stdout.strip().splitlines()[-1])


def main():
    args = parse_args()
    sys.path.insert(0, str(Path(args.build) / "python"))
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import torch
    from paircast.torch import ShardPairs

    torch.set_num_threads(1)
    tmp = tempfile.TemporaryDirectory(prefix="bench_loader.")
    base = Path(args.out or tmp.name)
    twelve, one = base / "twelve", base / "one"
    if not (twelve / "pairs.txt").exists():
        generate(args, twelve, max(1, -(-3 * args.pairs_per_scene // 12)), "both")
    if not list(one.glob("pairs-*.tar")):
        generate(args, one, 1 << 20, "shards")
    shards12 = sorted(str(p) for p in twelve.glob("pairs-*.tar"))
    shards1 = sorted(str(p) for p in one.glob("pairs-*.tar"))
    official = official_dataset(args, twelve, base / "data")
    count = len(official)

    rows = []  # (name, pairs/s, pairs/s per core)
    results = {}
    # Interleaved, so that a change of load on the machine touches every loader alike.
    best = {"official": 0.0, "shards12": 0.0, "shards1": 0.0}
    for r in range(args.rounds):
        best["official"] = max(best["official"], loader_rate(official, args, 1)[0])
        for name, files in (("shards12", shards12), ("shards1", shards1)):
            batched = ShardPairs(files, crop=args.crop, seed=r, batch_size=args.batch_size)
            best[name] = max(best[name], loader_rate(batched, args, 1, batched=True)[0])
            pairs = ShardPairs(files, crop=args.crop, seed=r)
            best[name + "_collated"] = max(best.get(name + "_collated", 0.0),
                                           loader_rate(pairs, args, 1)[0])
    trainer = {w: trainer_loader(args, shards12, w) for w in (1, args.workers)}

    w = args.workers
    rows.append((f"official PairsDataset crop{args.crop}, {w} workers", best["official"],
                 best["official"] / w))
    rows.append((f"ShardPairs crop={args.crop}, 12 shards, {w} workers", best["shards12"],
                 best["shards12"] / w))
    rows.append((f"ShardPairs crop={args.crop}, 1 shard, {w} workers", best["shards1"],
                 best["shards1"] / w))
    for name, label in (("shards12", "12 shards"), ("shards1", "1 shard")):
        rate = best[name + "_collated"]
        rows.append((f"  same, per pair, collated: {label}", rate, rate / w))
    for k, t in trainer.items():
        rows.append((f"C++ trainer loader, {k} thread{'s' if k > 1 else ''}",
                     t["pairs_per_second"], t["pairs_per_second_per_thread"]))
    print(f"{count} pairs at {args.resolution}x{args.resolution}, crop {args.crop}, batch "
          f"{args.batch_size}, best of {args.rounds} rounds")
    print(f"{'loader':<46}{'pairs/s':>10}{'per core':>10}{'cores for %g/s' % args.gpu_rate:>18}")
    for name, rate, per_core in rows:
        print(f"{name:<46}{rate:>10.1f}{per_core:>10.1f}{args.gpu_rate / per_core:>18.1f}")
    ratio12 = best["shards12"] / best["official"]
    ratio1 = best["shards1"] / best["official"]
    print(f"ShardPairs / official: 12 shards {ratio12:.2f}x, 1 shard {ratio1:.2f}x "
          f"(target >= 2.0x)")
    results = {"bench": "loader", "pairs": count, "resolution": args.resolution,
               "crop": args.crop, "workers": w, "batch_size": args.batch_size,
               "torch": torch.__version__,
               "official_pairs_per_second": best["official"],
               "shard_pairs_12_pairs_per_second": best["shards12"],
               "shard_pairs_1_pairs_per_second": best["shards1"],
               "shard_pairs_collated_12_pairs_per_second": best["shards12_collated"],
               "shard_pairs_collated_1_pairs_per_second": best["shards1_collated"],
               "ratio_12_shards": ratio12, "ratio_1_shard": ratio1,
               "trainer_pairs_per_second_per_thread": {
                   str(k): t["pairs_per_second_per_thread"] for k, t in trainer.items()},
               "cores_for_gpu_rate": {name: args.gpu_rate / per_core
                                      for name, _, per_core in rows}}
    print(json.dumps(results))


if __name__ == "__main__":
    main()
