"""How much of a face's identity a landmark detector's points carry.

For each yaw of a `gpmm synth` set (or a set re-rendered by make_set.py) this aligns every
identity's true 68 points and the detector's 68 points to the yaw's mean shape (similarity
Procrustes), takes each identity's deviation from that mean (what tells one face from another
in the 2-D points), and regresses the detector's deviation on the true one, in inter-ocular
distances: a slope of 1 and a correlation of 1 would mean the detector sees every identity
difference; a slope below 1 means it pulls faces toward its own average face. Per face region
and over all points.

Usage: python detector_identity.py SET_DIR [DETECTOR_DIR]   (default DETECTOR_DIR: SET_DIR/detector)
Prints a Markdown table. Needs numpy.
"""

import re
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

REGIONS = {"jaw": range(0, 17), "brows": range(17, 27), "nose": range(27, 36), "eyes": range(36, 48), "mouth": range(48, 68)}


def read_pts(path):
    """The points of an iBUG .pts file (the lines between the braces)."""
    text = Path(path).read_text()
    body = text[text.index("{") + 1 : text.index("}")]
    return np.array([[float(v) for v in line.split()] for line in body.strip().splitlines()])


def aligned(points, reference):
    """`points` moved onto `reference` by the least-squares similarity (centred)."""
    a = points - points.mean(0)
    b = reference - reference.mean(0)
    u, s, vt = np.linalg.svd(a.T @ b)
    return (s.sum() / (a**2).sum()) * a @ (u @ vt)


def slope_and_r(true_dev, det_dev):
    """Least-squares slope (detector on truth, through 0) and the correlation."""
    x, z = true_dev.ravel(), det_dev.ravel()
    return (x @ z) / (x @ x), (x @ z) / np.sqrt((x @ x) * (z @ z))


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    set_dir = Path(sys.argv[1])
    det_dir = Path(sys.argv[2]) if len(sys.argv) > 2 else set_dir / "detector"
    by_yaw = defaultdict(list)
    for truth in sorted(set_dir.glob("*.pts")):
        m = re.search(r"_yaw(-?\d+)\.pts$", truth.name)
        detected = det_dir / truth.name
        if not m or not detected.is_file():
            continue
        t, d = read_pts(truth), read_pts(detected)
        if t.shape == (68, 2) and d.shape == (68, 2) and np.isfinite(d).all():
            by_yaw[int(m.group(1))].append((t, d))
    if not by_yaw:
        sys.exit(f"no pairs of 68-point .pts files in {set_dir} and {det_dir}")
    print("| yaw | faces | all: slope, r | " + " | ".join(f"{k}: slope, r" for k in REGIONS) + " |")
    print("|---|---|---|" + "---|" * len(REGIONS))
    for yaw in sorted(by_yaw):
        pairs = by_yaw[yaw]
        truths = np.array([t for t, _ in pairs])
        reference = truths.mean(0)
        for _ in range(3):
            truths_a = np.array([aligned(t, reference) for t in truths])
            reference = truths_a.mean(0)
        iod = np.linalg.norm(reference[45] - reference[36])
        det_a = np.array([aligned(d, reference) for _, d in pairs]) / iod
        truths_a = truths_a / iod
        true_dev, det_dev = truths_a - truths_a.mean(0), det_a - det_a.mean(0)
        cells = [slope_and_r(true_dev, det_dev)]
        cells += [slope_and_r(true_dev[:, list(r)], det_dev[:, list(r)]) for r in REGIONS.values()]
        print(f"| {yaw} | {len(pairs)} | " + " | ".join(f"{s:.2f}, {r:.2f}" for s, r in cells) + " |")


if __name__ == "__main__":
    main()
