#!/usr/bin/env python3
"""Where a gpmm model's landmark vertices fall on the ICT faces of a realistic set, and how far each
detector is from those points and from the set's own (ICT) landmarks.

The sets' truth is ICT's iBUG-68 vertices; a model's landmarks are its template's vertices, placed
by another convention. A detector trained on the model's renders learns the model's points, so part
of its error against ICT's is a difference of definitions that no training removes. This script
measures that part:

    python landmark_definitions.py transfer MODEL -o DEFS.json [--gpmm BIN] [--landmark-weight W] [--albedo NPY]
    python landmark_definitions.py report SET DEFS.json [POINTS_DIR ...]
    python landmark_definitions.py write SET DEFS.json OUT_DIR

transfer registers MODEL to ICT's neutral face (`gpmm register --landmark-weight W`: 0, the
default, uses ICT's landmarks for the rigid alignment only, so the surface alone decides where each
model vertex lands; 20, gpmm's usual weight, pulls the model's landmarks toward ICT's and so gives a
lower bound of the difference) and stores, for each model landmark, the closest point on ICT's
surface (triangle and barycentric weights). On ICT's shared topology that point moves with every
identity.
report prints, per |yaw| and over the set, the median error (mean over the 68 points / outer-eye-
corner distance) of the transferred points against the set's truth ("floor": a detector that found
the model's points exactly), then for each POINTS_DIR its error against the truth and against the
transferred points, and per landmark group the same with the mean offset along the eye line (x)
and across it (y, down).
write writes the transferred points of every image as .pts (e.g. to fit with `gpmm bench-fit
--landmarks-dir`).
"""
import argparse, json, math, os, struct, subprocess, sys, tempfile
import numpy as np
from make_set import Ict, face_frame, rotation, project  # the same directory: the set's own faces and projection
from detect_landmarks import GROUPS, read_pts, write_pts


def model_tensor(path, name):
    """One tensor of a .gpmm file (a safetensors container, docs/model-format.md)."""
    with open(path, "rb") as f:
        n = struct.unpack("<Q", f.read(8))[0]
        header = json.loads(f.read(n))
        if name not in header:
            sys.exit(f"{path}: no '{name}' tensor; is it a gpmm model?")
        t = header[name]
        start, end = t["data_offsets"]
        f.seek(8 + n + start)
        return np.frombuffer(f.read(end - start), dtype={"U32": "<u4", "F32": "<f4", "F64": "<f8"}[t["dtype"]]).reshape(t["shape"])


def ply_positions(path):
    """Vertex positions of a binary little-endian PLY as `gpmm register` writes it (float x y z, then uchar colours)."""
    data = open(path, "rb").read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    lines = data[:end].decode().splitlines()
    at = next(i for i, l in enumerate(lines) if l.startswith("element vertex"))
    n = int(lines[at].split()[2])
    props = []
    for l in lines[at + 1:]:
        if not l.startswith("property"):
            break
        props.append((l.split()[2], {"float": "<f4", "uchar": "u1"}[l.split()[1]]))
    v = np.frombuffer(data[end:end + n * np.dtype(props).itemsize], dtype=np.dtype(props))
    return np.stack([v["x"], v["y"], v["z"]], axis=1).astype(np.float64)


def closest_barycentric(p, a, b, c):
    """Barycentric weights of the point of triangle abc closest to p."""
    e = np.stack([b - a, c - a], axis=1)
    u, v = np.linalg.lstsq(e, p - a, rcond=None)[0]
    if min(u, v, 1 - u - v) >= 0:
        return np.array([1 - u - v, u, v])
    best = None  # outside: the closest point lies on an edge
    corners = (a, b, c)
    for i, j in ((0, 1), (1, 2), (2, 0)):
        d = corners[j] - corners[i]
        t = float(np.clip((p - corners[i]) @ d / (d @ d), 0.0, 1.0))
        dist = np.linalg.norm(corners[i] + t * d - p)
        if best is None or dist < best[0]:
            w = np.zeros(3)
            w[i], w[j] = 1 - t, t
            best = (dist, w)
    return best[1]


def registered_ict(model, ict, gpmm, landmark_weight=None):
    """ICT's neutral face registered into `model`'s topology (`gpmm register`, ICT's landmarks; in
    ICT's frame): (vertex positions, register.json). `landmark_weight` None keeps register's default."""
    with tempfile.TemporaryDirectory() as tmp:
        mesh, lm, out = (os.path.join(tmp, n) for n in ("ict.ply", "ict.json", "reg"))
        with open(mesh, "w") as f:
            f.write(f"ply\nformat ascii 1.0\nelement vertex {len(ict.neutral)}\nproperty float x\nproperty float y\nproperty float z\n"
                    f"element face {len(ict.tris)}\nproperty list uchar int vertex_indices\nend_header\n")
            f.writelines("%.5f %.5f %.5f\n" % tuple(p) for p in ict.neutral)
            f.writelines("3 %d %d %d\n" % tuple(t) for t in ict.tris)
        json.dump({"scheme": "ibug68", "vertex_ids": ict.landmarks.tolist()}, open(lm, "w"))
        weight = [] if landmark_weight is None else ["--landmark-weight", str(landmark_weight)]
        cmd = [gpmm, "register", model, mesh, "--landmarks", lm, *weight, "-o", out]
        r = subprocess.run(cmd, capture_output=True, text=True)
        if r.returncode != 0:
            sys.exit(f"{' '.join(cmd)} failed:\n{r.stderr}")
        print(r.stderr.strip().splitlines()[0], file=sys.stderr)
        return ply_positions(os.path.join(out, "registered.ply")), json.load(open(os.path.join(out, "register.json")))


def transfer(a):
    ict = Ict(a.ict)
    ids = model_tensor(a.model, "landmarks").astype(np.int64)
    registered, _ = registered_ict(a.model, ict, a.gpmm, a.landmark_weight)
    points = registered[ids]
    if a.albedo:
        # Each ICT vertex takes the model's mean colour at the nearest registered vertex; where the model does
        # not reach (over 5 mm away: ears, neck), the median colour.
        colour = model_tensor(a.model, "color.mean").astype(np.float64)
        near = np.empty(len(ict.neutral), np.int64)
        dist = np.empty(len(ict.neutral))
        for s in range(0, len(ict.neutral), 500):
            d = np.linalg.norm(ict.neutral[s:s + 500, None, :] - registered[None, :, :], axis=2)
            near[s:s + 500], dist[s:s + 500] = d.argmin(axis=1), d.min(axis=1)
        albedo = colour[near]
        albedo[dist > 5.0] = np.median(colour, axis=0)
        np.save(a.albedo, albedo.astype(np.float32))
        print(f"wrote {a.albedo} ({(dist <= 5.0).mean():.0%} of ICT's vertices within 5 mm of the model)", file=sys.stderr)
    centroids = ict.neutral[ict.tris].mean(axis=1)
    tris, weights, dist = [], [], []
    for p in points:
        best = None
        for t in np.argsort(np.linalg.norm(centroids - p, axis=1))[:40]:
            w = closest_barycentric(p, *ict.neutral[ict.tris[t]])
            d = float(np.linalg.norm(w @ ict.neutral[ict.tris[t]] - p))
            if best is None or d < best[0]:
                best = (d, int(t), w)
        dist.append(best[0])
        tris.append(best[1])
        weights.append(best[2].tolist())
    iod = np.linalg.norm(ict.neutral[ict.landmarks[36]] - ict.neutral[ict.landmarks[45]])
    onto = np.array([np.array(w) @ ict.neutral[ict.tris[t]] for t, w in zip(tris, weights)])
    off = (onto - ict.neutral[ict.landmarks]) / iod
    json.dump({"format": "gpmm-landmark-transfer", "model": a.model, "landmark_weight": a.landmark_weight,
               "ict_triangles": tris, "barycentric": weights}, open(a.output, "w"), indent=1)
    print(f"model landmarks on ICT's neutral face: {np.median(dist):.2f} mm from its surface (median); "
          f"3D offset from ICT's points / outer-eye-corner distance:", file=sys.stderr)
    for g, r in GROUPS.items():
        o = off[list(r)]
        print(f"  {g:5s} |d| {np.linalg.norm(o, axis=1).mean():.3f}  mean x {o[:, 0].mean():+.3f} y {o[:, 1].mean():+.3f} z {o[:, 2].mean():+.3f}", file=sys.stderr)
    print(f"wrote {a.output}", file=sys.stderr)


def transferred_points(setdir, defs, ict):
    """(image record, the set's truth, the transferred points) for every image of setdir, projected as make_set.py does."""
    truth = json.load(open(os.path.join(setdir, "truth.json")))
    ids = {i["id"]: i for i in truth["identities"]}
    tris, weights = np.array(defs["ict_triangles"]), np.array(defs["barycentric"])
    for im in truth["images"]:
        shape = ict.shape(ids[im["identity"]]["shape_coefficients"])
        axes, center = face_frame(shape[ict.landmarks])
        rot = rotation(*(math.radians(im[k]) for k in ("yaw_deg", "pitch_deg", "roll_deg")))

        def proj(x):
            return project(((x - center) @ axes.T) @ rot.T + np.array(im["translation_mm"]), im["focal_px"], *im["principal_px"])

        t = np.array(im["landmarks"])
        if np.abs(proj(shape[ict.landmarks]) - t).max() > 0.05:
            sys.exit(f"{setdir}: {im['image']}: ICT's landmarks do not project onto the set's truth; is it a make_set.py set of these ICT data?")
        yield im, t, proj(np.einsum("kj,kjc->kc", weights, shape[ict.tris[tris]]))


def report(a):
    ict, defs = Ict(a.ict), json.load(open(a.defs))
    rows, groups = [], {d: {g: [] for g in GROUPS} for d in a.points}
    for im, t, m in transferred_points(a.set, defs, ict):
        e = np.linalg.norm(t[36] - t[45])
        x = (t[45] - t[36]) / e
        frame = np.array([x, [-x[1], x[0]]])
        row = [abs(round(im["yaw_deg"])), np.linalg.norm(m - t, axis=1).mean() / e]
        for d in a.points:
            f = os.path.join(d, im["landmarks_file"])
            if not os.path.exists(f):
                row += [np.nan, np.nan]
                continue
            p = read_pts(f)
            row += [np.linalg.norm(p - t, axis=1).mean() / e, np.linalg.norm(p - m, axis=1).mean() / e]
            for g, r in GROUPS.items():
                r = list(r)
                groups[d][g].append((np.linalg.norm(p[r] - t[r], axis=1).mean() / e, np.linalg.norm(p[r] - m[r], axis=1).mean() / e,
                                     *(((p[r] - m[r]) @ frame.T).mean(axis=0) / e)))
        rows.append(row)
    r = np.array(rows, dtype=float)
    print(f"{a.set}: {len(r)} images; model points from {a.defs} (landmark weight {defs['landmark_weight']})")
    print("|yaw|    n  floor" + "".join(f"  | {os.path.basename(d.rstrip('/'))}: vs truth, vs model points" for d in a.points))
    for y in [*sorted(set(r[:, 0])), None]:
        m = np.ones(len(r), bool) if y is None else r[:, 0] == y
        print(f"{'all' if y is None else int(y):>5} {m.sum():4d}  " + "  ".join(f"{np.nanmedian(r[m, j]):.3f}" for j in range(1, r.shape[1])))
    for d in a.points:
        print(f"{d}, per group: median vs truth, vs model points; mean offset from the model points (x along the eyes, y down)")
        for g, v in groups[d].items():
            v = np.array(v)
            print(f"  {g:5s} {np.median(v[:, 0]):.3f}  {np.median(v[:, 1]):.3f}  x {v[:, 2].mean():+.3f} y {v[:, 3].mean():+.3f}")


def write(a):
    ict, defs = Ict(a.ict), json.load(open(a.defs))
    os.makedirs(a.out_dir, exist_ok=True)
    n = 0
    for im, _, m in transferred_points(a.set, defs, ict):
        write_pts(os.path.join(a.out_dir, im["landmarks_file"]), m.tolist())
        n += 1
    print(f"wrote {n} .pts to {a.out_dir}", file=sys.stderr)


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ict", default=os.path.join(os.environ.get("GPMM_DATA", os.path.join(here, "../../../shared/data")), "ict"))
    sub = ap.add_subparsers(dest="cmd", required=True)
    t = sub.add_parser("transfer", help="register MODEL to ICT's neutral face and store where its landmarks fall")
    t.add_argument("model")
    t.add_argument("-o", "--output", required=True)
    t.add_argument("--gpmm", default=os.path.join(here, "../../target/release/gpmm"))
    t.add_argument("--landmark-weight", type=float, default=0.0)
    t.add_argument("--albedo", help="also write the model's mean colour on ICT's vertices (.npy, for make_set.py --albedo)")
    r = sub.add_parser("report", help="the floor and each detector's error against the truth and the model's points")
    r.add_argument("set")
    r.add_argument("defs")
    r.add_argument("points", nargs="*")
    w = sub.add_parser("write", help="the model's points of every image as .pts")
    w.add_argument("set")
    w.add_argument("defs")
    w.add_argument("out_dir")
    a = ap.parse_args()
    {"transfer": transfer, "report": report, "write": write}[a.cmd](a)


if __name__ == "__main__":
    main()
