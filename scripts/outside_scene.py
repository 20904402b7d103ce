#!/usr/bin/env python3
"""A degs scene directory from a `scripts/blender_scenes.py` render (issue #32).

  python3 scripts/outside_scene.py RENDER EVENTS OUT --fps 20 [--contrast 0.1]

RENDER: the folder `blender_scenes.py` wrote (cameras.json, images/, gt/novel/).
EVENTS: an event file made from RENDER/hr/ by any simulator (e.g. `evflow simulate
--frames RENDER/hr --out events.evs`); copied into OUT as is.
OUT: a new folder (refused when it exists): transforms_train.json (every hr frame on the
--fps grid), transforms_test.json (the in-between times blender_scenes.py chose),
transforms_novel.json, images/, gt/{test,novel}/ (the moving-object masks) and events.*;
with RENDER/depth/ (`blender_scenes.py --depth-only`) also gt/train/depth_NNNN.exr, the
train frames' true depth (channel Z), from which `gaussians/examples/depth_prior.rs`
writes a depth prior.

The frames are 8-bit sRGB (no `frame_encoding` field: the manifest default). Only the
Python standard library is needed.
"""

import argparse
import json
import os
import shutil
import sys


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("render")
    p.add_argument("events")
    p.add_argument("out")
    p.add_argument("--fps", type=int, required=True, help="train frames per second")
    p.add_argument("--contrast", type=float, default=0.1, help="the events' threshold C")
    a = p.parse_args()

    meta_path = os.path.join(a.render, "cameras.json")
    with open(meta_path) as f:
        meta = json.load(f)
    rate = meta["rate"]
    if rate % a.fps:
        sys.exit(f"{meta_path}: {rate} fps renders cannot give {a.fps} fps train frames")
    if os.path.exists(a.out):
        sys.exit(f"{a.out}: exists; give a new folder")
    step = rate // a.fps
    span = meta["seconds"]
    os.makedirs(os.path.join(a.out, "images"))
    os.makedirs(os.path.join(a.out, "gt", "novel"))
    os.makedirs(os.path.join(a.out, "gt", "test"))

    def frame(name, t, m):
        return {
            "file_path": f"images/{name}",
            "timestamp": t,
            "time": min(max(t / span, 0.0), 1.0),
            "transform_matrix": m,
        }

    def copy(src, name):
        shutil.copyfile(os.path.join(a.render, "images", src), os.path.join(a.out, "images", name))

    hr = {v["index"]: v for v in meta["views"]["hr"]}
    train = []
    for i in sorted(hr):
        if i % step == 0:
            name = f"train_{len(train):04d}.png"
            copy(f"hr_{i:05d}.png", name)
            train.append(frame(name, hr[i]["time"], hr[i]["transform_matrix"]))
            depth = os.path.join(a.render, "depth", f"hr_{i:05d}.exr")
            if os.path.exists(depth):
                os.makedirs(os.path.join(a.out, "gt", "train"), exist_ok=True)
                dst = os.path.join(a.out, "gt", "train", f"depth_{len(train) - 1:04d}.exr")
                shutil.copyfile(depth, dst)
    test = []
    for k, v in enumerate(meta["views"]["test"]):
        i = v["index"]
        if i % step == 0:
            sys.exit(f"{meta_path}: test frame {i} falls on the {a.fps} fps train grid")
        name = f"test_{k:04d}.png"
        copy(f"hr_{i:05d}.png", name)
        mask = os.path.join(a.render, "gt", "test", f"object_{k:04d}.png")
        if os.path.exists(mask):
            shutil.copyfile(mask, os.path.join(a.out, "gt", "test", f"object_{k:04d}.png"))
        test.append(frame(name, hr[i]["time"], hr[i]["transform_matrix"]))
    novel = []
    for k, v in enumerate(meta["views"]["novel"]):
        name = f"novel_{k:04d}.png"
        copy(name, name)
        novel.append(frame(name, v["time"], v["transform_matrix"]))
        mask = os.path.join(a.render, "gt", "novel", f"object_{k:04d}.png")
        if os.path.exists(mask):
            shutil.copyfile(mask, os.path.join(a.out, "gt", "novel", f"object_{k:04d}.png"))

    ext = os.path.splitext(a.events)[1]
    shutil.copyfile(a.events, os.path.join(a.out, "events" + ext))
    cam = meta["camera"]
    for split, frames in (("train", train), ("test", test), ("novel", novel)):
        doc = {"camera": cam, "frames": frames}
        if split == "train":
            doc["events"] = {"path": "events" + ext, "contrast_threshold": a.contrast}
        with open(os.path.join(a.out, f"transforms_{split}.json"), "w") as f:
            json.dump(doc, f, indent=1)
    with open(os.path.join(a.out, "outside.json"), "w") as f:
        json.dump(
            {
                "renderer": meta["renderer"],
                "scene": meta["scene"],
                "train_fps": a.fps,
                "events": os.path.abspath(a.events),
                "moving_mask": "gt/novel/object_NNNN.png: nonzero where a moving object covers the view",
            },
            f,
            indent=1,
        )
    print(f"{a.out}: {len(train)} train, {len(test)} test, {len(novel)} novel frames")


if __name__ == "__main__":
    main()
