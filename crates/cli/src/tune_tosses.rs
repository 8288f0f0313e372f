//! `realitygap tune STUDY` for a study of tossed objects
//! (`assets/studies/contactnets2020.toml`): the contact fitted on the
//! study's tosses and scored on the ones it holds out (the work is
//! [`realitygap_tune::tosses`]'s; this is options, progress and summary).

use crate::tune::{cores, TuneRequest, Tuned};
use crate::ui::Ui;
use anyhow::{bail, Context, Result};
use realitygap_core::params::PhysicalParams;
use realitygap_runner::prepare::{engine_names, find_engine, overrides_for};
use realitygap_runner::slurm::Executor;
use realitygap_study::data_source::assets_dir;
use realitygap_study::toss_study::TossStudy;
use realitygap_tune::search::SearchOptions;
use realitygap_tune::space::Space;
use realitygap_tune::tosses::{supported_space, tune_tosses as tune, TossTune};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

/// The space every engine's toss tune searches unless `--space`.
pub const TOSS_SPACE_IN_ASSETS: &str = "tuning/tosses.toml";

/// Runs the toss tune `request` asks for with the study file `study`.
pub fn tune_tosses(request: &TuneRequest, study: &Path, ui: &dyn Ui) -> Result<Tuned> {
    let args = request;
    for (given, flag) in [
        (args.params.is_some(), "--params"),
        (args.scene.is_some(), "--scene"),
        (args.efforts, "--efforts"),
        (args.runs.is_some(), "--runs"),
        (args.holdout.is_some(), "--holdout"),
        (args.robot.is_some(), "--robot"),
        (!args.packages.is_empty(), "--package"),
        (args.keep_registration, "--keep-registration"),
        (args.iterations.is_some(), "--iterations"),
    ] {
        if given {
            bail!(
                "{flag} does not apply to a study of tosses ({}): its held_out_every chooses the tosses to fit on and to hold out",
                study.display()
            );
        }
    }
    if !matches!(args.executor, Executor::Local) {
        bail!("a study of tosses is tuned on this machine only (--executor local)");
    }
    let registry = crate::engines;
    let engine = find_engine(registry, &args.engine)?;
    if engine.name() == realitygap_core::engine::PHYSICS_FREE_ENGINE {
        bail!(
            "--engine {}: the physics-free toss (ballistic, frozen at first contact) has nothing to tune; it is the table's physics-free row",
            engine.name()
        );
    }
    let spec = TossStudy::from_file(study)?;
    let space_file = args
        .space
        .clone()
        .unwrap_or_else(|| assets_dir().join(TOSS_SPACE_IN_ASSETS));
    let space = supported_space(engine.as_ref(), &Space::from_file(&space_file)?);
    if !space.held.is_empty() {
        ui.note(format!(
            "{} has no equivalent of {}: not fitted",
            engine.name(),
            space.held.join(", ")
        ));
    }
    let mut settings = match &args.settings {
        Some(f) => PhysicalParams::from_file(f)?
            .engine_settings
            .remove(engine.name())
            .with_context(|| {
                format!(
                    "--settings {}: no [engine.{}] table",
                    f.display(),
                    engine.name()
                )
            })?,
        None => Default::default(),
    };
    settings.extend(overrides_for(
        &args.set,
        engine.name(),
        &engine_names(registry),
    )?);
    let set = spec.load(&args.data)?;
    let (training, held_out) = spec.split(&set);
    let budget = args.budget.unwrap_or(spec.budget);
    let jobs = args.jobs.unwrap_or_else(cores);
    ui.note(format!(
        "tune {} on {}: {} tosses to fit on, {} held out (every {}th); space {} ({} parameters); {budget} evaluations on {jobs} threads",
        engine.name(),
        spec.name,
        training.len(),
        held_out.len(),
        spec.held_out_every,
        space_file.display(),
        space.len()
    ));
    let request = TossTune {
        engine: engine.as_ref(),
        set: &set,
        training: &training,
        held_out: &held_out,
        space: &space,
        settings: &settings,
        options: SearchOptions {
            budget,
            seed: args.seed,
            jobs,
            restarts: args.restarts,
            stall_m: None,
        },
        out: &args.out,
        study: study.display().to_string(),
    };
    let bar = ui.bar(budget as u64, "evaluations");
    let started = Instant::now();
    let on_progress = |p: realitygap_tune::search::Progress| {
        bar.set_position(p.done as u64);
        let fresh = p.done.saturating_sub(p.replayed);
        bar.set_message(format!(
            "best {:.4} edges, {:.2} evaluations/s{}",
            p.best,
            fresh as f64 / started.elapsed().as_secs_f64().max(1e-9),
            if p.replayed > 0 {
                format!(" ({} replayed)", p.replayed)
            } else {
                String::new()
            }
        ));
    };
    let scored = AtomicU64::new(0);
    let on_scored = || {
        if scored.fetch_add(1, Ordering::SeqCst) == 0 {
            ui.note(format!(
                "scoring {} at its defaults and tuned on the {} held-out tosses",
                engine.name(),
                held_out.len()
            ));
        }
    };
    let result = tune(&request, &on_progress, &on_scored);
    bar.finish();
    let result = result?;
    ui.say(result.markdown.clone());
    ui.note("\nwrote:".into());
    for f in &result.files {
        ui.note(format!("  {}", f.display()));
    }
    Ok(Tuned {
        markdown: result.markdown,
        files: result.files,
    })
}
