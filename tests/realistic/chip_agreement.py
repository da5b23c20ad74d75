#!/usr/bin/env python3
"""Do chips and their bordered copies fit alike, compared with the fit's own seed-to-seed spread?

Reads the output of face_chips.py (OUT/chips and OUT/bordered, detector points), fits every image
of both sets with two seeds (`gpmm fit` for pose, `gpmm eval recognition` for identity), and prints
two tables: per pair of runs, how many probes get the same rank-1 identity, and the pose
differences (median and max |difference| of yaw, pitch, roll; share within 0.5 degrees on all
three; the mean signed difference, which shows a bias). Chip vs bordered with the same seed is
the border's effect; bordered vs bordered with two seeds is the chain's own spread.

    python chip_agreement.py OUT --gpmm target/release/gpmm --model model.gpmm [--seeds 1 2]
"""
import argparse, json, os, subprocess, sys
import numpy as np


def run(cmd):
    r = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if r.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed:\n{r.stderr}")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", help="face_chips.py's output directory")
    ap.add_argument("--gpmm", default="target/release/gpmm")
    ap.add_argument("--model", required=True)
    ap.add_argument("--seeds", type=int, nargs=2, default=[1, 2])
    a = ap.parse_args()
    sets = ("chips", "bordered")
    truth = json.load(open(os.path.join(a.out, "chips", "truth.json")))
    names = [im["image"] for im in truth["images"]]
    runs = [(s, seed) for s in sets for seed in a.seeds]
    identity, pose = {}, {}
    for s, seed in runs:
        d = os.path.join(a.out, s)
        rec = os.path.join(a.out, "agreement", f"recognition-{s}-{seed}")
        run([a.gpmm, "eval", "recognition", "--synth", d, "--landmarks-dir", os.path.join(d, "detector"),
             "--model", a.model, "--fit-seed", str(seed), "-o", rec])
        probes = json.load(open(os.path.join(rec, "recognition.json")))["rows"][0]["probes"]
        identity[s, seed] = {p[0]: p[2] for p in probes}
        angles = []
        for n in names:
            fit = os.path.join(a.out, "agreement", f"fit-{s}-{seed}", os.path.splitext(n)[0])
            stem = os.path.splitext(n)[0]
            run([a.gpmm, "fit", a.model, os.path.join(d, n), "--landmarks", os.path.join(d, "detector", stem + ".pts"),
                 "--seed", str(seed), "--no-timing", "-o", fit])
            f = json.load(open(os.path.join(fit, "fit.json")))
            angles.append([f["yaw_deg"], f["pitch_deg"], f["roll_deg"]])
        pose[s, seed] = np.array(angles)
        print(f"fitted {s} with seed {seed}", file=sys.stderr)
    s1, s2 = a.seeds
    pairs = [(("chips", s1), ("bordered", s1), "border (same seed)"), (("chips", s2), ("bordered", s2), "border (same seed)"),
             (("bordered", s1), ("bordered", s2), "seed (same image)"), (("chips", s1), ("chips", s2), "seed (same image)")]
    print("| runs compared | what differs | same rank-1 identity | abs. yaw / pitch / roll difference, median (max) | all three within 0.5 deg | mean signed yaw / pitch / roll difference |")
    print("|---|---|---|---|---|---|")
    for x, y, what in pairs:
        same = sum(identity[x][k] == identity[y][k] for k in identity[x])
        d = pose[x] - pose[y]
        ad = np.abs(d)
        med = " / ".join(f"{np.median(ad[:, i]):.2f} ({ad[:, i].max():.2f})" for i in range(3))
        within = int((ad.max(1) <= 0.5).sum())
        bias = " / ".join(f"{m:+.3f}" for m in d.mean(0))
        print(f"| {x[0]} {x[1]} vs {y[0]} {y[1]} | {what} | {same} of {len(identity[x])} | {med} | {within} of {len(d)} | {bias} |")


if __name__ == "__main__":
    main()
