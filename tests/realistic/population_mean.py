#!/usr/bin/env python3
"""What a learned model could reach: a gpmm model given the population's mean face as its mean.

`gpmm learn` moves a model's mean toward the faces it sees. How far it could usefully go is
measured with a model whose mean is the population's own, as far as the model's topology and
span can hold it: ICT's neutral face (the mean of the world the realistic sets are drawn from),
registered into the model (`gpmm register`, ICT's landmarks as anchors), then brought into the
model's frame by the similarity that best aligns it to the model's mean. Its components are the
model's own. Two further changes isolate what else the figures depend on:

    python population_mean.py make MODEL -o OUT.gpmm [--ict-landmarks] [--prior-scale S] [--gpmm BIN]
    python population_mean.py offsets MODEL [MODEL ...] --reference REF.gpmm [--name TITLE ...] -o OFFSETS.png

make writes the model with the population's mean. --ict-landmarks also moves its 68 landmark
vertices to ICT's convention (the registered vertex nearest each of ICT's landmark vertices), so
that fits to ICT's exact points pull on the points ICT marks; --prior-scale S multiplies the shape
prior's standard deviation by S (fields × S, eigenvalues × S²).
offsets draws, for each MODEL, how far its mean shape lies from REF's (e.g. a model made by `make`)
along REF's normals, after the best similarity: red where the model lies outside, blue inside.
Printed: per model, the median and mean distance and the median share of the first model's offset
it closes where that offset exceeds 1.5 mm (give the model learning started from first).
"""
import argparse, json, os, struct, sys
import numpy as np
from make_set import Ict  # the same directory: ICT's faces
from landmark_definitions import model_tensor, registered_ict


def read_container(path):
    """(raw bytes, header, data start) of a .gpmm file (a safetensors container, docs/model-format.md)."""
    raw = open(path, "rb").read()
    if len(raw) < 8:
        sys.exit(f"{path}: too short to be a gpmm model")
    n = struct.unpack("<Q", raw[:8])[0]
    try:
        header = json.loads(raw[8:8 + n])
    except ValueError as e:
        sys.exit(f"{path}: not a gpmm model (its header is not JSON: {e})")
    for name in ("shape.mean", "shape.fields", "shape.eigenvalues", "landmarks", "triangles"):
        if name not in header:
            sys.exit(f"{path}: no '{name}' tensor; is it a gpmm model?")
    return bytearray(raw), header, 8 + n


def replace(raw, header, start, name, values):
    """Writes `values` over tensor `name` (same dtype and size)."""
    a, b = header[name]["data_offsets"]
    dtype = {"U32": "<u4", "F32": "<f4", "F64": "<f8"}[header[name]["dtype"]]
    data = np.ascontiguousarray(values, dtype=dtype).tobytes()
    if len(data) != b - a:
        sys.exit(f"tensor {name}: {len(data)} bytes for {b - a}")
    raw[start + a:start + b] = data


def similarity(src, dst):
    """`src` moved by the similarity (rotation, translation, scale) that best aligns it to `dst` (least squares)."""
    ms, md = src.mean(0), dst.mean(0)
    s, d = src - ms, dst - md
    u, sv, vt = np.linalg.svd(d.T @ s)
    flip = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    rot = u @ flip @ vt
    scale = (sv * np.diag(flip)).sum() / (s ** 2).sum()
    return scale * s @ rot.T + md


def make(a):
    ict = Ict(a.ict)
    raw, header, start = read_container(a.model)
    mean = model_tensor(a.model, "shape.mean").astype(np.float64)
    registered, _ = registered_ict(a.model, ict, a.gpmm)
    if registered.shape != mean.shape:
        sys.exit(f"{a.model}: the registered mesh has {len(registered)} vertices, the model {len(mean)}")
    replace(raw, header, start, "shape.mean", similarity(registered, mean))
    if a.ict_landmarks:
        targets = ict.neutral[ict.landmarks]
        d = np.linalg.norm(registered[None, :, :] - targets[:, None, :], axis=2)
        ids = d.argmin(axis=1)
        old = model_tensor(a.model, "landmarks").astype(np.int64)
        print(f"landmarks at ICT's points: {int((ids != old).sum())} of 68 moved; nearest vertex median {np.median(d.min(1)):.2f} mm, "
              f"max {d.min(1).max():.2f} mm from ICT's point", file=sys.stderr)
        replace(raw, header, start, "landmarks", ids)
    if a.prior_scale is not None:
        if not (a.prior_scale > 0 and np.isfinite(a.prior_scale)):
            sys.exit(f"--prior-scale {a.prior_scale}: a positive number")
        replace(raw, header, start, "shape.fields", model_tensor(a.model, "shape.fields") * a.prior_scale)
        replace(raw, header, start, "shape.eigenvalues", model_tensor(a.model, "shape.eigenvalues") * a.prior_scale ** 2)
    open(a.output, "wb").write(raw)
    print(f"wrote {a.output}", file=sys.stderr)


def vertex_normals(v, tris):
    n = np.zeros_like(v)
    face = np.cross(v[tris[:, 1]] - v[tris[:, 0]], v[tris[:, 2]] - v[tris[:, 0]])
    for k in range(3):
        np.add.at(n, tris[:, k], face)
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)


def offsets(a):
    from PIL import Image, ImageDraw
    ref = model_tensor(a.reference, "shape.mean").astype(np.float64)
    normals = vertex_normals(ref, model_tensor(a.reference, "triangles").astype(np.int64))
    columns = []
    names = a.name or []
    if len(names) > len(a.models):
        sys.exit(f"{len(names)} --name for {len(a.models)} models")
    for i, path in enumerate(a.models):
        m = model_tensor(path, "shape.mean").astype(np.float64)
        if m.shape != ref.shape:
            sys.exit(f"{path}: {len(m)} vertices, the reference {len(ref)}: not the same topology")
        name = names[i] if i < len(names) else os.path.join(os.path.basename(os.path.dirname(os.path.abspath(path))), os.path.basename(path))
        columns.append((name, ((similarity(m, ref) - ref) * normals).sum(1)))
    gap = columns[0][1]
    far = np.abs(gap) > 1.5
    for name, off in columns:
        closed = np.median(1 - off[far] / gap[far]) if far.any() else float("nan")
        print(f"{name}: |offset| median {np.median(np.abs(off)):.2f} mm, mean {np.abs(off).mean():.2f} mm; "
              f"gap closed where the first model is > 1.5 mm off ({far.mean():.0%} of vertices): median {closed:.2f}")
    cell, pad, lim = 260, 24, a.limit
    xy = ref[:, :2]
    lo, hi = xy.min(0), xy.max(0)
    k = (cell - 20) / (hi - lo).max()
    img = Image.new("RGB", (cell * len(columns), cell + pad), "white")
    draw = ImageDraw.Draw(img)
    order = np.argsort(ref[:, 2])  # far vertices first: the near ones are drawn over them
    for c, (name, off) in enumerate(columns):
        draw.text((c * cell + 8, 4), name[:34], fill="black")
        for i in order:
            t = float(np.clip(off[i] / lim, -1, 1))
            colour = (255, int(255 * (1 - t)), int(255 * (1 - t))) if t > 0 else (int(255 * (1 + t)), int(255 * (1 + t)), 255)
            x = c * cell + 10 + (xy[i, 0] - lo[0]) * k
            y = pad + 10 + (hi[1] - xy[i, 1]) * k
            draw.ellipse([x - 1.5, y - 1.5, x + 1.5, y + 1.5], fill=colour)
    draw.text((8, cell + pad - 14), f"red: outside the reference, blue: inside; full colour at {lim:g} mm", fill="black")
    img.save(a.output)
    print(f"wrote {a.output}", file=sys.stderr)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ict", default=os.path.join(os.environ.get("GPMM_DATA", "../shared/data"), "ict"), help="ICT data directory")
    sub = ap.add_subparsers(dest="cmd", required=True)
    m = sub.add_parser("make", help="the model with the population's mean")
    m.add_argument("model")
    m.add_argument("-o", "--output", required=True)
    m.add_argument("--ict-landmarks", action="store_true", help="move the landmark vertices to ICT's convention")
    m.add_argument("--prior-scale", type=float, help="multiply the shape prior's standard deviation by this")
    m.add_argument("--gpmm", default="gpmm", help="the gpmm program")
    o = sub.add_parser("offsets", help="a picture of how far models' means lie from a reference's")
    o.add_argument("models", nargs="+")
    o.add_argument("--reference", required=True)
    o.add_argument("--name", action="append", help="a column's title, once per model in order (default: the file's folder and name)")
    o.add_argument("--limit", type=float, default=4.0, help="offset (mm) drawn in full colour")
    o.add_argument("-o", "--output", required=True)
    a = ap.parse_args()
    {"make": make, "offsets": offsets}[a.cmd](a)


if __name__ == "__main__":
    main()
