#!/usr/bin/env python3
"""A real-photo set with every photo shrunk so that its longer side is at most LONG pixels.

    python shrink_set.py SET OUT LONG      # e.g. 500: the size of Pascal VOC's photos

Each photo STEM.EXT of SET with a STEM.faces.json is written to OUT/STEM.jpg, resized with a
Lanczos filter when it is larger (smaller photos are copied as they are), and its reference boxes
and 68 points are scaled with it (the format of README.md beside this script). `gpmm eval detect
OUT` then says how the finder does on small photos, whose faces are small too. Needs pillow.
"""
import argparse, glob, json, os

from PIL import Image


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("set")
    ap.add_argument("out")
    ap.add_argument("long", type=int, help="the longest side a photo keeps (px)")
    a = ap.parse_args()
    if a.long < 1:
        ap.error(f"LONG must be a positive number of pixels, not {a.long}")
    os.makedirs(a.out, exist_ok=True)
    written = 0
    for faces_path in sorted(glob.glob(os.path.join(a.set, "*.faces.json"))):
        stem = os.path.basename(faces_path)[: -len(".faces.json")]
        photos = [p for p in glob.glob(os.path.join(glob.escape(a.set), glob.escape(stem) + ".*"))
                  if p.lower().endswith((".jpg", ".jpeg", ".png", ".ppm"))]
        if not photos:
            continue
        img = Image.open(photos[0]).convert("RGB")
        k = min(1.0, a.long / max(img.size))
        if k < 1.0:
            img = img.resize((max(1, round(img.size[0] * k)), max(1, round(img.size[1] * k))), Image.LANCZOS)
        with open(faces_path) as f:
            meta = json.load(f)
        for face in meta["faces"]:
            face["box"] = [v * k for v in face["box"]]
            if face.get("landmarks"):
                face["landmarks"] = [[x * k, y * k] for x, y in face["landmarks"]]
        meta["source"] = f'{meta.get("source", "")}; shrunk by {k:.4f} (shrink_set.py)'
        img.save(os.path.join(a.out, stem + ".jpg"), quality=92)
        with open(os.path.join(a.out, stem + ".faces.json"), "w") as f:
            json.dump(meta, f, indent=1)
        written += 1
    print(f"{written} photos written to {a.out}")


if __name__ == "__main__":
    main()
