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
iBUG-68. Photos that are byte-identical to one of an --exclude folder (the dev and test sets, the
project's shared photos) are left out, so the pool never holds a photo a set is scored on. The
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
]


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
    a = ap.parse_args()
    from PIL import Image
    checkouts = {}
    for c in a.checkout:
        name, sep, path = c.partition("=")
        if not sep:
            sys.exit(f"--checkout {c}: expected OWNER/NAME=PATH")
        checkouts[name] = Checkout(path)
    excluded = set()
    for d in a.exclude:
        for p in glob.glob(os.path.join(d, "**", "*"), recursive=True):
            if os.path.isfile(p) and p.lower().endswith((".jpg", ".jpeg", ".png", ".ppm")):
                excluded.add(hashlib.sha256(open(p, "rb").read()).hexdigest())
    mapping = make_set.detect_landmarks.load_mapping(a.mapping)
    os.makedirs(a.out, exist_ok=True)
    listed, summary = [], {"images": 0, "faces": 0, "with_landmarks": 0, "left_out": 0}
    for repo, licence, pattern in SOURCES:
        co = checkouts.get(repo)
        if co is None:
            print(f"warning: no --checkout for {repo}; its photos are left out", file=sys.stderr)
            continue
        commit = co.commit()
        prefix = repo.split("/")[1].split("-")[0].lower()
        for name in sorted(n for n in co.files() if re.match(pattern, n)):
            data = co.read(name)
            stem = f"{prefix}_{os.path.splitext(name)[0].replace('/', '_')}"
            if not data:
                print(f"warning: {repo}: {name} is empty (a large-file pointer?); left out", file=sys.stderr)
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
            img.save(os.path.join(a.out, stem + ".jpg"), quality=95)
            faces = [{"box": [round(v, 2) for v in box], "score": round(score, 3),
                      "landmarks": make_set.landmarks_in(img, box, mapping)}
                     for score, box in make_set.detect_boxes(img)]
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
        json.dump({"sources": [{"repository": r, "licence": l, "photos": p} for r, l, p in SOURCES],
                   "photos": listed, "summary": summary}, f, indent=1)
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
