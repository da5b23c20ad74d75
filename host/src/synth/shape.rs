//! Geometry of the ICT face area: its face frame and its boundary loops (the holes to close).

use super::*;

pub(super) fn mean3(colors: impl Iterator<Item = Vec3>) -> Vec3 {
    let (s, n) = colors.fold(([0.0f32; 3], 0usize), |(s, n), c| ([s[0] + c[0], s[1] + c[1], s[2] + c[2]], n + 1));
    s.map(|v| v / n.max(1) as f32)
}

/// Maps `points` into the face frame of their iBUG-68 landmarks `ids` (the frame `template.rs`
/// normalizes to; no scaling). The error says why the landmarks define no frame.
pub(super) fn to_face_frame(points: &[[f64; 3]], ids: &[u32]) -> Result<Vec<[f64; 3]>, &'static str> {
    if ids.len() != IBUG68_COUNT {
        return Err("the face frame needs the 68 iBUG landmarks");
    }
    let lm: Vec<[f64; 3]> = ids.iter().map(|&i| points[i as usize]).collect();
    let frame = crate::mesh::template::ibug_frame(&lm)?;
    Ok(points
        .iter()
        .map(|p| {
            let d = sub(*p, frame.center);
            [dot(frame.axes[0], d), dot(frame.axes[1], d), dot(frame.axes[2], d)]
        })
        .collect())
}

/// Boundary loops (edges of exactly one triangle), each as a vertex list following the
/// triangles' own direction of the boundary half-edges.
pub(super) fn boundary_loops(triangles: &[[u32; 3]], n: usize) -> Vec<Vec<u32>> {
    use std::collections::HashMap;
    let mut count: HashMap<(u32, u32), u32> = HashMap::new();
    for t in triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *count.entry((a.min(b), a.max(b))).or_insert(0) += 1;
        }
    }
    // Boundary half-edges a -> b (as they occur in their triangle).
    let mut next: Vec<Vec<u32>> = vec![Vec::new(); n];
    let mut starts = Vec::new();
    for t in triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            if count.get(&(a.min(b), a.max(b))) == Some(&1) {
                next[a as usize].push(b);
                starts.push(a);
            }
        }
    }
    let mut loops = Vec::new();
    for &s in &starts {
        if next[s as usize].is_empty() {
            continue;
        }
        let mut ring = vec![s];
        let mut cur = s;
        while let Some(b) = next[cur as usize].pop() {
            if b == s {
                break;
            }
            ring.push(b);
            cur = b;
            if ring.len() > n {
                break;
            }
        }
        loops.push(ring);
    }
    loops
}

pub(super) fn loop_length(ring: &[u32], pos: &[[f64; 3]]) -> f64 {
    (0..ring.len()).map(|k| norm(sub(pos[ring[k] as usize], pos[ring[(k + 1) % ring.len()] as usize]))).sum()
}
