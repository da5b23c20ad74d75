#!/usr/bin/env python3
"""Photos fitted with several models, side by side: one row per face, for each model the fit drawn
into the photo and the fitted face rendered frontal and at 45 degrees.

    python fits_side_by_side.py OUT.png --model A.gpmm --model B.gpmm [--name A --name B]
        [--gpmm gpmm] [--data DIR] [--work DIR]

Every photo of DATA/images with a .pts beside it (one row per .pts: two_people_0.pts and
two_people_1.pts are two rows of two_people.jpg) is fitted with `gpmm fit MODEL PHOTO --landmarks
PTS` at its defaults; the fitted shape and colour coefficients are rendered with `gpmm render`
under an ambient light. Prints each fit's landmark and pixel RMSE as a Markdown table. Needs
Pillow (the venv of tests/realistic has it).
"""
import argparse, glob, json, os, subprocess, sys, tempfile

from PIL import Image, ImageDraw

CELL = 160


def photos(data):
    """(name, image, pts, one-based) of every landmarked photo of DATA/images."""
    rows = []
    for pts in sorted(glob.glob(os.path.join(data, "images", "*.pts"))):
        stem = os.path.splitext(os.path.basename(pts))[0]
        base = stem.rsplit("_", 1)[0] if stem[-2:-1] == "_" and stem[-1].isdigit() else stem
        image = next((p for p in glob.glob(os.path.join(data, "images", base + ".*")) if not p.endswith(".pts")), None)
        if image is None:
            print(f"warning: {pts}: no photo {base}.* beside it; left out", file=sys.stderr)
            continue
        rows.append((stem, image, pts, image.endswith(".ppm")))  # the 300-W asset counts from one
    return rows


def run(cmd):
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed:\n{r.stderr}")
    return r.stdout


def fitted(gpmm, model, image, pts, one_based, out):
    """fit.json of one fit, and three CELL-sized pictures: the fit over the photo, frontal, 45 degrees."""
    cmd = [gpmm, "fit", model, image, "--landmarks", pts, "-o", out]
    run(cmd + (["--pts-one-based"] if one_based else []))
    fit = json.load(open(os.path.join(out, "fit.json")))
    overlay = Image.open(os.path.join(out, "overlay.png")).convert("RGB")
    w, h = overlay.size
    third = w // 3
    blend = overlay.crop((2 * third, 14, w, h)).resize((CELL, CELL))  # the third panel, under its title
    views = []
    for yaw in (0, 45):
        png = os.path.join(out, f"yaw{yaw}.png")
        run([gpmm, "render", model, "-o", png, "--size", f"{CELL}x{CELL}", "--yaw", str(yaw), "--light", "frontal",
             "--shape", ",".join(f"{c:.5f}" for c in fit["shape"]), "--color", ",".join(f"{c:.5f}" for c in fit["color"])])
        views.append(Image.open(png).convert("RGB"))
    return fit, [blend] + views


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out")
    ap.add_argument("--model", action="append", required=True)
    ap.add_argument("--name", action="append", default=[])
    ap.add_argument("--gpmm", default="gpmm")
    ap.add_argument("--data", default=os.environ.get("GPMM_DATA", os.path.join("..", "shared", "data")))
    ap.add_argument("--work", default=None, help="keep the fits here (default: a temporary folder)")
    a = ap.parse_args()
    names = a.name + [os.path.splitext(os.path.basename(m))[0] for m in a.model[len(a.name):]]
    rows = photos(a.data)
    if not rows:
        sys.exit(f"{a.data}/images: no photo with a .pts")
    work = a.work or tempfile.mkdtemp(prefix="gpmm-side-")
    head = 18
    sheet = Image.new("RGB", (CELL * (1 + 3 * len(a.model)), head + CELL * len(rows)), (24, 24, 24))
    draw = ImageDraw.Draw(sheet)
    draw.text((4, 3), "photo", fill=(230, 230, 230))
    for m, name in enumerate(names):
        draw.text((CELL * (1 + 3 * m) + 4, 3), f"{name}: fit, frontal, 45 deg", fill=(230, 230, 230))
    print("| photo | " + " | ".join(f"{n} landmark / pixel RMSE" for n in names) + " |")
    print("|---|" + "---|" * len(names))
    for r, (stem, image, pts, one_based) in enumerate(rows):
        cells, figures = [], []
        for m, model in enumerate(a.model):
            fit, pics = fitted(a.gpmm, model, image, pts, one_based, os.path.join(work, f"{stem}-{m}"))
            if m == 0:
                c = fit["crop"]
                photo = Image.open(image).convert("RGB").crop((c["x"], c["y"], c["x"] + c["side"], c["y"] + c["side"]))
                cells.append(photo.resize((CELL, CELL)))
            cells += pics
            figures.append(f"{fit['landmark_rmse_px']:.2f} px / {fit['pixel_rmse']:.4f}")
        for k, pic in enumerate(cells):
            sheet.paste(pic, (k * CELL, head + r * CELL))
        print(f"| {stem} | " + " | ".join(figures) + " |")
    sheet.save(a.out)
    print(f"wrote {a.out}", file=sys.stderr)


if __name__ == "__main__":
    main()
