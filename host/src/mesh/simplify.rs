//! Mesh simplification to a vertex budget (meshoptimizer's attribute-aware simplifier), shared by
//! the template import and the device quantization: locked vertices (the landmarks) are kept,
//! colours weigh as attributes, vertices are never moved, only dropped.

use meshopt::{SimplifyOptions, VertexDataAdapter};

/// Rounds of meshoptimizer, each aiming at fewer triangles, before giving up.
const MAX_ROUNDS: usize = 40;

/// Why a mesh could not be simplified to its budget.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimplifyError {
    /// The budget is below the vertices that must be kept.
    #[error("cannot simplify to {target} vertices: the {locked} landmark vertices must be kept")]
    BelowLocked {
        /// The vertex budget.
        target: usize,
        /// The locked vertices.
        locked: usize,
    },
    /// Colours or indices do not match the vertices.
    #[error("inconsistent mesh: colours or indices do not match the vertices")]
    Inconsistent,
    /// meshoptimizer refused the vertex data.
    #[error("meshopt: {0}")]
    Meshopt(String),
    /// Every round kept more vertices than the budget.
    #[error("could not simplify {vertices} vertices to at most {target}")]
    OverBudget {
        /// The mesh's vertices.
        vertices: usize,
        /// The vertex budget.
        target: usize,
    },
}

/// A simplification: the kept vertex ids (ascending) and the kept triangles in source ids.
#[derive(Debug, Clone, PartialEq)]
pub struct Simplified {
    /// Kept vertex ids, ascending: the vertices of the kept triangles plus the locked ones.
    pub kept: Vec<u32>,
    /// Kept triangles, in the source's vertex ids.
    pub triangles: Vec<[u32; 3]>,
}

/// Simplifies to at most `target` vertices: `positions` and `colors` per vertex, `locked` vertex
/// ids always kept. Within the budget everything is kept as it is.
pub fn simplify_to(
    positions: &[[f32; 3]],
    colors: &[[f32; 3]],
    triangles: &[[u32; 3]],
    locked: &[u32],
    target: usize,
) -> Result<Simplified, SimplifyError> {
    let n = positions.len();
    if n <= target {
        return Ok(Simplified { kept: (0..n as u32).collect(), triangles: triangles.to_vec() });
    }
    if target < locked.len() {
        return Err(SimplifyError::BelowLocked { target, locked: locked.len() });
    }
    if colors.len() != n || locked.iter().chain(triangles.iter().flatten()).any(|&i| i as usize >= n) {
        return Err(SimplifyError::Inconsistent);
    }
    let attributes: Vec<f32> = colors.iter().flatten().copied().collect();
    let weights = [0.5f32; 3];
    let mut lock = vec![false; n];
    for &id in locked {
        lock[id as usize] = true;
    }
    let indices: Vec<u32> = triangles.iter().flatten().copied().collect();
    let stride = std::mem::size_of::<[f32; 3]>();
    let adapter =
        VertexDataAdapter::new(meshopt::typed_to_bytes(positions), stride, 0).map_err(|e| SimplifyError::Meshopt(e.to_string()))?;
    let mut target_indices = ((indices.len() as f64) * target as f64 / n as f64) as usize / 3 * 3;
    for _ in 0..MAX_ROUNDS {
        let out = meshopt::simplify_with_attributes_and_locks(
            &indices,
            &adapter,
            &attributes,
            &weights,
            stride,
            &lock,
            target_indices,
            1.0,
            SimplifyOptions::None,
            None,
        );
        let mut used = lock.clone();
        for &i in &out {
            if let Some(u) = used.get_mut(i as usize) {
                *u = true;
            }
        }
        let count = used.iter().filter(|&&u| u).count();
        if count <= target {
            let kept = (0..n as u32).filter(|&i| used[i as usize]).collect();
            return Ok(Simplified { kept, triangles: out.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect() });
        }
        let next = ((target_indices as f64) * target as f64 / count as f64 * 0.98) as usize / 3 * 3;
        target_indices = if next == 0 || next >= target_indices { target_indices.saturating_sub(3) } else { next };
        if target_indices == 0 {
            break;
        }
    }
    Err(SimplifyError::OverBudget { vertices: n, target })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Positions, colours and triangles.
    type Grid = (Vec<[f32; 3]>, Vec<[f32; 3]>, Vec<[u32; 3]>);

    /// A flat grid of `k × k` vertices, two triangles per cell.
    fn grid(k: u32) -> Grid {
        let pos = (0..k * k).map(|i| [(i % k) as f32, (i / k) as f32, 0.0]).collect();
        let col = (0..k * k).map(|i| [0.5, (i % 7) as f32 / 7.0, 0.2]).collect();
        let mut tris = Vec::new();
        for y in 0..k - 1 {
            for x in 0..k - 1 {
                let i = y * k + x;
                tris.push([i, i + 1, i + k]);
                tris.push([i + 1, i + k + 1, i + k]);
            }
        }
        (pos, col, tris)
    }

    #[test]
    fn keeps_the_locked_vertices_within_the_budget() {
        let (pos, col, tris) = grid(30);
        let locked = [0, 29, 450, 899];
        let s = simplify_to(&pos, &col, &tris, &locked, 200).unwrap();
        assert!(s.kept.len() <= 200 && s.kept.len() > 20, "{} kept", s.kept.len());
        assert!(locked.iter().all(|l| s.kept.contains(l)));
        assert!(s.triangles.iter().flatten().all(|i| s.kept.contains(i)));
        assert!(s.kept.windows(2).all(|w| w[0] < w[1]));
        assert_eq!(simplify_to(&pos, &col, &tris, &locked, 2000).unwrap().kept.len(), 900);
        assert!(simplify_to(&pos, &col, &tris, &locked, 3).is_err());
        assert!(simplify_to(&pos, &col[..5], &tris, &locked, 100).is_err());
    }
}
