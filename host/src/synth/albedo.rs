//! Albedo transfer from the template to the ICT neutral (closest point on the aligned template).

use super::*;
use crate::mesh::align::Similarity;
use crate::mesh::closest::{closest_on_triangle, Grid};

/// The template's colours on the ICT neutral (face frame) by landmark-aligned closest vertex.
pub(super) fn transfer_albedo(options: &SynthOptions, neutral_face: &[[f64; 3]], landmarks: &[u32]) -> Result<Vec<Vec3>, SynthError> {
    let dir = &options.template_dir;
    let topts = TemplateOptions { no_crop: true, ..Default::default() };
    let template =
        load_template(&dir.join("lee-perry-smith.ply"), &dir.join("landmarks_ibug68.json"), &topts).map_err(SynthError::Template)?;
    if template.landmarks.len() != IBUG68_COUNT {
        return Err(SynthError::Data {
            path: dir.join("landmarks_ibug68.json"),
            message: format!("the template needs {IBUG68_COUNT} iBUG landmarks, it has {}", template.landmarks.len()),
        });
    }
    let src: Vec<[f64; 3]> = (17..IBUG68_COUNT).map(|k| template.mesh.positions[template.landmarks[k] as usize]).collect();
    let dst: Vec<[f64; 3]> = (17..IBUG68_COUNT).map(|k| neutral_face[landmarks[k] as usize]).collect();
    let sim = Similarity::fit(&src, &dst)
        .ok_or_else(|| SynthError::Render { message: "cannot align the template to the ICT landmarks".into() })?;
    let aligned: Vec<[f64; 3]> = template.mesh.positions.iter().map(|&p| sim.apply(p)).collect();
    let grid = Grid::new(&aligned, 6.0);
    let mut incident: Vec<Vec<u32>> = vec![Vec::new(); aligned.len()];
    for (k, t) in template.mesh.triangles.iter().enumerate() {
        for &i in t {
            if let Some(list) = incident.get_mut(i as usize) {
                list.push(k as u32);
            }
        }
    }
    let colors = &template.mesh.colors;
    let color = |i: u32| colors.get(i as usize).map_or([0.5; 3], |c| c.map(|v| v as f32));
    Ok(neutral_face
        .iter()
        .map(|&p| {
            let Some(v) = grid.nearest(&aligned, p) else {
                return [0.5; 3];
            };
            // The closest point on the triangles around the closest vertex, colour interpolated there.
            let mut best = (norm(sub(aligned[v], p)), [v as u32; 3], [1.0, 0.0, 0.0]);
            for &k in &incident[v] {
                let t = template.mesh.triangles[k as usize];
                let (q, bary) = closest_on_triangle(p, t.map(|i| aligned[i as usize]));
                let d = norm(sub(q, p));
                if d < best.0 {
                    best = (d, t, bary);
                }
            }
            let (_, t, b) = best;
            let c = t.map(color);
            std::array::from_fn(|ch| (b[0] as f32) * c[0][ch] + (b[1] as f32) * c[1][ch] + (b[2] as f32) * c[2][ch])
        })
        .collect())
}
