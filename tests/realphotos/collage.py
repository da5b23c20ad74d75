#!/usr/bin/env python3
"""A collage of portraits: one photo of many faces, from the one-face photos of a real-photo set.

    python collage.py SET OUT_DIR [--count 25] [--tile 200] [--seed 0]

takes the photos of SET (the faces.json format of make_set.py, README.md beside this script) that
hold exactly one face with points of at least 64 px, picks COUNT of them at random (SEED), cuts a
square of twice the face's box around each face, and lays them in a grid of TILE-px cells: a
group photo whose every face is known. Writes OUT_DIR/collage.jpg and OUT_DIR/collage.faces.json
(each face's box and 68 points moved into the collage), so `gpmm eval detect OUT_DIR` scores it and
`gpmm fit MODEL OUT_DIR/collage.jpg --faces all` fits it. Needs pillow.
"""
import argparse, glob, json, math, os, random

from PIL import Image


def one_face_photos(folder):
    """(photo path, face) of the set's photos with exactly one face, with points, of 64 px or more."""
    found = []
    for meta_path in sorted(glob.glob(os.path.join(folder, "*.faces.json"))):
        faces = json.load(open(meta_path))["faces"]
        if len(faces) != 1 or faces[0].get("landmarks") is None:
            continue
        x0, y0, x1, y1 = faces[0]["box"]
        if max(x1 - x0, y1 - y0) < 64:
            continue
        stem = meta_path[: -len(".faces.json")]
        photo = next((stem + ext for ext in (".jpg", ".png", ".jpeg") if os.path.isfile(stem + ext)), None)
        if photo:
            found.append((photo, faces[0]))
    return found


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("set")
    ap.add_argument("out")
    ap.add_argument("--count", type=int, default=25)
    ap.add_argument("--tile", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    photos = one_face_photos(a.set)
    if len(photos) < a.count:
        raise SystemExit(f"{a.set}: {len(photos)} one-face photos of 64 px or more, {a.count} asked for")
    chosen = random.Random(a.seed).sample(photos, a.count)
    side = math.ceil(math.sqrt(a.count))
    rows = math.ceil(a.count / side)
    collage = Image.new("RGB", (side * a.tile, rows * a.tile), (128, 128, 128))
    faces, sources = [], []
    for i, (path, face) in enumerate(chosen):
        x0, y0, x1, y1 = face["box"]
        cx, cy, half = (x0 + x1) / 2, (y0 + y1) / 2, max(x1 - x0, y1 - y0)
        scale = a.tile / (2 * half)
        crop = Image.open(path).convert("RGB").crop((round(cx - half), round(cy - half), round(cx + half), round(cy + half)))
        ox, oy = (i % side) * a.tile, (i // side) * a.tile
        collage.paste(crop.resize((a.tile, a.tile), Image.LANCZOS), (ox, oy))
        move = lambda x, y: [round(ox + (x - (round(cx - half))) * scale, 2), round(oy + (y - (round(cy - half))) * scale, 2)]
        faces.append({"box": move(x0, y0) + move(x1, y1), "score": face.get("score"),
                      "landmarks": [move(x, y) for x, y in face["landmarks"]]})
        sources.append(os.path.basename(path))
    os.makedirs(a.out, exist_ok=True)
    collage.save(os.path.join(a.out, "collage.jpg"), quality=92)
    meta = {"source": f"collage of {a.count} one-face photos of {os.path.abspath(a.set)} (seed {a.seed}): {', '.join(sources)}",
            "reference": "the set's own reference faces, moved into the collage", "faces": faces}
    with open(os.path.join(a.out, "collage.faces.json"), "w") as f:
        json.dump(meta, f, indent=1)
    print(f"{a.out}/collage.jpg: {a.count} faces of {a.tile // 2} px in a {side} x {rows} grid")


if __name__ == "__main__":
    main()
