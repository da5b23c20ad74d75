#!/usr/bin/env python3
"""Face-free photographs for `gpmm train-init --backgrounds DIR`, from Debian's wallpaper packages.

    python backgrounds.py OUT [--cache DIR] [--packages P ...]

downloads PACKAGES with `apt-get download` (nothing is installed), takes one picture per
wallpaper (the size closest to 1920 px wide), scales it to at most 1024 px on its longer side,
and keeps it only if MediaPipe's face detector (make_set.py's, whole picture and tiles) finds no
face in it. Writes OUT/NAME.jpg, each package's Debian copyright file as OUT/PACKAGE.copyright,
and OUT/sources.json (every picture kept or dropped, with its package). Run with the venv of
tests/realistic (mediapipe, pillow). These packages give no photo to the real-photo sets of
make_set.py: training never sees the photos it is scored on.
"""
import argparse, json, os, re, shutil, sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import make_set  # noqa: E402  (fetching packages and the reference face detector)

PACKAGES = ["plasma-workspace-wallpapers", "mate-backgrounds", "ukui-wallpapers"]
# Face-free pictures no training command uses: the face-free half of the unseen tuning photos
# (docs/real-photos.md), made with --packages.
HELD_PACKAGES = ["lomiri-wallpapers", "lomiri-wallpapers-16.04", "lomiri-wallpapers-20.04",
                 "sway-backgrounds"]
LONGER_SIDE = 1024


def pictures(tree):
    """(name, path) of one picture per wallpaper under an extracted package TREE."""
    found = {}
    for root, _, files in os.walk(tree):
        for f in files:
            if not f.lower().endswith((".jpg", ".jpeg", ".png")) or "screenshot" in f.lower():
                continue
            path = os.path.join(root, f)
            if os.path.islink(path):
                continue
            m = re.search(r"wallpapers/([^/]+)/contents/images(_dark)?/(\d+)x(\d+)", path)
            if m:  # Plasma: one folder per wallpaper, one file per screen size
                key, width = m.group(1) + (m.group(2) or ""), int(m.group(3))
            else:
                # MATE: NAME.jpg and NAME_WxH.jpg are one picture at several sizes.
                sized = re.match(r"(.+)_(\d+)x(\d+)$", os.path.splitext(f)[0])
                key, width = (sized.group(1), int(sized.group(2))) if sized else (os.path.splitext(f)[0], 1920)
            best = found.get(key)
            if best is None or abs(width - 1920) < abs(best[0] - 1920):
                found[key] = (width, path)
    return sorted((k, p) for k, (_, p) in found.items())


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out")
    ap.add_argument("--cache", default=None, help="where downloads are kept (default OUT/downloads)")
    ap.add_argument("--packages", nargs="+", default=PACKAGES,
                    help=f"Debian packages to take pictures from (default: {' '.join(PACKAGES)}; the held-out "
                         f"pictures for tuning false positives: {' '.join(HELD_PACKAGES)})")
    a = ap.parse_args()
    from PIL import Image
    cache = a.cache or os.path.join(a.out, "downloads")
    os.makedirs(a.out, exist_ok=True)
    report = {"packages": {}, "kept": [], "dropped": []}
    for package in a.packages:
        deb = make_set.fetch("deb", package, cache)
        tree = deb + ".files"
        if not os.path.isdir(tree):
            make_set.subprocess.run(["dpkg-deb", "-x", deb, tree], check=True)
        report["packages"][package] = os.path.basename(deb)
        copyright_file = os.path.join(tree, "usr/share/doc", package, "copyright")
        if os.path.isfile(copyright_file):
            shutil.copyfile(copyright_file, os.path.join(a.out, package + ".copyright"))
        for key, path in pictures(tree):
            img = Image.open(path).convert("RGB")
            scale = LONGER_SIDE / max(img.size)
            if scale < 1:
                img = img.resize((round(img.width * scale), round(img.height * scale)), Image.LANCZOS)
            name = re.sub(r"[^A-Za-z0-9_-]", "_", f"{package.split('-')[0]}_{key}")
            entry = {"name": name + ".jpg", "package": package, "file": os.path.relpath(path, tree)}
            boxes = make_set.detect_boxes(img)
            if boxes:
                entry["faces"] = [round(s, 2) for s, _ in boxes]
                report["dropped"].append(entry)
                print(f"dropped {entry['file']}: the detector finds {len(boxes)} face(s)", file=sys.stderr)
                continue
            img.save(os.path.join(a.out, name + ".jpg"), quality=92)
            report["kept"].append(entry)
    json.dump(report, open(os.path.join(a.out, "sources.json"), "w"), indent=1)
    print(f"{len(report['kept'])} face-free pictures in {a.out}, {len(report['dropped'])} dropped")


if __name__ == "__main__":
    main()
