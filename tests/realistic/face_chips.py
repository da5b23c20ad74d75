#!/usr/bin/env python3
"""Face-recognition chips from a set: each face cut tight around its landmarks into a 150 x 150
square, so the outermost points (jaw, chin) lie about a pixel outside it, as recognition pipelines
crop them; beside it, the same chip with a border of the photo around it (BORDER chip pixels each
side, the same sampling grid). Both get truth.json and .pts for `gpmm eval recognition`, and a
detector/ directory when the set has one (the chip is cut around the detector's points, as a
pipeline would).

    python face_chips.py SET_DIR OUT_DIR [--identities 10] [--border 4]

writes OUT_DIR/chips and OUT_DIR/bordered.
"""
import argparse, copy, json, os
import numpy as np
from PIL import Image
from detect_landmarks import read_pts, write_pts  # the same directory

SIDE = 150


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("set_dir")
    ap.add_argument("out_dir")
    ap.add_argument("--identities", type=int, default=10)
    ap.add_argument("--border", type=int, default=4)
    a = ap.parse_args()
    truth = json.load(open(os.path.join(a.set_dir, "truth.json")))
    det_dir = os.path.join(a.set_dir, "detector")
    has_det = os.path.isdir(det_dir)
    outs = {name: os.path.join(a.out_dir, name) for name in ("chips", "bordered")}
    for d in outs.values():
        os.makedirs(os.path.join(d, "detector") if has_det else d, exist_ok=True)
    kept = {name: [] for name in outs}
    outside = 0
    for im in truth["images"]:
        if im["identity"] >= a.identities:
            continue
        det_file = os.path.join(det_dir, im["landmarks_file"])
        if has_det and not os.path.isfile(det_file):
            continue  # no detection: a pipeline would have no chip either
        exact = read_pts(os.path.join(a.set_dir, im["landmarks_file"]))
        cut_by = read_pts(det_file) if has_det else exact
        lo, hi = cut_by.min(0), cut_by.max(0)
        centre, e = (lo + hi) / 2, (hi - lo).max()
        # The outermost points fall a pixel outside: the box spans SIDE + 2 chip pixels.
        scale = (SIDE + 2) / e  # chip px per photo px
        img = Image.open(os.path.join(a.set_dir, im["image"])).convert("RGB")
        for name, border in (("chips", 0), ("bordered", a.border)):
            n = SIDE + 2 * border
            x0, y0 = centre - (SIDE / 2 + border) / scale
            box = (x0, y0, x0 + n / scale, y0 + n / scale)
            img.resize((n, n), Image.LANCZOS, box=box).save(os.path.join(outs[name], im["image"]))
            to_chip = lambda p: (p - [x0, y0]) * scale
            write_pts(os.path.join(outs[name], im["landmarks_file"]), to_chip(exact))
            if has_det:
                write_pts(os.path.join(outs[name], "detector", im["landmarks_file"]), to_chip(read_pts(det_file)))
            if border == 0:
                q = to_chip(cut_by)
                outside += int(((q < 0) | (q > SIDE)).any())
            c = copy.deepcopy(im)
            c.update(width=n, height=n, focal_px=im["focal_px"] * scale,
                     principal_px=list(to_chip(np.array(im["principal_px"]))), landmarks=to_chip(exact).tolist())
            kept[name].append(c)
    for name, d in outs.items():
        t = dict(truth, images=kept[name])
        json.dump(t, open(os.path.join(d, "truth.json"), "w"), indent=1)
    n = len(kept["chips"])
    print(f"{n} chips of {len({c['identity'] for c in kept['chips']})} identities; {outside} with a landmark outside the chip")


if __name__ == "__main__":
    main()
