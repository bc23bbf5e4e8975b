"""paircast.torch: LivePairs and ShardPairs in DataLoaders, and a few training steps."""

import numpy as np
import pytest

torch = pytest.importorskip("torch")
from torch import nn  # noqa: E402
from torch.utils.data import DataLoader  # noqa: E402

import paircast  # noqa: E402
from paircast.torch import IMAGENET_MEAN, IMAGENET_STD, LivePairs, ShardPairs  # noqa: E402
from conftest import RESOLUTION, ROOM, take  # noqa: E402


def live(**kwargs):
    options = dict(seed=3, resolution=RESOLUTION, threads=1)
    options.update(kwargs)
    return LivePairs([ROOM], **options)


def normalised(image):
    mean = torch.tensor(IMAGENET_MEAN).view(3, 1, 1)
    std = torch.tensor(IMAGENET_STD).view(3, 1, 1)
    return (torch.from_numpy(image).permute(2, 0, 1).float() / 255 - mean) / std


def test_yields_croco_pairs_of_the_stream():
    pairs = list(live(length=2))
    assert len(pairs) == 2
    for (image1, image2), s in zip(pairs, take(2)):
        assert image1.dtype == torch.float32 and image1.shape == (3, RESOLUTION, RESOLUTION)
        torch.testing.assert_close(image1, normalised(s["images"][0]))
        torch.testing.assert_close(image2, normalised(s["images"][1]))


def test_crops_are_drawn_per_image():
    for item in live(length=3, crop=40, return_dict=True):
        assert item["image1"].shape == (3, 40, 40)
        for key, view in (("1", 0), ("2", item["view2"])):
            top, left = item["crop" + key]
            expected = normalised(np.ascontiguousarray(
                item["images"][view][top:top + 40, left:left + 40]))
            torch.testing.assert_close(item["image" + key], expected)


def test_draws_depend_on_the_pair_only():
    """Crops and the second view are the same whatever the threads and the order."""
    def draws(**kwargs):
        items = live(views=3, length=6, crop=32, return_dict=True, **kwargs)
        return {int(i["index"]): (i["crop1"], i["crop2"], i["view2"]) for i in items}
    one = draws(threads=1)
    two = draws(threads=2)
    common = one.keys() & two.keys()
    assert common and {k: one[k] for k in common} == {k: two[k] for k in common}


def test_set_epoch_moves_on_to_fresh_pairs():
    dataset = live(length=3, return_dict=True)
    first = {int(i["index"]) for i in dataset}
    dataset.set_epoch(1)
    second = {int(i["index"]) for i in dataset}
    assert len(first) == len(second) == 3 and not first & second


def keys(loader):
    return [(s["scene"], int(s["index"])) for s in loader]


def test_workers_and_ranks_read_disjoint_parts():
    seen = []
    for rank in range(2):
        dataset = live(length=8, return_dict=True, rank=rank, world_size=2)
        assert len(dataset) == 4
        part = keys(DataLoader(dataset, batch_size=None, num_workers=2))
        assert len(part) == 4 and len(set(part)) == 4
        seen.append(set(part))
    assert not seen[0] & seen[1]
    assert len(seen[0] | seen[1]) == 8


def test_shard_pairs_match_the_stream(croco_pairs):
    shards = str(croco_pairs / "pairs-*.tar")
    stream = {s["index"]: s for s in take(3)}
    items = list(ShardPairs(shards, return_dict=True, depth=True))
    assert sorted(int(i["index"]) for i in items) == [0, 1, 2]
    for item in items:
        s = stream[int(item["index"])]
        np.testing.assert_array_equal(item["depths"], s["depths"])
        assert item["covis"][0] == pytest.approx(s["covis"][0])
        jpeg = paircast.decode_image(
            (croco_pairs / "room" / f"{item['index']:08d}_1.jpeg").read_bytes(), "x.jpeg")
        np.testing.assert_array_equal(item["images"][0], jpeg)
        torch.testing.assert_close(item["image1"], normalised(jpeg))


def test_shard_pairs_split_among_workers_and_ranks(croco_pairs):
    shards = str(croco_pairs / "pairs-*.tar")
    for world in (1, 2):  # 2 and 4 readers of 2 shards: split by shard, then by sample
        seen = []
        for rank in range(world):
            dataset = ShardPairs(shards, return_dict=True, rank=rank, world_size=world)
            seen += keys(DataLoader(dataset, batch_size=None, num_workers=2))
        assert sorted(i for _, i in seen) == [0, 1, 2]


def test_multi_view_shards_and_live_pairs(multiview_shards):
    stream = {s["index"]: s for s in take(3, views=3)}
    items = list(ShardPairs(str(multiview_shards / "pairs-*.tar"), return_dict=True, depth=True))
    assert sorted(int(i["index"]) for i in items) == sorted(stream)
    for item in items:
        s = stream[int(item["index"])]
        assert item["images"].shape == (3, RESOLUTION, RESOLUTION, 3)
        np.testing.assert_array_equal(item["depths"], s["depths"])
        np.testing.assert_allclose(item["covis"], s["covis"], rtol=0, atol=1e-12)
        np.testing.assert_allclose(item["visibility"], s["visibility"], rtol=0, atol=1e-12)
        assert item["view2"] in (1, 2)
        torch.testing.assert_close(item["image2"], normalised(item["images"][item["view2"]]))
    views2 = {item["view2"] for item in live(views=3, length=8, return_dict=True)}
    assert views2 <= {1, 2}
    with pytest.raises(ValueError, match="views"):
        live(views=1)


def test_missing_shards_raise():
    with pytest.raises(paircast.Error, match="no such shard"):
        ShardPairs("/nonexistent/pairs-*.tar")


class TinyCroCo(nn.Module):
    """CroCo's shape at toy size: the visible patches of image 1 and all of image 2 go through
    a shared encoder; a decoder with cross-attention to image 2 predicts the masked patches."""

    def __init__(self, patch=16, dim=64, size=RESOLUTION):
        super().__init__()
        self.patch = patch
        n = (size // patch) ** 2
        self.embed = nn.Linear(3 * patch * patch, dim)
        self.pos = nn.Parameter(0.02 * torch.randn(1, n, dim))
        self.encoder = nn.TransformerEncoderLayer(dim, 4, 2 * dim, dropout=0.0, batch_first=True)
        self.mask_token = nn.Parameter(torch.zeros(1, 1, dim))
        self.decoder = nn.TransformerDecoderLayer(dim, 4, 2 * dim, dropout=0.0, batch_first=True)
        self.head = nn.Linear(dim, 3 * patch * patch)

    def patchify(self, x):  # [B, 3, H, W] -> [B, N, p*p*3]
        p = self.patch
        b, c, h, w = x.shape
        x = x.reshape(b, c, h // p, p, w // p, p).permute(0, 2, 4, 3, 5, 1)
        return x.reshape(b, (h // p) * (w // p), p * p * c)

    def forward(self, image1, image2, mask):  # mask: [B, N], True where masked
        b = image1.shape[0]
        x1 = self.embed(self.patchify(image1)) + self.pos
        visible = self.encoder(x1[~mask].reshape(b, -1, x1.shape[-1]))
        features2 = self.encoder(self.embed(self.patchify(image2)) + self.pos)
        tokens = self.mask_token.expand(b, mask.shape[1], -1).clone()
        tokens[~mask] = visible.reshape(-1, visible.shape[-1])
        return self.head(self.decoder(tokens + self.pos, features2))


def test_training_on_live_pairs_lowers_the_loss():
    torch.manual_seed(0)
    model = TinyCroCo()
    optimizer = torch.optim.AdamW(model.parameters(), lr=2e-3, betas=(0.9, 0.95))
    loader = DataLoader(live(length=4 * 20, seed=1), batch_size=4)
    losses = []
    for image1, image2 in loader:
        n = model.patchify(image1).shape[1]
        order = torch.rand(image1.shape[0], n).argsort(dim=1)
        mask = torch.zeros(image1.shape[0], n, dtype=torch.bool)
        mask.scatter_(1, order[:, : int(0.9 * n)], True)  # CroCo's mask ratio
        pred = model(image1, image2, mask)
        loss = ((pred - model.patchify(image1)) ** 2).mean(-1)[mask].mean()
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
    assert len(losses) == 20
    first, last = np.mean(losses[:4]), np.mean(losses[-4:])
    print(f"loss {first:.3f} -> {last:.3f}")
    assert last < 0.8 * first, f"loss did not fall: {first:.3f} -> {last:.3f}"
