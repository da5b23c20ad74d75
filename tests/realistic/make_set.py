#!/usr/bin/env python3
"""Re-renders a `gpmm synth` set with an independent renderer (Mitsuba 3, path traced).

The scenes are the set's own (identities, poses, cameras from its truth.json), so its truth.json
and exact .pts stay valid; what changes is everything the project's renderer decides: light
transport (an environment light plus a sun with cast shadows, inter-reflections), the skin
albedo (a skin tone per identity, darker lips and brows, smooth variation; none of the template's
transferred colours), anti-aliasing and the background (a textured, blurred image instead of a
flat colour). Colours are written linear, as gpmm reads them (no gamma).

    python make_set.py SYNTH_DIR OUT_DIR [--spp 64] [--scale 2] [--seed 0] [--ict DIR] [--wide K1,K2] [--person]
                       [--sun-off] [--flat-background] [--unpainted-skin] [--albedo NPY]

--wide puts each face small in a wider frame: the frame is K (drawn from K1..K2) times the
scene's size across its shorter side, 4:3 or 3:4, the face anywhere in it, the background drawn
for the whole frame. The camera is the scene's with its principal point moved with the face (a
crop of a larger frame); truth.json (sizes, principal points, landmarks) and the .pts follow.

--person (with --wide) draws a person around the face in the wider frame, in 2D behind the
render: a head of the face's skin tone, hair over and around it (sometimes long), a neck and
clothed shoulders down to the frame's edge. Photos show faces on people; the ICT mesh is a face
mask only. The shapes are drawn from the landmarks, by a generator of their own (none of gpmm's
training code), so the set tests what a head, hair and clothes around a face do to a detector.

Ablations (each changes one thing and keeps every random draw, so the rest of each image is the
same): --sun-off lights the face by the environment alone (its radiance raised by the sun's
share); --flat-background puts a mid-grey behind the face; --unpainted-skin leaves out the darker
lips and brows; --albedo NPY gives every face the per-vertex linear RGB colours of NPY (ICT's
vertex order, e.g. a model's colours from `landmark_definitions.py transfer --albedo`) instead of
the skin generator's. They measure which of the renderer's choices a detector is sensitive to.
"""
import argparse, json, math, os, shutil, sys
import numpy as np
from detect_landmarks import write_pts  # the same directory; mediapipe is imported only to detect

MIRROR = [(0, 16), (1, 15), (2, 14), (3, 13), (4, 12), (5, 11), (6, 10), (7, 9), (17, 26), (18, 25), (19, 24), (20, 23),
          (21, 22), (31, 35), (32, 34), (36, 45), (37, 44), (38, 43), (39, 42), (40, 47), (41, 46), (48, 54), (49, 53),
          (50, 52), (59, 55), (58, 56), (60, 64), (61, 63), (67, 65)]


SUN_SHARE = 0.45  # the sun's irradiance over pi (a white surface facing it reflects this much)


def face_frame(lm):
    """gpmm's face frame of 68 iBUG landmarks (host/src/mesh/template.rs, ibug_frame)."""
    xs = sum(lm[r] - lm[l] for l, r in MIRROR)
    mids = sum(0.5 * (lm[l] + lm[r]) for l, r in MIRROR) / len(MIRROR)
    x = xs / np.linalg.norm(xs)
    up = lm[27] - lm[8]
    up = up - x * up.dot(x)
    y = up / np.linalg.norm(up)
    z = np.cross(x, y)
    c = lm.mean(axis=0)
    center = c - x * (c - mids).dot(x)
    return np.stack([x, y, z]), center


def rotation(yaw, pitch, roll):
    cy, sy, cp, sp, cr, sr = math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch), math.cos(roll), math.sin(roll)
    rz = np.array([[cr, -sr, 0], [sr, cr, 0], [0, 0, 1]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rx = np.array([[1, 0, 0], [0, cp, -sp], [0, sp, cp]])
    return rz @ ry @ rx


class Ict:
    """ICT's neutral face, identity modes, triangles and iBUG-68 vertex ids, in millimetres."""

    def __init__(self, d):
        self.neutral = np.load(os.path.join(d, "neutral.npy")).astype(np.float64) * 10.0
        self.modes = np.load(os.path.join(d, "identity_modes.npy"), mmap_mode="r")
        self.tris = np.load(os.path.join(d, "triangles.npy")).astype(np.int64)
        self.landmarks = np.array(json.load(open(os.path.join(d, "landmarks_ibug68.json")))["vertex_ids"])

    def shape(self, coeffs):
        """The identity with these shape coefficients (vertices in mm)."""
        c = np.asarray(coeffs, dtype=np.float64)
        return self.neutral + np.tensordot(c, self.modes[: len(c)].astype(np.float64), axes=1) * 10.0


def boundary_loops(tris, n):
    """Loops of edges used by one triangle, following the triangles' own direction."""
    count = {}
    for t in tris:
        for a, b in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])):
            k = (min(a, b), max(a, b))
            count[k] = count.get(k, 0) + 1
    nxt = {}
    for t in tris:
        for a, b in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])):
            if count[(min(a, b), max(a, b))] == 1:
                nxt[a] = b
    loops, seen = [], set()
    for s in list(nxt):
        if s in seen:
            continue
        loop, v = [], s
        while v not in seen and v in nxt:
            seen.add(v)
            loop.append(v)
            v = nxt[v]
        loops.append(loop)
    return loops


def project(p, f, cx, cy):
    return np.stack([cx + f * p[:, 0] / -p[:, 2], cy - f * p[:, 1] / -p[:, 2]], axis=1)


def skin_albedo(face, lm_ids, rng, painted=True):
    """A skin tone per identity, darker/redder lips, darker brows, smooth variation (linear RGB)."""
    tone = np.array([rng.uniform(0.35, 0.75), 0.0, 0.0])
    tone[1] = tone[0] * rng.uniform(0.62, 0.72)
    tone[2] = tone[0] * rng.uniform(0.48, 0.6)
    alb = np.tile(tone, (len(face), 1))
    lm = face[lm_ids]
    def blend(points, radius, color, strength):
        d = np.min(np.linalg.norm(face[:, None, :] - points[None, :, :], axis=2), axis=1)
        w = strength * np.exp(-(d / radius) ** 2)[:, None]
        return alb * (1 - w) + color * w
    if painted:
        alb = blend(lm[48:68], 4.0, tone * np.array([1.0, 0.55, 0.6]), 0.8)
        alb = blend(lm[17:27], 3.0, tone * 0.35, 0.7)
    for _ in range(6):
        c = face[rng.integers(len(face))]
        d = np.linalg.norm(face - c, axis=1)
        alb *= (1 + rng.normal(0, 0.08) * np.exp(-(d / rng.uniform(15, 50)) ** 2))[:, None]
    return np.clip(alb, 0.02, 0.95)


def background(w, h, rng):
    """Smooth colour blobs plus fine texture: not a flat colour, not a face."""
    yy, xx = np.mgrid[0:h, 0:w] / max(w, h)
    img = np.tile(rng.uniform(0.1, 0.8, 3), (h, w, 1))
    for _ in range(5):
        c, r, col = rng.uniform(0, 1, 2), rng.uniform(0.1, 0.5), rng.uniform(0.05, 0.9, 3)
        a = np.exp(-(((xx - c[0]) ** 2 + (yy - c[1]) ** 2) / r ** 2))[..., None]
        img = img * (1 - 0.7 * a) + col * 0.7 * a
    img += rng.normal(0, 0.03, (h, w, 1)) * np.sin(40 * xx + 25 * yy)[..., None]
    return np.clip(img, 0, 1)


def ellipse(xx, yy, cx, cy, rx, ry):
    return ((xx - cx) / rx) ** 2 + ((yy - cy) / ry) ** 2 < 1.0


def person(img, lm, skin, rng):
    """Paints a head, hair, neck and clothed shoulders around the face whose landmarks are `lm`
    (frame pixels) into `img` (H x W x 3, linear), in place."""
    h, w = img.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    jaw, brows = lm[0:17], lm[17:27]
    centre = lm[27:36].mean(axis=0)
    fw = max(np.ptp(jaw[:, 0]), 1.0)
    fh = max(lm[8, 1] - brows[:, 1].min(), 1.0)
    # The skull behind the face: shifted away from where the nose points.
    turn = (lm[30, 0] - 0.5 * (jaw[0, 0] + jaw[16, 0])) / fw
    hx = centre[0] - 0.9 * turn * fw
    hy = brows[:, 1].min() + 0.05 * fh
    rx, ry = fw * rng.uniform(0.62, 0.78), fh * rng.uniform(0.85, 1.0)
    shade = lambda c, v: np.clip(c * v, 0, 1)
    cloth = [np.array([0.03, 0.03, 0.05]), np.full(3, 0.7), rng.uniform(0.03, 0.6, 3)][rng.integers(3)]
    top = lm[8, 1] + rng.uniform(0.35, 0.8) * fh
    half = fw * rng.uniform(1.0, 1.4)
    torso = (yy > top + 0.5 * np.clip(np.abs(xx - hx) - 0.6 * fw, 0, None) * 0.6) & (np.abs(xx - hx) < half + (yy - top) * 0.25)
    img[torso] = shade(cloth, 0.8 + 0.2 * np.sin(xx[torso] / fw * 3)[:, None])
    neck = (np.abs(xx - (hx + 0.5 * (centre[0] - hx))) < 0.38 * fw) & (yy > lm[8, 1] - 0.3 * fh) & (yy < top + 0.2 * fh)
    img[neck] = shade(skin, 0.7)
    hair = None
    if rng.random() < 0.85:
        tone = [np.array([0.02, 0.015, 0.01]), np.array([0.1, 0.06, 0.03]), np.array([0.3, 0.2, 0.1]), np.array([0.5, 0.4, 0.25]), np.full(3, 0.4)][rng.integers(5)]
        grow = rng.uniform(1.05, 1.3)
        hair = ellipse(xx, yy, hx, hy - 0.1 * fh, rx * grow, ry * grow * 0.95)
        if rng.random() < 0.4:  # long: down past the chin
            length = lm[8, 1] + rng.uniform(0.0, 1.2) * fh
            hair |= (np.abs(xx - hx) < rx * grow) & (yy > hy) & (yy < length)
        streaks = 1 + 0.25 * np.sin(xx / max(fw, 1) * rng.uniform(20, 60)) * np.cos(yy / max(fh, 1) * 3)
        img[hair] = shade(tone, streaks[hair][:, None])
    head = ellipse(xx, yy, hx, hy, rx, ry)
    if hair is not None:
        head &= yy > brows[:, 1].min() - rng.uniform(0.1, 0.35) * fh
    img[head] = shade(skin, 0.85)


def widen(im, rgb, alpha, wide, rng, skin=None):
    """The render placed in a wider frame over a background drawn for that frame; `im` (the
    truth.json entry) is updated to the new frame."""
    h, w = rgb.shape[:2]
    k = rng.uniform(*wide)
    long_side = rng.random() < 0.5
    big_w, big_h = (round(k * w * 4 / 3), round(k * h)) if long_side else (round(k * w), round(k * h * 4 / 3))
    ox, oy = int(rng.integers(0, big_w - w + 1)), int(rng.integers(0, big_h - h + 1))
    out = background(big_w, big_h, rng)
    if skin is not None:
        person(out, np.array(im["landmarks"]) + np.array([ox, oy]), skin, rng)
    region = out[oy:oy + h, ox:ox + w]
    out[oy:oy + h, ox:ox + w] = rgb + (1 - alpha) * region
    im["width"], im["height"] = big_w, big_h
    im["face_fraction"] = im.get("face_fraction", 0.0) * (w * h) / (big_w * big_h)
    im["principal_px"] = [im["principal_px"][0] + ox, im["principal_px"][1] + oy]
    im["landmarks"] = [[x + ox, y + oy] for x, y in im["landmarks"]]
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("synth_dir")
    ap.add_argument("out_dir")
    ap.add_argument("--ict", default=os.environ.get("GPMM_DATA", os.path.join(os.path.dirname(__file__), "../../../shared/data")) + "/ict")
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--scale", type=int, default=2, help="render at this multiple of the size, then box-downsample")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--wide", help="K1,K2: a frame K1..K2 times the scene's size, the face placed anywhere in it")
    ap.add_argument("--person", action="store_true", help="with --wide: a head, hair, neck and clothes drawn around the face")
    ap.add_argument("--sun-off", action="store_true", help="ablation: no sun; the environment light takes its share")
    ap.add_argument("--flat-background", action="store_true", help="ablation: a mid-grey background (not with --wide)")
    ap.add_argument("--unpainted-skin", action="store_true", help="ablation: no darker lips and brows")
    ap.add_argument("--albedo", help="ablation: per-vertex linear RGB albedo (.npy, ICT's vertex order) for every face")
    a = ap.parse_args()
    if a.flat_background and a.wide:
        sys.exit("--flat-background is for sets without --wide (a wide frame draws its own background)")
    if a.person and not a.wide:
        sys.exit("--person needs --wide (the person is drawn in the wider frame)")
    wide = [float(v) for v in a.wide.split(",")] if a.wide else None
    if wide is not None and not (len(wide) == 2 and 1.0 <= wide[0] <= wide[1]):
        sys.exit(f"--wide takes K1,K2 with 1 <= K1 <= K2 (got {a.wide})")
    import mitsuba as mi  # only here: landmark_definitions.py imports this file's projection with numpy alone
    from PIL import Image
    mi.set_variant("scalar_rgb")
    truth = json.load(open(os.path.join(a.synth_dir, "truth.json")))
    ict = Ict(a.ict)
    neutral, tris, lm_ids = ict.neutral, ict.tris, ict.landmarks
    fixed_albedo = None
    if a.albedo:
        fixed_albedo = np.load(a.albedo)
        if fixed_albedo.shape != neutral.shape:
            sys.exit(f"{a.albedo}: shape {fixed_albedo.shape}, need {neutral.shape} (one RGB per ICT vertex)")
    loops = sorted(boundary_loops(tris.tolist(), len(neutral)), key=len)
    holes = loops[:-1]  # the longest loop is the outer border and stays open
    os.makedirs(a.out_dir, exist_ok=True)
    shutil.copy(os.path.join(a.synth_dir, "truth.json"), a.out_dir)
    worst = 0.0
    ids = {i["id"]: i for i in truth["identities"]}
    for k, im in enumerate(truth["images"]):
        shape = ict.shape(ids[im["identity"]]["shape_coefficients"])
        axes, center = face_frame(shape[lm_ids])
        face = (shape - center) @ axes.T
        # Close the eye and mouth holes with fans around their centroids (dark inside).
        verts, faces = [face], [tris]
        extra = len(face)
        for loop in holes:
            c = face[loop].mean(axis=0)
            verts.append(c[None, :])
            faces.append(np.array([[loop[j], loop[(j + 1) % len(loop)], extra] for j in range(len(loop))])[:, ::-1])
            extra += 1
        allv = np.concatenate(verts)
        allf = np.concatenate(faces)
        rng = np.random.default_rng([a.seed, im["identity"]])
        alb = np.concatenate([skin_albedo(face, lm_ids, rng, painted=not a.unpainted_skin), np.full((len(holes), 3), 0.03)])
        if fixed_albedo is not None:
            alb[: len(face)] = fixed_albedo
        rot = rotation(*(math.radians(im[key]) for key in ("yaw_deg", "pitch_deg", "roll_deg")))
        cam = allv @ rot.T + np.array(im["translation_mm"])
        w, h, f = im["width"], im["height"], im["focal_px"]
        cx, cy = im["principal_px"]
        pts = project(cam[lm_ids], f, cx, cy)
        worst = max(worst, float(np.abs(pts - np.array(im["landmarks"])).max()))
        view_rng = np.random.default_rng([a.seed, im["identity"], im["yaw_index"], 7])
        props = mi.Properties()
        props["bsdf"] = mi.load_dict({"type": "twosided", "material": {"type": "diffuse", "reflectance": {"type": "mesh_attribute", "name": "vertex_color"}}})
        mesh = mi.Mesh("face", len(cam), len(allf), props=props, has_vertex_normals=False)
        params = mi.traverse(mesh)
        params["vertex_positions"] = cam.astype(np.float32).ravel().tolist()
        params["faces"] = allf.astype(np.uint32).ravel().tolist()
        params.update()
        mesh.add_attribute("vertex_color", 3, alb.astype(np.float32).ravel().tolist())
        sun = np.array(im["light_direction"]) + view_rng.normal(0, 0.3, 3)
        sun /= np.linalg.norm(sun)
        amb = float(np.mean(im["light_ambient"])) * view_rng.uniform(0.7, 1.0)
        scene = mi.load_dict({
            "type": "scene",
            "integrator": {"type": "path", "max_depth": 4, "hide_emitters": True},
            "sensor": {
                "type": "perspective", "fov_axis": "x", "fov": math.degrees(2 * math.atan(w / 2 / f)),
                "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 0], target=[0, 0, -1], up=[0, 1, 0]),
                "film": {"type": "hdrfilm", "width": w * a.scale, "height": h * a.scale, "pixel_format": "rgba", "rfilter": {"type": "box"}},
                "sampler": {"type": "independent", "sample_count": a.spp},
            },
            "face": mesh,
            "env": {"type": "constant", "radiance": {"type": "rgb", "value": ((amb + SUN_SHARE * a.sun_off) * np.array([1.0, 0.97, 0.92])).tolist()}},
            "sun": {"type": "directional", "direction": (-sun).tolist(), "irradiance": {"type": "rgb", "value": [0.0 if a.sun_off else math.pi * SUN_SHARE] * 3}},
        })
        img = np.array(mi.render(scene))
        img = img.reshape(h, a.scale, w, a.scale, 4).mean(axis=(1, 3))
        rgb, alpha = img[..., :3], img[..., 3:4]
        if wide is None:
            bg = background(w, h, view_rng)
            out = rgb + (1 - alpha) * (np.full_like(bg, 0.35) if a.flat_background else bg)
            shutil.copy(os.path.join(a.synth_dir, im["landmarks_file"]), a.out_dir)
        else:
            skin = None
            if a.person:  # the face's own linear skin tone, as rendered
                inside = alpha[..., 0] > 0.99
                skin = rgb[inside].mean(axis=0) if inside.any() else np.full(3, 0.4)
            out = widen(im, rgb, alpha, wide, np.random.default_rng([a.seed, im["identity"], im["yaw_index"], 11]), skin)
            write_pts(os.path.join(a.out_dir, im["landmarks_file"]), im["landmarks"])
        Image.fromarray((np.clip(out, 0, 1) * 255 + 0.5).astype(np.uint8)).save(os.path.join(a.out_dir, im["image"]))
        print(f"\r{k + 1}/{len(truth['images'])} {im['image']}", end="", file=sys.stderr)
    if wide is not None:
        json.dump(truth, open(os.path.join(a.out_dir, "truth.json"), "w"))
    print(f"\nlargest difference between our projection of the landmark vertices and the set's .pts: {worst:.4f} px", file=sys.stderr)


if __name__ == "__main__":
    main()
