#!/usr/bin/env python3
"""Furnished homes against box-furnished ones: the same floor plans and seeds, measured side by side.

For N random plans (make_scenes --random N --seed S) it writes three versions: box furniture
(the default), Sweet Home 3D models (--furnish) and the bare rooms (--shell). Then, per version:
  - per scene: triangles, textures, load time and the memory the loaded scene takes
    (generate_pairs' scene_stats), and generation's pairs a second and full renders a pair;
  - per rendered view (render_view --random V, the same seed): the share of pixels on furniture
    (the view rendered again in the bare rooms: pixels whose depth there is over 5 cm farther),
    depth discontinuities (the share of pixels with a 4-neighbour more than 5 % nearer or
    farther) and the image-gradient energy (mean squared finite difference of the grey image,
    values in [0, 1]), each as quartiles over the views.
The habitat test scenes (../shared/scenes) join the view measures where they exist.

    /usr/bin/python3 bench/furnish_scenes.py [--build build] [--scenes 4] [--seed 1]
        [--views 24] [--resolution 128] [--pairs 30] [--out /tmp/furnish_bench]
"""
import argparse
import glob
import json
import os
import re
import subprocess
import sys

import numpy as np
import OpenImageIO as oiio


def run(cmd, **kw):
    return subprocess.run(cmd, check=True, capture_output=True, text=True, **kw)


def read(path):
    return oiio.ImageInput.open(path).read_image("float")


def view_measures(rgb_path, depth_path, shell_depth_path=None):
    depth = read(depth_path)[..., 0]
    valid = depth > 0
    grey = read(rgb_path)[..., :3].mean(axis=2)
    gx, gy = np.diff(grey, axis=1), np.diff(grey, axis=0)
    energy = float((gx ** 2).mean() + (gy ** 2).mean())
    jump = np.zeros_like(valid)
    for axis in (0, 1):
        a = np.take(depth, range(depth.shape[axis] - 1), axis=axis)
        b = np.take(depth, range(1, depth.shape[axis]), axis=axis)
        both = (a > 0) & (b > 0)
        j = both & (np.abs(a - b) > 0.05 * np.minimum(a, b))
        pad = [(0, 0), (0, 0)]
        pad[axis] = (0, 1)
        jump |= np.pad(j, pad)
        pad[axis] = (1, 0)
        jump |= np.pad(j, pad)
    out = {"discontinuities": float(jump[valid].mean()) if valid.any() else 0.0,
           "gradient_energy": energy}
    if shell_depth_path:
        shell = read(shell_depth_path)[..., 0]
        furniture = valid & ((shell <= 0) | (shell - depth > 0.05))
        out["furniture_share"] = float(furniture[valid].mean()) if valid.any() else 0.0
    return out


def quartiles(values):
    q = np.percentile(values, [25, 50, 75])
    return f"{q[1]:.3g} ({q[0]:.3g}-{q[2]:.3g})"


def scene_files(folder):
    return sorted(glob.glob(os.path.join(folder, "*", "*.obj")))


def render_views(build, scene, out, args, shell_scene=None):
    run([f"{build}/tools/render_view", "--scene", scene, "--random", str(args.views), "--out", out,
         "--resolution", str(args.resolution), "--seed", str(args.seed)])
    measures = []
    for cam in sorted(glob.glob(os.path.join(out, "[0-9]*.json"))):
        stem = cam[:-5]
        shell_depth = None
        if shell_scene:
            shell_depth = stem + "_shell_depth.exr"
            run([f"{build}/tools/render_view", "--scene", shell_scene, "--camera", cam,
                 "--depth", shell_depth])
        measures.append(view_measures(stem + ".png", stem + "_depth.exr", shell_depth))
    return measures


def generation(build, folder, out, pairs):
    summary = json.loads(run([f"{build}/tools/generate_pairs", "--scenes", folder, "--out", out,
                              "--pairs-per-scene", str(pairs), "--resolution", "128",
                              "--quiet"]).stdout)
    return summary


def textures_of(build, scene):
    line = run([f"{build}/tools/render_view", "--scene", scene, "--random", "1", "--out",
                "/tmp/furnish_bench_probe", "--resolution", "16"]).stdout
    m = re.search(r"(\d+) textures", line)
    return int(m.group(1)) if m else 0


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--build", default="build")
    p.add_argument("--scenes", type=int, default=4)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--views", type=int, default=24)
    p.add_argument("--resolution", type=int, default=128)
    p.add_argument("--pairs", type=int, default=30)
    p.add_argument("--models", default="all")
    p.add_argument("--out", default="/tmp/furnish_bench")
    args = p.parse_args()
    b = args.build
    kinds = {"box": [], "furnished": ["--furnish", "--models", args.models], "shell": ["--shell"]}
    for kind, extra in kinds.items():
        run([f"{b}/tools/make_scenes", "--random", str(args.scenes), "--seed", str(args.seed),
             "--out", f"{args.out}/{kind}"] + extra)
    rows = {}
    for kind in ("box", "furnished"):
        folder = f"{args.out}/{kind}"
        summary = generation(b, folder, f"{args.out}/pairs_{kind}", args.pairs)
        stats = summary["scene_stats"]
        views = []
        for scene in scene_files(folder):
            name = os.path.basename(os.path.dirname(scene))
            shell = f"{args.out}/shell/{name}/{name}.obj"
            views += render_views(b, scene, f"{args.out}/views_{kind}/{name}", args, shell)
        rows[kind] = {
            "triangles": quartiles([s["triangles"] for s in stats]),
            "textures": quartiles([textures_of(b, s) for s in scene_files(folder)]),
            "load_seconds": quartiles([s["load_seconds"] for s in stats]),
            "scene_mib": quartiles([s["bytes"] / 2 ** 20 for s in stats if s["bytes"] > 0]),
            "pairs_per_second": f"{summary['pairs_per_second']:.2f}",
            "renders_per_pair": f"{summary['renders']['per_pair']:.2f}",
            "furniture_share": quartiles([v["furniture_share"] for v in views]),
            "discontinuities": quartiles([v["discontinuities"] for v in views]),
            "gradient_energy": quartiles([v["gradient_energy"] for v in views]),
        }
    shared = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "shared", "scenes")
    habitat = sorted(glob.glob(os.path.join(shared, "**", "*.glb"), recursive=True))
    if habitat:
        views = []
        for scene in habitat:
            name = os.path.splitext(os.path.basename(scene))[0]
            views += render_views(b, scene, f"{args.out}/views_habitat/{name}", args)
        rows["habitat"] = {"discontinuities": quartiles([v["discontinuities"] for v in views]),
                           "gradient_energy": quartiles([v["gradient_energy"] for v in views])}
    keys = ["triangles", "textures", "load_seconds", "scene_mib", "pairs_per_second",
            "renders_per_pair", "furniture_share", "discontinuities", "gradient_energy"]
    cols = list(rows)
    print(f"{args.scenes} plans, seed {args.seed}, {args.views} views of {args.resolution} px each; "
          "median (quartiles)")
    print("| | " + " | ".join(cols) + " |")
    print("| --- |" + " --- |" * len(cols))
    for k in keys:
        print(f"| {k} | " + " | ".join(rows[c].get(k, "") for c in cols) + " |")
    json.dump(rows, open(f"{args.out}/furnish_bench.json", "w"), indent=1)


if __name__ == "__main__":
    sys.exit(main())
