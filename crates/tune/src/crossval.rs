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

use crate::outputs::{Comparison, ScenePhases, Scored, Summary};
use anyhow::{bail, Result};
use realitygap_report::Figure;
use realitygap_report::FigureKind;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// One fold: the runs it holds out; every other run is fitted on.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
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
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
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
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SourceRow {
    /// `untuned`, `tuned`, `physics-free`, `physics-free + actuator (fitted)`.
    pub source: String,
    /// Per scene, in study order (`None`: a fold could not score it).
    pub scenes: Vec<Option<Spread>>,
    /// The sum over scenes.
    pub total: Option<Spread>,
}

/// The tuned engine minus a physics-free row, fold by fold.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Difference {
    /// The physics-free row.
    pub against: String,
    /// Per scene.
    pub scenes: Vec<Option<Spread>>,
    /// The total (negative: the tuned engine is closer).
    pub total: Option<Spread>,
}

/// A fold's tune, as the summary names it.
#[derive(Debug, Clone, Serialize, Deserialize)]
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
#[derive(Debug, Clone, Serialize, Deserialize)]
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
    /// Per scene, the held-out errors by phase and against time.
    pub phases: Vec<PhaseBreakdown>,
    /// The answer in words.
    pub verdict: String,
    /// The tune's options that differ from the defaults, as typed (e.g.
    /// `--prior-weight 10`); empty at the defaults. Absent from the files
    /// of cross-validations made before it existed.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub options: Vec<String>,
}

impl CrossValidation {
    /// The engine, with the options it was tuned with when not the
    /// defaults: `mujoco` or `mujoco (--prior-weight 10)`.
    pub fn label(&self) -> String {
        if self.options.is_empty() {
            self.engine.clone()
        } else {
            format!("{} ({})", self.engine, self.options.join(" "))
        }
    }
}

/// One scene's held-out errors by phase of its schedule, over the folds.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PhaseBreakdown {
    /// Scene.
    pub scene: String,
    /// Start times of the phases, s.
    pub phases_s: Vec<f64>,
    /// Each source's accumulated error per phase (m), over the folds.
    pub rows: Vec<PhaseRow>,
    /// The tuned engine minus each physics-free row, per phase.
    pub differences: Vec<PhaseRow>,
    /// Each source's error against time, averaged over the folds (the
    /// figures).
    pub curves: Vec<Curve>,
    /// Step times of the curves, s.
    pub t_s: Vec<f64>,
}

/// A source's (or a difference's) per-phase spreads over the folds.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PhaseRow {
    /// The source, or for a difference the physics-free row subtracted.
    pub source: String,
    /// Per phase (`None`: a fold did not measure it).
    pub phases: Vec<Option<Spread>>,
}

/// A source's mean over the folds, per step, of its held-out errors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Curve {
    /// The source.
    pub source: String,
    /// The mean wrist's distance to the real mean wrist, m.
    pub distance_m: Vec<Option<f64>>,
    /// The mean wrist's height minus the real mean wrist's, m.
    pub height_m: Vec<Option<f64>>,
}

/// The mean over `folds` of each step's value (`None` where a fold has
/// none).
fn mean_curve(folds: &[&[Option<f64>]]) -> Vec<Option<f64>> {
    let n = folds.iter().map(|f| f.len()).min().unwrap_or(0);
    (0..n)
        .map(|k| {
            let v: Option<Vec<f64>> = folds.iter().map(|f| f[k]).collect();
            v.map(|v| v.iter().sum::<f64>() / v.len() as f64)
        })
        .collect()
}

/// The held-out errors by phase of every scene, gathered over the folds
/// (`per_fold[f]` is fold `f`'s held-out [`ScenePhases`]). A source or a
/// scene missing from any fold is left out.
pub fn gather_phases(per_fold: &[&[ScenePhases]]) -> Vec<PhaseBreakdown> {
    let Some(first) = per_fold.first() else {
        return Vec::new();
    };
    first
        .iter()
        .filter_map(|scene| {
            let folds: Vec<&ScenePhases> = per_fold
                .iter()
                .map(|f| f.iter().find(|s| s.scene == scene.scene))
                .collect::<Option<_>>()?;
            let phases = scene.phases_s.len();
            let source_in = |name: &str| -> Option<Vec<&crate::outputs::SourcePhases>> {
                folds
                    .iter()
                    .map(|f| f.sources.iter().find(|s| s.source == name))
                    .collect()
            };
            let per_phase = |values: &dyn Fn(usize, usize) -> Option<f64>| -> Vec<Option<Spread>> {
                (0..phases)
                    .map(|p| {
                        Spread::of(&(0..folds.len()).map(|f| values(f, p)).collect::<Vec<_>>())
                    })
                    .collect()
            };
            let mut rows = Vec::new();
            let mut curves = Vec::new();
            for s in &scene.sources {
                let Some(each) = source_in(&s.source) else {
                    continue;
                };
                rows.push(PhaseRow {
                    source: s.source.clone(),
                    phases: per_phase(&|f, p| each[f].phase_errors_m.get(p).copied()),
                });
                let d: Vec<&[Option<f64>]> = each.iter().map(|x| x.distance_m.as_slice()).collect();
                let h: Vec<&[Option<f64>]> = each.iter().map(|x| x.height_m.as_slice()).collect();
                curves.push(Curve {
                    source: s.source.clone(),
                    distance_m: mean_curve(&d),
                    height_m: mean_curve(&h),
                });
            }
            let tuned = source_in("tuned");
            let differences = match &tuned {
                Some(tuned) => scene
                    .sources
                    .iter()
                    .filter(|s| s.source != "tuned" && s.source != "untuned")
                    .filter_map(|s| {
                        let other = source_in(&s.source)?;
                        Some(PhaseRow {
                            source: s.source.clone(),
                            phases: per_phase(&|f, p| {
                                Some(
                                    tuned[f].phase_errors_m.get(p)?
                                        - other[f].phase_errors_m.get(p)?,
                                )
                            }),
                        })
                    })
                    .collect(),
                None => Vec::new(),
            };
            Some(PhaseBreakdown {
                scene: scene.scene.clone(),
                phases_s: scene.phases_s.clone(),
                rows,
                differences,
                curves,
                t_s: scene.t_s.clone(),
            })
        })
        .collect()
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
    let per_fold: Vec<&[ScenePhases]> = held.iter().map(|c| c.phases.as_slice()).collect();
    Ok(CrossValidation {
        engine: engine.to_string(),
        runs,
        scenes,
        folds: fold_results,
        rows,
        differences,
        phases: gather_phases(&per_fold),
        verdict,
        options: Vec::new(),
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
        cv.label(),
        cv.verdict
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
    m.push_str(&phases_markdown(cv));
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

/// The sources the figures draw, in order: the tuned engine and the two
/// physics-free rows (the untuned engine, metres off in scene 2, would
/// flatten them).
const DRAWN: [&str; 3] = ["tuned", "physics-free + actuator (fitted)", "physics-free"];

/// The figures of `cv`: per scene, the held-out wrist distance and
/// height against time, averaged over the folds.
pub fn figures(cv: &CrossValidation) -> Vec<Figure> {
    cv.phases
        .iter()
        .flat_map(|p| scene_figures(cv, p))
        .collect()
}

/// The held-out distance and height figures of one scene of `cv`.
fn scene_figures(cv: &CrossValidation, p: &PhaseBreakdown) -> [Figure; 2] {
    use realitygap_report::held_out::{held_out_figure, HeldOutCurve, HeldOutMaking};
    let making = HeldOutMaking {
        scene: &p.scene,
        engine: &cv.engine,
        folds: cv.folds.len(),
        t_s: &p.t_s,
        phases_s: &p.phases_s,
    };
    [FigureKind::HeldOutDistance, FigureKind::HeldOutHeight].map(|kind| {
        let curves: Vec<HeldOutCurve> = DRAWN
            .iter()
            .filter_map(|name| p.curves.iter().find(|c| c.source == *name))
            .map(|c| HeldOutCurve {
                source: legend(&cv.engine, &c.source),
                values: if kind == FigureKind::HeldOutHeight {
                    c.height_m.clone()
                } else {
                    c.distance_m.clone()
                },
            })
            .collect();
        held_out_figure(kind, &curves, &making)
    })
}

/// A source's name in a figure's legend.
fn legend(engine: &str, source: &str) -> String {
    match source {
        "tuned" | "untuned" => format!("{engine} {source}"),
        FITTED_ROW => realitygap_report::held_out::ACTUATOR_ONLY.into(),
        "physics-free" => realitygap_report::held_out::PERFECT_TRACKING.into(),
        s => s.to_string(),
    }
}

/// Writes `crossval.md`, `crossval.json` and the figures (`figures/`,
/// SVG and PNG) into `out`; returns the files written.
pub fn write(cv: &CrossValidation, out: &Path) -> Result<Vec<PathBuf>> {
    let io = |p: &Path, e: std::io::Error| anyhow::anyhow!("writing {}: {e}", p.display());
    let dir = out.join("figures");
    std::fs::create_dir_all(&dir).map_err(|e| io(&dir, e))?;
    let mut files = Vec::new();
    let md = out.join("crossval.md");
    std::fs::write(&md, markdown(cv)).map_err(|e| io(&md, e))?;
    files.push(md);
    let json = out.join("crossval.json");
    std::fs::write(&json, serde_json::to_string_pretty(cv)? + "\n").map_err(|e| io(&json, e))?;
    files.push(json);
    for f in figures(cv) {
        files.extend(f.write(&dir)?);
    }
    Ok(files)
}

/// The physics-free row an engine's tune must beat for physics to pay.
pub const FITTED_ROW: &str = "physics-free + actuator (fitted)";

/// `DIR/crossval.json` as `tune --folds` wrote it (or that file named
/// directly), with an error naming the file.
pub fn read(path: &Path) -> Result<CrossValidation> {
    let file = if path.is_dir() {
        path.join("crossval.json")
    } else {
        path.to_path_buf()
    };
    let text = std::fs::read_to_string(&file).map_err(|e| {
        anyhow::anyhow!(
            "reading {}: {e} (expected the crossval.json that `tune --folds K --out DIR` writes)",
            file.display()
        )
    })?;
    serde_json::from_str(&text).map_err(|e| {
        anyhow::anyhow!(
            "{}: line {}, column {}: not a cross-validation written by `tune --folds`: {e}",
            file.display(),
            e.line(),
            e.column()
        )
    })
}

/// The tuned engine's held-out total minus the fitted physics-free row's,
/// over the folds.
pub fn against_fitted(cv: &CrossValidation) -> Option<&Spread> {
    cv.differences
        .iter()
        .find(|d| d.against == FITTED_ROW)?
        .total
        .as_ref()
}

/// The sentence a report's verdict opens with: which tuned engines beat
/// the physics-free model behind its fitted actuator stage on the runs
/// they did not see (each with its difference and the folds it is ahead
/// in), and, when none does, that none does.
pub fn lead(cvs: &[CrossValidation]) -> Option<String> {
    let scored: Vec<(&CrossValidation, &Spread)> = cvs
        .iter()
        .filter_map(|c| Some((c, against_fitted(c)?)))
        .collect();
    if scored.is_empty() {
        return None;
    }
    let part = |(c, d): &(&CrossValidation, &Spread)| {
        format!(
            "{} {:+.2} m [{:+.2}, {:+.2}], ahead in {} of {} folds",
            c.label(),
            d.mean,
            d.interval[0],
            d.interval[1],
            d.below_zero(),
            d.folds.len()
        )
    };
    // Ahead: the interval below zero; behind: above; level: across it.
    let pick = |f: &dyn Fn(&Spread) -> bool| -> Vec<&(&CrossValidation, &Spread)> {
        scored.iter().filter(|(_, d)| f(d)).collect()
    };
    let win = pick(&|d| d.interval[1] < 0.0);
    let lose = pick(&|d| d.interval[0] > 0.0);
    let level = pick(&|d| d.interval[1] >= 0.0 && d.interval[0] <= 0.0);
    // Each description once, in the order first met (engines may be
    // cross-validated over different folds).
    let mut folds: Vec<String> = Vec::new();
    for (c, d) in &scored {
        let f = format!("{} folds of runs 1-{}", d.folds.len(), c.runs);
        if !folds.contains(&f) {
            folds.push(f);
        }
    }
    let how = format!(
        "Tuned and cross-validated ({}, each run held out once; tuned engine minus the physics-free model behind its fitted actuator stage, held-out wrist total with a 95 % interval over folds)",
        folds.join("; ")
    );
    let names = |v: &[&(&CrossValidation, &Spread)]| -> String {
        v.iter().map(|x| part(x)).collect::<Vec<_>>().join("; ")
    };
    let who = |v: &[&(&CrossValidation, &Spread)]| -> String {
        v.iter()
            .map(|(c, _)| c.label())
            .collect::<Vec<_>>()
            .join(", ")
    };
    let is = |v: &[&(&CrossValidation, &Spread)]| if v.len() == 1 { "is" } else { "are" };
    // The level and the behind, as clauses after the first.
    let mut tail = String::new();
    if !level.is_empty() && !win.is_empty() {
        tail.push_str(&format!(
            "; {} {} level with it ({})",
            who(&level),
            is(&level),
            names(&level)
        ));
    }
    if !lose.is_empty() && lose.len() < scored.len() {
        tail.push_str(&format!(
            "; {} {} behind it ({})",
            who(&lose),
            is(&lose),
            names(&lose)
        ));
    }
    Some(if win.len() == scored.len() {
        format!(
            "{how}, every tuned engine measured beats the physics-free model on runs it did not see ({}).",
            names(&win)
        )
    } else if !win.is_empty() {
        format!(
            "{how}, {} beat{} the physics-free model on runs {} did not see ({}){tail}.",
            who(&win),
            if win.len() == 1 { "s" } else { "" },
            if win.len() == 1 { "it" } else { "they" },
            names(&win),
        )
    } else if !level.is_empty() {
        format!(
            "{how}, no tuned engine is ahead of the physics-free model on runs it did not see by more than the folds' spread: {} {} level with it ({}){tail}.",
            who(&level),
            is(&level),
            names(&level),
        )
    } else {
        format!(
            "{how}, no tuned engine beats the physics-free model on runs it did not see: physics does not pay on this arm's wrist ({}).",
            names(&lose)
        )
    })
}

/// The report's section of cross-validated tunes: the lead sentence, one
/// row per engine, and per engine the held-out figures of the scene where
/// it loses most to the fitted physics-free row.
pub fn report_section(cvs: &[CrossValidation]) -> realitygap_report::html::ExtraSection {
    let mut paragraphs: Vec<String> = cvs.iter().map(|c| c.verdict.clone()).collect();
    paragraphs.push(
        "Each engine and the physics-free model's actuator stage were tuned on the runs of the other folds and scored on each fold's runs in turn (`tune --folds K`); the figures show, for the scene where each tuned engine loses most to the fitted physics-free row, where in time that loss lies.".into(),
    );
    let interval = |s: Option<&Spread>| {
        s.map_or("n/a".to_string(), |s| {
            format!("{:.2} [{:.2}, {:.2}]", s.mean, s.interval[0], s.interval[1])
        })
    };
    let mut rows = Vec::new();
    let mut figs = Vec::new();
    for c in cvs {
        let total = |name: &str| {
            c.rows
                .iter()
                .find(|r| r.source == name)
                .and_then(|r| r.total.as_ref())
        };
        let d = against_fitted(c);
        let worst = c
            .differences
            .iter()
            .find(|x| x.against == FITTED_ROW)
            .and_then(|x| {
                x.scenes
                    .iter()
                    .enumerate()
                    .filter_map(|(i, s)| Some((i, s.as_ref()?.mean)))
                    .max_by(|a, b| a.1.total_cmp(&b.1))
            });
        let pushes: Vec<String> = c
            .folds
            .iter()
            .filter_map(|f| f.cube_push_m.map(|[_, t]| format!("{t:.3}")))
            .collect();
        rows.push(vec![
            c.label(),
            interval(total("tuned")),
            interval(total(FITTED_ROW)),
            d.map_or("n/a".into(), |d| {
                format!(
                    "{:+.2} [{:+.2}, {:+.2}]",
                    d.mean, d.interval[0], d.interval[1]
                )
            }),
            d.map_or("n/a".into(), |d| {
                format!("{} of {}", d.below_zero(), d.folds.len())
            }),
            worst.map_or("n/a".into(), |(i, v)| {
                format!("{} ({v:+.2})", c.scenes.get(i).map_or("?", String::as_str))
            }),
            if pushes.is_empty() {
                "—".into()
            } else {
                pushes.join(", ")
            },
        ]);
        if let Some(p) = worst.and_then(|(i, _)| {
            let scene = c.scenes.get(i)?;
            c.phases.iter().find(|p| p.scene == *scene)
        }) {
            figs.extend(scene_figures(c, p));
        }
    }
    realitygap_report::html::ExtraSection {
        id: "crossval".into(),
        title: "Does physics pay? Tuned engines cross-validated".into(),
        lead: lead(cvs).into_iter().collect(),
        paragraphs,
        header: [
            "engine",
            "tuned, held out (m)",
            "physics-free + actuator, fitted (m)",
            "tuned minus it (m)",
            "folds ahead",
            "scene lost most (m)",
            "cube push per fold, tuned (m)",
        ]
        .map(String::from)
        .to_vec(),
        rows,
        figures: figs,
        replay: Vec::new(),
    }
}

/// A phase's time span, e.g. `2.0-3.5 s`.
fn span(p: &PhaseBreakdown, i: usize) -> String {
    let end = p.phases_s.get(i + 1).copied().or_else(|| {
        let (a, b) = (p.t_s.first()?, p.t_s.last()?);
        let dt = p.t_s.get(1).map_or(0.0, |x| x - a);
        Some(b + dt)
    });
    match end {
        Some(e) => format!("{:.1}-{:.1} s", p.phases_s[i], e),
        None => format!("from {:.1} s", p.phases_s[i]),
    }
}

/// The section of `crossval.md` by phase, with the figures.
fn phases_markdown(cv: &CrossValidation) -> String {
    if cv.phases.is_empty() {
        return String::new();
    }
    let mut m = String::from(
        "\n## By phase of the schedule\n\nEach scene's held-out accumulated error split at the schedule's new targets (m; mean over folds with its 95 % t interval), and the tuned engine minus each physics-free row per phase. The figures show where in time the error lies: the distance to the real wrist, and the height against the real wrist's (a servo that sags under gravity is below it while the arm holds still).\n",
    );
    for p in &cv.phases {
        m.push_str(&format!("\n### {}\n\n| phase |", p.scene));
        for r in &p.rows {
            m.push_str(&format!(" {} |", legend(&cv.engine, &r.source)));
        }
        for d in &p.differences {
            m.push_str(&format!(" tuned minus {} |", d.source));
        }
        m.push_str("\n|---|");
        m.push_str(&"---:|".repeat(p.rows.len() + p.differences.len()));
        m.push('\n');
        for i in 0..p.phases_s.len() {
            m.push_str(&format!("| {}: {} |", i + 1, span(p, i)));
            for r in &p.rows {
                let c = match r.phases.get(i).cloned().flatten() {
                    Some(s) => {
                        format!("{:.2} [{:.2}, {:.2}]", s.mean, s.interval[0], s.interval[1])
                    }
                    None => "n/a".into(),
                };
                m.push_str(&format!(" {c} |"));
            }
            for d in &p.differences {
                m.push_str(&format!(
                    " {} |",
                    signed(&d.phases.get(i).cloned().flatten())
                ));
            }
            m.push('\n');
        }
        m.push('\n');
        for kind in [FigureKind::HeldOutDistance, FigureKind::HeldOutHeight] {
            let stem = realitygap_report::held_out::stem(&cv.engine, &p.scene, kind);
            m.push_str(&format!(
                "![{}: {}](figures/{stem}.png)\n",
                p.scene,
                kind.title("").to_lowercase()
            ));
        }
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

    fn source(name: &str, phases: [f64; 2], height: f64) -> crate::outputs::SourcePhases {
        crate::outputs::SourcePhases {
            source: name.into(),
            phase_errors_m: phases.to_vec(),
            distance_m: vec![Some(phases[0]), Some(phases[1]), None],
            height_m: vec![Some(height); 3],
        }
    }

    fn scene(sources: Vec<crate::outputs::SourcePhases>) -> ScenePhases {
        ScenePhases {
            scene: "scene2_two_joints".into(),
            phases_s: vec![0.0, 0.1],
            t_s: vec![0.0, 0.1, 0.2],
            sources,
        }
    }

    /// Per phase, each source's spread over the folds and the tuned
    /// engine's difference from each physics-free row; the curves are the
    /// folds' mean step by step; a source missing from a fold is left out.
    #[test]
    fn phases_gather_fold_by_fold_and_leave_out_what_a_fold_lacks() {
        let fold1 = [scene(vec![
            source("untuned", [9.0, 9.0], -0.2),
            source("tuned", [1.0, 3.0], -0.02),
            source("physics-free + actuator (fitted)", [1.5, 2.0], 0.0),
        ])];
        let fold2 = [scene(vec![
            source("tuned", [2.0, 5.0], -0.04),
            source("physics-free + actuator (fitted)", [2.5, 3.0], 0.01),
        ])];
        let p = gather_phases(&[&fold1, &fold2]);
        assert_eq!(p.len(), 1);
        let p = &p[0];
        let names: Vec<&str> = p.rows.iter().map(|r| r.source.as_str()).collect();
        assert_eq!(names, ["tuned", "physics-free + actuator (fitted)"]);
        let tuned = p.rows[0].phases[1].as_ref().unwrap();
        assert!((tuned.mean - 4.0).abs() < 1e-12);
        assert_eq!(p.differences.len(), 1);
        let d = &p.differences[0];
        assert_eq!(d.source, "physics-free + actuator (fitted)");
        let first = d.phases[0].as_ref().unwrap();
        assert!((first.mean + 0.5).abs() < 1e-12 && first.below_zero() == 2);
        let second = d.phases[1].as_ref().unwrap();
        assert!((second.mean - 1.5).abs() < 1e-12 && second.below_zero() == 0);
        assert_eq!(p.curves[0].distance_m, [Some(1.5), Some(4.0), None]);
        assert!((p.curves[0].height_m[0].unwrap() + 0.03).abs() < 1e-12);

        let cv = CrossValidation {
            engine: "mujoco".into(),
            runs: 4,
            scenes: vec![p.scene.clone()],
            folds: Vec::new(),
            rows: Vec::new(),
            differences: Vec::new(),
            phases: vec![p.clone()],
            verdict: String::new(),
            options: vec!["--prior-weight 10".into()],
        };
        let md = markdown(&cv);
        assert!(
            md.starts_with("# Cross-validated tune of mujoco (--prior-weight 10)\n"),
            "{md}"
        );
        assert!(md.contains("### scene2_two_joints"), "{md}");
        assert!(md.contains("| 2: 0.1-0.3 s | 4.00 ["), "{md}");
        assert!(md.contains("+1.50 ["), "{md}");
        assert!(md.contains("(figures/crossval_mujoco_scene2_two_joints_held_out_height.png)"));
        let figs = figures(&cv);
        let stems: Vec<&str> = figs.iter().map(|f| f.stem.as_str()).collect();
        assert_eq!(
            stems,
            [
                "crossval_mujoco_scene2_two_joints_held_out_distance",
                "crossval_mujoco_scene2_two_joints_held_out_height"
            ]
        );
        assert_eq!(figs[1].lines[0].name, "mujoco tuned");
        let dir = tempfile::tempdir().unwrap();
        let files = write(&cv, dir.path()).unwrap();
        assert_eq!(files.len(), 6);
        assert!(files.iter().all(|f| f.exists()));
    }

    /// A cross-validation of `engine` whose tuned totals minus the fitted
    /// row's are `diffs`, fold by fold.
    fn cv_of(engine: &str, diffs: [f64; 4]) -> CrossValidation {
        let spread = |v: [f64; 4]| Spread::of(&v.map(Some));
        CrossValidation {
            engine: engine.into(),
            runs: 20,
            scenes: vec!["scene2_two_joints".into()],
            folds: Vec::new(),
            rows: vec![SourceRow {
                source: "tuned".into(),
                scenes: vec![spread(diffs.map(|d| 14.0 + d))],
                total: spread(diffs.map(|d| 14.0 + d)),
            }],
            differences: vec![Difference {
                against: FITTED_ROW.into(),
                scenes: vec![spread(diffs)],
                total: spread(diffs),
            }],
            phases: Vec::new(),
            verdict: format!("{engine}'s own verdict"),
            options: Vec::new(),
        }
    }

    /// The verdict's first sentence says whether any tuned engine beats
    /// the fitted physics-free row: none, some (named), or all.
    #[test]
    fn the_lead_says_whether_physics_pays() {
        let lose = cv_of("mujoco", [1.0, 1.5, 2.0, 1.1]);
        let tie = cv_of("ode", [-0.1, 0.1, 0.05, -0.02]);
        let win = cv_of("dart", [-0.5, -0.6, -0.4, -0.55]);
        let none = lead(&[lose.clone(), tie.clone()]).unwrap();
        assert!(
            none.contains(", no tuned engine is ahead of the physics-free model on runs it did not see by more than the folds' spread: ode is level with it (ode +0.01 m ["),
            "{none}"
        );
        assert!(
            none.contains(", ahead in 2 of 4 folds); mujoco is behind it (mujoco +1.40 m ["),
            "{none}"
        );
        assert!(none.contains("4 folds of runs 1-20"), "{none}");
        let behind = lead(std::slice::from_ref(&lose)).unwrap();
        assert!(
            behind.contains("no tuned engine beats the physics-free model on runs it did not see: physics does not pay on this arm's wrist (mujoco +1.40 m"),
            "{behind}"
        );
        let some = lead(&[lose.clone(), win.clone()]).unwrap();
        assert!(
            some.contains(
                ", dart beats the physics-free model on runs it did not see (dart -0.51 m"
            ),
            "{some}"
        );
        assert!(some.contains("); mujoco is behind it (mujoco"), "{some}");
        let three = lead(&[lose.clone(), win.clone(), tie.clone()]).unwrap();
        assert!(
            three.contains("; ode is level with it (ode +0.01 m")
                && three.contains("; mujoco is behind it"),
            "{three}"
        );
        let mut pulled = win.clone();
        pulled.options = vec!["--prior-weight 10".into()];
        let named = lead(&[pulled]).unwrap();
        assert!(
            named.contains("did not see (dart (--prior-weight 10) -0.51 m"),
            "{named}"
        );
        let all = lead(std::slice::from_ref(&win)).unwrap();
        assert!(all.contains("every tuned engine measured beats"), "{all}");
        assert!(lead(&[]).is_none());
        // Fold counts that differ are each named once, in order met.
        let mut three = cv_of("rapier", [0.3, 0.2, 0.4, 0.0]);
        three.differences[0].total = Spread::of(&[Some(0.3), Some(0.2), Some(0.4)]);
        let mixed = lead(&[lose.clone(), three, tie.clone()]).unwrap();
        assert!(
            mixed.contains("(4 folds of runs 1-20; 3 folds of runs 1-20, each run"),
            "{mixed}"
        );

        let section = report_section(&[lose, win]);
        assert_eq!(section.lead, [some]);
        assert_eq!(section.rows.len(), 2);
        assert_eq!(section.rows[0][0], "mujoco");
        assert_eq!(section.rows[0][4], "0 of 4");
        assert!(section.rows[0][5].starts_with("scene2_two_joints (+1.40)"));
        assert!(section.paragraphs[0].contains("mujoco's own verdict"));
    }

    /// A folder without crossval.json, and a file that is not one, are
    /// errors naming the file.
    #[test]
    fn reading_names_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let e = read(dir.path()).unwrap_err().to_string();
        assert!(
            e.contains("crossval.json") && e.contains("tune --folds"),
            "{e}"
        );
        let f = dir.path().join("crossval.json");
        std::fs::write(&f, "{\n  \"engine\": 3\n}\n").unwrap();
        let e = read(&f).unwrap_err().to_string();
        assert!(e.contains("crossval.json: line 2"), "{e}");
        let cv = cv_of("mujoco", [1.0, 1.5, 2.0, 1.1]);
        std::fs::write(&f, serde_json::to_string(&cv).unwrap()).unwrap();
        assert_eq!(read(dir.path()).unwrap().engine, "mujoco");
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
