"""paircast.torch.ShardLoader: the batches of ShardPairs, bit for bit, decoded by C++ threads into
a ring of buffers made once; batches stay valid for `keep` batches; bad input is named."""

import warnings

import pytest

torch = pytest.importorskip("torch")

import paircast  # noqa: E402
from paircast.torch import ShardLoader, ShardPairs, normalize  # noqa: E402
from conftest import RESOLUTION, run_tool, ROOM  # noqa: E402
from test_shard_loader import rewrite  # noqa: E402

CROP = 48


@pytest.fixture(scope="module")
def shards(tmp_path_factory):
    """23 pairs of the room in shards of 5 (the last one short): enough for the ring to wrap."""
    out = tmp_path_factory.mktemp("loader")
    run_tool("generate_pairs", "--scenes", ROOM, "--out", out, "--pairs-per-scene", 23,
             "--resolution", RESOLUTION, "--seed", 4, "--jobs", 2, "--format", "shards",
             "--shard-size", 5)
    files = sorted(str(p) for p in out.glob("pairs-*.tar"))
    assert len(files) == 5
    return files


def cloned(batches):
    return [(a.clone(), b.clone()) for a, b in batches]


def assert_same(got, want):
    assert len(got) == len(want)
    for (a1, a2), (b1, b2) in zip(got, want):
        assert a1.dtype == b1.dtype and a1.shape == b1.shape
        assert torch.equal(a1, b1) and torch.equal(a2, b2)


@pytest.mark.parametrize("options", [
    dict(),
    dict(shuffle=True),
    dict(rank=1, world_size=2),          # 5 shards, 2 readers: split by shard
    dict(rank=2, world_size=7),          # more readers than shards: split by sample
    dict(drop_last=True),
    dict(dtype="uint8"),
    dict(normalize=False),
])
@pytest.mark.parametrize("threads", [1, 3])
def test_batches_equal_shard_pairs_bit_for_bit(shards, options, threads):
    loader = ShardLoader(shards, batch_size=3, crop=CROP, threads=threads, seed=7, **options)
    reference = ShardPairs(shards, crop=CROP, batch_size=3, seed=7, **options)
    for epoch in (0, 1):
        loader.set_epoch(epoch)
        reference.set_epoch(epoch)
        got = cloned(loader)
        assert_same(got, cloned(reference))
        assert len(loader) == len(got)
    # And against the pairs one at a time, stacked: the reference that batches nothing.
    one_by_one = ShardPairs(shards, crop=CROP, seed=7, **options)
    one_by_one.set_epoch(1)
    pairs = list(one_by_one)
    stacked = [torch.stack([p[k] for p in pairs]) for k in range(2)]
    flat = [torch.cat([b[k] for b in got]) for k in range(2)]
    n = flat[0].shape[0]
    assert torch.equal(flat[0], stacked[0][:n]) and torch.equal(flat[1], stacked[1][:n])


def test_epochs_differ_and_reuse_the_same_buffers(shards):
    loader = ShardLoader(shards, batch_size=4, crop=CROP, threads=2, prefetch=2, keep=1)
    seen, epochs = set(), []
    for epoch in range(3):
        loader.set_epoch(epoch)
        batches = []
        for a, b in loader:
            seen.add(a.data_ptr())
            seen.add(b.data_ptr())
            batches.append(a.clone())
        epochs.append(torch.cat(batches))
    assert len(seen) == 2 * (1 + 2)  # keep + prefetch buffers of each view, for all 3 epochs
    assert not torch.equal(epochs[0], epochs[1])


def test_a_batch_stays_valid_for_keep_batches(shards):
    for keep in (1, 3):
        loader = ShardLoader(shards, batch_size=2, crop=CROP, threads=2, keep=keep, prefetch=1)
        held = []  # (view, its copy when it was taken)
        for a, _ in loader:
            held.append((a, a.clone()))
            # The batch just taken and the keep - 1 before it are intact.
            for view, copy in held[-keep:]:
                assert torch.equal(view, copy)
        if keep == 1:  # with one buffer held, older batches were written again
            assert any(not torch.equal(v, c) for v, c in held[:-3])


def test_leaving_early_stops_the_threads_and_a_new_pass_starts_afresh(shards):
    loader = ShardLoader(shards, batch_size=2, crop=CROP, threads=2)
    first = next(iter(loader))[0].clone()
    for a, _ in loader:
        assert torch.equal(a, first)
        break
    assert sum(1 for _ in loader) == len(loader) == 12


def test_normalize_on_the_device_equals_the_float_decode(shards):
    raw = cloned(ShardLoader(shards, batch_size=5, crop=CROP, dtype="uint8"))
    floats = cloned(ShardLoader(shards, batch_size=5, crop=CROP))
    for (u1, u2), (f1, f2) in zip(raw, floats):
        assert u1.dtype == torch.uint8
        torch.testing.assert_close(normalize(u1), f1, rtol=0, atol=1e-6)
        out = torch.empty_like(f2)
        assert normalize(u2, out=out) is out
        torch.testing.assert_close(out, f2, rtol=0, atol=1e-6)


def test_a_corrupt_pair_is_skipped_as_shard_pairs_skips_it(shards, tmp_path):
    keys = [paircast.ShardSet([shards[1]]).info(i)[0] for i in range(5)]
    corrupt = rewrite(shards[1], tmp_path / "corrupt.tar", lambda n, d: (
        n, d[:200] + b"\0" * (len(d) - 200) if n in (f"{keys[1]}.2.jpg", f"{keys[3]}.1.jpg")
        else d))
    files = [shards[0], corrupt, *shards[2:]]
    for threads in (1, 2):
        with pytest.warns(RuntimeWarning, match=f"corrupt.tar: {keys[1]}.2.jpg") as caught:
            got = cloned(ShardLoader(files, batch_size=3, crop=CROP, threads=threads))
        assert sum("skipped" in str(w.message) for w in caught) == 2
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            want = cloned(ShardPairs(files, crop=CROP, batch_size=3))
        assert_same(got, want)
        assert sum(a.shape[0] for a, _ in got) == 21


def test_bad_options_and_shards_are_named(shards, tmp_path):
    with pytest.raises(ValueError, match="threads, prefetch and keep must be positive"):
        ShardLoader(shards, threads=0)
    with pytest.raises(ValueError, match="crop"):
        ShardLoader(shards, crop=None)
    with pytest.raises(ValueError, match="batch_size must be positive"):
        ShardLoader(shards, batch_size=0)
    with pytest.raises(ValueError, match="larger than the images"):
        next(iter(ShardLoader(shards, crop=RESOLUTION + 1)))
    with pytest.raises(paircast.Error, match="nothing.tar: no such shard"):
        ShardLoader(str(tmp_path / "nothing.tar"))
    junk = tmp_path / "junk.tar"
    junk.write_bytes(b"not a tar at all" * 100)
    with pytest.raises(paircast.Error, match="junk.tar"):
        ShardLoader([str(junk)])
    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match="pin_memory=True needs CUDA"):
            ShardLoader(shards, pin_memory=True, crop=CROP)


def test_the_engine_refuses_bad_buffers_and_samples(shards):
    s = paircast.ShardSet(shards)
    a = torch.empty(2, 3, CROP, CROP).numpy()
    engine = paircast._paircast.ShardBatches
    with pytest.raises(ValueError, match="one shape and dtype"):
        engine(s, [(a, torch.empty(2, 3, CROP, CROP + 1).numpy())] * 3, [0])
    with pytest.raises(ValueError, match="C-contiguous"):
        engine(s, [(a, torch.empty(2, 3, CROP, 2 * CROP).numpy()[..., ::2])] * 3, [0])
    with pytest.raises(paircast.Error, match="3 buffers needed, 1 given"):
        engine(s, [(a, a.copy())], [0])
    with pytest.raises(paircast.Error, match="sample 99 of 23"):
        engine(s, [(a, a.copy()) for _ in range(3)], [0, 99])
    core = engine(s, [(a, a.copy()) for _ in range(3)], [0, 1, 2])
    assert core.next()[1] == 2
    core.close()
    with pytest.raises(paircast.Error, match="closed"):
        core.next()


def test_the_draws_are_numpys(shards):
    """The C++ threads draw each pair's crops with NumPy's generator, bit for bit: checked on
    crops of 1 pixel less than the image, where every draw shows in the pixels."""
    small = RESOLUTION - 1
    for seed, epoch in ((0, 0), (12345, 3), (2**40 + 1, 7)):
        loader = ShardLoader(shards, batch_size=4, crop=small, seed=seed, dtype="uint8")
        reference = ShardPairs(shards, crop=small, batch_size=4, seed=seed, dtype="uint8")
        loader.set_epoch(epoch)
        reference.set_epoch(epoch)
        assert_same(cloned(loader), cloned(reference))
