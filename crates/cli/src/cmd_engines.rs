//! `realitygap engines`: the physics engines compiled into this binary, and
//! the registry the other commands find them in.

use anyhow::Result;
use realitygap::param_table;
use realitygap_core::engine::Engine;

/// Arguments of `realitygap engines`.
#[derive(clap::Args)]
pub struct Args {
    /// Also list the settings each engine accepts (`[engine.NAME]` in a
    /// scene file, or `--set` on `realitygap run`).
    #[arg(long)]
    pub settings: bool,
    /// Also list, per engine, the physical parameters (`--params FILE`) it
    /// honours and what each becomes in the engine.
    #[arg(long)]
    pub params: bool,
    /// Also list, per engine, how its servos take each kind of joint
    /// command (velocity targets, position targets with the PD law,
    /// efforts): the engine's own mechanism.
    #[arg(long)]
    pub commands: bool,
    /// Makes the pinned Python environment of a built-in engine adapter
    /// (`mujoco4`, ...) in the engines folder (~/.cache/realitygap/engines,
    /// or $REALITYGAP_ENGINES_DIR), then lists the engines.
    #[arg(long, value_name = "NAME")]
    pub install: Vec<String>,
}

/// Every engine this binary can run, by name ([`realitygap::engines`]).
pub fn compiled() -> Vec<Box<dyn Engine>> {
    realitygap::engines()
}

/// Prints the compiled-in engines, one per line: name, version, default
/// timestep.
pub fn run(args: Args) -> Result<()> {
    use realitygap_engine_remote::registry;
    for name in &args.install {
        let adapter = registry::adapter(name).ok_or_else(|| {
            let names: Vec<&str> = registry::ADAPTERS.iter().map(|a| a.name).collect();
            anyhow::anyhow!(
                "--install {name}: not a built-in engine adapter (they are: {})",
                names.join(", ")
            )
        })?;
        eprintln!(
            "installing engine {name} into {}",
            registry::venv_dir(adapter).display()
        );
        registry::install(adapter).map_err(|e| anyhow::anyhow!("--install {name}: {e}"))?;
    }
    let engines = compiled();
    if engines.is_empty() {
        println!("no engine compiled in (build with `--features mujoco`)");
        return Ok(());
    }
    let width = engines.iter().map(|e| e.name().len()).max().unwrap_or(0);
    for e in &engines {
        println!(
            "{:<width$}  {}  (default timestep {} s)",
            e.name(),
            e.version(),
            e.default_timestep_s()
        );
        if args.settings {
            for s in e.settings_help() {
                println!("{:<width$}    {:<18} {}", "", s.key, s.help);
            }
        }
        if args.params {
            for (key, mapping) in param_table(e.as_ref()) {
                println!("{:<width$}    {:<30} {}", "", key.pattern(), mapping);
            }
        }
        if args.commands {
            for c in e.command_support() {
                println!(
                    "{:<width$}    {:<17} {}",
                    "",
                    format!("{} ({})", c.kind.name(), c.kind.unit()),
                    c.mechanism
                );
            }
        }
    }
    for adapter in registry::ADAPTERS {
        if !registry::is_installed(adapter) {
            println!(
                "{:<width$}  not installed: {}",
                adapter.name,
                registry::install_line(adapter.name)
            );
        }
    }
    Ok(())
}
