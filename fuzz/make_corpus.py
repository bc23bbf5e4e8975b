#!/usr/bin/python3
"""Writes the small seed corpora in fuzz/corpus/<target>/ (each file a few KB at most).

Tiny scenes, JSON records and checkpoints are made here from scratch; the .flo and EXR members
and the shard with flow and depth are real outputs of generate_pairs. All are inputs our readers
accept, so that libFuzzer starts from valid structure and mutates inward. Run it again after
changing a format (the files are committed):

  /usr/bin/python3 fuzz/make_corpus.py [--pairs DIR | --build BUILD_DIR]

--pairs DIR takes the real outputs from DIR, written by
  generate_pairs --scenes scenes/room --out DIR --pairs-per-scene 2 --resolution 16 --save-flow
    --save-depth --format both --shard-size 1 --seed 3 --jobs 1
otherwise that command is run from BUILD_DIR/tools (default build/) into a temporary folder.
Without either, and without torch for the checkpoint seeds, those targets' seeds are left as they
are: a target's folder is emptied only when its seeds are written again. The checkpoint seeds
need Debian's python3-torch (/usr/bin/python3).
"""
import argparse
import collections
import io
import json
import os
import shutil
import struct
import subprocess
import tarfile
import tempfile
import zlib

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ROOT = os.path.join(REPO, "fuzz", "corpus")
_written = set()  # targets whose folder this run emptied


def write(target, name, data, limit=8192):
    folder = os.path.join(ROOT, target)
    if target not in _written:
        shutil.rmtree(folder, ignore_errors=True)
        _written.add(target)
    os.makedirs(folder, exist_ok=True)
    if isinstance(data, str):
        data = data.encode()
    assert len(data) <= limit, (target, name, len(data))
    with open(os.path.join(folder, name), "wb") as f:
        f.write(data)


# ---- OBJ ----

def obj_seeds():
    write("fuzz_scene_obj", "triangle.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    write("fuzz_scene_obj", "quad_uv_normals.obj",
          "# a quad with texture coordinates and normals, as two faces\n"
          "o quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
          "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\n"
          "s off\nf 1/1/1 2/2/1 3/3/1\nf 1/1/1 3/3/1 4/4/1\n")
    write("fuzz_scene_obj", "groups_negative_polygon.obj",
          "mtllib missing.mtl\ng floor\nusemtl grey\n"
          "v -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nv 0 0 -1.5\n"
          "f -5 -1 -4 -3 -2\n"
          "g wall\nusemtl red\nv -1 0 -1 0.5 0.2 0.2\nv 1 0 -1 0.5 0.2 0.2\nv 0 2 -1 0.5 0.2 0.2\n"
          "f 6 7 8\nl 1 2\np 3\n")


# ---- PLY ----

PLY_TRI_ASCII = (
    "ply\nformat ascii 1.0\ncomment made by fuzz/make_corpus.py\n"
    "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
    "property uchar red\nproperty uchar green\nproperty uchar blue\n"
    "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
    "0 0 0 255 0 0\n1 0 0 0 255 0\n0 1 0 0 0 255\n3 0 1 2\n")


def ply_binary(endian):
    fmt = "binary_little_endian" if endian == "<" else "binary_big_endian"
    header = ("ply\nformat %s 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
              "property float z\nproperty float s\nproperty float t\n"
              "element face 2\nproperty list uchar int vertex_indices\nend_header\n" % fmt)
    body = b""
    for x, y, z, s, t in [(0, 0, 0, 0, 0), (1, 0, 0, 1, 0), (1, 1, 0, 1, 1), (0, 1, 0, 0, 1)]:
        body += struct.pack(endian + "5f", x, y, z, s, t)
    for face in [(0, 1, 2), (0, 2, 3)]:
        body += struct.pack(endian + "B3i", 3, *face)
    return header.encode() + body


def ply_scan(replica):
    """Binary little-endian, as ScanNet (x y z, uchar RGBA, triangles) and Replica (x y z,
    nx ny nz, uchar RGB, quads) write them: the files loadScene's own PLY reader takes."""
    props = "property float x\nproperty float y\nproperty float z\n"
    if replica:
        props += "property float nx\nproperty float ny\nproperty float nz\n"
    props += "property uchar red\nproperty uchar green\nproperty uchar blue\n"
    if not replica:
        props += "property uchar alpha\n"
    faces = [(0, 1, 2, 3)] if replica else [(0, 1, 2), (0, 2, 3)]
    header = ("ply\nformat binary_little_endian 1.0\nelement vertex 4\n" + props +
              "element face %d\nproperty list uchar int vertex_indices\nend_header\n" % len(faces))
    body = b""
    for x, y in [(0, 0), (1, 0), (1, 1), (0, 1)]:
        body += struct.pack("<3f", x, y, 0)
        body += struct.pack("<3f", 0, 0, 1) if replica else b""
        body += bytes([200, 100, 50]) + (b"" if replica else b"\xff")
    for face in faces:
        body += struct.pack("<B%di" % len(face), len(face), *face)
    return header.encode() + body


def ply_seeds():
    write("fuzz_scene_ply", "triangle_ascii.ply", PLY_TRI_ASCII)
    write("fuzz_scene_ply", "scannet_rgba_binary_le.ply", ply_scan(False))
    write("fuzz_scene_ply", "replica_quads_binary_le.ply", ply_scan(True))
    write("fuzz_scene_ply", "quad_binary_le.ply", ply_binary("<"))
    write("fuzz_scene_ply", "quad_binary_be.ply", ply_binary(">"))
    write("fuzz_scene_ply", "quad_ascii_polygon.ply",
          "ply\nformat ascii 1.0\nelement vertex 4\nproperty double x\nproperty double y\n"
          "property double z\nelement face 1\nproperty list uchar uint vertex_indices\n"
          "end_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n")


# ---- GLB ----

def png_1x1(rgb):
    def chunk(kind, data):
        return (struct.pack(">I", len(data)) + kind + data +
                struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))
    raw = b"\x00" + bytes(rgb)  # filter byte, one RGB pixel
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 1, 1, 8, 2, 0, 0, 0)) +
            chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


def glb(gltf, binary):
    binary += b"\0" * (-len(binary) % 4)
    gltf["buffers"] = [{"byteLength": len(binary)}]
    text = json.dumps(gltf, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    total = 12 + 8 + len(text) + 8 + len(binary)
    return (b"glTF" + struct.pack("<II", 2, total) + struct.pack("<I", len(text)) + b"JSON" + text +
            struct.pack("<I", len(binary)) + b"BIN\0" + binary)


def glb_seeds():
    positions = struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0)
    indices = struct.pack("<3H", 0, 1, 2) + b"\0\0"
    write("fuzz_scene_glb", "triangle.glb", glb({
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "translation": [0, 0, 1]}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}],
        "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.2, 0.2, 1]}}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36},
                        {"buffer": 0, "byteOffset": 36, "byteLength": 6}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                       "min": [0, 0, 0], "max": [1, 1, 0]},
                      {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}],
    }, positions + indices))

    # The same triangle with a Basis Universal texture, as HM3D's .basis.glb files hold
    # (GOOGLE_texture_basis: a texture without a plain source, an image/basis image).
    basis = b"sB" + bytes(range(30))
    write("fuzz_scene_glb", "basis_texture.glb", glb({
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}],
        "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.2, 0.2, 1],
                                                "baseColorTexture": {"index": 0}}}],
        "textures": [{"extensions": {"GOOGLE_texture_basis": {"source": 0}}}],
        "images": [{"bufferView": 2, "mimeType": "image/basis"}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36},
                        {"buffer": 0, "byteOffset": 36, "byteLength": 6},
                        {"buffer": 0, "byteOffset": 44, "byteLength": len(basis)}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                       "min": [0, 0, 0], "max": [1, 1, 0]},
                      {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}],
        "extensionsUsed": ["GOOGLE_texture_basis"],
        "extensionsRequired": ["GOOGLE_texture_basis"],
    }, positions + indices + basis))

    # A quad with colours and UVs, instanced by two nodes under a rotated parent, and a texture
    # held in the file (a 1x1 PNG).
    quad = struct.pack("<12f", 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0)
    colors = struct.pack("<16f", *([1, 0, 0, 1] * 4))
    uvs = struct.pack("<8f", 0, 0, 1, 0, 1, 1, 0, 1)
    idx = struct.pack("<6H", 0, 1, 2, 0, 2, 3) + b""
    png = png_1x1((10, 200, 30))
    blob = quad + colors + uvs + idx
    views = [(0, len(quad)), (len(quad), len(colors)), (len(quad) + len(colors), len(uvs)),
             (len(quad) + len(colors) + len(uvs), len(idx))]
    png_offset = len(blob) + (-len(blob) % 4)
    blob += b"\0" * (-len(blob) % 4) + png
    write("fuzz_scene_glb", "instanced_textured_quad.glb", glb({
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"children": [1, 2], "rotation": [0, 0.7071068, 0, 0.7071068]},
                  {"mesh": 0},
                  {"mesh": 0, "matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 2, 0, 0, 1]}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "COLOR_0": 1, "TEXCOORD_0": 2},
                                    "indices": 3, "material": 0}]}],
        "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
        "textures": [{"source": 0}],
        "images": [{"bufferView": 4, "mimeType": "image/png"}],
        "bufferViews": [{"buffer": 0, "byteOffset": o, "byteLength": n} for o, n in views] +
                       [{"buffer": 0, "byteOffset": png_offset, "byteLength": len(png)}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
                       "min": [0, 0, 0], "max": [1, 1, 0]},
                      {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC4"},
                      {"bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC2"},
                      {"bufferView": 3, "componentType": 5123, "count": 6, "type": "SCALAR"}],
    }, blob))


# ---- camera and sample JSON, shards ----

def camera(t, width=64, height=48, rotation=None):
    r = rotation or [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
    return {"camera_intrinsics": [[32.0, 0, width / 2], [0, 32.0, height / 2], [0, 0, 1]],
            "R_cam2world": r, "t_cam2world": t, "width": width, "height": height}


def record(index, scene="room"):
    return {"paircast_shard_version": 1, "scene": scene, "index": index, "seed": 7,
            "camera1": camera([0, 1.5, 0]),
            "camera2": camera([0.5, 1.5, 0.1], rotation=[[0, 0, 1], [0, 1, 0], [-1, 0, 0]]),
            "covis": 0.55, "v_ij": 0.6, "v_ji": 0.55, "valid_fraction1": 0.9,
            "valid_fraction2": 0.95, "candidates": 3}


def camera_seeds():
    write("fuzz_camera_json", "camera.json", json.dumps(camera([0, 1.5, 0])))
    croco = camera([1, 2, 3], rotation=[[0, -1, 0], [1, 0, 0], [0, 0, 1]])
    del croco["width"], croco["height"]  # CroCo's camera_params.json has no size
    write("fuzz_camera_json", "croco_no_size.json", json.dumps(croco, indent=1))


def sample_json_seeds():
    write("fuzz_sample_json", "record.json", json.dumps(record(3)))
    minimal = {k: v for k, v in record(0, "a").items()
               if k in ("paircast_shard_version", "scene", "index", "camera1", "camera2",
                        "covis", "v_ij", "v_ji")}
    write("fuzz_sample_json", "minimal.json", json.dumps(minimal, indent=1))


JPEG_STUB = b"\xff\xd8\xff\xe0\x00\x10JFIF\x00\x01\x01\x00\x00\x01\x00\x01\x00\x00\xff\xd9"


def tar(entries):
    """A ustar archive like ShardWriter's: fixed owner, mode and time; no padding record."""
    out = b""
    for name, data, kind, link in entries:
        info = tarfile.TarInfo(name)
        info.size, info.mode, info.mtime, info.type, info.linkname = len(data), 0o644, 0, kind, link
        info.uname = info.gname = ""
        out += info.tobuf(format=tarfile.USTAR_FORMAT) + data + b"\0" * (-len(data) % 512)
    return out + b"\0" * 1024


def shard_seeds():
    rec = json.dumps(record(0)).encode()
    write("fuzz_shard", "one_sample.tar", tar([
        ("room-00000000.1.jpg", JPEG_STUB, tarfile.REGTYPE, ""),
        ("room-00000000.2.jpg", JPEG_STUB, tarfile.REGTYPE, ""),
        ("room-00000000.json", rec, tarfile.REGTYPE, "")]))
    write("fuzz_shard", "depth_and_links.tar", tar([
        ("room-00000001.1.jpg", JPEG_STUB, tarfile.REGTYPE, ""),
        ("room-00000001.2.jpg", JPEG_STUB, tarfile.REGTYPE, ""),
        ("room-00000001.1.depth.exr", b"v/1\x01", tarfile.REGTYPE, ""),
        ("room-00000001.2.depth.exr", b"v/1\x01", tarfile.REGTYPE, ""),
        ("room-00000001.json", json.dumps(record(1)).encode(), tarfile.REGTYPE, ""),
        ("room-00000002.1.jpg", b"", tarfile.SYMTYPE, "/etc/passwd"),
        ("../room-00000002.json", b"{}", tarfile.REGTYPE, "")]))
    # The trainer reads the same files through the same index (shard/shard_index.h).
    for name in ("one_sample.tar", "depth_and_links.tar"):
        with open(os.path.join(ROOT, "fuzz_shard", name), "rb") as f:
            write("fuzz_shard_index", name, f.read())


# ---- real outputs: .flo and EXR members, a shard with flow and depth ----

GENERATE = ["--scenes", os.path.join(REPO, "scenes", "room"), "--pairs-per-scene", "2",
            "--resolution", "16", "--save-flow", "--save-depth", "--format", "both",
            "--shard-size", "1", "--seed", "3", "--jobs", "1", "--quiet"]


def real_outputs(pairs, build, scratch):
    """The folder of generate_pairs' outputs (module docstring), or None when there is none."""
    if pairs:
        return pairs
    tool = os.path.join(build, "tools", "generate_pairs")
    if not os.access(tool, os.X_OK):
        return None
    out = os.path.join(scratch, "pairs")
    subprocess.run([tool, "--out", out] + GENERATE, check=True, stdout=subprocess.DEVNULL)
    return out


def read(path):
    with open(path, "rb") as f:
        return f.read()


def real_seeds(folder):
    """Members as generate_pairs writes them, in CroCo's layout and in shards (the same bytes)."""
    croco = os.path.join(folder, "room")
    for pair in ("00000000", "00000001"):
        write("fuzz_flo", "room_%s_1_flow.flo" % pair, read(os.path.join(croco, pair + "_1_flow.flo")))
        write("fuzz_exr", "room_%s_1_depth.exr" % pair,
              read(os.path.join(croco, pair + "_1_depth.exr")))
    # A shard of one pair with both views' JPEGs, depth and flow: what finetune and ShardPairs
    # read. At generate_pairs' smallest resolution (16) it is 18 KiB, over the 8 KiB of the other
    # seeds; libFuzzer's -max_len follows the largest seed.
    shard = read(os.path.join(folder, "pairs-000000.tar"))
    for target in ("fuzz_shard", "fuzz_shard_index"):
        write(target, "room_flow_depth.tar", shard, limit=20 * 1024)


# ---- checkpoints ----

def checkpoint_seeds():
    try:
        import torch
    except ImportError:
        print("make_corpus: python3-torch missing, checkpoint seeds left as they are")
        return

    def save(target, name, obj):
        buf = io.BytesIO()
        torch.save(obj, buf)
        write(target, name, buf.getvalue(), limit=16 * 1024)

    w = torch.arange(6, dtype=torch.float32).reshape(2, 3)
    save("fuzz_checkpoint", "croco_style.pth", {
        "model": collections.OrderedDict(
            [("enc.weight", w), ("enc.bias", torch.zeros(2, dtype=torch.float16))]),
        "args": argparse.Namespace(model="CroCoNet(enc_depth=2)", lr=1e-4, norm_pix_loss=True),
        "epoch": 3,
        "optimizer": {"state": {0: {"step": torch.tensor(5.0), "exp_avg": torch.ones(2, 3)}},
                      "param_groups": [{"lr": 1e-4, "betas": (0.9, 0.95), "params": [0, 1]}]},
    })
    base = torch.arange(8, dtype=torch.float64)
    save("fuzz_checkpoint", "views_and_dtypes.pth", collections.OrderedDict([
        ("slice", base[2:5]), ("matrix", base.view(2, 4)), ("transposed", base.view(2, 4).t()),
        ("long", torch.tensor([1, -2, 3], dtype=torch.int64)),
        ("mask", torch.tensor([True, False])), ("scalar", torch.tensor(2.5)),
        ("empty", torch.zeros(0, 3)), ("param", torch.nn.Parameter(torch.ones(2)))]))
    finetune_checkpoint_seeds(torch, save)


def downstream_state(task, head, img, patch, width, mlp_ratio, rope):
    """{name: shape} of DownstreamNet (model/downstream.h) with one encoder and one decoder block
    of `width` channels and one head each."""
    E = D = width
    grid = img // patch
    shapes = collections.OrderedDict()

    def linear(name, out, inp):
        shapes[name + ".weight"], shapes[name + ".bias"] = (out, inp), (out,)

    def norm(name, dim):
        shapes[name + ".weight"], shapes[name + ".bias"] = (dim,), (dim,)

    def block(prefix, dim, cross):
        norm(prefix + "norm1", dim)
        linear(prefix + "attn.qkv", 3 * dim, dim)
        linear(prefix + "attn.proj", dim, dim)
        if cross:
            for name in ("projq", "projk", "projv", "proj"):
                linear(prefix + "cross_attn." + name, dim, dim)
        norm(prefix + "norm2", dim)
        if cross:
            norm(prefix + "norm3", dim)
            norm(prefix + "norm_y", dim)  # norm_im2_in_dec
        linear(prefix + "mlp.fc1", mlp_ratio * dim, dim)
        linear(prefix + "mlp.fc2", dim, mlp_ratio * dim)

    shapes["patch_embed.proj.weight"], shapes["patch_embed.proj.bias"] = (E, 3, patch, patch), (E,)
    if not rope:
        shapes["enc_pos_embed"], shapes["dec_pos_embed"] = (grid * grid, E), (grid * grid, D)
    block("enc_blocks.0.", E, False)
    norm("enc_norm", E)
    if task != "depth":
        linear("decoder_embed", D, E)
        block("dec_blocks.0.", D, True)
        norm("dec_norm", D)
    if head == "linear":
        linear("prediction_head", patch * patch * (2 if task == "flow" else 1), D)
    else:  # pose: PoseHead(D, patches), 64 hidden
        linear("head.fc1", 64, D)
        linear("head.fc2", 12, grid * grid * 64)
    return shapes


def finetune_checkpoint(torch, task, head, img, patch, width, pos_embed):
    """What finetune's checkpoints hold (finetune/finetune.cpp FinetuneTask::save, the training
    loop's entries), for a one-block model. Every tensor is a view of one storage: torch.save
    writes one record per storage, and 46 records would double the file. Its pickle alone (46
    names and tensors, 5 KiB) and the pose head (64 hidden values a patch) take it past the 8 KiB
    of other seeds: save() allows 16 KiB."""
    shapes = downstream_state(task, head, img, patch, width, 1, pos_embed != "cosine")
    sizes = [int(torch.Size(s).numel()) for s in shapes.values()]
    torch.manual_seed(sum(sizes))
    flat = torch.randn(sum(sizes)) * 0.02
    state, offset = collections.OrderedDict(), 0
    for (name, shape), n in zip(shapes.items(), sizes):
        state[name] = flat[offset:offset + n].view(shape)
        offset += n
    kwargs = {"img_size": img, "patch_size": patch, "mask_ratio": 0.9, "enc_embed_dim": width,
              "enc_depth": 1, "enc_num_heads": 1, "dec_embed_dim": width, "dec_depth": 1,
              "dec_num_heads": 1, "mlp_ratio": 1, "norm_im2_in_dec": True, "pos_embed": pos_embed}
    return {"model": state, "epoch": 1, "croco_kwargs": kwargs, "task": task, "head": head,
            "args": dict(kwargs, decoder="cross"), "step": 4, "seed": 0, "batch_size": 2,
            "accum_iter": 1, "init": "random"}


def finetune_checkpoint_seeds(torch, save):
    save("fuzz_finetune_checkpoint", "flow_linear_cosine.pth",
         finetune_checkpoint(torch, "flow", "linear", 8, 4, 4, "cosine"))
    save("fuzz_finetune_checkpoint", "depth_linear_rope.pth",
         finetune_checkpoint(torch, "depth", "linear", 8, 4, 4, "RoPE100"))
    save("fuzz_finetune_checkpoint", "pose_one_patch.pth",
         finetune_checkpoint(torch, "pose", "pose", 4, 4, 4, "cosine"))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pairs", help="generate_pairs' outputs (see above)")
    parser.add_argument("--build", default=os.path.join(REPO, "build"),
                        help="the build whose tools/generate_pairs writes them (default build/)")
    args = parser.parse_args()
    # The real shard shares its folders with seeds made here: kept when it cannot be made again.
    shards = {t: os.path.join(ROOT, t, "room_flow_depth.tar") for t in ("fuzz_shard",
                                                                         "fuzz_shard_index")}
    old = {t: read(p) for t, p in shards.items() if os.path.exists(p)}
    obj_seeds()
    ply_seeds()
    glb_seeds()
    camera_seeds()
    sample_json_seeds()
    shard_seeds()
    with tempfile.TemporaryDirectory() as scratch:
        folder = real_outputs(args.pairs, args.build, scratch)
        if folder:
            real_seeds(folder)
        else:
            print("make_corpus: no generate_pairs (--pairs, --build): .flo, EXR and real shard "
                  "seeds left as they are")
            for target, data in old.items():
                write(target, os.path.basename(shards[target]), data, limit=len(data))
    checkpoint_seeds()
    for target in sorted(os.listdir(ROOT)):
        files = os.listdir(os.path.join(ROOT, target))
        size = sum(os.path.getsize(os.path.join(ROOT, target, f)) for f in files)
        print("%-18s %d files, %d bytes" % (target, len(files), size))


if __name__ == "__main__":
    main()
