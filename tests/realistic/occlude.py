#!/usr/bin/env python3
"""Makes an occluded copy of a set with truth: each image gets one occluder drawn over the face
from its landmarks, and the occluder's footprint is written beside it as truth
(`NAME.occluder.png`: white where the occluder covers the photo).

Occluders, one per image in turn (a seeded choice of size, colour and place):
  glasses  dark lenses over both eyes, a bridge and arms
  hand     a skin-coloured palm and fingers over mouth and chin (the tone read from the cheeks)
  mask     a cloth mask or scarf over the lower face, folds and a pattern
  hair     dark strands across forehead and one eye
  patch    a rectangle of another photograph (from --photos) over part of the face
Each covers roughly 15-35 % of the landmarks' box; `occluders.json` lists the kind and the
fraction covered per image. truth.json and the exact .pts are copied unchanged (a detector's
points must be read again from the occluded images: detect_landmarks.py).

    python occlude.py SET_DIR OUT_DIR --photos DIR [--seed 3] [--kinds glasses,hand,mask,hair,patch]
"""
import argparse, glob, json, os, shutil
import numpy as np
from PIL import Image, ImageDraw, ImageFilter
from detect_landmarks import read_pts  # the same directory

SS = 4  # supersampling of the drawing


def center(pts, idx):
    return pts[idx].mean(axis=0)


def skin_tone(img, pts):
    """The median colour of two cheek patches (between the eye's outer corner and the mouth corner)."""
    samples = []
    for eye, mouth in ((36, 48), (45, 54)):
        c = (pts[eye] + pts[mouth]) / 2
        x, y = int(c[0]), int(c[1])
        patch = img[max(0, y - 2) : y + 3, max(0, x - 2) : x + 3].reshape(-1, 3)
        if len(patch):
            samples.append(patch)
    if not samples:
        return np.array([190, 150, 120], dtype=np.float64)
    return np.median(np.concatenate(samples), axis=0)


def layer(w, h):
    """A supersampled RGBA drawing surface."""
    im = Image.new("RGBA", (w * SS, h * SS), (0, 0, 0, 0))
    return im, ImageDraw.Draw(im)


def S(p):
    return tuple(float(v) * SS for v in p)


def glasses(w, h, pts, rng, img):
    im, d = layer(w, h)
    iod = np.linalg.norm(center(pts, range(42, 48)) - center(pts, range(36, 42)))
    lw, lh = iod * rng.uniform(0.75, 0.95), iod * rng.uniform(0.5, 0.65)
    shade = rng.uniform(10, 55)
    tint = np.array([1.0, 1.0, 1.0]) + rng.uniform(-0.2, 0.2, 3)
    col = tuple(int(np.clip(shade * t, 0, 255)) for t in tint) + (int(rng.uniform(235, 255)),)
    frame = tuple(int(v) for v in rng.uniform(5, 60, 3)) + (255,)
    for idx in (range(36, 42), range(42, 48)):
        c = center(pts, idx) + np.array([0, iod * 0.05])
        box = [S(c - [lw / 2, lh / 2]), S(c + [lw / 2, lh / 2])]
        d.rounded_rectangle(box, radius=lh * SS * 0.4, fill=col, outline=frame, width=max(1, int(iod * SS * 0.05)))
        # a highlight on the lens
        hl = c + np.array([-lw * 0.2, -lh * 0.2])
        d.ellipse([S(hl - [lw * 0.08, lh * 0.06]), S(hl + [lw * 0.08, lh * 0.06])], fill=(200, 200, 210, 90))
    l, r = center(pts, range(36, 42)), center(pts, range(42, 48))
    d.line([S(l + [lw / 2, 0]), S(r - [lw / 2, 0])], fill=frame, width=max(1, int(iod * SS * 0.06)))
    d.line([S(l - [lw / 2, 0]), S(pts[0] + [0, -iod * 0.1])], fill=frame, width=max(1, int(iod * SS * 0.06)))
    d.line([S(r + [lw / 2, 0]), S(pts[16] + [0, -iod * 0.1])], fill=frame, width=max(1, int(iod * SS * 0.06)))
    return im


def hand(w, h, pts, rng, img):
    im, d = layer(w, h)
    tone = skin_tone(img, pts) * rng.uniform(0.9, 1.15) + rng.uniform(-12, 12, 3)
    col = tuple(int(v) for v in np.clip(tone, 0, 255)) + (255,)
    dark = tuple(int(v) for v in np.clip(tone * 0.75, 0, 255)) + (255,)
    iod = np.linalg.norm(pts[45] - pts[36])
    mouth = center(pts, range(48, 68))
    palm = mouth + np.array([rng.uniform(-0.3, 0.3) * iod, iod * rng.uniform(0.25, 0.45)])
    pw, ph = iod * rng.uniform(0.6, 0.75), iod * rng.uniform(0.4, 0.5)
    d.ellipse([S(palm - [pw, ph]), S(palm + [pw, ph])], fill=col)
    side = rng.choice([-1, 1])
    for k in range(4):
        y = palm[1] - ph * 0.75 + k * ph * 0.45
        x0, x1 = palm[0], palm[0] + side * iod * rng.uniform(1.0, 1.25)
        fw = iod * 0.16
        d.rounded_rectangle([S((min(x0, x1), y - fw / 2)), S((max(x0, x1), y + fw / 2))], radius=fw * SS / 2, fill=col, outline=dark)
    return im.filter(ImageFilter.GaussianBlur(SS * 0.4))


def mask(w, h, pts, rng, img):
    im, d = layer(w, h)
    base = rng.uniform(30, 230, 3)
    col = tuple(int(v) for v in base) + (255,)
    nose = pts[30] if rng.random() < 0.5 else pts[33]
    poly = [S(pts[1]), S(nose + [-(pts[30][0] - pts[1][0]) * 0.3, 0]), S(nose), S(nose + [(pts[15][0] - pts[30][0]) * 0.3, 0]), S(pts[15])]
    poly += [S(pts[i] + [0, 2]) for i in range(14, 1, -1)]
    d.polygon(poly, fill=col)
    # folds: darker horizontal bands
    top, bottom = nose[1], pts[8][1]
    for k in range(1, 4):
        y = top + (bottom - top) * k / 4
        shade = tuple(int(v * 0.7) for v in base) + (120,)
        d.line([S((pts[2][0], y)), S((pts[14][0], y))], fill=shade, width=max(1, int(SS * 1.5)))
    return im.filter(ImageFilter.GaussianBlur(SS * 0.3))


def hair(w, h, pts, rng, img):
    im, d = layer(w, h)
    base = rng.uniform(10, 90)
    col = np.array([base * 1.1, base * 0.9, base * 0.7])
    iod = np.linalg.norm(pts[45] - pts[36])
    side = rng.choice([0, 1])
    eye = center(pts, range(36, 42) if side == 0 else range(42, 48))
    top = center(pts, range(17, 27)) - np.array([0, iod * 0.6])
    for k in range(int(rng.integers(9, 15))):
        start = top + np.array([rng.uniform(-0.9, 0.9) * iod, rng.uniform(-0.2, 0.1) * iod])
        end = eye + np.array([rng.uniform(-0.7, 0.7) * iod, rng.uniform(0.0, 0.9) * iod])
        mid = (start + end) / 2 + rng.uniform(-0.3, 0.3, 2) * iod
        line = [S((1 - t) ** 2 * start + 2 * (1 - t) * t * mid + t**2 * end) for t in np.linspace(0, 1, 20)]
        c = tuple(int(v) for v in np.clip(col * rng.uniform(0.8, 1.3), 0, 255)) + (255,)
        d.line(line, fill=c, width=max(1, int(SS * iod * rng.uniform(0.06, 0.14))), joint="curve")
    return im.filter(ImageFilter.GaussianBlur(SS * 0.3))


def patch(w, h, pts, rng, img, photos):
    im, _ = layer(w, h)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    bw, bh = hi - lo
    pw, ph = bw * rng.uniform(0.45, 0.6), bh * rng.uniform(0.45, 0.6)
    x = rng.uniform(lo[0] - pw * 0.2, hi[0] - pw * 0.8)
    y = rng.uniform(lo[1], hi[1] - ph * 0.8)
    src = Image.open(photos[int(rng.integers(len(photos)))]).convert("RGB")
    sw, sh = src.size
    cw = int(min(sw, sh) * rng.uniform(0.2, 0.5))
    ch = int(cw * ph / pw)
    cx, cy = int(rng.integers(0, max(1, sw - cw))), int(rng.integers(0, max(1, sh - ch)))
    piece = src.crop((cx, cy, cx + cw, cy + max(1, ch))).resize((max(1, int(pw * SS)), max(1, int(ph * SS))), Image.BILINEAR)
    im.paste(piece.convert("RGBA"), (int(x * SS), int(y * SS)))
    return im


KINDS = {"glasses": glasses, "hand": hand, "mask": mask, "hair": hair, "patch": patch}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("set_dir")
    ap.add_argument("out_dir")
    ap.add_argument("--photos", help="folder of photographs (jpg/png) the patches are cut from", required=True)
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--kinds", default="glasses,hand,mask,hair,patch")
    a = ap.parse_args()
    kinds = a.kinds.split(",")
    for k in kinds:
        if k not in KINDS:
            ap.error(f"unknown occluder {k!r}: one of {', '.join(KINDS)}")
    photos = sorted(p for p in glob.glob(os.path.join(a.photos, "**", "*"), recursive=True) if p.lower().endswith((".jpg", ".jpeg", ".png")))
    if "patch" in kinds and not photos:
        ap.error(f"no photographs (jpg/png) in {a.photos}")
    truth = json.load(open(os.path.join(a.set_dir, "truth.json")))
    rng = np.random.default_rng(a.seed)
    os.makedirs(a.out_dir, exist_ok=True)
    shutil.copy(os.path.join(a.set_dir, "truth.json"), os.path.join(a.out_dir, "truth.json"))
    listing = []
    for i, entry in enumerate(truth["images"]):
        name = entry["image"]
        pts_file = entry["landmarks_file"]
        pts = read_pts(os.path.join(a.set_dir, pts_file))
        src = Image.open(os.path.join(a.set_dir, name)).convert("RGB")
        img = np.asarray(src).astype(np.float64)
        w, h = src.size
        kind = kinds[i % len(kinds)]
        draw = KINDS[kind]
        big = draw(w, h, pts, rng, img, photos) if kind == "patch" else draw(w, h, pts, rng, img)
        occ = big.resize((w, h), Image.BOX)
        out = Image.alpha_composite(src.convert("RGBA"), occ).convert("RGB")
        out.save(os.path.join(a.out_dir, name))
        alpha = np.asarray(occ)[:, :, 3] > 127
        Image.fromarray((alpha * 255).astype(np.uint8)).save(os.path.join(a.out_dir, os.path.splitext(name)[0] + ".occluder.png"))
        shutil.copy(os.path.join(a.set_dir, pts_file), os.path.join(a.out_dir, pts_file))
        lo, hi = np.floor(pts.min(axis=0)).astype(int), np.ceil(pts.max(axis=0)).astype(int)
        box = alpha[max(0, lo[1]) : hi[1], max(0, lo[0]) : hi[0]]
        listing.append({"image": name, "occluder": kind, "box_fraction": float(box.mean()) if box.size else 0.0})
    json.dump({"format": "gpmm-occluders", "version": 1, "seed": a.seed, "images": listing}, open(os.path.join(a.out_dir, "occluders.json"), "w"), indent=1)
    fr = np.array([e["box_fraction"] for e in listing])
    for k in kinds:
        sel = [e["box_fraction"] for e in listing if e["occluder"] == k]
        if sel:
            print(f"{k}: {len(sel)} images, median {np.median(sel):.2f} of the landmarks' box")
    print(f"{len(listing)} images, median {np.median(fr):.2f} of the landmarks' box covered")


if __name__ == "__main__":
    main()
