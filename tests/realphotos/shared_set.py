#!/usr/bin/env python3
"""The project's shared photos as a real-photo detection set (a report-only check).

    python shared_set.py OUT [--data DIR]

Each photo of DATA/images with one or more .pts files (STEM.pts, or STEM_0.pts, STEM_1.pts, ...
for several faces) is copied to OUT with STEM.faces.json: per face the landmarks' box as the
reference box and the 68 points (the 300-W asset takeo.pts counts from one and is shifted to
the convention of .pts files read by gpmm). `gpmm eval detect OUT --init INIT` then scores it.
Standard library only.
"""
import argparse, glob, json, os, re, shutil, sys


def read_pts(path):
    text = open(path).read()
    body = text[text.index("{") + 1:text.index("}")]
    return [[float(v) for v in line.split()] for line in body.strip().splitlines() if line.strip()]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out")
    ap.add_argument("--data", default=os.environ.get("GPMM_DATA", os.path.join("..", "shared", "data")))
    a = ap.parse_args()
    images = os.path.join(a.data, "images")
    os.makedirs(a.out, exist_ok=True)
    stems = {}
    for pts in sorted(glob.glob(os.path.join(images, "*.pts"))):
        stem = re.sub(r"_\d+$", "", os.path.splitext(os.path.basename(pts))[0])
        stems.setdefault(stem, []).append(pts)
    if not stems:
        sys.exit(f"{images}: no .pts files")
    for stem, files in stems.items():
        photo = next((p for p in glob.glob(os.path.join(images, stem + ".*")) if not p.endswith(".pts")), None)
        if photo is None:
            print(f"warning: {stem}: no photo beside its .pts; left out", file=sys.stderr)
            continue
        shift = 1.0 if photo.endswith(".ppm") else 0.0  # the 300-W asset counts pixels from one
        faces = []
        for f in files:
            p = [[x - shift, y - shift] for x, y in read_pts(f)]
            xs, ys = [q[0] for q in p], [q[1] for q in p]
            faces.append({"box": [min(xs), min(ys), max(xs), max(ys)], "landmarks": p if len(p) == 68 else None})
        shutil.copyfile(photo, os.path.join(a.out, os.path.basename(photo)))
        meta = {"source": f"the project's shared photos ({os.path.basename(photo)})",
                "reference": "the .pts files beside the photo (detector-made or manual, README of the data)", "faces": faces}
        json.dump(meta, open(os.path.join(a.out, stem + ".faces.json"), "w"), indent=1)
        print(f"{stem}: {len(faces)} face(s)")


if __name__ == "__main__":
    main()
