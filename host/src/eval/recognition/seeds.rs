//! Rank-1 recognition over several fit seeds (`gpmm eval recognition --fit-seed 0,1,2,3`): one
//! seed's pooled accuracy moves by several points with the chains' random path, so a decision
//! between two settings reads the mean and the spread of a few seeds.

use super::report::RecognitionReport;
use crate::eval::{create_dir, write_text, EvalError};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// One model's pooled rank-1 accuracy per seed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SeedRow {
    /// Model label (as in each seed's report).
    pub label: String,
    /// Pooled accuracy (0–1) per seed, in the order of [`SeedSummary::seeds`].
    pub per_seed: Vec<f64>,
    /// Mean over the seeds.
    pub mean: f64,
    /// Smallest of the seeds.
    pub min: f64,
    /// Largest of the seeds.
    pub max: f64,
}

/// The pooled accuracies of every model over the seeds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SeedSummary {
    /// The fit seeds, one report each.
    pub seeds: Vec<u64>,
    /// Chance rate (1 / gallery size).
    pub chance: f64,
    /// One row per model of the first report (a model missing from a later report is an error).
    pub rows: Vec<SeedRow>,
    /// The command line.
    pub command: String,
}

/// Gathers `reports` (one per seed of `seeds`, same models) into one row per model.
pub fn summarize(seeds: &[u64], reports: &[RecognitionReport], command: String) -> Result<SeedSummary, EvalError> {
    let first = match reports.first() {
        Some(r) if reports.len() == seeds.len() => r,
        _ => return Err(EvalError::Invalid(format!("{} reports for {} seeds", reports.len(), seeds.len()))),
    };
    let rows = first
        .rows
        .iter()
        .map(|row| {
            let per_seed = reports
                .iter()
                .zip(seeds)
                .map(|(r, seed)| {
                    r.rows
                        .iter()
                        .find(|x| x.label == row.label)
                        .map(|x| x.pooled.accuracy)
                        .ok_or_else(|| EvalError::Invalid(format!("model {} has no result with fit seed {seed}", row.label)))
                })
                .collect::<Result<Vec<f64>, _>>()?;
            let n = per_seed.len().max(1) as f64;
            Ok(SeedRow {
                label: row.label.clone(),
                mean: per_seed.iter().sum::<f64>() / n,
                min: per_seed.iter().copied().fold(f64::INFINITY, f64::min),
                max: per_seed.iter().copied().fold(f64::NEG_INFINITY, f64::max),
                per_seed,
            })
        })
        .collect::<Result<Vec<_>, EvalError>>()?;
    Ok(SeedSummary { seeds: seeds.to_vec(), chance: first.chance, rows, command })
}

/// The summary as a Markdown table (percent, one decimal).
pub fn markdown(s: &SeedSummary) -> String {
    let pct = |v: f64| format!("{:.1}", 100.0 * v);
    let mut out = String::from("# Rank-1 recognition over fit seeds (all probes pooled)\n\n| model |");
    for seed in &s.seeds {
        out.push_str(&format!(" seed {seed} |"));
    }
    out.push_str(" mean | min | max |\n|---|");
    out.push_str(&"---|".repeat(s.seeds.len() + 3));
    out.push('\n');
    for r in &s.rows {
        out.push_str(&format!("| {} |", r.label));
        for v in &r.per_seed {
            out.push_str(&format!(" {} |", pct(*v)));
        }
        out.push_str(&format!(" **{}** | {} | {} |\n", pct(r.mean), pct(r.min), pct(r.max)));
    }
    out.push_str(&format!("\nChance {} %. Each seed's full report: `seed-N/recognition.md`.\n\nCommand: `{}`\n", pct(s.chance), s.command));
    out
}

/// Writes `seeds.md` and `seeds.json` into `out`.
pub fn write_summary(s: &SeedSummary, out: &Path) -> Result<(), EvalError> {
    create_dir(out)?;
    write_text(&out.join("seeds.md"), &markdown(s))?;
    let json = serde_json::to_string_pretty(s).map_err(|error| EvalError::Json { what: "seed summary", error })?;
    write_text(&out.join("seeds.json"), &(json + "\n"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_report_per_seed_is_required() {
        let e = summarize(&[0, 1], &[], String::new()).unwrap_err();
        assert!(e.to_string().contains("0 reports for 2 seeds"), "{e}");
    }
}
