//! Dense symmetric positive-definite solves by Cholesky, in fixed memory (the light solve's 9×9
//! systems, the shape solve's up to 70×70).

use crate::error::FitError;

/// Solves `A x = b` for the leading `n × n` block of a symmetric positive-definite `A` (its lower
/// triangle is read; it is overwritten by the Cholesky factor). Entries past `n` of the result
/// are zero. Errors with [`FitError::Singular`] on a non-positive or non-finite pivot.
pub(crate) fn solve<const N: usize>(a: &mut [[f32; N]; N], b: &[f32; N], n: usize) -> Result<[f32; N], FitError> {
    let n = n.min(N);
    let at = |a: &[[f32; N]; N], i: usize, j: usize| a.get(i).and_then(|r| r.get(j)).copied().unwrap_or(0.0);
    for j in 0..n {
        let mut d = at(a, j, j);
        for k in 0..j {
            d -= at(a, j, k) * at(a, j, k);
        }
        if !(d > 0.0 && d.is_finite()) {
            return Err(FitError::Singular);
        }
        let d = libm::sqrtf(d);
        if let Some(e) = a.get_mut(j).and_then(|r| r.get_mut(j)) {
            *e = d;
        }
        for i in j + 1..n {
            let mut s = at(a, i, j);
            for k in 0..j {
                s -= at(a, i, k) * at(a, j, k);
            }
            if let Some(e) = a.get_mut(i).and_then(|r| r.get_mut(j)) {
                *e = s / d;
            }
        }
    }
    // Forward: L y = b; backward: Lᵀ x = y.
    let mut y = [0.0f32; N];
    for i in 0..n {
        let mut s = b.get(i).copied().unwrap_or(0.0);
        for k in 0..i {
            s -= at(a, i, k) * y.get(k).copied().unwrap_or(0.0);
        }
        if let Some(e) = y.get_mut(i) {
            *e = s / at(a, i, i);
        }
    }
    let mut x = [0.0f32; N];
    for i in (0..n).rev() {
        let mut s = y.get(i).copied().unwrap_or(0.0);
        for k in i + 1..n {
            s -= at(a, k, i) * x.get(k).copied().unwrap_or(0.0);
        }
        if let Some(e) = x.get_mut(i) {
            *e = s / at(a, i, i);
        }
    }
    Ok(x)
}
