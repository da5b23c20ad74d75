//! Loading the synthetic world: the ICT identity model with its holes closed, the template's
//! albedo transferred onto it, identities and their rendered views (see the module docs of [`super`]).

use super::*;

impl SynthWorld {
    /// Loads and checks the ICT model and the template, closes the holes and transfers the albedo.
    pub fn load(options: &SynthOptions) -> Result<Self, SynthError> {
        options.validate()?;
        let dir = &options.ict_dir;
        let neutral_path = dir.join("neutral.npy");
        let modes_path = dir.join("identity_modes.npy");
        let tri_path = dir.join("triangles.npy");
        let lm_path = dir.join("landmarks_ibug68.json");
        let data_err = |path: &Path, message: String| SynthError::Data { path: path.to_path_buf(), message };

        let (shape, neutral_cm) = npy::read_f32(&neutral_path)?;
        if shape.len() != 2 || shape[1] != 3 || shape[0] < IBUG68_COUNT {
            return Err(data_err(&neutral_path, format!("expected shape (N, 3) with N >= {IBUG68_COUNT}, found {shape:?}")));
        }
        let n = shape[0];
        if !neutral_cm.iter().all(|v| v.is_finite()) {
            return Err(data_err(&neutral_path, "contains NaN or infinite values".into()));
        }
        let neutral: Vec<[f64; 3]> =
            neutral_cm.chunks_exact(3).map(|c| [10.0 * f64::from(c[0]), 10.0 * f64::from(c[1]), 10.0 * f64::from(c[2])]).collect();

        let (shape, tri_raw) = npy::read_u32(&tri_path)?;
        if shape.len() != 2 || shape[1] != 3 || shape[0] == 0 {
            return Err(data_err(&tri_path, format!("expected shape (T, 3), found {shape:?}")));
        }
        if let Some(bad) = tri_raw.iter().find(|&&i| i as usize >= n) {
            return Err(data_err(&tri_path, format!("vertex index {bad} out of range: {} has {n} vertices", neutral_path.display())));
        }
        let mut triangles: Vec<[u32; 3]> = tri_raw.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();

        let (shape, mut modes) = npy::read_f32(&modes_path)?;
        if shape.len() != 3 || shape[1] != n || shape[2] != 3 || shape[0] == 0 {
            return Err(data_err(&modes_path, format!("expected shape (K, {n}, 3) to match {}, found {shape:?}", neutral_path.display())));
        }
        if !modes.iter().all(|v| v.is_finite()) {
            return Err(data_err(&modes_path, "contains NaN or infinite values".into()));
        }
        let n_modes = options.modes.map_or(shape[0], |m| m.min(shape[0]));
        modes.truncate(n_modes * n * 3);
        for v in modes.iter_mut() {
            *v *= 10.0;
        }

        let (scheme, landmarks) = read_landmarks_json(&lm_path)
            .map_err(|e| SynthError::Data { path: lm_path.clone(), message: strip_path(&e.to_string(), &lm_path) })?;
        if scheme != "ibug68" || landmarks.len() != IBUG68_COUNT {
            return Err(data_err(&lm_path, format!("expected scheme ibug68 with 68 ids, found {scheme:?} with {} ids", landmarks.len())));
        }
        if let Some((k, id)) = landmarks.iter().enumerate().find(|(_, &id)| id as usize >= n) {
            return Err(data_err(&lm_path, format!("landmark {k} refers to vertex {id} but the mesh has {n} vertices")));
        }

        // The neutral in its face frame (the albedo is transferred there; bump centres live there).
        let neutral_face = to_face_frame(&neutral, &landmarks).map_err(|m| data_err(&lm_path, m.to_string()))?;
        // Winding: counter-clockwise seen from outside means the summed normal points toward +z (the camera).
        let mut nz = 0.0;
        for t in &triangles {
            let [a, b, c] = t.map(|i| neutral_face[i as usize]);
            nz += cross(sub(b, a), sub(c, a))[2];
        }
        let flipped = nz < 0.0;
        if flipped {
            for t in triangles.iter_mut() {
                t.swap(1, 2);
            }
        }

        // Close the inner boundary loops.
        let loops = boundary_loops(&triangles, n);
        let lm_pos = |ids: std::ops::Range<usize>| -> [f64; 3] {
            let s = ids.clone().fold([0.0; 3], |acc, k| add(acc, neutral_face[landmarks[k] as usize]));
            mul(s, 1.0 / ids.len() as f64)
        };
        let targets = [(lm_pos(36..42), HoleKind::Eye), (lm_pos(42..48), HoleKind::Eye), (lm_pos(60..68), HoleKind::Mouth)];
        let eye_width = norm(sub(neutral_face[landmarks[39] as usize], neutral_face[landmarks[36] as usize]));
        let outer =
            loops.iter().enumerate().map(|(k, l)| (k, loop_length(l, &neutral_face))).max_by(|a, b| a.1.total_cmp(&b.1)).map(|(k, _)| k);
        let mut fans = Vec::new();
        for (k, ring) in loops.into_iter().enumerate() {
            if Some(k) == outer || ring.len() < 3 {
                continue;
            }
            let c = centroid(ring.iter().map(|&i| neutral_face[i as usize]));
            let kind = targets
                .iter()
                .map(|(p, kind)| (norm(sub(*p, c)), *kind))
                .min_by(|a, b| a.0.total_cmp(&b.0))
                .filter(|(d, _)| *d < eye_width)
                .map_or(HoleKind::Other, |(_, kind)| kind);
            let center = (n + fans.len()) as u32;
            // `ring` follows the boundary half-edges a -> b of its triangles; the fan uses b -> a.
            for w in 0..ring.len() {
                let (a, b) = (ring[w], ring[(w + 1) % ring.len()]);
                triangles.push([b, a, center]);
            }
            fans.push(Fan { ring, center, kind });
        }

        let template_albedo = transfer_albedo(options, &neutral_face, &landmarks)?;
        let mut base_albedo = template_albedo;
        for fan in &fans {
            let mean = mean3(fan.ring.iter().map(|&i| base_albedo[i as usize]));
            base_albedo.push(match fan.kind {
                HoleKind::Eye => [0.035, 0.03, 0.028],
                HoleKind::Mouth => mean.map(|c| 0.4 * c),
                HoleKind::Other => mean,
            });
        }
        Ok(Self {
            options: options.clone(),
            n_ict: n,
            n_modes,
            neutral,
            modes,
            triangles,
            fans,
            landmarks,
            base_albedo,
            neutral_face,
            flipped,
        })
    }

    /// Sizes of the loaded model.
    pub fn summary(&self) -> IctSummary {
        IctSummary {
            vertices: self.n_ict,
            modes: self.n_modes,
            triangles: self.triangles.len(),
            holes: self.fans.iter().map(|f| f.kind).collect(),
            flipped: self.flipped,
        }
    }

    /// The render triangles (ICT triangles, then the hole fans), counter-clockwise seen from outside.
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// The 68 landmark vertex ids.
    pub fn landmarks(&self) -> &[u32] {
        &self.landmarks
    }

    /// The transferred template albedo before per-identity variation (fan centres included).
    pub fn base_albedo(&self) -> &[Vec3] {
        &self.base_albedo
    }

    /// The world's mean face: the ICT neutral in its face frame (fan centres included, as
    /// [`Self::identity`] places them) with the transferred template albedo, no variation.
    pub fn mean_face(&self) -> (Vec<Vec3>, Vec<Vec3>) {
        let mut positions: Vec<Vec3> = self.neutral_face.iter().map(|p| p.map(|v| v as f32)).collect();
        for fan in &self.fans {
            let c = centroid(fan.ring.iter().map(|&i| self.neutral_face[i as usize]));
            positions.push(c.map(|v| v as f32));
        }
        (positions, self.base_albedo.clone())
    }

    /// Identity `id`: random coefficients, shape in its face frame, varied albedo (deterministic for (seed, id)).
    pub fn identity(&self, id: usize) -> Result<Identity, SynthError> {
        let mut rng = stream(self.options.seed, id as u64, 0);
        let s = self.options.identity_scale;
        let coefficients: Vec<f32> = (0..self.n_modes).map(|_| s * rng.sample::<f32, _>(StandardNormal)).collect();
        let n = self.n_ict;
        let mut acc: Vec<f32> = self.neutral.iter().flat_map(|p| p.map(|v| v as f32)).collect();
        for (k, &w) in coefficients.iter().enumerate() {
            if w == 0.0 {
                continue;
            }
            for (a, m) in acc.iter_mut().zip(&self.modes[k * n * 3..(k + 1) * n * 3]) {
                *a += w * m;
            }
        }
        let raw: Vec<[f64; 3]> = acc.chunks_exact(3).map(|c| [f64::from(c[0]), f64::from(c[1]), f64::from(c[2])]).collect();
        let face = to_face_frame(&raw, &self.landmarks).map_err(|m| SynthError::Render { message: format!("identity {id}: {m}") })?;
        let mut positions: Vec<Vec3> = face.iter().map(|p| p.map(|v| v as f32)).collect();
        for fan in &self.fans {
            let c = centroid(fan.ring.iter().map(|&i| face[i as usize]));
            positions.push(c.map(|v| v as f32));
        }

        // Albedo variation.
        let brightness = rng.random_range(0.8f32..1.15);
        let tint = [0; 3].map(|_| (0.05 * rng.sample::<f32, _>(StandardNormal)).exp());
        let bumps: Vec<AlbedoBump> = (0..ALBEDO_BUMPS)
            .map(|_| {
                let v = rng.random_range(0..n);
                let center = self.neutral_face[v].map(|c| c as f32);
                let radius = rng.random_range(20.0f32..60.0);
                let g = 0.12 * rng.sample::<f32, _>(StandardNormal);
                let amplitude = [0; 3].map(|_| g + 0.04 * rng.sample::<f32, _>(StandardNormal));
                AlbedoBump { center, radius, amplitude }
            })
            .collect();
        let variation = AlbedoVariation { brightness, tint, bumps };
        let mut albedo = self.base_albedo.clone();
        for (i, a) in albedo.iter_mut().enumerate() {
            // Fan centres take the variation at their ring's centroid on the neutral.
            let p = if i < n {
                self.neutral_face[i]
            } else {
                let fan = &self.fans[i - n];
                centroid(fan.ring.iter().map(|&r| self.neutral_face[r as usize]))
            };
            let mut log = [0.0f32; 3];
            for b in &variation.bumps {
                let d2: f32 = (0..3).map(|k| (p[k] as f32 - b.center[k]).powi(2)).sum();
                let g = (-d2 / (b.radius * b.radius)).exp();
                for (l, amp) in log.iter_mut().zip(b.amplitude) {
                    *l += amp * g;
                }
            }
            for ((a, t), l) in a.iter_mut().zip(tint).zip(log) {
                *a = (*a * brightness * t * l.exp()).clamp(0.0, 1.0);
            }
        }
        Ok(Identity { id, coefficients, positions, albedo, variation })
    }

    /// Renders `identity` at the yaw `yaw_index` of the options, with that view's random pose, camera and light.
    pub fn render_view(&self, identity: &Identity, yaw_index: usize) -> Result<SynthFace, SynthError> {
        let o = &self.options;
        let yaw_deg = *o
            .yaws_deg
            .get(yaw_index)
            .ok_or_else(|| SynthError::Options { message: format!("yaw index {yaw_index} is out of range ({} yaws)", o.yaws_deg.len()) })?;
        let expected = self.base_albedo.len();
        if identity.positions.len() != expected || identity.albedo.len() != expected {
            return Err(SynthError::Options {
                message: format!(
                    "identity {} has {} positions and {} colours, the world has {expected} vertices",
                    identity.id,
                    identity.positions.len(),
                    identity.albedo.len()
                ),
            });
        }
        let mut rng = stream(o.seed, identity.id as u64, 1 + yaw_index as u64);
        let size = o.size;
        let m = o.max_pitch_roll_deg;
        let pitch_deg = if m > 0.0 { rng.random_range(-m..=m) } else { 0.0 };
        let roll_deg = if m > 0.0 { rng.random_range(-m..=m) } else { 0.0 };
        let fov_deg = rng.random_range(o.fov_deg[0]..=o.fov_deg[1]);
        let fill = rng.random_range(o.face_fill[0]..=o.face_fill[1]);
        let shift = [rng.random_range(-0.05f32..=0.05), rng.random_range(-0.05f32..=0.05)];
        let focal = Camera::focal_from_fov(size, fov_deg.to_radians());
        let camera = Camera::centered(size, size, focal);

        // Framing: the face (chin to forehead) fills `fill` of the image height.
        let lm = |k: usize| identity.positions[self.landmarks[k] as usize];
        let chin = lm(8)[1];
        let eyes = (lm(36)[1] + lm(39)[1] + lm(42)[1] + lm(45)[1]) / 4.0;
        let top = lm(19)[1].max(lm(24)[1]) + 0.5 * (eyes - chin);
        let height = (top - chin).max(1.0);
        let distance = focal * height / (fill * size as f32);
        let center = [0.0, 0.5 * (top + chin), 0.0];
        let mut pose =
            Pose { yaw: yaw_deg.to_radians(), pitch: pitch_deg.to_radians(), roll: roll_deg.to_radians(), translation: [0.0; 3] };
        let rc = pose.transform_point(center);
        let px_to_mm = distance / focal;
        // Image x right = camera +x; image y down = camera −y.
        let off = [shift[0] * size as f32 * px_to_mm, -shift[1] * size as f32 * px_to_mm];
        pose.translation = [off[0] - rc[0], off[1] - rc[1], -distance - rc[2]];

        // Light: ambient plus one directional term no stronger than it.
        let a = rng.random_range(0.55f32..0.85);
        let light_ambient = [0; 3].map(|_| a * rng.random_range(0.95f32..1.05));
        let d = rng.random_range(0.15f32..0.45);
        let light_diffuse: [f32; 3] = std::array::from_fn(|c| (d * rng.random_range(0.95f32..1.05)).min(light_ambient[c]));
        let theta = rng.random_range(0.0f32..70.0).to_radians();
        let phi = rng.random_range(-std::f32::consts::PI..std::f32::consts::PI);
        let light_direction = [theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()];
        let light = ShLight::from_ambient_diffuse(light_ambient, light_diffuse, light_direction);
        let background_rgb = [0; 3].map(|_| rng.random_range(0.1f32..0.9));

        // Render.
        let n = identity.positions.len();
        let mut normals = vec![[0.0f32; 3]; n];
        let mut projected = vec![ProjectedVertex::INVALID; n];
        vertex_stage(&identity.positions, &identity.albedo, &self.triangles, &pose, &camera, &light, &mut normals, &mut projected)
            .map_err(|e| SynthError::Render { message: format!("vertex stage: {e}") })?;
        let mut raster: Box<TileRasterizer<TILE, TILE, BIN>> = Box::new(TileRasterizer::new());
        let mut sink = FrameSink::new(size, size);
        raster
            .render(&projected, &self.triangles, size, size, Cull::Clockwise, &mut sink)
            .map_err(|e| SynthError::Render { message: format!("rasterizer: {e}") })?;

        let sigma = o.background_noise;
        let mut image = RgbImage::new(size, size);
        let mut covered = 0usize;
        for (i, px) in image.pixels_mut().enumerate() {
            let noise: [f32; 3] = [0; 3].map(|_| sigma * rng.sample::<f32, _>(StandardNormal));
            let c = match sink.color[i] {
                Some(c) => {
                    covered += 1;
                    c
                }
                None => std::array::from_fn(|k| background_rgb[k] + noise[k]),
            };
            *px = Rgb(c.map(to_u8));
        }

        // Landmarks and their visibility (depth test against the rendered surface around them).
        let mut landmarks = Vec::with_capacity(IBUG68_COUNT);
        let mut landmarks_visible = Vec::with_capacity(IBUG68_COUNT);
        let tol = (3.0 * px_to_mm).max(5.0);
        for &id in &self.landmarks {
            let q = pose.transform_point(identity.positions[id as usize]);
            let (pt, vis) = match camera.project(q) {
                Some(s) => ([s.x, s.y], sink.visible(s.x, s.y, -q[2], tol)),
                None => ([f32::NAN, f32::NAN], false),
            };
            landmarks.push(pt);
            landmarks_visible.push(vis);
        }
        if landmarks.iter().flatten().any(|v| !v.is_finite()) {
            return Err(SynthError::Render { message: format!("identity {}: a landmark is behind the camera", identity.id) });
        }
        let stem = format!("{:04}_yaw{}", identity.id, yaw_tag(yaw_deg));
        let truth = ImageTruth {
            image: format!("{stem}.png"),
            landmarks_file: format!("{stem}.pts"),
            identity: identity.id,
            yaw_index,
            yaw_deg,
            pitch_deg,
            roll_deg,
            translation_mm: pose.translation,
            focal_px: focal,
            fov_deg,
            principal_px: camera.principal,
            width: size,
            height: size,
            light: light.coeffs,
            light_ambient,
            light_diffuse,
            light_direction,
            background_rgb,
            background_noise: sigma,
            shape_coefficients: identity.coefficients.clone(),
            landmarks,
            landmarks_visible,
            face_fraction: covered as f32 / (size as f32 * size as f32),
        };
        Ok(SynthFace { image, truth })
    }
}
