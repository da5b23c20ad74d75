#!/usr/bin/env python3
"""How a set's landmark errors depend on the sun of its Mitsuba renders: per image, the mean
landmark error over the inter-ocular distance (outer eye corners) against the sun's component
toward the camera (recomputed from the set's truth.json and seed exactly as make_set.py draws it),
in bands, and per landmark group the error and the mean offset toward the lit side of the image.

    python sun_bias.py SET_DIR POINTS_DIR --seed 21     # the set's make_set.py --seed
"""
import argparse, json, os
import numpy as np
from detect_landmarks import GROUPS, read_pts  # the same directory
BANDS = ((-1.0, 0.3), (0.3, 0.6), (0.6, 0.85), (0.85, 1.01))


def sun_of(image, seed):
    """The sun direction make_set.py lit `image` with (camera frame, unit)."""
    rng = np.random.default_rng([seed, image["identity"], image["yaw_index"], 7])
    sun = np.array(image["light_direction"]) + rng.normal(0, 0.3, 3)
    return sun / np.linalg.norm(sun)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("set_dir")
    ap.add_argument("points_dir", help="a .pts per image, named as the set's")
    ap.add_argument("--seed", type=int, required=True, help="the seed make_set.py rendered the set with")
    a = ap.parse_args()
    truth = json.load(open(os.path.join(a.set_dir, "truth.json")))
    rows = []
    for im in truth["images"]:
        path = os.path.join(a.points_dir, im["landmarks_file"])
        if not os.path.exists(path):
            continue
        p, q = read_pts(path), read_pts(os.path.join(a.set_dir, im["landmarks_file"]))
        iod = np.linalg.norm(q[36] - q[45])
        sun = sun_of(im, a.seed)
        toward = np.array([sun[0], -sun[1]]) / (np.linalg.norm(sun[:2]) + 1e-9)  # image y points down
        err = np.linalg.norm(p - q, axis=1) / iod
        along = (p - q) @ toward / iod
        rows.append((sun[2], err.mean(), {g: (err[list(ix)].mean(), along[list(ix)].mean()) for g, ix in GROUPS.items()}))
    if not rows:
        raise SystemExit(f"no .pts of {a.set_dir}'s images in {a.points_dir}")
    z, e = np.array([r[0] for r in rows]), np.array([r[1] for r in rows])
    print(f"{len(rows)} images; correlation of the error with the sun's z: {np.corrcoef(z, e)[0, 1]:+.2f}")
    for lo, hi in BANDS:
        sel = [r for r in rows if lo <= r[0] < hi]
        if not sel:
            continue
        groups = "  ".join(
            f"{g} {np.median([r[2][g][0] for r in sel]):.3f} ({np.mean([r[2][g][1] for r in sel]):+.3f})" for g in GROUPS
        )
        print(f"sun_z [{lo:+.2f}, {hi:.2f}): {len(sel):3d} images, median {np.median([r[1] for r in sel]):.3f} | {groups}")
    print("(per group: median error / IOD, and in brackets the mean offset toward the lit side)")


if __name__ == "__main__":
    main()
