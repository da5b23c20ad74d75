#!/usr/bin/env python3
"""Device accuracy against the host's on a realistic set: pose errors and rank-1 recognition.

For every image of a `gpmm synth`-style set (truth.json; Mitsuba renders, see README.md), fits
  host:   `gpmm fit MODEL IMAGE --landmarks PTS` (the workstation's default fit), and
  device: `gpmm device-fit BLOB IMAGE --landmarks PTS` (the m4f blob of the same model). With
          --host-only the device's fit runs on the host core (`device-fit --host-only`, the same
          function bit for bit, as tests/tests/firmware_fit.rs checks); without it under QEMU.
Then reports, per side, the median |yaw|, |pitch|, |roll| error against the truth (degrees, the
crop's camera, both sides cropping alike) and rank-1 recognition: gallery the yaw-0 image of each
identity, probes the other yaws, identified by the largest cosine of the best sample's joint
vector (50 shape + 50 colour coefficients).

    python3 tests/realistic/device_accuracy.py --gpmm target/release/gpmm --model M.gpmm \
        --blob m4f.blob --set $REALISTIC_DATA/set [--landmarks-dir $REALISTIC_DATA/set/detector] \
        [--host-only] [--identities N] [--yaws 0,30] [--jobs 2] [--seed S] [--device-arg=ARG ...] -o OUT

Fits are cached in OUT (a rerun only fits what is missing); the table goes to OUT/accuracy.md.
Standard library only.
"""

import argparse
import concurrent.futures as cf
import json
import math
import os
import subprocess
import sys


def run(cmd, out_path):
    """Runs `cmd`, writing its stdout to out_path (kept only on success)."""
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({res.returncode}): {res.stderr.strip()[-600:]}")
    with open(out_path + ".tmp", "w") as f:
        f.write(res.stdout)
    os.replace(out_path + ".tmp", out_path)


def host_fit(args, image, pts, out_dir):
    fit = os.path.join(out_dir, "fit.json")
    if not os.path.exists(fit):
        cmd = [args.gpmm, "fit", args.model, image, "--landmarks", pts, "-o", out_dir, "--seed", str(args.seed)]
        res = subprocess.run(cmd, capture_output=True, text=True)
        if res.returncode != 0:
            raise RuntimeError(f"gpmm fit {image}: {res.stderr.strip()[-600:]}")
    with open(fit) as f:
        j = json.load(f)
    return {"yaw": j["yaw_deg"], "pitch": j["pitch_deg"], "roll": j["roll_deg"], "shape": j["shape"], "color": j["color"]}


def device_fit(args, image, pts, out_json):
    if not os.path.exists(out_json):
        cmd = [args.gpmm, "device-fit", args.blob, image, "--landmarks", pts, "--seed", str(args.seed)] + args.device_arg
        if args.host_only:
            cmd.append("--host-only")
        run(cmd, out_json)
    with open(out_json) as f:
        j = json.load(f)
    return {"yaw": j["yaw_deg"], "pitch": j["pitch_deg"], "roll": j["roll_deg"], "shape": j["shape"], "color": j["color"]}


def joint(fit, shape, color):
    return list(fit["shape"][:shape]) + list(fit["color"][:color])


def cosine(a, b):
    na = math.sqrt(sum(x * x for x in a))
    nb = math.sqrt(sum(x * x for x in b))
    return sum(x * y for x, y in zip(a, b)) / max(na * nb, 1e-30)


def median(v):
    v = sorted(v)
    n = len(v)
    return float("nan") if n == 0 else (v[n // 2] if n % 2 else 0.5 * (v[n // 2 - 1] + v[n // 2]))


def rank1(fits, images, shape, color):
    gallery = {im["identity"]: joint(fits[im["image"]], shape, color) for im in images if im["yaw_deg"] == 0.0}
    probes = [im for im in images if im["yaw_deg"] != 0.0 and im["identity"] in gallery]
    hits = 0
    for im in probes:
        v = joint(fits[im["image"]], shape, color)
        best = max(gallery, key=lambda g: cosine(v, gallery[g]))
        hits += best == im["identity"]
    return hits, len(probes)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--gpmm", default="target/release/gpmm")
    ap.add_argument("--model", required=True, help="the host's model (.gpmm)")
    ap.add_argument("--blob", required=True, help="the device's blob of the same model (gpmm quantize --profile m4f)")
    ap.add_argument("--set", required=True, help="directory with truth.json, the images and their exact .pts")
    ap.add_argument("--landmarks-dir", help="take the .pts from here (e.g. a detector's) instead of the set's")
    ap.add_argument("--host-only", action="store_true", help="the device's fit on the host core (no QEMU)")
    ap.add_argument("--identities", type=int, help="only the first N identities")
    ap.add_argument("--yaws", help="only these yaws (degrees, comma-separated; 0 is the gallery)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0, help="seed of both sides' chains")
    ap.add_argument("--device-arg", action="append", default=[], metavar="ARG",
                    help="one more argument of `gpmm device-fit` (repeatable; e.g. --device-arg=--image-steps=600)")
    ap.add_argument("--components", type=int, default=50, help="shape and colour components of the joint vector")
    ap.add_argument("-o", "--output", required=True)
    args = ap.parse_args()

    with open(os.path.join(args.set, "truth.json")) as f:
        truth = json.load(f)
    yaws = None if args.yaws is None else {float(y) for y in args.yaws.split(",")}
    images = [
        im
        for im in truth["images"]
        if (args.identities is None or im["identity"] < args.identities) and (yaws is None or im["yaw_deg"] in yaws)
    ]
    os.makedirs(os.path.join(args.output, "host"), exist_ok=True)
    os.makedirs(os.path.join(args.output, "device"), exist_ok=True)
    pts_dir = args.landmarks_dir or args.set
    # A detector that found no face wrote no .pts: such images are left out on both sides.
    missing = [im["image"] for im in images if not os.path.isfile(os.path.join(pts_dir, os.path.splitext(im["image"])[0] + ".pts"))]
    images = [im for im in images if im["image"] not in missing]
    if missing:
        print(f"{len(missing)} images without landmarks in {pts_dir} left out: {', '.join(missing)}", file=sys.stderr)

    def both(im):
        stem = os.path.splitext(im["image"])[0]
        image, pts = os.path.join(args.set, im["image"]), os.path.join(pts_dir, stem + ".pts")
        h = host_fit(args, image, pts, os.path.join(args.output, "host", stem))
        d = device_fit(args, image, pts, os.path.join(args.output, "device", stem + ".json"))
        return im["image"], h, d

    host, device = {}, {}
    with cf.ThreadPoolExecutor(args.jobs) as pool:
        for done, (name, h, d) in enumerate(pool.map(both, images), 1):
            host[name], device[name] = h, d
            print(f"\r{done}/{len(images)} fitted", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)

    k = args.components
    rows = []
    for label, fits in (("host (`gpmm fit`)", host), ("m4f (`gpmm device-fit`)", device)):
        err = {a: [abs(fits[im["image"]][a] - im[f"{a}_deg"]) for im in images] for a in ("yaw", "pitch", "roll")}
        hits, n = rank1(fits, images, k, k)
        rows.append((label, 100.0 * hits / max(n, 1), hits, n, median(err["yaw"]), median(err["pitch"]), median(err["roll"])))
    how = "device fits on the host core (bit-identical to QEMU)" if args.host_only else "device fits under QEMU"
    lines = [
        f"{len(images)} images ({len({im['identity'] for im in images})} identities), landmarks from {pts_dir}"
        + (f" ({len(missing)} without landmarks left out)" if missing else "")
        + f"; {how}",
        "",
        "| fit | rank-1 | median \\|yaw\\| / \\|pitch\\| / \\|roll\\| error |",
        "|---|---|---|",
    ]
    for label, r1, hits, n, ye, pe, re in rows:
        lines.append(f"| {label} | {r1:.1f} % ({hits}/{n}) | {ye:.2f}° / {pe:.2f}° / {re:.2f}° |")
    text = "\n".join(lines) + "\n"
    with open(os.path.join(args.output, "accuracy.md"), "w") as f:
        f.write(text)
    print(text)


if __name__ == "__main__":
    main()
