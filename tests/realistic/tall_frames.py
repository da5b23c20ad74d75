#!/usr/bin/env python3
"""Pads a set's frames into tall portrait frames (16:9, 2:1 or 2.27:1 height to width), as phones
take them: the frame is placed at a random height and its top and bottom rows are repeated (with
a little noise) to fill the rest; truth.json and the .pts follow.

    python tall_frames.py SET_DIR OUT_DIR [--seed 5]
"""
import argparse, json, os
import numpy as np
from PIL import Image
from detect_landmarks import read_pts, write_pts  # the same directory


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("set_dir")
    ap.add_argument("out_dir")
    ap.add_argument("--seed", type=int, default=5)
    a = ap.parse_args()
    truth = json.load(open(os.path.join(a.set_dir, "truth.json")))
    rng = np.random.default_rng(a.seed)
    os.makedirs(a.out_dir, exist_ok=True)
    for im in truth["images"]:
        img = np.asarray(Image.open(os.path.join(a.set_dir, im["image"])).convert("RGB")).astype(np.float32)
        h, w = img.shape[:2]
        tall = max(h, int(round(w * rng.choice([16 / 9, 2.0, 2.27]))))
        top = int(rng.integers(0, tall - h + 1))
        out = np.pad(img, ((top, tall - h - top), (0, 0), (0, 0)), mode="edge") + rng.normal(0, 3, (tall, w, 3))
        Image.fromarray(np.clip(out, 0, 255).astype(np.uint8)).save(os.path.join(a.out_dir, im["image"]))
        pts = read_pts(os.path.join(a.set_dir, im["landmarks_file"])) + np.array([0.0, top])
        write_pts(os.path.join(a.out_dir, im["landmarks_file"]), pts.tolist())
        im["height"], im["landmarks"] = tall, pts.tolist()
        im["principal_px"] = [im["principal_px"][0], im["principal_px"][1] + top]
    json.dump(truth, open(os.path.join(a.out_dir, "truth.json"), "w"))


if __name__ == "__main__":
    main()
