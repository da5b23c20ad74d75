#!/usr/bin/env python3
"""Landmarks from a real detector (MediaPipe face mesh, 468 points) as iBUG-68 `.pts` files.

MediaPipe's points are not iBUG's, so a 468 -> 68 correspondence is needed. It is learned, not
hand-written: on a *calibration* set (made with another seed than any set it is used on), each
iBUG point takes the MediaPipe point closest to it on average over the frontal images. Then:

    python detect_landmarks.py calibrate CALIB_DIR -o mapping.json
    python detect_landmarks.py detect SET_DIR --mapping mapping.json -o SET_DIR/detector

`detect` writes NAME.pts (iBUG-68, 0-based pixel coordinates, centres at +0.5) for every image
of SET_DIR/truth.json where a face is found, and prints the RMSE to the exact landmarks and the
images with no detection (they are left out: gpmm bench-fit reports them as failed fits).
"""
import argparse, json, os, sys
import numpy as np

UPSCALE = 4  # MediaPipe wants faces larger than 128 px
# The iBUG-68 landmark groups, for per-group figures.
GROUPS = {"jaw": range(0, 17), "brows": range(17, 27), "nose": range(27, 36), "eyes": range(36, 48), "mouth": range(48, 68)}


def mesh_points(path):
    from PIL import Image
    return mesh_points_of(Image.open(path).convert("RGB"))


def mesh_points_of(img):
    """The 468 face-mesh points of the one face in a PIL RGB image, or None."""
    import mediapipe as mp  # only here: reading and writing .pts needs numpy alone
    from PIL import Image
    w, h = img.size
    up = UPSCALE if max(w, h) < 400 else 1  # photos are large enough as they are
    big = np.asarray(img.resize((w * up, h * up), Image.BICUBIC))
    with mp.solutions.face_mesh.FaceMesh(static_image_mode=True, max_num_faces=1, refine_landmarks=False) as fm:
        r = fm.process(big)
    if not r.multi_face_landmarks:
        return None
    # Normalized [0, 1] image coordinates -> 0-based continuous pixels of the original image.
    return np.array([[p.x * w, p.y * h] for p in r.multi_face_landmarks[0].landmark])


def load_mapping(path):
    """The iBUG-68 <- MediaPipe-468 index list that `calibrate` wrote to PATH."""
    return json.load(open(path))["ibug68_from_mediapipe"]


def read_pts(path):
    lines = open(path).read().split("{")[1].split("}")[0].split()
    return np.array(lines, dtype=np.float64).reshape(-1, 2)


def write_pts(path, pts):
    with open(path, "w") as f:
        f.write(f"version: 1\nn_points:  {len(pts)}\n{{\n")
        for x, y in pts:
            f.write(f"{x:.3f} {y:.3f}\n")
        f.write("}\n")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("calibrate")
    c.add_argument("dir")
    c.add_argument("-o", "--output", required=True)
    d = sub.add_parser("detect")
    d.add_argument("dir")
    d.add_argument("--mapping", required=True)
    d.add_argument("-o", "--output", required=True)
    p = sub.add_parser("photos", help="every .png/.jpg of DIR: NAME.pts in OUTPUT (RMSE to DIR/NAME.pts when present)")
    p.add_argument("dir")
    p.add_argument("--mapping", required=True)
    p.add_argument("-o", "--output", required=True)
    a = ap.parse_args()
    if a.cmd == "photos":
        mapping = load_mapping(a.mapping)
        os.makedirs(a.output, exist_ok=True)
        report = {}
        for name in sorted(os.listdir(a.dir)):
            stem, ext = os.path.splitext(name)
            if ext.lower() not in (".png", ".jpg", ".jpeg"):
                continue
            mp_pts = mesh_points(os.path.join(a.dir, name))
            if mp_pts is None:
                report[name] = "no face found"
                continue
            pts = mp_pts[mapping]
            write_pts(os.path.join(a.output, stem + ".pts"), pts)
            given = os.path.join(a.dir, stem + ".pts")
            if os.path.exists(given):
                ref = read_pts(given)
                iod = np.linalg.norm(ref[36] - ref[45])
                report[name] = {"mean_error_px": float(np.linalg.norm(pts - ref, axis=1).mean()),
                                "mean_error_iod_pct": float(100 * np.linalg.norm(pts - ref, axis=1).mean() / iod)}
            else:
                report[name] = "detected"
        print(json.dumps(report, indent=1))
        return
    truth = json.load(open(os.path.join(a.dir, "truth.json")))
    if a.cmd == "calibrate":
        acc, n = np.zeros((68, 468)), 0
        for im in truth["images"]:
            if abs(im["yaw_deg"]) > 1:
                continue
            mp_pts = mesh_points(os.path.join(a.dir, im["image"]))
            if mp_pts is None:
                continue
            exact = np.array(im["landmarks"])
            acc += np.linalg.norm(exact[:, None, :] - mp_pts[None, :, :], axis=2)
            n += 1
        if n == 0:
            sys.exit("no frontal image with a detection in the calibration set")
        mapping = acc.argmin(axis=1).tolist()
        json.dump({"detector": "mediapipe face_mesh 468", "frontal_images": n, "ibug68_from_mediapipe": mapping}, open(a.output, "w"), indent=1)
        print(f"mapping from {n} frontal images written to {a.output}", file=sys.stderr)
        return
    mapping = load_mapping(a.mapping)
    os.makedirs(a.output, exist_ok=True)
    sq, missed = [], []
    for im in truth["images"]:
        mp_pts = mesh_points(os.path.join(a.dir, im["image"]))
        if mp_pts is None:
            missed.append(im["image"])
            continue
        pts = mp_pts[mapping]
        write_pts(os.path.join(a.output, im["landmarks_file"]), pts)
        sq.extend(((pts - np.array(im["landmarks"])) ** 2).sum(axis=1))
    rmse = float(np.sqrt(np.mean(sq))) if sq else float("nan")
    print(json.dumps({"images": len(truth["images"]), "detected": len(truth["images"]) - len(missed), "missed": missed,
                      "rmse_px_to_exact": rmse}, indent=1))


if __name__ == "__main__":
    main()
