//! Uncertainty of the accumulated error, by bootstrap over runs.
//!
//! The accumulated error of a source is `sum_k || mean_source(k) -
//! mean_real(k) ||` over the control steps `k`. Which real runs happened to
//! be recorded (and, for a simulator whose runs differ, which of its runs)
//! is a sample; the bootstrap redraws it. In every replicate the real runs
//! are drawn with replacement (the same draw for every source, so that two
//! sources are compared on the same replicate: a paired comparison), and
//! a source's runs are drawn too when they are not all identical. The 95 %
//! interval is the 2.5 and 97.5 percentiles of the replicates.
//!
//! Draws are seeded and deterministic: the real runs' draws come from one
//! stream, each source's from a stream of its own derived from its name, so
//! adding or removing a source changes no other source's interval.

use realitygap_core::controller::SplitMix64;
use realitygap_core::fingerprint::Fingerprint;
use realitygap_core::Vec3;
use serde::{Deserialize, Serialize};

/// Settings of the bootstrap.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BootstrapOptions {
    /// Replicates drawn (0 turns the bootstrap off).
    pub resamples: usize,
    /// Seed of the draws.
    pub seed: u64,
    /// Confidence level of the intervals, e.g. 0.95.
    pub level: f64,
}

impl Default for BootstrapOptions {
    fn default() -> Self {
        BootstrapOptions {
            resamples: 1000,
            seed: 2019,
            level: 0.95,
        }
    }
}

/// A confidence interval, metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Interval {
    /// Lower bound, metres.
    pub low_m: f64,
    /// Upper bound, metres.
    pub high_m: f64,
}

/// The runs of one source on the control grid, as a dense array: per run
/// and step the wrist position (metres), NaN where the run has no sample.
#[derive(Debug, Clone, PartialEq)]
pub struct RunTracks {
    steps: usize,
    /// `runs x steps x 3`, row-major.
    values: Vec<f64>,
    runs: usize,
    identical: bool,
}

impl RunTracks {
    /// Packs per-run tracks (`None` or missing steps become NaN). Runs
    /// longer than `steps` are cut.
    pub fn new(tracks: &[Vec<Option<Vec3>>], steps: usize) -> RunTracks {
        let mut values = vec![f64::NAN; tracks.len() * steps * 3];
        for (r, t) in tracks.iter().enumerate() {
            for (k, p) in t.iter().take(steps).enumerate() {
                if let Some(p) = p.filter(|p| p.is_finite()) {
                    let i = (r * steps + k) * 3;
                    values[i..i + 3].copy_from_slice(&p.to_array());
                }
            }
        }
        let stride = steps * 3;
        let identical = (1..tracks.len()).all(|r| {
            values[r * stride..(r + 1) * stride]
                .iter()
                .zip(&values[..stride])
                .all(|(a, b)| (a.is_nan() && b.is_nan()) || (a - b).abs() <= 1e-12)
        });
        RunTracks {
            steps,
            values,
            runs: tracks.len(),
            identical,
        }
    }

    /// Number of runs.
    pub fn runs(&self) -> usize {
        self.runs
    }

    /// True when every run is the same (a deterministic simulator): drawing
    /// its runs again changes nothing.
    pub fn all_identical(&self) -> bool {
        self.identical
    }

    /// Per-step mean with run `r` counted `weights[r]` times, written into
    /// `out` (`steps x 3`; NaN where no weighted run has a sample).
    fn weighted_mean(&self, weights: &[f64], out: &mut [f64]) {
        let stride = self.steps * 3;
        let mut total = vec![0.0; self.steps];
        out.iter_mut().for_each(|x| *x = 0.0);
        for (r, &w) in weights.iter().enumerate() {
            if w == 0.0 {
                continue;
            }
            let run = &self.values[r * stride..(r + 1) * stride];
            for k in 0..self.steps {
                let p = &run[k * 3..k * 3 + 3];
                if p[0].is_nan() {
                    continue;
                }
                total[k] += w;
                out[k * 3] += w * p[0];
                out[k * 3 + 1] += w * p[1];
                out[k * 3 + 2] += w * p[2];
            }
        }
        for k in 0..self.steps {
            for c in 0..3 {
                out[k * 3 + c] = if total[k] > 0.0 {
                    out[k * 3 + c] / total[k]
                } else {
                    f64::NAN
                };
            }
        }
    }
}

/// Sum over steps of the distance between two per-step means (`steps x 3`),
/// over the steps where both have a value; NaN when there is none.
fn accumulated(a: &[f64], b: &[f64]) -> f64 {
    let mut sum = 0.0;
    let mut any = false;
    for (p, q) in a.chunks_exact(3).zip(b.chunks_exact(3)) {
        let d = ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt();
        if d.is_finite() {
            sum += d;
            any = true;
        }
    }
    if any {
        sum
    } else {
        f64::NAN
    }
}

/// Draws `n` indices with replacement: how often each run is drawn.
fn draw_counts(rng: &mut SplitMix64, n: usize, counts: &mut [f64]) {
    counts.iter_mut().for_each(|c| *c = 0.0);
    for _ in 0..n {
        let i = ((rng.uniform() * n as f64) as usize).min(n - 1);
        counts[i] += 1.0;
    }
}

/// A stream seed for a source, from the bootstrap seed and its name (FNV-1a).
fn stream_seed(seed: u64, name: &str) -> u64 {
    seed ^ Fingerprint::new().eat(name.as_bytes()).value()
}

/// The bootstrap replicates of every source's accumulated error, metres:
/// `result[s][b]` for source `s` and replicate `b` (NaN when there is no
/// overlap). Replicate `b` uses the same draw of the real runs for every
/// source. Sources are given as (name, runs).
pub fn replicates(
    reference: &RunTracks,
    sources: &[(&str, &RunTracks)],
    opts: &BootstrapOptions,
) -> Vec<Vec<f64>> {
    let steps = reference.steps;
    let mut out = vec![Vec::with_capacity(opts.resamples); sources.len()];
    if reference.runs == 0 {
        for o in &mut out {
            o.resize(opts.resamples, f64::NAN);
        }
        return out;
    }
    let mut ref_rng = SplitMix64::new(opts.seed);
    let mut src_rngs: Vec<SplitMix64> = sources
        .iter()
        .map(|(n, _)| SplitMix64::new(stream_seed(opts.seed, n)))
        .collect();
    let fixed: Vec<Option<Vec<f64>>> = sources
        .iter()
        .map(|(_, t)| {
            (t.identical && t.runs > 0 && t.steps == steps).then(|| {
                let mut m = vec![0.0; steps * 3];
                t.weighted_mean(&vec![1.0; t.runs], &mut m);
                m
            })
        })
        .collect();
    let mut ref_counts = vec![0.0; reference.runs];
    let mut ref_mean = vec![0.0; steps * 3];
    let mut src_mean = vec![0.0; steps * 3];
    for _ in 0..opts.resamples {
        draw_counts(&mut ref_rng, reference.runs, &mut ref_counts);
        reference.weighted_mean(&ref_counts, &mut ref_mean);
        for (s, (_, t)) in sources.iter().enumerate() {
            let e = match &fixed[s] {
                Some(m) => accumulated(m, &ref_mean),
                None if t.runs == 0 || t.steps != steps => f64::NAN,
                None => {
                    let mut counts = vec![0.0; t.runs];
                    draw_counts(&mut src_rngs[s], t.runs, &mut counts);
                    t.weighted_mean(&counts, &mut src_mean);
                    accumulated(&src_mean, &ref_mean)
                }
            };
            out[s].push(e);
        }
    }
    out
}

/// The `q`-quantile (0..1) of the finite values, by linear interpolation
/// between order statistics; `None` when there is none.
pub fn quantile(values: &[f64], q: f64) -> Option<f64> {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let pos = q.clamp(0.0, 1.0) * (v.len() - 1) as f64;
    let (i, f) = (pos.floor() as usize, pos.fract());
    Some(if i + 1 < v.len() {
        v[i] + f * (v[i + 1] - v[i])
    } else {
        v[i]
    })
}

/// Percentile interval of replicates at `level` (e.g. 0.95 gives the 2.5 %
/// and 97.5 % quantiles). `None` when fewer than half of the replicates
/// are finite.
pub fn percentile_interval(replicates: &[f64], level: f64) -> Option<Interval> {
    let finite = replicates.iter().filter(|x| x.is_finite()).count();
    if replicates.is_empty() || finite * 2 < replicates.len() {
        return None;
    }
    let a = (1.0 - level) / 2.0;
    Some(Interval {
        low_m: quantile(replicates, a)?,
        high_m: quantile(replicates, 1.0 - a)?,
    })
}

/// A paired comparison of the closest source with the runner-up in one
/// scene, over the same bootstrap replicates.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PairedComparison {
    /// The source with the smallest accumulated error.
    pub closest: String,
    /// The source with the next smallest.
    pub runner_up: String,
    /// Runner-up's error minus the closest's, metres.
    pub difference_m: f64,
    /// Interval of that difference over the replicates, metres.
    pub difference_interval_m: Option<Interval>,
    /// Share of the replicates in which the closest source is closer
    /// (ties count half): the probability that it really is closer.
    pub probability_closer: f64,
    /// True when the difference's interval lies above 0: the two can be
    /// told apart at the interval's level.
    pub distinguishable: bool,
}

/// Compares two sources' replicates (paired by index). `a` is the one
/// with the smaller point estimate.
pub fn paired(
    a: (&str, f64, &[f64]),
    b: (&str, f64, &[f64]),
    level: f64,
) -> Option<PairedComparison> {
    let diffs: Vec<f64> = a.2.iter().zip(b.2).map(|(x, y)| y - x).collect();
    let finite: Vec<f64> = diffs.iter().copied().filter(|d| d.is_finite()).collect();
    if finite.is_empty() {
        return None;
    }
    let wins: f64 = finite
        .iter()
        .map(|d| match d.partial_cmp(&0.0) {
            Some(std::cmp::Ordering::Greater) => 1.0,
            Some(std::cmp::Ordering::Equal) => 0.5,
            _ => 0.0,
        })
        .sum();
    let interval = percentile_interval(&diffs, level);
    Some(PairedComparison {
        closest: a.0.to_string(),
        runner_up: b.0.to_string(),
        difference_m: b.1 - a.1,
        difference_interval_m: interval,
        probability_closer: wins / finite.len() as f64,
        distinguishable: interval.is_some_and(|i| i.low_m > 0.0),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The true mean track of the real arm and a fixed source `d` away.
    fn truth(steps: usize) -> (Vec<Vec3>, Vec<Vec3>) {
        let real: Vec<Vec3> = (0..steps)
            .map(|k| Vec3::new(0.01 * k as f64, 0.0, 0.5))
            .collect();
        let src = real
            .iter()
            .enumerate()
            .map(|(k, p)| *p + Vec3::new(0.0, 0.02, 0.01 * (k as f64 * 0.3).sin()))
            .collect();
        (real, src)
    }

    /// Real runs: the true track plus a per-run offset (5 mm per axis) and
    /// per-step noise (3 mm per axis).
    fn draw_runs(rng: &mut SplitMix64, real: &[Vec3], runs: usize) -> Vec<Vec<Option<Vec3>>> {
        (0..runs)
            .map(|_| {
                let o = Vec3::new(rng.normal(), rng.normal(), rng.normal()).scale(0.005);
                real.iter()
                    .map(|p| {
                        let e = Vec3::new(rng.normal(), rng.normal(), rng.normal()).scale(0.003);
                        Some(*p + o + e)
                    })
                    .collect()
            })
            .collect()
    }

    #[test]
    fn intervals_cover_the_true_value_at_close_to_the_nominal_rate() {
        let steps = 20;
        let (real, src) = truth(steps);
        let true_error: f64 = real.iter().zip(&src).map(|(a, b)| a.distance(*b)).sum();
        let source = RunTracks::new(&[src.iter().map(|p| Some(*p)).collect()], steps);
        let opts = BootstrapOptions {
            resamples: 400,
            seed: 5,
            level: 0.95,
        };
        let mut rng = SplitMix64::new(99);
        let trials = 300;
        let mut covered = 0;
        for t in 0..trials {
            let runs = draw_runs(&mut rng, &real, 20);
            let reference = RunTracks::new(&runs, steps);
            let opts = BootstrapOptions {
                seed: opts.seed + t,
                ..opts
            };
            let reps = replicates(&reference, &[("s", &source)], &opts);
            let i = percentile_interval(&reps[0], opts.level).unwrap();
            if i.low_m <= true_error && true_error <= i.high_m {
                covered += 1;
            }
        }
        let rate = covered as f64 / trials as f64;
        eprintln!("bootstrap coverage: {covered} of {trials} ({rate:.3}) at nominal 0.95");
        assert!((0.90..=0.985).contains(&rate), "coverage {rate}");
    }

    #[test]
    fn draws_are_deterministic_and_independent_of_other_sources() {
        let (real, src) = truth(10);
        let mut rng = SplitMix64::new(1);
        let reference = RunTracks::new(&draw_runs(&mut rng, &real, 8), 10);
        let a = RunTracks::new(&[src.iter().map(|p| Some(*p)).collect()], 10);
        let b = RunTracks::new(&draw_runs(&mut rng, &src, 5), 10);
        assert!(a.all_identical() && !b.all_identical());
        let opts = BootstrapOptions::default();
        let both = replicates(&reference, &[("a", &a), ("b", &b)], &opts);
        let only_b = replicates(&reference, &[("b", &b)], &opts);
        assert_eq!(both[1], only_b[0]);
        assert_eq!(both, replicates(&reference, &[("a", &a), ("b", &b)], &opts));
        // A varying source's own runs widen its interval.
        let ia = percentile_interval(&both[0], 0.95).unwrap();
        let ib = percentile_interval(&both[1], 0.95).unwrap();
        assert!(ib.high_m - ib.low_m > ia.high_m - ia.low_m, "{ia:?} {ib:?}");
    }

    #[test]
    fn paired_comparison_separates_clear_gaps_and_not_ties() {
        let (real, src) = truth(20);
        let mut rng = SplitMix64::new(3);
        let reference = RunTracks::new(&draw_runs(&mut rng, &real, 20), 20);
        let near = RunTracks::new(&[src.iter().map(|p| Some(*p)).collect()], 20);
        let far_track: Vec<Option<Vec3>> = src
            .iter()
            .map(|p| Some(*p + Vec3::new(0.0, 0.03, 0.0)))
            .collect();
        let far = RunTracks::new(&[far_track], 20);
        let opts = BootstrapOptions::default();
        let reps = replicates(
            &reference,
            &[("near", &near), ("far", &far), ("twin", &near)],
            &opts,
        );
        let c = paired(("near", 1.0, &reps[0]), ("far", 2.0, &reps[1]), 0.95).unwrap();
        assert!(c.distinguishable && c.probability_closer > 0.99, "{c:?}");
        let tie = paired(("near", 1.0, &reps[0]), ("twin", 1.0, &reps[2]), 0.95).unwrap();
        assert!(
            !tie.distinguishable && tie.probability_closer == 0.5,
            "{tie:?}"
        );
    }

    #[test]
    fn quantiles_interpolate() {
        let v = [4.0, 1.0, 3.0, 2.0, f64::NAN];
        assert_eq!(quantile(&v, 0.0), Some(1.0));
        assert_eq!(quantile(&v, 0.5), Some(2.5));
        assert_eq!(quantile(&v, 1.0), Some(4.0));
        assert_eq!(quantile(&[], 0.5), None);
        assert!(percentile_interval(&[f64::NAN, f64::NAN, 1.0], 0.95).is_none());
    }
}
