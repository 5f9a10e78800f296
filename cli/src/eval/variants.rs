//! The evaluation repeated: once per colour cast (`--cast`, [`fusepose_scene::render::cast`])
//! and per sampling seed (`--seeds N`: seeds `seed`, `seed + 1`, …), then one
//! summary row per cast and run, with the mean and standard deviation over
//! the seeds.
//!
//! The network samples each region's points at random, and one seed is one
//! draw: on the tuning splits a single run moved by up to 3.5 ADD(S) and 0.25
//! ghosts per frame between seeds (docs/BENCHMARKS.md, session 25), as much
//! as most changes it was used to judge.

use std::path::PathBuf;

use super::Args;
use fusepose_scene::render::cast::Cast;

/// Runs `run_one` once per cast and seed (a single cast and seed: just once,
/// as it always did), then prints the summary. `run_one` returns the
/// summaries `--json` writes, keyed by run name. Output files of each variant
/// get a `_<cast>` and / or `_seed<N>` suffix.
pub fn run_each(
    args: Args,
    run_one: impl Fn(Args) -> anyhow::Result<serde_json::Map<String, serde_json::Value>>,
) -> anyhow::Result<()> {
    let mut casts = args.cast.clone();
    casts.dedup();
    let seeds = args.seeds.max(1);
    if casts.len() <= 1 && seeds == 1 {
        return run_one(args).map(|_| ());
    }
    // (cast, run name, each seed's overall summary)
    let mut rows: Vec<(Cast, String, Vec<serde_json::Value>)> = Vec::new();
    for &cast in &casts {
        for k in 0..seeds as u64 {
            let mut one = args.clone();
            one.cast = vec![cast];
            one.seeds = 1;
            one.seed = args.seed.wrapping_add(k);
            let mut tags = Vec::new();
            if casts.len() > 1 {
                tags.push(cast.name().to_string());
            }
            if seeds > 1 {
                tags.push(format!("seed{}", one.seed));
            }
            let tag = tags.join("_");
            let suffix = |p: &Option<PathBuf>| p.as_deref().map(|p| super::suffixed(p, &tag));
            (one.json, one.csv, one.per_object_csv, one.plot) =
                (suffix(&args.json), suffix(&args.csv), suffix(&args.per_object_csv), suffix(&args.plot));
            one.overlay = args.overlay.as_ref().map(|d| d.join(&tag));
            println!("\n=== colour cast: {}, sampling seed {} ===", cast.name(), one.seed);
            for (run, summary) in run_one(one)? {
                let Some(o) = summary.get("overall") else { continue };
                match rows.iter_mut().find(|(c, r, _)| *c == cast && *r == run) {
                    Some((_, _, all)) => all.push(o.clone()),
                    None => rows.push((cast, run, vec![o.clone()])),
                }
            }
        }
    }
    if seeds > 1 {
        println!("\nby colour cast, mean ± standard deviation over {seeds} sampling seeds (from {})", args.seed);
    } else {
        println!("\nby colour cast (issue 19 robustness column)");
    }
    println!(
        "{:<6}  {:<16}  {:>15}  {:>15}  {:>15}  {:>15}  {:>15}",
        "cast", "run", "ADD-S AUC", "ADD(S) AUC", "ADD-S<2cm", "ghosts/frame", "stray/frame"
    );
    for (cast, run, all) in &rows {
        println!("{}", summary_row(*cast, run, all));
    }
    Ok(())
}

/// One row: each number's mean over `all` (one overall summary per seed),
/// with ± its sample standard deviation when there are several.
fn summary_row(cast: Cast, run: &str, all: &[serde_json::Value]) -> String {
    let column = |f: &dyn Fn(&serde_json::Value) -> f64| {
        let v: Vec<f64> = all.iter().map(f).collect();
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        if v.len() < 2 {
            return format!("{mean:.2}");
        }
        let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        format!("{mean:.2} ± {sd:.2}")
    };
    let num = |o: &serde_json::Value, k: &str| o.get(k).and_then(serde_json::Value::as_f64).unwrap_or(f64::NAN);
    format!(
        "{:<6}  {:<16}  {:>15}  {:>15}  {:>15}  {:>15}  {:>15}",
        cast.name(),
        run,
        column(&|o| num(o, "add_s_auc")),
        column(&|o| num(o, "add_s_auc_symmetric_aware")),
        column(&|o| num(o, "add_s_lt_2cm")),
        column(&|o| num(o, "unmatched_estimates") / num(o, "frames").max(1.0)),
        column(&|o| num(o, "stray_poses") / num(o, "frames").max(1.0)),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn overall(add_s: f64, add: f64, ghosts: u64) -> serde_json::Value {
        serde_json::json!({"add_s_auc": add_s, "add_s_auc_symmetric_aware": add,
            "add_s_lt_2cm": 95.0, "unmatched_estimates": ghosts, "stray_poses": 2 * ghosts, "frames": 60})
    }

    #[test]
    fn one_seed_shows_the_overall_numbers_and_ghosts_and_strays_per_frame() {
        let row = summary_row(Cast::Cool, "net", &[overall(93.456, 80.0, 12)]);
        assert!(row.starts_with("cool    net"), "{row}");
        assert!(row.contains("93.46") && row.contains("80.00") && row.contains(" 0.20 "), "{row}");
        assert!(row.ends_with("0.40"), "{row}");
        assert!(!row.contains('±'), "{row}");
    }

    #[test]
    fn several_seeds_show_the_mean_and_the_sample_standard_deviation() {
        let row = summary_row(Cast::None, "net", &[overall(80.0, 70.0, 6), overall(82.0, 74.0, 18)]);
        // Means 81 and 72; sample sd of (80, 82) = √2, of (70, 74) = 2√2; ghosts 0.1 and 0.3 per
        // frame, strays twice that.
        assert!(row.contains("81.00 ± 1.41"), "{row}");
        assert!(row.contains("72.00 ± 2.83"), "{row}");
        assert!(row.contains("0.20 ± 0.14") && row.ends_with("0.40 ± 0.28"), "{row}");
    }
}
