#!/usr/bin/env python3
"""A training pool of real photos of people, from the example photos of open-source face projects.

    python make_pool.py OUT --mapping MAPPING.json --checkout OWNER/NAME=PATH ...

`gpmm train-init --backgrounds OUT` shows the finder the faces of these photos as faces and the
rest of each photo (hands, suits, rooms, crowds' surroundings) as background. The photos come from
the repositories in SOURCES; give each one's checkout with --checkout (a work tree or a git
directory, e.g. `git clone --bare`): no package registry ships them, so this script downloads
nothing. Repositories without a --checkout are skipped with a warning.

Every photo gets STEM.faces.json in the format of make_set.py (README.md beside this script): the
faces MediaPipe's full-range detector finds, each with the 68 points of the face mesh mapped to
iBUG-68. Photos that are one of an --exclude folder (the dev and test sets, the project's shared
photos), byte for byte or at another size or compression, are left out, so the pool never holds a photo a
set is scored on; a photo several repositories ship is taken once, and one where the detector finds no
face is left out unless FACE_FREE lists it. The
photos of dlib and eos are not among the sources (they are kept as an independent check).
Run with the venv of tests/realistic (mediapipe, pillow).
"""
import argparse, glob, hashlib, io, json, os, re, subprocess, sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import make_set  # noqa: E402  (the reference detector and the 468 -> 68 mapping)

# (repository, licence, the photos: a regular expression over paths in the repository).
SOURCES = [
    ("serengil/deepface", "MIT (repository); portraits of public figures used as its test set",
     r"^tests/unit/dataset/[^/]+\.(jpg|jpeg|png)$"),
    ("Linzaer/Ultra-Light-Fast-Generic-Face-Detector-1MB", "MIT (repository); group photos of its examples",
     r"^imgs/[^/]+\.jpg$"),
    ("TencentARC/GFPGAN", "Apache-2.0 (repository); its example inputs", r"^inputs/whole_imgs/[^/]+\.(jpg|png)$"),
    ("timesler/facenet-pytorch", "MIT (repository); its example photos", r"^data/(multiface\.jpg|test_images/[^/]+/[^/]+\.jpg)$"),
    # Group photos and crowds (WIDER FACE-style: many faces of 30-100 px). Dense crowds where the reference detector
    # finds a small part of the faces are left out (the faces it misses would be trained on as "no face"): the
    # parades and the second meeting of DSFD-Pytorch-Inference, the crowds of LFFD and CenterFace, FaceAiSharp's
    # 10-megapixel summit photo.
    ("vladmandic/human", "MIT (repository); its real sample photos (groups, people, stock portraits); "
     "its cgi-* renders and ai-* generated faces are left out", r"^samples/in/(group|person|stock|solvay)[^/]*\.jpg$"),
    ("vladmandic/face-api", "MIT (repository); its demo group photos", r"^demo/sample[0-9]+\.jpg$"),
    ("justadudewhohacks/face-api.js", "MIT (repository); its example photos (group photos, expressions); "
     "the 150x150 grey face crops are left out", r"^examples/images/[^/]+\.jpg$"),
    ("hukkelas/DSFD-Pytorch-Inference", "Apache-2.0 (repository); a WIDER FACE meeting photo of its examples",
     r"^images/11_Meeting_Meeting_11_Meeting_Meeting_11_176\.jpg$"),
    ("TropComplique/mtcnn-pytorch", "MIT (repository); office group photos (example.png has boxes drawn)",
     r"^images/office[0-9]+\.jpg$"),
    ("sthanhng/yoloface", "MIT (repository); its sample group photos", r"^samples/[^/]+\.jpg$"),
    ("biubug6/Pytorch_Retinaface", "MIT (LICENSE.MIT); a crowd photo of its README (curve/1.jpg has boxes drawn)",
     r"^curve/test\.jpg$"),
    ("ShiqiYu/libfacedetection", "BSD-3-Clause (repository); the test photos of its mobile demos",
     r"^mobile/(Android/FaceDetection/app/src/main/assets|iOS/FaceDetection)/[^/]+\.jpg$"),
    ("ORB-HD/deface", "MIT (repository); its street example", r"^examples/city\.jpg$"),
    ("bubbliiiing/retinaface-pytorch", "MIT (repository); its street and crowd examples", r"^img/[^/]+\.jpg$"),
    ("peteryuX/retinaface-tf2", "MIT (repository); a WIDER FACE photo of its examples", r"^data/[^/]+\.jpg$"),
    ("exadel-inc/CompreFace", "Apache-2.0 (repository); the sample photos of its embedding calculator and load "
     "tests (groups, portraits; 017_0.jpg is a landscape)",
     r"^(embedding-calculator/sample_images/0(0[0-9]|1[0-6])_[^/]+\.jpg|load-tests/docker/tests/(detect|verify)/faces/[^/]+\.jpg)$"),
    ("georg-jung/FaceAiSharp", "MIT (repository); its example photos (a family, portraits)",
     r"^examples/(Barack_Obama_03|biden_7mpx|obama_family)\.jpg$"),
    ("blaueck/tf-mtcnn", "MIT (repository); its family test photo", r"^test_image\.jpg$"),
    ("JDAI-CV/FaceX-Zoo", "Apache-2.0 (repository); two of its face SDK test photos (two portraits side by side, "
     "one masked)", r"^face_sdk/api_usage/test_images/(test1|test3_mask)\.jpg$"),
    ("oarriaga/face_classification", "MIT (repository); its test photo (the other photos have boxes drawn)",
     r"^images/test_image\.jpg$"),
    # People in scenes: sports, streets, rooms, odd light (test images of pose datasets: COCO, MPII, CrowdPose,
    # OCHuman, PoseTrack, AI Challenger, Human3.6M, MPI-INF-3DHP, WFLW, 300W, AFLW, COFW, LaPa, hands).
    ("open-mmlab/mmpose", "Apache-2.0 (repository); the test images of its datasets (photos of people only: "
     "no animals, renders, drawings, night-vision frames, consecutive video frames)",
     r"^(projects/rtmpose/examples/onnxruntime/human-pose\.jpeg|tests/data/("
     r"300vw/(001/imgs/000006|401/imgs/000731)\.jpg|"
     r"(300w|300wlp|aflw|aic|coco|cofw|crowdpose|lapa|mhp|mpii|ochuman|wflw|deepfasion2|onehand10k|interhand2\.6m|"
     r"mpi_inf_3dhp)/[^/]+\.(jpg|png)|humanart/real_human/.+\.jpg|jhmdb/[^/]+/00001\.png|"
     r"posetrack18/images/.+\.jpg|h36m/S[0-9]+/[^/]+/[^/]+\.jpg))$"),
    # Portraits and turned heads (AFLW2000, 300W-LP, VoxCeleb-style frames, celebrities).
    ("sicxu/Deep3DFaceRecon_pytorch", "MIT (repository); its example portraits", r"^datasets/examples/[^/]+\.(jpg|png)$"),
    ("yfeng95/PRNet", "MIT (repository); its test photos (AFLW2000 and others; the masked 3.jpg and the cartoon "
     "5.jpg are left out)", r"^TestImages/([0124]|trump|AFLW2000/image[0-9]+)\.jpg$"),
    ("cleardusk/3DDFA_V2", "MIT (repository); its example inputs", r"^examples/inputs/[^/]+\.jpg$"),
    ("cleardusk/3DDFA", "MIT (repository); its C++ demo frame (its other samples are renders or duplicates)",
     r"^c\+\+/demo\.jpg$"),
    ("FacePerceiver/facer", "MIT (repository); its sample photos (profiles, grimaces)", r"^samples/data/[^/]+\.jpg$"),
    ("cmusatyalab/openface", "Apache-2.0 (repository); its example portraits", r"^images/examples/[^/]+\.jpg$"),
    ("serengil/retinaface", "MIT (repository); its test photos", r"^tests/dataset/[^/]+\.jpg$"),
    ("xinntao/facexlib", "MIT (repository); its test portraits", r"^assets/test2?\.jpg$"),
    ("hollance/BlazeFace-PyTorch", "Apache-2.0 (as MediaPipe, its LICENSE); 128x128 test photos", r"^[0-9]faces?\.png$"),
    ("1adrianb/face-alignment", "BSD-3-Clause (repository); its test photo", r"^test/assets/aflw-test\.jpg$"),
    ("ipazc/mtcnn", "MIT (repository); its example photo", r"^resources/ivan\.jpg$"),
    ("justinshenk/fer", "MIT (repository); its example photo", r"^justin\.jpg$"),
    ("davidsandberg/facenet", "MIT (repository); LFW photos of its tests", r"^data/images/[^/]+\.jpg$"),
    ("elliottzheng/face-detection", "MIT (repository); its example portraits (batman.jpg: a masked face, left out)",
     r"^examples/(obama|trump)\.jpg$"),
]

# Photos of people that show no face (hands, a torso): kept though the reference detector finds no face in them.
# Any other photo where it finds none is left out: there the face is missed (a close-up, a profile, a tiny or dark
# face), and the rest of a pool photo is trained on as "no face".
FACE_FREE = {
    "open-mmlab/mmpose": r"^tests/data/(interhand2\.6m|onehand10k|deepfasion2)/",
}

# The repositories the recipe trains on (docs/real-photos.md, "The recipe"), and so the start gpmm ships:
# the first RECIPE_SOURCES of SOURCES. The others make the unseen pool set the recipe is tuned on.
RECIPE_SOURCES = 4

# Two photos whose hashes (below) differ in at most this many of their 256 bits are the same photo (another
# size, another compression, a few pixels of border): only the first one met is kept, and one that matches a
# photo of an --exclude folder is left out as its byte-identical copy would be.
NEAR_DUPLICATE_BITS = 24


def photo_hash(img):
    """A difference hash of the photo: 256 bits, each whether a pixel of a 17x16 grey thumbnail is brighter than
    its right-hand neighbour. Resizing and recompression change few bits; another photo changes about half."""
    from PIL import Image
    g = img.convert("L").resize((17, 16), Image.BILINEAR)
    px = g.tobytes()
    bits = 0
    for y in range(16):
        for x in range(16):
            bits = (bits << 1) | (px[y * 17 + x] > px[y * 17 + x + 1])
    return bits


def near(h, hashes):
    """The first of `hashes` ((hash, name) pairs) within NEAR_DUPLICATE_BITS of `h`, else None."""
    for other, name in hashes:
        if bin(h ^ other).count("1") <= NEAR_DUPLICATE_BITS:
            return name
    return None


class Checkout:
    """Files of one repository: a work tree, or a git directory read at HEAD."""

    def __init__(self, path):
        self.path = path
        self.git = not os.path.isdir(os.path.join(path, ".git")) and os.path.isfile(os.path.join(path, "HEAD"))
        if not (self.git or os.path.isdir(path)):
            sys.exit(f"--checkout {path}: neither a work tree nor a git directory")

    def files(self):
        if self.git:
            out = subprocess.run(["git", "--git-dir", self.path, "ls-tree", "-r", "--name-only", "HEAD"],
                                 check=True, capture_output=True, text=True).stdout
            return out.split("\n")
        return [os.path.relpath(os.path.join(d, f), self.path).replace(os.sep, "/")
                for d, _, fs in os.walk(self.path) if "/.git" not in d for f in fs]

    def read(self, name):
        if self.git:
            r = subprocess.run(["git", "--git-dir", self.path, "show", f"HEAD:{name}"], capture_output=True)
            return r.stdout if r.returncode == 0 else b""
        with open(os.path.join(self.path, name), "rb") as f:
            return f.read()

    def commit(self):
        args = ["git", "--git-dir", self.path] if self.git else ["git", "-C", self.path]
        r = subprocess.run(args + ["rev-parse", "HEAD"], capture_output=True, text=True)
        return r.stdout.strip() if r.returncode == 0 else "unknown"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out")
    ap.add_argument("--mapping", required=True, help="mapping.json of detect_landmarks.py calibrate")
    ap.add_argument("--checkout", action="append", default=[], metavar="OWNER/NAME=PATH",
                    help="where a repository of SOURCES is checked out (repeat per repository)")
    ap.add_argument("--exclude", action="append", default=[], metavar="DIR",
                    help="photos of DIR (and its subfolders) are never taken into the pool")
    ap.add_argument("--recipe", action="store_true",
                    help=f"only the first {RECIPE_SOURCES} repositories of SOURCES, the recipe's (each needs a --checkout)")
    ap.add_argument("--held", action="store_true",
                    help=f"only the repositories after the first {RECIPE_SOURCES}: the unseen pool set")
    a = ap.parse_args()
    if a.recipe and a.held:
        sys.exit("--recipe and --held take disjoint repositories: give one")
    sources = SOURCES[:RECIPE_SOURCES] if a.recipe else SOURCES[RECIPE_SOURCES:] if a.held else SOURCES
    from PIL import Image
    checkouts = {}
    for c in a.checkout:
        name, sep, path = c.partition("=")
        if not sep:
            sys.exit(f"--checkout {c}: expected OWNER/NAME=PATH")
        checkouts[name] = Checkout(path)
    excluded, excluded_looks = set(), []
    for d in a.exclude:
        for p in glob.glob(os.path.join(d, "**", "*"), recursive=True):
            if os.path.isfile(p) and p.lower().endswith((".jpg", ".jpeg", ".png", ".ppm")):
                data = open(p, "rb").read()
                excluded.add(hashlib.sha256(data).hexdigest())
                try:
                    excluded_looks.append((photo_hash(Image.open(io.BytesIO(data))), p))
                except OSError:
                    pass
    taken = []  # (hash, repository and path) of the photos kept so far
    mapping = make_set.detect_landmarks.load_mapping(a.mapping)
    os.makedirs(a.out, exist_ok=True)
    listed, summary = [], {"images": 0, "faces": 0, "with_landmarks": 0, "left_out": 0, "no_face_found": 0}
    prefixes = {}
    for repo, _, _ in SOURCES:  # a short file-name prefix per repository; the full name where short ones clash
        short = repo.split("/")[1].split("-")[0].lower()
        prefixes[repo] = short if short not in prefixes.values() else re.sub(r"[^a-z0-9]+", "_", repo.lower())
    for repo, licence, pattern in sources:
        co = checkouts.get(repo)
        if co is None and a.recipe:
            sys.exit(f"--recipe: no --checkout for {repo}; the recipe's pool needs all of its first {RECIPE_SOURCES} repositories")
        if co is None:
            print(f"warning: no --checkout for {repo}; its photos are left out", file=sys.stderr)
            continue
        commit = co.commit()
        prefix = prefixes[repo]
        for name in sorted(n for n in co.files() if re.match(pattern, n)):
            data = co.read(name)
            stem = f"{prefix}_{os.path.splitext(name)[0].replace('/', '_')}"
            if not data or data.startswith(b"version https://git-lfs"):
                what = "a Git LFS pointer, not the photo" if data else "empty"
                print(f"warning: {repo}: {name} is {what}; left out", file=sys.stderr)
                summary["left_out"] += 1
                continue
            if hashlib.sha256(data).hexdigest() in excluded:
                print(f"{repo}: {name} is a photo of an excluded folder; left out", file=sys.stderr)
                summary["left_out"] += 1
                continue
            try:
                img = Image.open(io.BytesIO(data)).convert("RGB")
            except OSError as e:
                print(f"warning: {repo}: {name} does not decode ({e}); left out", file=sys.stderr)
                summary["left_out"] += 1
                continue
            look = photo_hash(img)
            same = near(look, excluded_looks)
            if same:
                print(f"{repo}: {name} is {same} of an excluded folder (another size or compression); left out",
                      file=sys.stderr)
                summary["left_out"] += 1
                continue
            same = near(look, taken)
            if same:
                print(f"{repo}: {name} is the same photo as {same}; left out", file=sys.stderr)
                summary["left_out"] += 1
                continue
            faces = [{"box": [round(v, 2) for v in box], "score": round(score, 3),
                      "landmarks": make_set.landmarks_in(img, box, mapping)}
                     for score, box in make_set.detect_boxes(img)]
            if not faces and not re.match(FACE_FREE.get(repo, r"$^"), name):
                print(f"{repo}: {name}: the reference detector finds no face in it; left out", file=sys.stderr)
                summary["left_out"] += 1
                summary["no_face_found"] += 1
                continue
            taken.append((look, f"{repo}: {name}"))
            img.save(os.path.join(a.out, stem + ".jpg"), quality=95)
            meta = {"source": f"repository {repo} at {commit}, {name}; licence: {licence}",
                    "reference": make_set.REFERENCE, "faces": faces}
            with open(os.path.join(a.out, stem + ".faces.json"), "w") as f:
                json.dump(meta, f, indent=1)
            listed.append({"photo": stem + ".jpg", "repository": repo, "commit": commit, "path": name,
                           "faces": len(faces)})
            summary["images"] += 1
            summary["faces"] += len(faces)
            summary["with_landmarks"] += sum(f["landmarks"] is not None for f in faces)
            print(f"{stem}.jpg: {len(faces)} face(s)")
    with open(os.path.join(a.out, "sources.json"), "w") as f:
        json.dump({"sources": [{"repository": r, "licence": l, "photos": p} for r, l, p in sources],
                   "photos": listed, "summary": summary}, f, indent=1)
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
