#!/usr/bin/env python3
"""Which face `gpmm fit --init` should take when the finder reports several: on a set with known
truth (truth.json with landmarks), how often each rule picks a box whose centre lies inside the
true face's landmark box. Rules: the best-scored face, and the largest of the faces scoring at
least SHARE x the best one (SHARE 0: the largest of all).

    python3 chosen_face.py SET_DIR --init INIT [--gpmm target/release/gpmm] [--shares 0,0.9,0.95]
"""
import argparse, json, os, subprocess


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("set_dir")
    ap.add_argument("--init", required=True)
    ap.add_argument("--gpmm", default="target/release/gpmm")
    ap.add_argument("--shares", default="0,0.9,0.95")
    a = ap.parse_args()
    shares = [float(x) for x in a.shares.split(",")]
    truth = json.load(open(os.path.join(a.set_dir, "truth.json")))
    hits = {"best": 0, **{f"largest >= {s} x best": 0 for s in shares}}
    n = 0
    for im in truth["images"]:
        r = subprocess.run([a.gpmm, "detect", os.path.join(a.set_dir, im["image"]), "--init", a.init], capture_output=True, text=True)
        if r.returncode != 0:
            continue  # no face found: no rule picks one
        faces = [f["box"] for f in json.loads(r.stdout)["faces"]]
        xs, ys = [p[0] for p in im["landmarks"]], [p[1] for p in im["landmarks"]]
        on_face = lambda b: min(xs) <= b["cx"] <= max(xs) and min(ys) <= b["cy"] <= max(ys)
        n += 1
        hits["best"] += on_face(faces[0])
        for s in shares:
            near = [f for f in faces if f["score"] >= s * faces[0]["score"]]
            hits[f"largest >= {s} x best"] += on_face(max(near, key=lambda f: f["size"]))
    print(f"{n} images with a face found; the chosen box on the true face:")
    for rule, k in hits.items():
        print(f"  {rule}: {k} of {n}")


if __name__ == "__main__":
    main()
