#!/usr/bin/env python3
"""bench_python: live pairs through a PyTorch DataLoader against generate_pairs, side by side.

Both run one after the other on the same scene, resolution and number of threads:
generate_pairs --jobs T (tar shards, its own pairs/s from summary.json, start-up included) and a
DataLoader with W workers over paircast.torch.LivePairs with T / W render threads each, yielding
CroCo's normalised (image1, image2) batches, timed from the DataLoader's creation to its last
batch. The ratio of the two is the figure (target: at least 0.8). The loader's rate after its
first batch is printed too, but it flatters the loader at small --pairs: the workers' queues
fill while the first batch is made.

    PYTHONPATH=build/python /usr/bin/python3 bench/bench_python.py --scenes scenes/room/room.obj
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
    p.add_argument("--scenes", nargs="+", default=[str(ROOT / "scenes/room/room.obj")])
    p.add_argument("--build", default=str(ROOT / "build"), help="CMake build folder")
    p.add_argument("--pairs", type=int, default=200, help="pairs timed in each run")
    p.add_argument("--resolution", type=int, default=256)
    p.add_argument("--threads", type=int, default=2, help="render threads in all (T)")
    p.add_argument("--workers", type=int, default=2, help="DataLoader workers (W)")
    p.add_argument("--batch-size", type=int, default=8)
    p.add_argument("--seed", type=int, default=0)
    return p.parse_args()


def run_generate_pairs(args, out):
    """generate_pairs' own pairs/s (its summary), with one pair per scene index as LivePairs."""
    per_scene = max(1, args.pairs // len(args.scenes))
    cmd = [str(Path(args.build) / "tools" / "generate_pairs"), "--scenes", *args.scenes,
           "--out", str(out), "--pairs-per-scene", str(per_scene), "--resolution",
           str(args.resolution), "--jobs", str(args.threads), "--seed", str(args.seed),
           "--format", "shards"]
    result = subprocess.run(cmd, capture_output=True, text=True, check=True)
    summary = json.loads(result.stdout.strip().splitlines()[-1])
    return summary["pairs"], summary["seconds"], summary["pairs_per_second"]


def run_loader(args):
    """A DataLoader over LivePairs: pairs after the first batch, their seconds, their rate, and
    the seconds to the first batch (workers started, scenes loaded)."""
    import torch
    from torch.utils.data import DataLoader

    from paircast.torch import LivePairs

    threads = max(1, args.threads // max(1, args.workers))
    batches = max(2, args.pairs // args.batch_size)
    dataset = LivePairs(args.scenes, seed=args.seed, resolution=args.resolution, threads=threads,
                        length=(batches + 1) * args.batch_size)
    loader = DataLoader(dataset, batch_size=args.batch_size, num_workers=args.workers,
                        drop_last=True)
    start = time.perf_counter()
    it = iter(loader)
    first = next(it)
    assert first[0].shape == (args.batch_size, 3, args.resolution, args.resolution)
    ready = time.perf_counter()
    pairs = 0
    for image1, image2 in it:
        pairs += image1.shape[0]
        if pairs >= batches * args.batch_size:
            break
    seconds = time.perf_counter() - ready
    del it
    return pairs, seconds, pairs / seconds, ready - start, torch.__version__


def main():
    args = parse_args()
    sys.path.insert(0, str(Path(args.build) / "python"))
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    with tempfile.TemporaryDirectory(prefix="bench_python.") as tmp:
        g_pairs, g_seconds, g_rate = run_generate_pairs(args, Path(tmp) / "pairs")
    l_pairs, l_seconds, l_rate, startup, torch_version = run_loader(args)
    # generate_pairs' seconds include its start-up (scene loading, floor maps), so the loader's
    # are counted from its creation too.
    l_rate_all = (l_pairs + args.batch_size) / (l_seconds + startup)
    ratio = l_rate_all / g_rate if g_rate > 0 else float("nan")
    print(f"{'':<34}{'pairs':>8}{'seconds':>10}{'pairs/s':>10}")
    print(f"{'generate_pairs --jobs %d' % args.threads:<34}{g_pairs:>8}{g_seconds:>10.2f}"
          f"{g_rate:>10.1f}")
    print(f"{'DataLoader(LivePairs) %d workers' % args.workers:<34}{l_pairs + args.batch_size:>8}"
          f"{l_seconds + startup:>10.2f}{l_rate_all:>10.1f}")
    print(f"{'  after its first batch':<34}{l_pairs:>8}{l_seconds:>10.2f}{l_rate:>10.1f}"
          f"   (first batch {startup:.2f} s)")
    print(f"ratio {ratio:.2f} (target >= 0.80)")
    print(json.dumps({"bench": "python", "resolution": args.resolution, "threads": args.threads,
                      "workers": args.workers, "scenes": args.scenes, "torch": torch_version,
                      "generate_pairs_per_second": g_rate, "loader_pairs_per_second": l_rate_all,
                      "loader_first_batch_seconds": startup,
                      "loader_pairs_per_second_after_first_batch": l_rate, "ratio": ratio}))


if __name__ == "__main__":
    main()
