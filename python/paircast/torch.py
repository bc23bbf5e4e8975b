"""PyTorch datasets over paircast: pairs rendered live (LivePairs) or read from tar shards
(ShardPairs).

Both are IterableDatasets that yield what CroCo's PairsDataset yields, (image1, image2): float32
[3, H, W] tensors normalised with ImageNet's mean and std, view 1 being the reference. Every
DataLoader worker of every torch.distributed rank reads a disjoint part of the data, so a
DataLoader needs no sampler:

    loader = DataLoader(LivePairs("scenes/", crop=224, length=100_000), batch_size=64,
                        num_workers=8, pin_memory=True, drop_last=True)

return_dict=True yields dicts instead: image1, image2 (as above), view2 (the view image2 shows),
crop1, crop2 (the (top, left) of each crop), plus the sample's own keys: images (uint8
[V, H, W, 3]), depths (float32 [V, H, W], z-depth, 0 on a miss), cameras (one dict per view),
covis ([V - 1], of each view with view 0), visibility ([V, V], v_ij, valid fractions on the
diagonal), scene, index.
"""

import glob
import math
import os
import zlib

import numpy as np
import torch
from torch.utils.data import IterableDataset, get_worker_info

from . import Error, PairStream, ShardReader

IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)


def _cores():
    """Cores this process may run on."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def reader_part(rank=None, world_size=None):
    """(part, parts, workers): this reader's place among the DataLoader workers of all ranks.

    rank and world_size default to torch.distributed's when it is initialised, else 0 and 1.
    """
    if rank is None or world_size is None:
        dist = torch.distributed
        running = dist.is_available() and dist.is_initialized()
        rank = rank if rank is not None else (dist.get_rank() if running else 0)
        world_size = world_size if world_size is not None else (
            dist.get_world_size() if running else 1)
    if not 0 <= rank < world_size:
        raise ValueError(f"rank {rank} is not in [0, world_size={world_size})")
    info = get_worker_info()
    worker, workers = (info.id, info.num_workers) if info is not None else (0, 1)
    return rank * workers + worker, world_size * workers, workers


class _Pairs(IterableDataset):
    """What LivePairs and ShardPairs share: turning a sample dict into CroCo's pair."""

    def __init__(self, seed, crop, normalize, return_dict, rank, world_size):
        super().__init__()
        if crop is not None:
            crop = (crop, crop) if isinstance(crop, int) else tuple(int(c) for c in crop)
            if len(crop) != 2 or min(crop) < 1:
                raise ValueError(f"crop must be a positive int or (height, width), not {crop}")
        self.seed = int(seed)
        self.crop = crop
        self.normalize = bool(normalize)
        self.return_dict = bool(return_dict)
        self.rank = rank
        self.world_size = world_size
        self.epoch = 0
        self._mean = torch.tensor(IMAGENET_MEAN).view(3, 1, 1)
        self._std = torch.tensor(IMAGENET_STD).view(3, 1, 1)

    def set_epoch(self, epoch):
        """Changes the random crops (and, for LivePairs with a length, the pairs) of the next
        iteration, as DistributedSampler.set_epoch does."""
        self.epoch = int(epoch)

    def _generator(self, sample):
        """The random draws of one sample (crops, the second view): a function of (seed, epoch,
        scene, index), so they do not depend on workers, ranks or threads."""
        scene = zlib.crc32(str(sample["scene"]).encode())
        return np.random.default_rng([self.seed, self.epoch, scene, int(sample["index"])])

    def _image(self, image, rng):
        """uint8 [H, W, 3] -> float32 [3, h, w] in [0, 1] (normalised), and the crop's corner.
        Crops are drawn independently for the two images, as CroCo's RandomCropPair does."""
        top = left = 0
        if self.crop is not None:
            h, w = self.crop
            if h > image.shape[0] or w > image.shape[1]:
                raise ValueError(f"crop {self.crop} is larger than the images "
                                 f"({image.shape[0]} x {image.shape[1]})")
            top = int(rng.integers(0, image.shape[0] - h + 1))
            left = int(rng.integers(0, image.shape[1] - w + 1))
            image = image[top:top + h, left:left + w]
        src = torch.from_numpy(image).permute(2, 0, 1)
        out = torch.empty(src.shape, dtype=torch.float32)
        out.copy_(src).div_(255.0)
        if self.normalize:
            out.sub_(self._mean).div_(self._std)
        return out, (top, left)

    def _pair(self, sample):
        """View 0 (the reference) and one other view, drawn when there are several."""
        rng = self._generator(sample)
        images = sample["images"]
        if images.shape[0] < 2:
            raise Error(f"sample {sample.get('key', sample['index'])} has one view: no pair")
        other = 1 if images.shape[0] == 2 else int(rng.integers(1, images.shape[0]))
        image1, crop1 = self._image(images[0], rng)
        image2, crop2 = self._image(images[other], rng)
        if not self.return_dict:
            return image1, image2
        out = dict(sample)
        out.update(image1=image1, image2=image2, view2=other, crop1=crop1, crop2=crop2)
        return out


class LivePairs(_Pairs):
    """Pairs rendered while training, by paircast.PairStream in each DataLoader worker.

    scenes: scene files, folders (searched recursively) or .txt lists, as generate_pairs'
    --scenes. A pair is a pure function of (seed, scene, index), so the data are the same bytes
    whatever the number of workers, ranks and threads; only the order may vary.
    threads: render threads per worker process; 0 shares the cores among the workers.
    length: pairs per epoch over all ranks (as len() of a map-style dataset); each rank yields
    length // world_size of them, and set_epoch() moves on to fresh pairs. None: endless.
    crop: a random crop of this size, drawn independently for each image (CroCo's crop224).
    """

    def __init__(self, scenes, seed=0, resolution=256, hfov=60.0, min_covis=0.5, max_covis=1.0,
                 views=2, up="y", scale=1.0, threads=0, crop=None, normalize=True,
                 return_dict=False, length=None, rank=None, world_size=None, queue=16):
        super().__init__(seed, crop, normalize, return_dict, rank, world_size)
        if int(views) < 2:
            raise ValueError(f"views={views}: a pair needs at least 2 views")
        if isinstance(scenes, (str, os.PathLike)):
            scenes = [scenes]
        self.scenes = [os.fspath(s) for s in scenes]
        self.stream_options = dict(resolution=int(resolution), hfov=float(hfov),
                                   min_covis=float(min_covis), max_covis=float(max_covis),
                                   views=int(views), up=up, scale=float(scale), queue=int(queue))
        self.threads = int(threads)
        if length is not None and int(length) < 1:
            raise ValueError("length must be positive (or None for an endless stream)")
        self.length = None if length is None else int(length)

    def __len__(self):
        if self.length is None:
            raise TypeError("LivePairs is endless; give length= for len()")
        _, world_size = self._rank()
        return self.length // world_size

    def _rank(self):
        part, parts, workers = reader_part(self.rank, self.world_size)
        return part // workers, parts // workers

    def __iter__(self):
        part, parts, workers = reader_part(self.rank, self.world_size)
        threads = self.threads or max(1, _cores() // workers)
        count, offset = None, 0
        if self.length is not None:
            per_rank = self.length // (parts // workers)
            worker = part % workers
            count = per_rank // workers + (1 if worker < per_rank % workers else 0)
            offset = self.epoch * math.ceil(self.length / parts)
            if count == 0:
                return
        stream = PairStream(self.scenes, seed=self.seed, threads=threads, start=part, step=parts,
                            offset=offset, **self.stream_options)
        try:
            for n, sample in enumerate(stream):
                yield self._pair(sample)
                if count is not None and n + 1 >= count:
                    break
        finally:
            stream.close()


class ShardPairs(_Pairs):
    """Pairs read from paircast's tar shards (generate_pairs --format shards).

    pattern: a glob ('pairs/pairs-*.tar'), a shard path, or a list of them. Shards are split
    among the readers (every DataLoader worker of every rank); with fewer shards than readers,
    each reader reads every shard and keeps every parts-th sample. shuffle: a new shard order
    each epoch (set_epoch). depth: also decode the depth maps when the shards have them.
    """

    def __init__(self, pattern, crop=None, normalize=True, return_dict=False, depth=False,
                 shuffle=False, seed=0, rank=None, world_size=None):
        super().__init__(seed, crop, normalize, return_dict, rank, world_size)
        patterns = [pattern] if isinstance(pattern, (str, os.PathLike)) else list(pattern)
        files = []
        for p in patterns:
            p = os.fspath(p)
            found = sorted(glob.glob(p)) if glob.has_magic(p) else [p]
            if not found or not all(os.path.isfile(f) for f in found):
                raise Error(f"{p}: no such shard")
            files += found
        self.files = files
        self.depth = bool(depth)
        self.shuffle = bool(shuffle)

    def __iter__(self):
        part, parts, _ = reader_part(self.rank, self.world_size)
        files = list(self.files)
        if self.shuffle:  # the same order in every reader, so the split stays disjoint
            np.random.default_rng([self.seed, self.epoch]).shuffle(files)
        by_file = len(files) >= parts
        mine = files[part::parts] if by_file else files
        n = 0
        for path in mine:
            with ShardReader(path, depth=self.depth) as reader:
                for sample in reader:
                    n += 1
                    if by_file or (n - 1) % parts == part:
                        yield self._pair(sample)
