//! The search: CMA-ES over the normalised space, each generation's
//! candidates evaluated in parallel, every evaluation appended to
//! `history.csv` once its generation has finished.
//!
//! - **Bounds**: CMA-ES searches all of R^n; a coordinate is folded into
//!   [0, 1] by reflection at the bounds ([`reflect`]), so every candidate
//!   lies in the space and the search can still move along a bound.
//! - **Determinism**: the candidates come from CMA-ES's own seeded
//!   generator and an evaluation depends only on its candidate, so a seed
//!   gives the same search whatever the number of jobs.
//! - **Resume**: a rerun reads `history.csv`, replays the finished
//!   generations from it without simulating (the same seed proposes the
//!   same candidates, bit for bit), and goes on from there. A generation
//!   cut short by a kill is evaluated again.

use crate::space::Space;
use anyhow::{bail, Context, Result};
use cmaes::{CMAESOptions, DVector, TerminationReason};
use realitygap_analysis::table::csv_field;
use std::collections::HashMap;
use std::fs::OpenOptions;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// The initial step size of the search, in normalised units (the space
/// is [0, 1] per coordinate).
pub const SIGMA0: f64 = 0.25;

/// Folds a CMA-ES coordinate into [0, 1] by reflection at 0 and 1.
pub fn reflect(x: f64) -> f64 {
    if !x.is_finite() {
        return 0.5;
    }
    let y = x.rem_euclid(2.0);
    if y <= 1.0 {
        y
    } else {
        2.0 - y
    }
}

/// One evaluated candidate, as written in `history.csv`.
#[derive(Debug, Clone, PartialEq)]
pub struct Evaluation {
    /// 0-based evaluation number.
    pub index: usize,
    /// 0-based generation.
    pub generation: usize,
    /// The objective, metres.
    pub objective: f64,
    /// The per-scene columns (accumulated errors, cube errors), metres;
    /// NaN where not measured.
    pub parts: Vec<f64>,
    /// Why it failed, if it did.
    pub failed: Option<String>,
    /// The parameter values, in the space's order, then the registration
    /// offset (3 rotations in degrees, 3 translations in mm) if fitted.
    pub values: Vec<f64>,
    /// The CMA-ES coordinates it was proposed at.
    pub x: Vec<f64>,
}

/// What one evaluation returns to the search.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// The objective.
    pub objective: f64,
    /// Per-scene columns (see [`Evaluation::parts`]).
    pub parts: Vec<f64>,
    /// Why it failed.
    pub failed: Option<String>,
}

/// Search settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SearchOptions {
    /// Evaluations at most (the last generation is finished).
    pub budget: usize,
    /// The seed of CMA-ES's generator.
    pub seed: u64,
    /// Parallel evaluations.
    pub jobs: usize,
    /// Restart a search that has stalled (or that CMA-ES itself ended)
    /// before the budget is spent, from a random point with twice the
    /// population (IPOP-CMA-ES), until the budget is spent.
    pub restarts: bool,
    /// The objective's own noise (metres): a search whose best has
    /// improved by less over [`stall_window`] generations has stalled.
    /// `None`: the real runs' noise when the tune's identifiability check
    /// measured it (`fit` fills it in), else a thousandth of the best.
    pub stall_m: Option<f64>,
}

/// The generations over which a search must improve by more than the
/// noise not to have stalled: CMA-ES's own history length for its
/// flat-fitness test, `10 + ceil(30 n / lambda)` for `n` coordinates and
/// `lambda` candidates per generation.
pub fn stall_window(n: usize, lambda: usize) -> usize {
    10 + (30 * n).div_ceil(lambda.max(1))
}

/// CMA-ES's default population for `n` coordinates, `4 + floor(3 ln n)`.
pub fn default_population(n: usize) -> usize {
    4 + (3.0 * (n.max(1) as f64).ln()).floor() as usize
}

/// Whether a run whose best objective after each generation is `bests`
/// has stalled: over the last [`stall_window`] generations it fell by
/// less than `stall_m` (a thousandth of the best without it).
pub fn stalled(bests: &[f64], window: usize, stall_m: Option<f64>) -> bool {
    if bests.len() <= window {
        return false;
    }
    let now = bests[bests.len() - 1];
    let then = bests[bests.len() - 1 - window];
    let tolerance = stall_m.unwrap_or(1e-3 * now.abs());
    then - now < tolerance
}

/// Progress of a search, reported after every evaluation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Progress {
    /// Evaluations done (replayed ones included).
    pub done: usize,
    /// Evaluations replayed from `history.csv`.
    pub replayed: usize,
    /// The budget.
    pub budget: usize,
    /// The best objective so far.
    pub best: f64,
}

/// How the search ended.
#[derive(Debug, Clone, PartialEq)]
pub struct SearchEnd {
    /// Every evaluation, in order.
    pub history: Vec<Evaluation>,
    /// Evaluations replayed from an earlier run.
    pub replayed: usize,
    /// Why it stopped: the budget, or CMA-ES's own criterion.
    pub reason: String,
}

impl SearchEnd {
    /// The best finished evaluation.
    pub fn best(&self) -> Option<&Evaluation> {
        self.history
            .iter()
            .filter(|e| e.failed.is_none())
            .min_by(|a, b| a.objective.total_cmp(&b.objective))
    }
}

/// `history.csv`: its header and rows.
pub struct History {
    path: PathBuf,
    header: Vec<String>,
    rows: Vec<Evaluation>,
}

/// Splits one CSV line (fields may be quoted with doubled quotes).
fn split_csv(line: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut cur = String::new();
    let mut quoted = false;
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match (c, quoted) {
            ('"', true) if chars.peek() == Some(&'"') => {
                cur.push('"');
                chars.next();
            }
            ('"', _) => quoted = !quoted,
            (',', false) => out.push(std::mem::take(&mut cur)),
            _ => cur.push(c),
        }
    }
    out.push(cur);
    out
}

impl History {
    /// The history at `path` with columns `part_names` (per-scene parts)
    /// and `value_names` (parameters), for `dims` CMA-ES coordinates: read
    /// back when the file exists (an error naming the line when it does
    /// not match), empty otherwise.
    pub fn open(
        path: &Path,
        part_names: &[String],
        value_names: &[String],
        dims: usize,
    ) -> Result<History> {
        let mut header: Vec<String> = ["evaluation", "generation", "objective_m", "failed"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        header.extend(part_names.iter().cloned());
        header.extend(value_names.iter().cloned());
        header.extend((0..dims).map(|i| format!("x{i}")));
        let mut h = History {
            path: path.to_path_buf(),
            header,
            rows: Vec::new(),
        };
        if path.exists() {
            h.read(part_names.len(), value_names.len(), dims)?;
        }
        Ok(h)
    }

    fn read(&mut self, parts: usize, values: usize, dims: usize) -> Result<()> {
        let text = std::fs::read_to_string(&self.path)
            .with_context(|| format!("reading {}", self.path.display()))?;
        let mut lines = text.lines();
        let head = lines.next().unwrap_or_default();
        if split_csv(head) != self.header {
            bail!(
                "{}:1: the columns differ from this tune's (another space or study?); use another --out or remove the file",
                self.path.display()
            );
        }
        for (i, line) in lines.enumerate() {
            if line.trim().is_empty() {
                continue;
            }
            let at = || format!("{}:{}", self.path.display(), i + 2);
            let f = split_csv(line);
            if f.len() != self.header.len() {
                bail!(
                    "{}: {} fields, expected {}",
                    at(),
                    f.len(),
                    self.header.len()
                );
            }
            let num = |k: usize| -> Result<f64> {
                f[k].parse::<f64>().with_context(|| {
                    format!(
                        "{}: column {}: `{}` is not a number",
                        at(),
                        self.header[k],
                        f[k]
                    )
                })
            };
            let int = |k: usize| -> Result<usize> {
                f[k].parse::<usize>().with_context(|| {
                    format!(
                        "{}: column {}: `{}` is not a count",
                        at(),
                        self.header[k],
                        f[k]
                    )
                })
            };
            let base = 4;
            self.rows.push(Evaluation {
                index: int(0)?,
                generation: int(1)?,
                objective: num(2)?,
                failed: (!f[3].is_empty()).then(|| f[3].clone()),
                parts: (base..base + parts).map(num).collect::<Result<_>>()?,
                values: (base + parts..base + parts + values)
                    .map(num)
                    .collect::<Result<_>>()?,
                x: (base + parts + values..base + parts + values + dims)
                    .map(num)
                    .collect::<Result<_>>()?,
            });
        }
        Ok(())
    }

    /// The rows read or appended.
    pub fn rows(&self) -> &[Evaluation] {
        &self.rows
    }

    /// Appends `rows` to the file (writing the header first if new).
    pub fn append(&mut self, rows: Vec<Evaluation>) -> Result<()> {
        let new = !self.path.exists();
        let mut file = OpenOptions::new()
            .create(true)
            .append(true)
            .open(&self.path)
            .with_context(|| format!("writing {}", self.path.display()))?;
        let mut text = String::new();
        if new {
            text.push_str(&self.header.join(","));
            text.push('\n');
        }
        let num = |v: f64| format!("{v:?}");
        for r in &rows {
            let mut f = vec![
                r.index.to_string(),
                r.generation.to_string(),
                num(r.objective),
                csv_field(&r.failed.as_deref().unwrap_or("").replace('\n', " ")),
            ];
            f.extend(r.parts.iter().map(|v| num(*v)));
            f.extend(r.values.iter().map(|v| num(*v)));
            f.extend(r.x.iter().map(|v| num(*v)));
            text.push_str(&f.join(","));
            text.push('\n');
        }
        file.write_all(text.as_bytes())
            .and_then(|_| file.sync_data())
            .with_context(|| format!("writing {}", self.path.display()))?;
        self.rows.extend(rows);
        Ok(())
    }
}

/// Adds generation `gen` to `all`: the rows replayed from the history,
/// then the fresh ones, sorted by coordinates (their order of completion
/// varies with the threads), numbered and appended to the history.
fn record_generation(
    history: &mut History,
    gen: usize,
    mut new: Vec<Evaluation>,
    all: &mut Vec<Evaluation>,
) -> Result<()> {
    new.sort_by(|a, b| {
        a.x.iter()
            .zip(&b.x)
            .map(|(p, q)| p.total_cmp(q))
            .find(|o| o.is_ne())
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    all.extend(
        history
            .rows()
            .iter()
            .filter(|e| e.generation == gen)
            .cloned(),
    );
    let start = history.rows().len();
    for (i, e) in new.iter_mut().enumerate() {
        e.index = start + i;
    }
    all.extend(new.iter().cloned());
    if !new.is_empty() {
        history.append(new)?;
    }
    Ok(())
}

/// Why CMA-ES stopped, in words.
fn stop_reason(reasons: &[TerminationReason], budget: usize) -> String {
    reasons
        .iter()
        .map(|r| match r {
            TerminationReason::MaxFunctionEvals => {
                format!("the budget of {budget} evaluations")
            }
            other => format!("CMA-ES stopped: {other:?}"),
        })
        .collect::<Vec<_>>()
        .join("; ")
}

fn key(x: &[f64]) -> Vec<u64> {
    x.iter().map(|v| v.to_bits()).collect()
}

/// Runs CMA-ES over `space` with `evaluate` (the candidate's normalised
/// coordinates in, its outcome out), appending to `history` and replaying
/// what it already holds. `value_of` turns normalised coordinates into the
/// values recorded in the history.
pub fn search(
    space: &Space,
    history: &mut History,
    options: SearchOptions,
    evaluate: &(dyn Fn(&[f64]) -> Outcome + Sync),
    value_of: &(dyn Fn(&[f64]) -> Vec<f64> + Sync),
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<SearchEnd> {
    let cache: HashMap<Vec<u64>, Evaluation> = history
        .rows()
        .iter()
        .map(|e| (key(&e.x), e.clone()))
        .collect();
    let generation = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let replayed = AtomicUsize::new(0);
    let best = Mutex::new(f64::INFINITY);
    let fresh: Mutex<Vec<Evaluation>> = Mutex::new(Vec::new());
    let objective = |x: &DVector<f64>| -> f64 {
        let x: Vec<f64> = x.iter().copied().collect();
        let (objective, was_cached) = match cache.get(&key(&x)) {
            Some(e) => (e.objective, true),
            None => {
                let u: Vec<f64> = x.iter().map(|v| reflect(*v)).collect();
                let out = evaluate(&u);
                let e = Evaluation {
                    index: 0,
                    generation: generation.load(Ordering::SeqCst),
                    objective: out.objective,
                    parts: out.parts,
                    failed: out.failed,
                    values: value_of(&u),
                    x,
                };
                fresh.lock().unwrap_or_else(|p| p.into_inner()).push(e);
                (out.objective, false)
            }
        };
        if was_cached {
            replayed.fetch_add(1, Ordering::SeqCst);
        }
        let n = done.fetch_add(1, Ordering::SeqCst) + 1;
        let b = {
            let mut b = best.lock().unwrap_or_else(|p| p.into_inner());
            *b = b.min(objective);
            *b
        };
        progress(Progress {
            done: n,
            replayed: replayed.load(Ordering::SeqCst),
            budget: options.budget,
            best: b,
        });
        objective
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(options.jobs.max(1))
        .build()
        .context("starting the evaluation threads")?;
    let n = space.start_unit().len();
    let budget = options.budget.max(1);
    let mut all: Vec<Evaluation> = Vec::new();
    // Runs of CMA-ES: one, or with restarts as many as the budget allows.
    let mut run = 0u32;
    let mut spent = 0usize;
    let mut first_generation = 0usize;
    let mut restarted: Vec<String> = Vec::new();
    let reason = loop {
        let lambda = default_population(n) << run;
        let start = if run == 0 {
            space.start_unit()
        } else {
            // A point drawn uniformly in the space, from the seed and the
            // run, so that a resumed search restarts where it did.
            let mut rng = realitygap_core::controller::SplitMix64::new(
                options.seed ^ u64::from(run).wrapping_mul(0x9E37_79B9_7F4A_7C15),
            );
            (0..n).map(|_| rng.uniform()).collect()
        };
        let mut cma = CMAESOptions::new(start, SIGMA0)
            .seed(options.seed.wrapping_add(u64::from(run)))
            .population_size(lambda)
            .max_function_evals(budget - spent)
            .build(&objective)
            .map_err(|e| anyhow::anyhow!("CMA-ES rejected its options: {e:?}"))?;
        let window = stall_window(n, lambda);
        let mut bests: Vec<f64> = Vec::new();
        let end = loop {
            let gen = first_generation + cma.generation();
            generation.store(gen, Ordering::SeqCst);
            let end = pool.install(|| cma.next_parallel());
            // An interrupted generation is not recorded: its evaluations were
            // cut short; the finished generations stay in the history.
            realitygap_runner::interrupt::check()?;
            let new = std::mem::take(&mut *fresh.lock().unwrap_or_else(|p| p.into_inner()));
            record_generation(history, gen, new, &mut all)?;
            if let Some(t) = end {
                break Some(t);
            }
            bests.push(
                cma.overall_best_individual()
                    .map_or(f64::INFINITY, |i| i.value),
            );
            if options.restarts && stalled(&bests, window, options.stall_m) {
                break None;
            }
        };
        spent += cma.function_evals();
        first_generation += cma.generation();
        let why = match &end {
            Some(t) => stop_reason(&t.reasons, options.budget),
            None => format!("stalled for {window} generations"),
        };
        let budget_spent = end.as_ref().is_some_and(|t| {
            t.reasons
                .iter()
                .any(|r| matches!(r, TerminationReason::MaxFunctionEvals))
        });
        // Another run needs room for a few generations of its population.
        if !options.restarts || budget_spent || budget - spent < 4 * (lambda * 2) {
            break if restarted.is_empty() {
                why
            } else {
                format!("{}; then {why}", restarted.join("; "))
            };
        }
        restarted.push(format!(
            "run {} ({lambda} candidates a generation) {why}, restarted at evaluation {spent}",
            run + 1
        ));
        run += 1;
    };
    all.sort_by_key(|e| e.index);
    Ok(SearchEnd {
        history: all,
        replayed: replayed.load(Ordering::SeqCst),
        reason,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::space::{Dim, Scale};

    fn space(n: usize) -> Space {
        Space {
            source: PathBuf::from("test.toml"),
            dims: (0..n)
                .map(|i| Dim {
                    key: format!("controller.k{i}"),
                    low: 0.0,
                    high: 10.0,
                    scale: Scale::Linear,
                    start: 5.0,
                })
                .collect(),
            settings: Default::default(),
            held: Vec::new(),
            registration: None,
            registration_start: None,
        }
    }

    /// A bowl with its minimum at values 2, 7, 4 (of [0, 10]); fails
    /// (like a diverging engine) where the first value exceeds 6.
    fn bowl(u: &[f64]) -> Outcome {
        let want = [0.2, 0.7, 0.4];
        if u[0] > 0.6 {
            return Outcome {
                objective: crate::objective::FAILED_OBJECTIVE,
                parts: vec![f64::NAN],
                failed: Some("diverged".into()),
            };
        }
        let o: f64 = u.iter().zip(want).map(|(a, b)| (a - b) * (a - b)).sum();
        Outcome {
            objective: o,
            parts: vec![o],
            failed: None,
        }
    }

    /// Equal histories (NaN parts of failed rows compare equal).
    fn same(a: &[Evaluation], b: &[Evaluation]) -> bool {
        format!("{a:?}") == format!("{b:?}")
    }

    fn values(u: &[f64]) -> Vec<f64> {
        u.iter().map(|x| x * 10.0).collect()
    }

    fn run(dir: &Path, budget: usize, jobs: usize) -> SearchEnd {
        run_on(dir, budget, jobs, false, &bowl)
    }

    fn run_on(
        dir: &Path,
        budget: usize,
        jobs: usize,
        restarts: bool,
        f: &(dyn Fn(&[f64]) -> Outcome + Sync),
    ) -> SearchEnd {
        let mut h = History::open(
            &dir.join("history.csv"),
            &["part_m".into()],
            &["a".into(), "b".into(), "c".into()],
            3,
        )
        .unwrap();
        search(
            &space(3),
            &mut h,
            SearchOptions {
                budget,
                seed: 7,
                jobs,
                restarts,
                stall_m: None,
            },
            f,
            &values,
            &|_| {},
        )
        .unwrap()
    }

    /// Writes into `to` the history in `from` as a kill would leave it:
    /// the header and the generations before `generation`. Returns the
    /// rows kept.
    fn cut_history(from: &Path, to: &Path, generation: usize) -> usize {
        let text = std::fs::read_to_string(from.join("history.csv")).unwrap();
        let kept: Vec<&str> = text
            .lines()
            .filter(|l| {
                l.split(',')
                    .nth(1)
                    .and_then(|g| g.parse::<usize>().ok())
                    .is_none_or(|g| g < generation)
            })
            .collect();
        std::fs::write(to.join("history.csv"), kept.join("\n") + "\n").unwrap();
        kept.len() - 1
    }

    /// Two optima: a wide basin around the start (its floor at 1) and a
    /// narrower, deeper one in a corner (its floor at 0).
    fn two_basins(u: &[f64]) -> Outcome {
        let d2 = |c: [f64; 3]| u.iter().zip(c).map(|(a, b)| (a - b) * (a - b)).sum::<f64>();
        let o = (1.0 + d2([0.55, 0.5, 0.45])).min(WIDTH * d2([0.1, 0.1, 0.9]));
        Outcome {
            objective: o,
            parts: vec![o],
            failed: None,
        }
    }
    const WIDTH: f64 = 8.0;

    #[test]
    fn a_stall_is_a_best_that_fell_by_less_than_the_noise_over_the_window() {
        let falling: Vec<f64> = (0..30).map(|g| 10.0 - g as f64).collect();
        assert!(!stalled(&falling, 25, Some(0.5)));
        assert!(
            !stalled(&falling[..25], 25, Some(100.0)),
            "too short to tell"
        );
        let flat: Vec<f64> = (0..30).map(|g| 1.0 + 0.001 / (g + 1) as f64).collect();
        assert!(stalled(&flat, 25, Some(0.05)));
        assert!(!stalled(&flat, 25, Some(1e-4)));
        // Without the noise: a thousandth of the best.
        assert!(stalled(&flat, 25, None));
        assert_eq!(stall_window(4, 8), 25);
        assert_eq!(default_population(4), 8);
    }

    #[test]
    fn restarts_leave_a_local_optimum_and_resume_where_they_stopped() {
        let a = tempfile::tempdir().unwrap();
        let once = run_on(a.path(), 2000, 2, false, &two_basins);
        assert!(once.best().unwrap().objective > 0.9, "{:?}", once.best());
        let b = tempfile::tempdir().unwrap();
        let again = run_on(b.path(), 2000, 2, true, &two_basins);
        assert!(again.reason.contains("restarted"), "{}", again.reason);
        assert!(again.best().unwrap().objective < 1e-3, "{:?}", again.best());
        // Generations are numbered on across the runs.
        let gens: Vec<usize> = again.history.iter().map(|e| e.generation).collect();
        assert!(gens.windows(2).all(|w| w[1] == w[0] || w[1] == w[0] + 1));
        // Cut after a restart, the search resumes to the same history.
        let last = *gens.last().unwrap();
        let c = tempfile::tempdir().unwrap();
        cut_history(b.path(), c.path(), last - 3);
        let resumed = run_on(c.path(), 2000, 1, true, &two_basins);
        assert!(
            same(&resumed.history, &again.history),
            "the resumed search differs"
        );
        assert_eq!(resumed.reason, again.reason);
    }

    #[test]
    fn reflect_folds_into_the_unit_interval() {
        for (x, want) in [
            (0.3, 0.3),
            (1.2, 0.8),
            (-0.25, 0.25),
            (2.5, 0.5),
            (-1.5, 0.5),
        ] {
            assert!((reflect(x) - want).abs() < 1e-12, "{x}");
        }
        assert_eq!(reflect(f64::NAN), 0.5);
    }

    #[test]
    fn finds_a_bowl_survives_failures_and_is_deterministic_across_jobs() {
        let a = tempfile::tempdir().unwrap();
        let b = tempfile::tempdir().unwrap();
        let one = run(a.path(), 600, 1);
        let two = run(b.path(), 600, 2);
        let best = one.best().unwrap();
        for (v, want) in best.values.iter().zip([2.0, 7.0, 4.0]) {
            assert!((v - want).abs() < 0.05, "{:?}", best.values);
        }
        assert!(
            one.history.iter().any(|e| e.failed.is_some()),
            "no failed candidate was tried"
        );
        assert!(same(&one.history, &two.history), "jobs 1 and 2 differ");
        assert_eq!(
            std::fs::read_to_string(a.path().join("history.csv")).unwrap(),
            std::fs::read_to_string(b.path().join("history.csv")).unwrap()
        );
    }

    #[test]
    fn a_killed_search_resumes_where_it_stopped() {
        let whole = tempfile::tempdir().unwrap();
        let cut = tempfile::tempdir().unwrap();
        let full = run(whole.path(), 120, 2);
        // A kill after some generations leaves whole generations in the
        // file (each is appended at once); keep the first 5 of them.
        let text = std::fs::read_to_string(whole.path().join("history.csv")).unwrap();
        let kept = cut_history(whole.path(), cut.path(), 5);
        let resumed = run(cut.path(), 120, 1);
        assert_eq!(resumed.replayed, kept);
        assert!(resumed.replayed > 0);
        assert!(
            same(&resumed.history, &full.history),
            "the resumed search differs"
        );
        assert_eq!(
            std::fs::read_to_string(cut.path().join("history.csv")).unwrap(),
            text
        );
        // A history of another space is refused, not mixed in.
        let mut h = History::open(&cut.path().join("history.csv"), &[], &["a".into()], 1);
        assert!(h
            .as_mut()
            .err()
            .unwrap()
            .to_string()
            .contains("history.csv:1"));
    }
}
