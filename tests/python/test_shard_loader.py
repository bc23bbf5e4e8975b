"""The shard codec from Python: ShardReader, ShardSet and ShardPairs read the same samples, the
crop path equals the whole-sample path, workers split samples without decoding others', and bad
shards are named."""

import io
import tarfile
import warnings

import numpy as np
import pytest

torch = pytest.importorskip("torch")
from torch.utils.data import DataLoader  # noqa: E402

import paircast  # noqa: E402
from paircast.torch import ShardPairs  # noqa: E402
from conftest import RESOLUTION  # noqa: E402

CROP = 48


def shard_files(croco_pairs):
    return sorted(str(p) for p in croco_pairs.glob("pairs-*.tar"))


def test_three_readers_agree_sample_for_sample(croco_pairs):
    files = shard_files(croco_pairs)
    whole = {}
    for path in files:
        for sample in paircast.ShardReader(path):
            whole[sample["key"]] = sample
    shards = paircast.ShardSet(files)
    assert len(shards) == len(whole) == 3
    for i in range(len(shards)):
        key, scene, index, views, height, width = shards.info(i)
        sample = whole[key]
        assert (scene, index, views) == (sample["scene"], sample["index"], 2)
        assert (height, width) == (RESOLUTION, RESOLUTION)
        for view in range(views):
            u8 = shards.decode(i, view, 0, 0, height, width, dtype="uint8")
            np.testing.assert_array_equal(u8.transpose(1, 2, 0), sample["images"][view])
    # ShardPairs' crops (decoded alone) equal the same crops of ShardReader's whole images,
    # which return_dict=True draws with the same generator.
    crops = list(ShardPairs(files, crop=CROP))
    dicts = list(ShardPairs(files, crop=CROP, return_dict=True))
    assert len(crops) == len(dicts) == 3
    for (image1, image2), item in zip(crops, dicts):
        torch.testing.assert_close(image1, item["image1"], rtol=0, atol=1e-6)
        torch.testing.assert_close(image2, item["image2"], rtol=0, atol=1e-6)


def test_batches_equal_the_pairs_and_uint8_holds_the_pixels(croco_pairs):
    files = shard_files(croco_pairs)
    pairs = list(ShardPairs(files, crop=CROP))
    batches = list(ShardPairs(files, crop=CROP, batch_size=2))
    assert [b[0].shape[0] for b in batches] == [2, 1]
    torch.testing.assert_close(torch.cat([b[0] for b in batches]),
                               torch.stack([p[0] for p in pairs]), rtol=0, atol=0)
    assert len(list(ShardPairs(files, crop=CROP, batch_size=2, drop_last=True))) == 1
    raw = list(ShardPairs(files, crop=CROP, dtype="uint8"))
    mean = torch.tensor(paircast.torch.IMAGENET_MEAN).view(3, 1, 1)
    std = torch.tensor(paircast.torch.IMAGENET_STD).view(3, 1, 1)
    for (u1, _), (f1, _) in zip(raw, pairs):
        assert u1.dtype == torch.uint8
        torch.testing.assert_close((u1.float() / 255 - mean) / std, f1, rtol=0, atol=1e-6)
    with pytest.raises(ValueError, match="crop"):
        ShardPairs(files, batch_size=4)
    with pytest.raises(ValueError, match="dtype"):
        ShardPairs(files, dtype="float16")


def test_workers_read_disjoint_samples_through_the_index(croco_pairs):
    files = shard_files(croco_pairs)[:1]  # one shard, two workers: split by sample
    seen = []
    for rank in range(2):
        loader = DataLoader(ShardPairs(files, crop=CROP, rank=rank, world_size=2),
                            batch_size=None, num_workers=2)
        seen += [tuple(image1.flatten()[:8].tolist()) for image1, _ in loader]
    alone = [tuple(image1.flatten()[:8].tolist()) for image1, _ in ShardPairs(files, crop=CROP)]
    assert len(seen) == len(alone) and sorted(seen) == sorted(alone)


def rewrite(src, dst, change):
    """A copy of shard `src` with each member's (name, bytes) passed through change()."""
    with tarfile.open(src) as tin, tarfile.open(dst, "w", format=tarfile.USTAR_FORMAT) as tout:
        for member in tin.getmembers():
            name, data = change(member.name, tin.extractfile(member).read())
            if name is None:
                continue
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tout.addfile(info, io.BytesIO(data))
    return str(dst)


def test_a_corrupt_jpeg_or_a_missing_member_skips_the_sample_with_a_warning(croco_pairs, tmp_path):
    src = shard_files(croco_pairs)[0]  # two samples
    keys = [paircast.ShardSet([src]).info(i)[0] for i in range(2)]
    corrupt = rewrite(src, tmp_path / "corrupt.tar", lambda n, d: (
        n, d[:200] + b"\0" * (len(d) - 200) if n == f"{keys[0]}.2.jpg" else d))
    with pytest.warns(RuntimeWarning, match=f"corrupt.tar: {keys[0]}.2.jpg"):
        assert len(list(ShardPairs([corrupt], crop=CROP))) == 1
    missing = rewrite(src, tmp_path / "missing.tar",
                      lambda n, d: (None, d) if n == f"{keys[1]}.1.jpg" else (n, d))
    with pytest.warns(RuntimeWarning, match=f"sample '{keys[1]}' is incomplete"):
        assert len(list(ShardPairs([missing], crop=CROP))) == 1


def test_another_version_and_a_truncated_shard_are_named(croco_pairs, tmp_path):
    src = shard_files(croco_pairs)[0]
    future = rewrite(src, tmp_path / "future.tar", lambda n, d: (
        n, d.replace(b'"paircast_shard_version":1', b'"paircast_shard_version":2')))
    for make in (lambda: ShardPairs([future], crop=CROP),
                 lambda: list(paircast.ShardReader(future))):
        with pytest.raises(paircast.Error, match="future.tar: .*version 2, this build reads version 1"):
            make()
    data = open(src, "rb").read()
    cut = tmp_path / "cut.tar"
    cut.write_bytes(data[: len(data) // 2 + 100])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        pairs = list(ShardPairs([str(cut)], crop=CROP))
    assert len(pairs) <= 1
    assert any("cut.tar: shard is truncated" in str(w.message) for w in caught)
