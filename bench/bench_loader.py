#!/usr/bin/env python3
"""bench_loader: paircast's shard loaders against naver/croco's official PairsDataset, side by side.

One run makes the pairs (generate_pairs: --pairs-per-scene pairs of each shipped scene at --resolution,
written once as 12 shards, once as 1 shard, and in CroCo's folder layout), then times on those
same pairs, interleaved, --rounds times (best round kept):
  - the official PairsDataset('habitat_release', trfs='crop224') (PIL decode, RandomCropPair,
    ToTensor, Normalize) through a DataLoader with W workers, on the CroCo layout of those pairs;
  - paircast.torch.ShardLoader(crop=224, batch_size=B): C++ threads decoding into a ring of batch
    tensors made once, float32 normalised with 2 threads (12 shards and 1) and 1 thread, and
    uint8;
  - paircast.torch.ShardPairs(crop=224, batch_size=B) through the same DataLoader as the official
    loader (batches made in the workers, in shared memory);
  - the C++ trainer's batch loader alone (bench_trainer_loader, the same ring of buffers), which
    adds CroCo's colour jitter and the masks: float32 with 1 and 2 threads, and the uint8 batches
    a CUDA run takes (crops and jitter draws, finished on the GPU).
For each it prints pairs/s and the minor page faults per pair (getrusage: the process and, once
the DataLoader's workers have exited, its children; the loaders made once are counted in their
steady state: after a pass that followed the DataLoaders' last fork, which leaves this process's
pages copy-on-write). Each DataLoader pass is timed from the iterator's creation
(workers started) to its last batch.
Thread scaling is timed over 4 epochs in a row of the same loader.
Targets: ShardLoader, float32, 2 threads, at least 2.5x the official loader with 2 workers, with 12
shards and with 1; at most 1 minor fault per pair; 2 threads at least 1.8x 1 thread.

    /usr/bin/python3 bench/bench_loader.py --croco-dir ~/src/croco
"""

import argparse
import json
import os
import resource
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


def minor_faults():
    """Minor page faults of this process and of its children that have exited."""
    return sum(resource.getrusage(who).ru_minflt
               for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))


def timed_pass(batches, args):
    """(pairs/s, minor faults per pair) of one pass over an iterable of (image1, image2)."""
    import torch

    faults = minor_faults()
    start = time.perf_counter()
    pairs = 0
    for image1, image2 in batches:
        assert image1.shape[1:] == (3, args.crop, args.crop)
        assert image1.dtype in (torch.float32, torch.uint8)
        pairs += image1.shape[0]
    seconds = time.perf_counter() - start
    if hasattr(batches, "_shutdown_workers"):
        batches._shutdown_workers()  # the workers exit, so RUSAGE_CHILDREN holds their faults
    return pairs / seconds, (minor_faults() - faults) / pairs


def data_loader_pass(dataset, args, epoch, batched=False):
    """One pass of a DataLoader with W workers over `dataset` (which makes its own batches when
    `batched`)."""
    from torch.utils.data import DataLoader

    if hasattr(dataset, "set_epoch"):
        dataset.set_epoch(epoch)
    loader = DataLoader(dataset, batch_size=None if batched else args.batch_size,
                        num_workers=args.workers)
    return timed_pass(iter(loader), args)


def shard_loader_pass(loader, args, epoch, epochs=1):
    """`epochs` epochs of a ShardLoader from `epoch` on, timed as one pass."""
    def batches():
        for e in range(epoch, epoch + epochs):
            loader.set_epoch(e)
            yield from loader
    return timed_pass(batches(), args)


def official_dataset(args, croco_layout, data_dir):
    """naver/croco's PairsDataset over `croco_layout`, as its pretrain.py builds it."""
    sys.path.insert(0, args.croco_dir)
    from datasets.pairs_dataset import PairsDataset  # naver/croco

    link = Path(data_dir) / "habitat_release"
    link.parent.mkdir(parents=True, exist_ok=True)
    if not link.exists():
        link.symlink_to(Path(croco_layout).resolve(), target_is_directory=True)
    return PairsDataset("habitat_release", trfs=f"crop{args.crop}", data_dir=str(data_dir))


def trainer_loader(args, shards, workers, batch_format="float32"):
    cmd = [str(Path(args.build) / "bench" / "bench_trainer_loader"), "--shards", *shards,
           "--batch-format", batch_format, "--workers", str(workers), "--batch-size", str(args.batch_size), "--img-size",
           str(args.crop), "--batches", str(max(4, 9 * args.pairs_per_scene // args.batch_size))]
    result = subprocess.run(cmd, check=True, capture_output=True, text=True)
    return json.loads(result.stdout.strip().splitlines()[-1])


def main():
    args = parse_args()
    sys.path.insert(0, str(Path(args.build) / "python"))
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import torch
    from paircast.torch import ShardLoader, ShardPairs

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

    w, b = args.workers, args.batch_size
    loaders = {  # made once, as a training run makes them
        "loader12": ShardLoader(shards12, batch_size=b, crop=args.crop, threads=2),
        "loader1": ShardLoader(shards1, batch_size=b, crop=args.crop, threads=2),
        "loader12_1t": ShardLoader(shards12, batch_size=b, crop=args.crop, threads=1),
        "loader12_u8": ShardLoader(shards12, batch_size=b, crop=args.crop, threads=2,
                                   dtype="uint8"),
    }
    for loader in loaders.values():  # the first pass makes the buffers: not the steady state
        shard_loader_pass(loader, args, 0)
    best = {}  # name -> (pairs/s, faults per pair of that pass)

    def keep(name, result):
        if name not in best or result[0] > best[name][0]:
            best[name] = result

    # Interleaved, so that a change of load on the machine touches every loader alike.
    for r in range(args.rounds):
        keep("official", data_loader_pass(official, args, r))
        for name, files in (("pairs12", shards12), ("pairs1", shards1)):
            keep(name, data_loader_pass(ShardPairs(files, crop=args.crop, seed=r, batch_size=b),
                                        args, r, batched=True))
        for name, loader in loaders.items():
            # The DataLoaders' forks made this process's pages copy-on-write: one pass writes
            # them again before the timed one, as a training run that forks nothing would.
            shard_loader_pass(loader, args, 10 * r + 1)
            keep(name, shard_loader_pass(loader, args, 10 * r + 2))
        # Thread scaling, over 4 epochs in a row (as training iterates), so that the start and
        # end of each short pass weigh less.
        for name in ("loader12", "loader12_1t"):
            keep(name + "_run", shard_loader_pass(loaders[name], args, 10 * r + 3, epochs=4))
    trainer = {k: trainer_loader(args, shards12, k) for k in (1, 2)}
    trainer_u8 = trainer_loader(args, shards12, 2, "uint8")

    labels = [
        ("official", f"official PairsDataset crop{args.crop}, {w} workers", w),
        ("loader12", "ShardLoader float32, 2 threads, 12 shards", 2),
        ("loader1", "ShardLoader float32, 2 threads, 1 shard", 2),
        ("loader12_1t", "ShardLoader float32, 1 thread, 12 shards", 1),
        ("loader12_u8", "ShardLoader uint8, 2 threads, 12 shards", 2),
        ("pairs12", f"ShardPairs batch_size={b}, 12 shards, {w} workers", w),
        ("pairs1", f"ShardPairs batch_size={b}, 1 shard, {w} workers", w),
    ]
    rows = [(label, *best[name], cores) for name, label, cores in labels]
    for k, t in trainer.items():
        rows.append((f"C++ trainer loader, float32, {k} thread{'s' if k > 1 else ''}",
                     t["pairs_per_second"], t["minor_faults_per_pair"], k))
    rows.append(("C++ trainer loader, uint8 (CUDA's), 2 threads", trainer_u8["pairs_per_second"],
                 trainer_u8["minor_faults_per_pair"], 2))
    print(f"{count} pairs at {args.resolution}x{args.resolution}, crop {args.crop}, batch "
          f"{b}, best of {args.rounds} rounds")
    print(f"{'loader':<48}{'pairs/s':>10}{'faults/pair':>13}{'cores for %g/s' % args.gpu_rate:>18}")
    for name, rate, faults, cores in rows:
        print(f"{name:<48}{rate:>10.1f}{faults:>13.2f}{args.gpu_rate * cores / rate:>18.1f}")
    official_rate = best["official"][0]
    ratio12 = best["loader12"][0] / official_rate
    ratio1 = best["loader1"][0] / official_rate
    scaling = best["loader12_run"][0] / best["loader12_1t_run"][0]
    faults = max(best[n][1] for n in loaders)
    trainer_ratio = trainer[2]["pairs_per_second"] / best["loader12"][0]
    print(f"ShardLoader / official: 12 shards {ratio12:.2f}x, 1 shard {ratio1:.2f}x "
          f"(target >= 2.5x)")
    print(f"ShardLoader faults per pair, steady state: at most {faults:.2f} (target <= 1)")
    print(f"ShardLoader 2 threads / 1 thread, 4 epochs in a row: {best['loader12_run'][0]:.1f} / "
          f"{best['loader12_1t_run'][0]:.1f} pairs/s = {scaling:.2f}x (target >= 1.8x)")
    print(f"C++ trainer loader (with jitter and masks) / ShardLoader, 2 threads: "
          f"{trainer_ratio:.2f}x")
    results = {"bench": "loader", "pairs": count, "resolution": args.resolution,
               "crop": args.crop, "workers": w, "batch_size": b,
               "torch": torch.__version__,
               "pairs_per_second": {name: best[name][0] for name in best},
               "minor_faults_per_pair": {name: best[name][1] for name in best},
               "trainer": {str(k): t for k, t in trainer.items()}, "trainer_uint8": trainer_u8,
               "ratio_12_shards": ratio12, "ratio_1_shard": ratio1,
               "thread_scaling": scaling, "trainer_over_shard_loader": trainer_ratio}
    print(json.dumps(results))

if __name__ == "__main__":
    main()
