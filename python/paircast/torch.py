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

flow=True (shards written with generate_pairs --save-flow, or the live stream) adds the exact
ground truth of the pair, cropped as the images are: flow1 (float32 [2, h, w], pixels: where each
pixel of crop 1 lands in crop 2, the offset between the crops applied), valid1 (bool [h, w]: the
flow is known, i.e. the pixel has depth and lies in front of view 2), flow2 and valid2 (view 2's
pixels into crop 1), and pose (float64 [4, 4]: view 2's camera in view 1's, mapping view 2's
camera coordinates to view 1's). With flow=True the pair is always views 1 and 2, whose flows
the files hold (shards keep view 1's flow into view 2 and every other view's into view 1).
Without return_dict it yields (image1, image2, flow1, valid1, pose).
"""

import glob
import math
import os
import warnings
import zlib

import numpy as np
import torch
from torch.utils.data import IterableDataset, get_worker_info

from . import Error, PairStream, ShardReader, ShardSet
from ._paircast import ShardBatches, prefault

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

    def __init__(self, seed, crop, normalize, return_dict, rank, world_size, flow=False):
        super().__init__()
        if crop is not None:
            crop = (crop, crop) if isinstance(crop, int) else tuple(int(c) for c in crop)
            if len(crop) != 2 or min(crop) < 1:
                raise ValueError(f"crop must be a positive int or (height, width), not {crop}")
        self.seed = int(seed)
        self.crop = crop
        self.normalize = bool(normalize)
        self.return_dict = bool(return_dict)
        self.flow = bool(flow)
        self.rank = rank
        self.world_size = world_size
        self.epoch = 0
        self._mean = torch.tensor(IMAGENET_MEAN).view(3, 1, 1)
        self._std = torch.tensor(IMAGENET_STD).view(3, 1, 1)

    def set_epoch(self, epoch):
        """Changes the random crops (and, for LivePairs with a length, the pairs) of the next
        iteration, as DistributedSampler.set_epoch does."""
        self.epoch = int(epoch)

    def _generator(self, scene, index):
        """The random draws of one sample (crops, the second view): a function of (seed, epoch,
        scene, index), so they do not depend on workers, ranks or threads."""
        return np.random.default_rng([self.seed, self.epoch, zlib.crc32(str(scene).encode()),
                                      int(index)])

    def _crop_box(self, height, width, rng):
        """(top, left, h, w) of the crop of an image of height x width: drawn from rng when crop
        is set (independently for the two images, as CroCo's RandomCropPair does), else the
        whole image."""
        if self.crop is None:
            return 0, 0, height, width
        h, w = self.crop
        if h > height or w > width:
            raise ValueError(f"crop {self.crop} is larger than the images ({height} x {width})")
        top = int(rng.integers(0, height - h + 1))
        left = int(rng.integers(0, width - w + 1))
        return top, left, h, w

    def _other_view(self, views, rng):
        """The view paired with view 0: view 1 of a pair (or with flow), else one drawn from
        rng."""
        return 1 if views == 2 or self.flow else int(rng.integers(1, views))

    def _image(self, image, rng):
        """uint8 [H, W, 3] -> float32 [3, h, w] in [0, 1] (normalised), and the crop's corner."""
        top, left, h, w = self._crop_box(image.shape[0], image.shape[1], rng)
        image = image[top:top + h, left:left + w]
        src = torch.from_numpy(image).permute(2, 0, 1)
        out = torch.empty(src.shape, dtype=torch.float32)
        out.copy_(src).div_(255.0)
        if self.normalize:
            out.sub_(self._mean).div_(self._std)
        return out, (top, left)

    def _pair(self, sample):
        """View 0 (the reference) and one other view, drawn when there are several."""
        rng = self._generator(sample["scene"], sample["index"])
        images = sample["images"]
        if images.shape[0] < 2:
            raise Error(f"sample {sample.get('key', sample['index'])} has one view: no pair")
        other = self._other_view(images.shape[0], rng)
        image1, crop1 = self._image(images[0], rng)
        image2, crop2 = self._image(images[other], rng)
        truth = self._ground_truth(sample, image1.shape[1:], crop1, crop2) if self.flow else {}
        if not self.return_dict:
            if self.flow:
                return image1, image2, truth["flow1"], truth["valid1"], truth["pose"]
            return image1, image2
        out = dict(sample)
        out.update(image1=image1, image2=image2, view2=other, crop1=crop1, crop2=crop2, **truth)
        return out

    def _ground_truth(self, sample, size, crop1, crop2):
        """flow1, valid1, flow2, valid2 and pose of views 0 and 1, for crops at crop1, crop2."""
        if "flows" not in sample:
            raise Error(f"sample {sample.get('key', sample['index'])} has no flow "
                        "(generate_pairs --save-flow)")
        flow1, valid1 = crop_flow(sample["flows"][0], crop1, crop2, size)
        flow2, valid2 = crop_flow(sample["flows"][1], crop2, crop1, size)
        pose = relative_pose(sample["cameras"][0], sample["cameras"][1])
        return dict(flow1=flow1, valid1=valid1, flow2=flow2, valid2=valid2, pose=pose)


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
                 return_dict=False, length=None, rank=None, world_size=None, queue=16, flow=False):
        super().__init__(seed, crop, normalize, return_dict, rank, world_size, flow)
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
                            offset=offset, flow=self.flow, **self.stream_options)
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
    each reader indexes every shard and decodes only every parts-th sample. shuffle: a new shard
    order each epoch (set_epoch). depth: also decode the depth maps when the shards have them.
    dtype: "float32" (normalised with ImageNet's mean and std unless normalize=False) or "uint8"
    ([3, h, w] as stored, for users who normalise on the GPU).

    Pairs (return_dict=False, depth=False) are read through paircast.ShardSet: only the crops
    are decoded, by libjpeg-turbo, straight into the tensors' layout, with the GIL released.
    batch_size=B yields batches ([B, 3, h, w] each, the last one smaller unless drop_last) that
    each worker decodes straight into shared memory, so the DataLoader (batch_size=None) neither
    collates nor copies them:

        DataLoader(ShardPairs(shards, crop=224, batch_size=64), batch_size=None, num_workers=8)
    return_dict=True decodes whole samples through paircast.ShardReader. A sample that cannot be
    used (a missing member, a corrupt JPEG) is skipped with a RuntimeWarning.
    """

    def __init__(self, pattern, crop=None, normalize=True, return_dict=False, depth=False,
                 shuffle=False, seed=0, rank=None, world_size=None, dtype="float32",
                 batch_size=None, drop_last=False, buffers=4, flow=False):
        super().__init__(seed, crop, normalize, return_dict, rank, world_size, flow)
        if int(buffers) < 1:
            raise ValueError(f"buffers must be positive, not {buffers}")
        self.buffers = int(buffers)
        self._ring = None
        if batch_size is not None:
            if int(batch_size) < 1:
                raise ValueError(f"batch_size must be positive, not {batch_size}")
            if return_dict or depth or flow or crop is None:
                raise ValueError("batch_size= batches pairs of one crop size: give crop=, "
                                 "without return_dict, depth and flow")
        self.batch_size = None if batch_size is None else int(batch_size)
        self.drop_last = bool(drop_last)
        if dtype not in ("float32", "uint8"):
            raise ValueError(f"dtype must be 'float32' or 'uint8', not {dtype!r}")
        if dtype == "uint8" and (return_dict or depth or flow):
            raise ValueError("dtype='uint8' is for pairs: use it without return_dict, depth and "
                             "flow")
        self.dtype = dtype
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
        self._shards = None
        if not (return_dict or depth or flow):
            self._index()  # here, so that a bad shard fails now and forked workers inherit it

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_shards"] = None  # rebuilt where it is unpickled (spawned workers)
        state["_ring"] = None
        return state

    def _index(self):
        """The ShardSet of every shard, and each shard's (first sample, count)."""
        if self._shards is None:
            shards = ShardSet(self.files)
            self._shards = shards, {path: (first, count) for path, first, count in shards.ranges()}
        return self._shards

    def _mine(self):
        """(files, by_file, part, parts): this reader's shards in this epoch's order, whether it
        reads them whole (by_file) or every parts-th sample of all of them."""
        part, parts, _ = reader_part(self.rank, self.world_size)
        files = list(self.files)
        if self.shuffle:  # the same order in every reader, so the split stays disjoint
            np.random.default_rng([self.seed, self.epoch]).shuffle(files)
        by_file = len(files) >= parts
        return (files[part::parts] if by_file else files), by_file, part, parts

    def __iter__(self):
        mine, by_file, part, parts = self._mine()
        if self.return_dict or self.depth or self.flow:
            yield from self._samples(mine, by_file, part, parts)
        elif self.batch_size is not None:
            yield from self._batches(mine, by_file, part, parts)
        else:
            yield from self._crops(mine, by_file, part, parts)

    def _samples(self, files, by_file, part, parts):
        """Whole samples through ShardReader, as dicts (or pairs) made by _pair."""
        n = 0
        for path in files:
            with ShardReader(path, depth=self.depth, flow=self.flow) as reader:
                for sample in reader:
                    n += 1
                    if by_file or (n - 1) % parts == part:
                        yield self._pair(sample)

    def _dtype(self):
        """What ShardSet decodes into: normalised float32, or uint8 (dtype="uint8", or
        normalize=False, which then divides by 255)."""
        return "float32" if self.dtype == "float32" and self.normalize else "uint8"

    def _order(self, files, by_file, part, parts):
        """This reader's samples (ShardSet indices) in the order it reads them: every sample of
        its files (by_file), or every parts-th of all of them."""
        _, ranges = self._index()
        order = [i for f in files for i in range(ranges[f][0], ranges[f][0] + ranges[f][1])]
        return order if by_file else order[part::parts]

    def _plan(self, files, by_file, part, parts):
        """(shards, i, other view, box1, box2) of each of this reader's pairs, with _pair's
        draws."""
        shards, _ = self._index()
        for i in self._order(files, by_file, part, parts):
            key, scene, index, views, height, width = shards.info(i)
            if views < 2:
                warnings.warn(f"{key}: one view, no pair; skipped", RuntimeWarning)
                continue
            rng = self._generator(scene, index)
            other = self._other_view(views, rng)
            yield shards, i, other, self._crop_box(height, width, rng), \
                self._crop_box(height, width, rng)

    def _as_output(self, image):
        """uint8 decoded for normalize=False becomes float32 in [0, 1]."""
        if self.dtype == "float32" and not self.normalize:
            return image.float().div_(255.0)
        return image

    def _crops(self, files, by_file, part, parts):
        """(image1, image2) through ShardSet: only the crops decoded."""
        dtype = self._dtype()
        for shards, i, other, box1, box2 in self._plan(files, by_file, part, parts):
            try:
                image1 = shards.decode(i, 0, *box1, dtype=dtype)
                image2 = shards.decode(i, other, *box2, dtype=dtype)
            except Error as e:
                warnings.warn(f"{e}, skipped", RuntimeWarning)
                continue
            yield self._as_output(torch.from_numpy(image1)), self._as_output(torch.from_numpy(image2))

    def _batches(self, files, by_file, part, parts):
        """Batches of (image1, image2), decoded straight into (shared) batch tensors, from a ring
        of `buffers` of them made once and reused."""
        dtype = torch.float32 if self._dtype() == "float32" else torch.uint8
        h, w = self.crop
        if self._ring is None or self._ring[0] != (get_worker_info() is None):
            ring = [[_batch_tensor((self.batch_size, 3, h, w), dtype) for _ in range(2)]
                    for _ in range(self.buffers)]
            self._ring = (get_worker_info() is None, ring, [[b.numpy() for b in r] for r in ring])
        _, ring, arrays = self._ring
        made, filled = 0, 0
        for shards, i, other, box1, box2 in self._plan(files, by_file, part, parts):
            batch, views = ring[made % self.buffers], arrays[made % self.buffers]
            try:
                shards.decode_into(i, 0, box1[0], box1[1], views[0][filled])
                shards.decode_into(i, other, box2[0], box2[1], views[1][filled])
            except Error as e:
                warnings.warn(f"{e}, skipped", RuntimeWarning)
                continue
            filled += 1
            if filled == self.batch_size:
                yield self._as_output(batch[0]), self._as_output(batch[1])
                made, filled = made + 1, 0
        if filled and not self.drop_last:
            batch = ring[made % self.buffers]
            yield self._as_output(batch[0][:filled]), self._as_output(batch[1][:filled])


class ShardLoader:
    """Batches of pairs from paircast's tar shards, decoded by C++ threads (the GIL released)
    straight into a ring of batch tensors made once and reused: a DataLoader replacement that
    allocates nothing per batch in its steady state.

        loader = ShardLoader("pairs/pairs-*.tar", batch_size=64, crop=224, threads=2)
        for epoch in range(epochs):
            loader.set_epoch(epoch)
            for view1, view2 in loader:   # [B, 3, 224, 224] float32, normalised
                ...

    The batches are those of ShardPairs(pattern, crop=crop, batch_size=batch_size, ...) with the
    same seed, epoch, shuffle and split, sample for sample and bit for bit; rank and world_size
    (torch.distributed's by default) split the shards as ShardPairs does. A pair that does not
    decode is skipped with a RuntimeWarning, as there.

    A batch is a view of the loader's own memory: it stays valid until `keep` more batches have
    been taken (keep=1: until the next one), then its buffer is filled again. Clone what must
    live longer. dtype="uint8" yields the crops as stored ([B, 3, h, w] uint8, 4 times fewer
    bytes), to be normalised on the GPU with paircast.torch.normalize; pin_memory=True makes the
    buffers pinned host memory, for copies to CUDA with non_blocking=True. prefetch: batches
    decoded ahead of the one taken.

    flow=True (shards written with generate_pairs --save-flow) yields (view1, view2, flow1,
    valid1, pose) batches: view 1's flow cut to its crop and moved into view 2's crop ([B, 2, h, w]
    float32, pixels), where it is known ([B, h, w] bool), and view 2's pose in view 1's camera
    ([B, 4, 4] float64). They are those of DataLoader(ShardPairs(pattern, crop=crop,
    flow=True), batch_size=batch_size) with the same seed and epoch; the pair is always views 1
    and 2.
    """

    def __init__(self, pattern, batch_size=64, crop=224, threads=2, dtype="float32",
                 pin_memory=False, shuffle=False, seed=0, rank=None, world_size=None,
                 drop_last=False, normalize=True, keep=1, prefetch=2, flow=False):
        if int(threads) < 1 or int(prefetch) < 1 or int(keep) < 1:
            raise ValueError(f"threads, prefetch and keep must be positive, not {threads}, "
                             f"{prefetch}, {keep}")
        self._pairs = ShardPairs(pattern, crop=crop, normalize=normalize, shuffle=shuffle,
                                 seed=seed, rank=rank, world_size=world_size, dtype=dtype,
                                 batch_size=batch_size, drop_last=drop_last)
        self.batch_size = self._pairs.batch_size
        self.threads, self.keep, self.prefetch = int(threads), int(keep), int(prefetch)
        self.pin_memory = bool(pin_memory)
        self.flow = bool(flow)
        if self.pin_memory and not torch.cuda.is_available():
            raise ValueError("pin_memory=True needs CUDA, and this torch sees no CUDA device")
        self._buffers = None  # made on the first iteration, kept for the loader's life

    @property
    def files(self):
        return self._pairs.files

    def set_epoch(self, epoch):
        """The crops (and, with shuffle, the shard order) of the next iteration."""
        self._pairs.set_epoch(epoch)

    def _ring(self):
        """[(view1, view2)] tensors decoded into, and their output form (float32 in [0, 1] for
        normalize=False, divided into a second ring)."""
        if self._buffers is None:
            h, w = self._pairs.crop
            raw = torch.float32 if self._pairs._dtype() == "float32" else torch.uint8
            shape = (self.batch_size, 3, h, w)

            def tensor(dtype):
                return torch.empty(shape, dtype=dtype, pin_memory=self.pin_memory)

            depth = self.keep + self.prefetch

            def truth():
                if not self.flow:
                    return ()
                b = self.batch_size
                return (torch.empty((b, 2, h, w), dtype=torch.float32, pin_memory=self.pin_memory),
                        torch.empty((b, h, w), dtype=torch.bool, pin_memory=self.pin_memory),
                        torch.empty((b, 4, 4), dtype=torch.float64, pin_memory=self.pin_memory))

            decoded = [(tensor(raw), tensor(raw)) + truth() for _ in range(depth)]
            outputs = decoded
            if self._pairs.dtype == "float32" and not self._pairs.normalize:
                outputs = [(tensor(torch.float32), tensor(torch.float32)) + d[2:]
                           for d in decoded]
            self._buffers = decoded, outputs
        return self._buffers

    def _order(self):
        """This reader's samples of this epoch, in order, as ShardPairs reads them."""
        return self._pairs._order(*self._pairs._mine())

    def __iter__(self):
        pairs = self._pairs
        shards, _ = pairs._index()
        decoded, outputs = self._ring()
        core = ShardBatches(shards, [tuple(t.numpy() for t in d) for d in decoded],
                            self._order(), seed=pairs.seed,
                            epoch=pairs.epoch, threads=self.threads, prefetch=self.prefetch,
                            keep=self.keep, drop_last=pairs.drop_last)
        try:
            while (got := core.next()) is not None:
                buffer, size, skipped = got
                for message in skipped:
                    warnings.warn(f"{message}, skipped", RuntimeWarning)
                yield self._output(decoded[buffer], outputs[buffer], size)
        finally:
            core.close()

    def _output(self, decoded, output, size):
        if output is not decoded:  # normalize=False: uint8 divided into float32 in [0, 1]
            for src, dst in zip(decoded[:2], output[:2]):
                torch.div(src[:size], 255.0, out=dst[:size])
        return tuple(output) if size == len(output[0]) else tuple(t[:size] for t in output)

    def __len__(self):
        """Batches per epoch (pairs with one view, which have no pair, counted as pairs)."""
        pairs = len(self._order())
        b = self.batch_size
        return pairs // b if self._pairs.drop_last else -(-pairs // b)


def crop_flow(flow, crop_from, crop_to, size):
    """A view's flow (float32 [H, W, 2], pixels, +inf where unknown) cut to the crop at crop_from
    ((top, left), of size (h, w)) and moved into the frame of the other view's crop at crop_to:
    (float32 [2, h, w], bool [h, w] where it is known)."""
    (top, left), (h, w) = crop_from, size
    part = np.asarray(flow[top:top + h, left:left + w], dtype=np.float32)
    shift = np.array([left - crop_to[1], top - crop_to[0]], dtype=np.float32)
    out = torch.from_numpy((part + shift).transpose(2, 0, 1).copy())
    valid = torch.isfinite(out).all(dim=0)
    return out, valid


def relative_pose(camera1, camera2):
    """float64 [4, 4]: camera 2's pose in camera 1's frame (R1^T R2, R1^T (t2 - t1)), from the
    cameras' R_cam2world and t_cam2world."""
    r1 = np.asarray(camera1["R_cam2world"], dtype=np.float64)
    r2 = np.asarray(camera2["R_cam2world"], dtype=np.float64)
    t1 = np.asarray(camera1["t_cam2world"], dtype=np.float64).reshape(3)
    t2 = np.asarray(camera2["t_cam2world"], dtype=np.float64).reshape(3)
    pose = np.eye(4)
    pose[:3, :3] = r1.T @ r2
    pose[:3, 3] = r1.T @ (t2 - t1)
    return torch.from_numpy(pose)


def normalize(images, out=None):
    """uint8 [..., 3, h, w] crops (ShardLoader(dtype="uint8"), on any device) to float32
    normalised with ImageNet's mean and std, as dtype="float32" decodes them."""
    mean = torch.tensor(IMAGENET_MEAN, device=images.device).view(3, 1, 1)
    std = torch.tensor(IMAGENET_STD, device=images.device).view(3, 1, 1)
    out = torch.div(images, 255.0, out=out)
    return out.sub_(mean).div_(std)


def _batch_tensor(shape, dtype):
    """An empty tensor, in shared memory inside a DataLoader worker (as its collate makes one), so
    that handing it to the main process copies nothing."""
    if get_worker_info() is None:
        return torch.empty(shape, dtype=dtype)
    numel = math.prod(shape)
    elem = torch.empty(0, dtype=dtype)
    if hasattr(elem, "_typed_storage"):  # torch >= 2.0
        storage = elem._typed_storage()._new_shared(numel)
    else:
        storage = elem.storage()._new_shared(numel)
    out = elem.new(storage).view(shape)
    prefault(out.numpy())  # one call instead of a page fault every 4 KiB as the decoder writes
    return out
