//! Cross-validation of a study tune: the real runs split into `k` folds of
//! consecutive runs; each fold is held out once while the engine (and the
//! physics-free model behind its own actuator stage) is fitted on the
//! others; the held-out scores are then gathered over the folds.
//!
//! One split says little when the runs drift: a model that wins on runs
//! 16-20 may lose on runs 1-4. The folds are the same for every engine and
//! for both physics-free rows, so the differences pair up fold by fold.
//! A fold's own tune is an ordinary tune folder (`OUT/fold-N`), resumable
//! like any other; this module only splits and gathers.

use crate::outputs::{Comparison, Scored, Summary};
use anyhow::{bail, Result};
use serde::Serialize;

/// One fold: the runs it holds out; every other run is fitted on.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Fold {
    /// 1-based.
    pub number: usize,
    /// The held-out runs as a run range (`1-5`).
    pub holdout: String,
}

/// Runs `1..=runs` split into `k` folds of consecutive runs, in order;
/// sizes differ by at most one (20 runs in 4 folds: 1-5, 6-10, 11-15,
/// 16-20). Consecutive, not interleaved: the real runs were recorded in
/// order, and a fold that holds out a stretch of them tests what drifts.
pub fn folds(runs: usize, k: usize) -> Result<Vec<Fold>> {
    if k < 2 {
        bail!("--folds {k}: cross-validation needs at least 2 folds");
    }
    if k > runs {
        bail!("--folds {k}: the study has {runs} real runs per scene, so at most {runs} folds");
    }
    let mut out = Vec::with_capacity(k);
    let mut start = 1;
    for f in 0..k {
        let size = runs / k + usize::from(f < runs % k);
        let end = start + size - 1;
        out.push(Fold {
            number: f + 1,
            holdout: if size == 1 {
                start.to_string()
            } else {
                format!("{start}-{end}")
            },
        });
        start = end + 1;
    }
    Ok(out)
}

/// A quantity over the folds: each fold's value, their mean and standard
/// deviation, and a 95 % interval of the mean.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Spread {
    /// The mean over folds.
    pub mean: f64,
    /// The standard deviation over folds (n - 1).
    pub sd: f64,
    /// Student's t interval of the mean, 95 %. The folds share training
    /// runs, so their scores are not independent: read it as a lower bound
    /// on the uncertainty.
    pub interval: [f64; 2],
    /// Each fold's value, in fold order.
    pub folds: Vec<f64>,
}

impl Spread {
    /// The spread of `values`; `None` when there are fewer than two or one
    /// is missing or not finite.
    pub fn of(values: &[Option<f64>]) -> Option<Spread> {
        let v: Vec<f64> = values.iter().copied().collect::<Option<Vec<f64>>>()?;
        if v.len() < 2 || v.iter().any(|x| !x.is_finite()) {
            return None;
        }
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        let half = t975(v.len() - 1) * sd / n.sqrt();
        Some(Spread {
            mean,
            sd,
            interval: [mean - half, mean + half],
            folds: v,
        })
    }

    /// How many folds are below zero (for a difference: the folds the
    /// first source wins).
    pub fn below_zero(&self) -> usize {
        self.folds.iter().filter(|x| **x < 0.0).count()
    }
}

/// The 97.5th percentile of Student's t with `df` degrees of freedom.
fn t975(df: usize) -> f64 {
    const T: [f64; 30] = [
        12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160,
        2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056,
        2.052, 2.048, 2.045, 2.042,
    ];
    match df {
        0 => f64::NAN,
        d if d <= T.len() => T[d - 1],
        _ => 1.96,
    }
}

/// One source's held-out scores over the folds.
#[derive(Debug, Clone, Serialize)]
pub struct SourceRow {
    /// `untuned`, `tuned`, `physics-free`, `physics-free + actuator (fitted)`.
    pub source: String,
    /// Per scene, in study order (`None`: a fold could not score it).
    pub scenes: Vec<Option<Spread>>,
    /// The sum over scenes.
    pub total: Option<Spread>,
}

/// The tuned engine minus a physics-free row, fold by fold.
#[derive(Debug, Clone, Serialize)]
pub struct Difference {
    /// The physics-free row.
    pub against: String,
    /// Per scene.
    pub scenes: Vec<Option<Spread>>,
    /// The total (negative: the tuned engine is closer).
    pub total: Option<Spread>,
}

/// A fold's tune, as the summary names it.
#[derive(Debug, Clone, Serialize)]
pub struct FoldResult {
    /// The fold.
    pub fold: Fold,
    /// Its tune folder.
    pub folder: String,
    /// The tune's own verdict on its held-out runs.
    pub verdict: String,
    /// The tune's wall time, seconds.
    pub wall_time_s: f64,
    /// The cube's held-out final displacement, real and tuned (m), when a
    /// scene has a cube.
    pub cube_push_m: Option<[f64; 2]>,
}

/// `crossval.json`: a study tune cross-validated over folds of real runs.
#[derive(Debug, Clone, Serialize)]
pub struct CrossValidation {
    /// The engine.
    pub engine: String,
    /// Real runs per scene.
    pub runs: usize,
    /// The scenes, in study order.
    pub scenes: Vec<String>,
    /// Each fold's tune.
    pub folds: Vec<FoldResult>,
    /// Each source's held-out scores over the folds.
    pub rows: Vec<SourceRow>,
    /// The tuned engine minus each physics-free row.
    pub differences: Vec<Difference>,
    /// The answer in words.
    pub verdict: String,
}

/// The held-out comparison of a fold's summary, or an error naming it.
fn held_out<'a>(fold: &Fold, s: &'a Summary) -> Result<&'a Comparison> {
    match &s.holdout {
        Some(c) => Ok(c),
        None => bail!(
            "fold {} (runs {} held out): its tune scored no held-out runs",
            fold.number,
            fold.holdout
        ),
    }
}

fn value(s: &Option<Scored>) -> Option<f64> {
    s.as_ref().map(|x| x.value_m)
}

/// Gathers the folds' tunes (`summaries[i]` is fold `folds[i]`'s, written
/// into `folders[i]`) into a cross-validation of `engine` over `runs` real
/// runs per scene.
pub fn gather(
    engine: &str,
    runs: usize,
    folds: &[Fold],
    folders: &[String],
    summaries: &[Summary],
) -> Result<CrossValidation> {
    if folds.len() != summaries.len() || folds.len() != folders.len() {
        bail!(
            "cross-validation: {} folds but {} tunes",
            folds.len(),
            summaries.len()
        );
    }
    let held: Vec<&Comparison> = folds
        .iter()
        .zip(summaries)
        .map(|(f, s)| held_out(f, s))
        .collect::<Result<_>>()?;
    let scenes: Vec<String> = held[0].scenes.iter().map(|s| s.scene.clone()).collect();
    // Each source's per-scene and total values, fold by fold.
    type Values = (Vec<Vec<Option<f64>>>, Vec<Option<f64>>);
    let mut sources: Vec<(String, Values)> = Vec::new();
    let mut push = |name: &str, scene_values: Vec<Option<f64>>, total: Option<f64>| {
        let at = match sources.iter().position(|(n, _)| n == name) {
            Some(i) => i,
            None => {
                sources.push((name.to_string(), (Vec::new(), Vec::new())));
                sources.len() - 1
            }
        };
        sources[at].1 .0.push(scene_values);
        sources[at].1 .1.push(total);
    };
    for c in &held {
        push(
            "untuned",
            c.scenes.iter().map(|s| value(&s.untuned)).collect(),
            value(&c.total_untuned),
        );
        push(
            "tuned",
            c.scenes.iter().map(|s| value(&s.tuned)).collect(),
            value(&c.total_tuned),
        );
        for b in &c.baselines {
            push(
                &b.source,
                b.scenes.iter().map(value).collect(),
                value(&b.total),
            );
        }
    }
    let per_scene = |v: &[Vec<Option<f64>>], i: usize| -> Vec<Option<f64>> {
        v.iter().map(|f| f.get(i).copied().flatten()).collect()
    };
    let rows: Vec<SourceRow> = sources
        .iter()
        .map(|(name, (sc, tot))| SourceRow {
            source: name.clone(),
            scenes: (0..scenes.len())
                .map(|i| {
                    (sc.len() == folds.len())
                        .then(|| Spread::of(&per_scene(sc, i)))
                        .flatten()
                })
                .collect(),
            total: (tot.len() == folds.len())
                .then(|| Spread::of(tot))
                .flatten(),
        })
        .collect();
    let tuned = &sources[1].1;
    let differences: Vec<Difference> = sources
        .iter()
        .skip(2)
        .filter(|(_, (sc, _))| sc.len() == folds.len())
        .map(|(name, (sc, tot))| {
            let minus = |a: &[Option<f64>], b: &[Option<f64>]| -> Vec<Option<f64>> {
                a.iter().zip(b).map(|(x, y)| Some((*x)? - (*y)?)).collect()
            };
            Difference {
                against: name.clone(),
                scenes: (0..scenes.len())
                    .map(|i| Spread::of(&minus(&per_scene(&tuned.0, i), &per_scene(sc, i))))
                    .collect(),
                total: Spread::of(&minus(&tuned.1, tot)),
            }
        })
        .collect();
    let fold_results = folds
        .iter()
        .zip(folders)
        .zip(summaries.iter().zip(&held))
        .map(|((f, folder), (s, c))| FoldResult {
            fold: f.clone(),
            folder: folder.clone(),
            verdict: s.verdict.clone(),
            wall_time_s: s.wall_time_s,
            cube_push_m: c.scenes.iter().find_map(|x| {
                let [real, _, tuned] = x.cube_push.as_ref()?;
                Some([(*real)?[0], (*tuned)?[0]])
            }),
        })
        .collect();
    let verdict = verdict(engine, runs, folds.len(), &rows, &differences);
    Ok(CrossValidation {
        engine: engine.to_string(),
        runs,
        scenes,
        folds: fold_results,
        rows,
        differences,
        verdict,
    })
}

/// The answer in words, from the totals' differences.
fn verdict(
    engine: &str,
    runs: usize,
    k: usize,
    rows: &[SourceRow],
    differences: &[Difference],
) -> String {
    let head = format!("Cross-validated over {k} folds of runs 1-{runs} (each run held out once)");
    let Some(tuned) = rows
        .iter()
        .find(|r| r.source == "tuned")
        .and_then(|r| r.total.as_ref())
    else {
        return format!("{head}, the tuned {engine} could not be scored in every fold.");
    };
    let mut parts = Vec::new();
    for d in differences {
        let Some(t) = &d.total else { continue };
        let word = if t.interval[1] < 0.0 {
            "beats"
        } else if t.interval[0] > 0.0 {
            "does not beat"
        } else if t.below_zero() == t.folds.len() {
            "is closer in every fold than"
        } else if t.below_zero() == 0 {
            "is further in every fold than"
        } else {
            "is not distinguishable from"
        };
        parts.push(format!(
            "{word} {} (tuned minus it {:+.2} m [{:+.2}, {:+.2}], below zero in {} of {k} folds)",
            d.against,
            t.mean,
            t.interval[0],
            t.interval[1],
            t.below_zero()
        ));
    }
    if parts.is_empty() {
        return format!(
            "{head}, the tuned {engine} scores {:.2} m on the runs it did not see; no physics-free row was scored.",
            tuned.mean
        );
    }
    format!(
        "{head}, the tuned {engine} ({:.2} m on the runs it did not see) {}.",
        tuned.mean,
        parts.join(", and ")
    )
}

fn cell(s: &Option<Spread>) -> String {
    match s {
        Some(s) => format!(
            "{:.2} [{:.2}, {:.2}] (sd {:.2})",
            s.mean, s.interval[0], s.interval[1], s.sd
        ),
        None => "n/a".into(),
    }
}

fn signed(s: &Option<Spread>) -> String {
    match s {
        Some(s) => format!(
            "{:+.2} [{:+.2}, {:+.2}], {} of {} below 0",
            s.mean,
            s.interval[0],
            s.interval[1],
            s.below_zero(),
            s.folds.len()
        ),
        None => "n/a".into(),
    }
}

/// `crossval.md`.
pub fn markdown(cv: &CrossValidation) -> String {
    let mut m = format!(
        "# Cross-validated tune of {}\n\n{}\n\n",
        cv.engine, cv.verdict
    );
    m.push_str(
        "Accumulated wrist error on each fold's held-out runs (m): the mean over folds, a 95 % \
         t interval of the mean, and the folds' standard deviation. The folds share training \
         runs, so the interval understates the uncertainty.\n\n",
    );
    m.push_str("| source |");
    for s in &cv.scenes {
        m.push_str(&format!(" {s} |"));
    }
    m.push_str(" total |\n|---|");
    m.push_str(&"---:|".repeat(cv.scenes.len() + 1));
    m.push('\n');
    for r in &cv.rows {
        m.push_str(&format!("| {} |", r.source));
        for s in &r.scenes {
            m.push_str(&format!(" {} |", cell(s)));
        }
        m.push_str(&format!(" {} |\n", cell(&r.total)));
    }
    if !cv.differences.is_empty() {
        m.push_str(
            "\n## The tuned engine minus each physics-free row, fold by fold\n\n| against |",
        );
        for s in &cv.scenes {
            m.push_str(&format!(" {s} |"));
        }
        m.push_str(" total |\n|---|");
        m.push_str(&"---:|".repeat(cv.scenes.len() + 1));
        m.push('\n');
        for d in &cv.differences {
            m.push_str(&format!("| {} |", d.against));
            for s in &d.scenes {
                m.push_str(&format!(" {} |", signed(s)));
            }
            m.push_str(&format!(" {} |\n", signed(&d.total)));
        }
    }
    m.push_str("\n## Folds\n\n| fold | held out | tuned total | cube push, real / tuned | wall time | folder |\n|---:|---|---:|---|---:|---|\n");
    let tuned = cv.rows.iter().find(|r| r.source == "tuned");
    for (i, f) in cv.folds.iter().enumerate() {
        let total = tuned
            .and_then(|r| r.total.as_ref())
            .and_then(|t| t.folds.get(i))
            .map_or("n/a".to_string(), |v| format!("{v:.2}"));
        let push = f
            .cube_push_m
            .map_or("—".to_string(), |[r, t]| format!("{r:.3} / {t:.3} m"));
        m.push_str(&format!(
            "| {} | {} | {} | {} | {:.0} s | {} |\n",
            f.fold.number, f.fold.holdout, total, push, f.wall_time_s, f.folder
        ));
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folds_are_consecutive_and_cover_every_run_once() {
        let f = folds(20, 4).unwrap();
        let text: Vec<&str> = f.iter().map(|x| x.holdout.as_str()).collect();
        assert_eq!(text, ["1-5", "6-10", "11-15", "16-20"]);
        let f = folds(7, 3).unwrap();
        let text: Vec<&str> = f.iter().map(|x| x.holdout.as_str()).collect();
        assert_eq!(text, ["1-3", "4-5", "6-7"]);
        let f = folds(3, 3).unwrap();
        let text: Vec<&str> = f.iter().map(|x| x.holdout.as_str()).collect();
        assert_eq!(text, ["1", "2", "3"]);
    }

    #[test]
    fn folds_refuse_what_cannot_be_split() {
        assert!(folds(20, 1).unwrap_err().to_string().contains("at least 2"));
        assert!(folds(5, 6)
            .unwrap_err()
            .to_string()
            .contains("at most 5 folds"));
    }

    #[test]
    fn spread_is_the_mean_and_a_t_interval() {
        let s = Spread::of(&[Some(1.0), Some(2.0), Some(3.0), Some(4.0)]).unwrap();
        assert!((s.mean - 2.5).abs() < 1e-12);
        let sd = (5.0f64 / 3.0).sqrt();
        assert!((s.sd - sd).abs() < 1e-12);
        let half = 3.182 * sd / 2.0;
        assert!((s.interval[0] - (2.5 - half)).abs() < 1e-9);
        assert!((s.interval[1] - (2.5 + half)).abs() < 1e-9);
        assert_eq!(
            Spread::of(&[Some(-1.0), Some(0.5)]).unwrap().below_zero(),
            1
        );
        assert!(Spread::of(&[Some(1.0), None]).is_none());
        assert!(Spread::of(&[Some(1.0)]).is_none());
        assert!(Spread::of(&[Some(1.0), Some(f64::NAN)]).is_none());
    }
}
