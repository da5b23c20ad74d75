#!/usr/bin/env python3
"""The finder's best box (`gpmm detect`) on a faces.json set: a quick score for init files.

    python best_box.py SET_DIR --init A.init [--init B.init ...] [--gpmm target/release/gpmm]

Per init file: of the photos with reference faces, how often the best box is on one of them (IoU
>= 0.5 with the square box of that face's reference landmarks, the finder's own box definition:
centre and larger side of the landmarks' box), the median and 90th percentile landmark error of
those hits (mean point distance over the reference's outer-eye-corner distance, points 36 and 45),
and on face-free photos how many get a box scored >= 0.5 (and >= 0.05, `gpmm detect`'s default).
Needs only the standard library. `gpmm eval detect` scores every face once detection reports them all.
"""
import argparse, json, math, os, subprocess


def square(cx, cy, size):
    """A square box [x0, y0, x1, y1] of side SIZE centred on (CX, CY)."""
    return [cx - size / 2, cy - size / 2, cx + size / 2, cy + size / 2]


def landmark_square(points):
    """The finder's box of a face: centre and larger side of its landmarks' bounding box."""
    xs, ys = [p[0] for p in points], [p[1] for p in points]
    return square((min(xs) + max(xs)) / 2, (min(ys) + max(ys)) / 2, max(max(xs) - min(xs), max(ys) - min(ys)))


def iou(a, b):
    """Intersection over union of two [x0, y0, x1, y1] boxes."""
    ix = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    iy = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - ix * iy
    return ix * iy / union if union > 0 else 0.0


def quantile(values, q):
    """The q-quantile of VALUES (nearest rank), NaN when empty."""
    v = sorted(values)
    return v[min(len(v) - 1, int(q * len(v)))] if v else float("nan")


def score(gpmm, init, set_dir):
    """The figures of one init file on one set."""
    faces_total, hits, errors, free, fp50, fp05, misses = 0, 0, [], 0, 0, 0, []
    for name in sorted(os.listdir(set_dir)):
        if not name.endswith(".faces.json"):
            continue
        stem = name[: -len(".faces.json")]
        image = next(os.path.join(set_dir, stem + e) for e in (".jpg", ".png", ".ppm") if os.path.exists(os.path.join(set_dir, stem + e)))
        ref = json.load(open(os.path.join(set_dir, name)))["faces"]
        out = subprocess.run([gpmm, "detect", "--init", init, image], capture_output=True, text=True)
        if out.returncode != 0:
            raise SystemExit(f"{image}: gpmm detect failed: {out.stderr.strip()}")
        det = json.loads(out.stdout)
        box = det.get("box") if isinstance(det, dict) else None
        if not ref:
            free += 1
            s = box["score"] if box else 0.0
            fp50 += s >= 0.5
            fp05 += s >= 0.05
            continue
        marked = [f for f in ref if f.get("landmarks")]
        if not marked:
            continue
        faces_total += 1
        found = box and max(((iou(square(box["cx"], box["cy"], box["size"]), landmark_square(f["landmarks"])), f) for f in marked), key=lambda t: t[0])
        if found and found[0] >= 0.5:
            hits += 1
            pts, ref_pts = det["landmarks"], found[1]["landmarks"]
            iod = math.dist(ref_pts[36], ref_pts[45])
            errors.append(sum(math.dist(p, q) for p, q in zip(pts, ref_pts)) / len(ref_pts) / iod)
        else:
            misses.append(stem)
    return {"photos_with_faces": faces_total, "best_box_on_a_face": hits, "landmark_error_median": round(quantile(errors, 0.5), 3),
            "landmark_error_p90": round(quantile(errors, 0.9), 3), "face_free_photos": free, "face_free_with_box_score_0.5": fp50,
            "face_free_with_box_score_0.05": fp05, "missed": misses}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("set_dir")
    ap.add_argument("--init", action="append", required=True)
    ap.add_argument("--gpmm", default="target/release/gpmm")
    a = ap.parse_args()
    print(json.dumps({init: score(a.gpmm, init, a.set_dir) for init in a.init}, indent=1))


if __name__ == "__main__":
    main()
