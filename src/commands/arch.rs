//! `occsim arch show|list`: print a machine architecture with every parameter's unit and
//! meaning, and the shared `--arch`, `--arch-file`, `--set` options of the commands that
//! run a machine.

use anyhow::Context;
use occsim_sim::arch::{Arch, BUILTIN_ARCHS};
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub struct ArchArgs {
    #[command(subcommand)]
    pub command: ArchCommand,
}

#[derive(clap::Subcommand)]
pub enum ArchCommand {
    /// Print an architecture as a TOML file, each parameter with its unit and meaning.
    Show(ShowArgs),
    /// List the built-in architectures.
    List {
        /// Print the list as JSON: per architecture `name`, `machine`, `title` and `boards`
        /// (null on a machine without boards).
        #[arg(long)]
        json: bool,
    },
}

#[derive(clap::Args)]
pub struct ShowArgs {
    /// A built-in architecture (o2 unless given; not beside --arch-file).
    #[arg(conflicts_with = "arch_file")]
    pub name: Option<String>,
    /// Load the architecture from this TOML file instead.
    #[arg(long, value_name = "FILE")]
    pub arch_file: Option<PathBuf>,
    /// Override one parameter (repeatable), e.g. --set engines=8.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Print the architecture as JSON instead: `name` (`ir4`, `my.toml`, `o2 (engines=2)`),
    /// `machine`, `title` and per parameter `key`,
    /// `value`, `default`, `unit`, `meaning`, `provenance` (V, V2 or I), `source` and
    /// `plausible` (an I parameter's `[low, high]`, else null).
    #[arg(long)]
    pub json: bool,
}

/// The built-in architecture a command takes when given none.
pub const DEFAULT_ARCH: &str = "o2";

/// How a command that runs a machine picks its architecture.
#[derive(clap::Args, Clone, Debug)]
pub struct ArchSelection {
    /// A built-in architecture (see `occsim arch list`).
    #[arg(long, default_value = DEFAULT_ARCH)]
    pub arch: String,
    /// Load the architecture from this TOML file instead (see `occsim arch show`).
    #[arg(long, value_name = "FILE", conflicts_with = "arch")]
    pub arch_file: Option<PathBuf>,
    /// Override one parameter (repeatable), e.g. --set counter_bits=16.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
}

impl ArchSelection {
    pub fn resolve(&self) -> anyhow::Result<Arch> {
        resolve(&self.arch, self.arch_file.as_deref(), &self.set)
    }

    /// The architecture as a chart's title names it: `ir4`, `my.toml`, `o2 (engines=2)`.
    pub fn describe(&self) -> String {
        describe(&self.arch, self.arch_file.as_deref(), &self.set)
    }

    /// The architecture resolved with `--engines E` applied ([`set_engines`]), and as a
    /// chart's title names it then (`ir4, 2 engines`).
    pub fn resolve_with_engines(&self, engines: Option<u64>) -> anyhow::Result<(Arch, String)> {
        let mut arch = self.resolve()?;
        set_engines(&mut arch, engines, &self.set)?;
        let name = match engines {
            Some(engines) => format!("{}, {engines} engines", self.describe()),
            None => self.describe(),
        };
        Ok((arch, name))
    }
}

/// `arch show --json`: the architecture's `name` (as a chart's title names it:
/// [`describe`]) and every parameter as the TOML's comments give it, in fields.
fn arch_json(name: &str, arch: &Arch) -> serde_json::Value {
    let parameters: Vec<serde_json::Value> = arch
        .entries()
        .map(|(param, value)| {
            serde_json::json!({
                "key": param.key,
                "value": value,
                "default": param.default,
                "unit": param.unit,
                "meaning": param.meaning,
                "provenance": param.provenance.mark.name(),
                "source": param.provenance.source,
                "plausible": param.provenance.plausible.map(|(low, high)| [low, high]),
            })
        })
        .collect();
    serde_json::json!({
        "name": name,
        "machine": arch.machine().name(),
        "title": arch.machine().title(),
        "parameters": parameters,
    })
}

/// A built-in name or a file, with its overrides: `o2 (engines=2, counter_bits=16)`.
pub fn describe(name: &str, file: Option<&Path>, sets: &[String]) -> String {
    let base = file.map_or(name.to_string(), |f| f.display().to_string());
    if sets.is_empty() {
        base
    } else {
        format!("{base} ({})", sets.join(", "))
    }
}

/// A built-in or file architecture with the `--set` overrides applied in order.
pub fn resolve(name: &str, file: Option<&Path>, sets: &[String]) -> anyhow::Result<Arch> {
    let mut arch = match file {
        Some(path) => {
            let text = super::read_settings_file(path, "architecture file")?;
            Arch::from_toml(&text)
                .with_context(|| format!("{}: invalid architecture", path.display()))?
        }
        None => Arch::builtin(name)?,
    };
    for (k, set) in sets.iter().enumerate() {
        if let Some(earlier) = set_of(&sets[..k], set_key(set)) {
            anyhow::bail!(
                "--set {set}: {} is set twice (--set {earlier})",
                set_key(set)
            );
        }
        arch.set(set).with_context(|| format!("--set {set}"))?;
    }
    Ok(arch)
}

/// The parameter a `--set KEY=VALUE` names.
pub fn set_key(set: &str) -> &str {
    set.split('=').next().unwrap_or(set).trim()
}

/// The `--set` of `sets` that names `key`, if one does.
pub fn set_of<'a>(sets: &'a [String], key: &str) -> Option<&'a String> {
    sets.iter().find(|set| set_key(set) == key)
}

/// `--engines E`, shorthand for `--set engines=E`, applied to `arch` (resolved with `sets`):
/// refused where a `--set engines=` says otherwise.
pub fn set_engines(arch: &mut Arch, engines: Option<u64>, sets: &[String]) -> anyhow::Result<()> {
    let Some(engines) = engines else {
        return Ok(());
    };
    if let Some(set) = set_of(sets, "engines") {
        anyhow::bail!("--engines {engines} and --set {set}: give the engine count once");
    }
    arch.set_value("engines", &engines.to_string())
        .context("--engines")
}

pub fn run(args: ArchArgs) -> anyhow::Result<()> {
    match args.command {
        ArchCommand::Show(show) => {
            let builtin = show.name.as_deref().unwrap_or(DEFAULT_ARCH);
            let arch = resolve(builtin, show.arch_file.as_deref(), &show.set)?;
            match show.json {
                true => {
                    let name = describe(builtin, show.arch_file.as_deref(), &show.set);
                    outln!(
                        "{}",
                        serde_json::to_string_pretty(&arch_json(&name, &arch))?
                    )
                }
                false => out!("{}", arch.to_documented_toml()),
            }
        }
        ArchCommand::List { json } => {
            let mut listed = Vec::new();
            for name in BUILTIN_ARCHS {
                let arch = Arch::builtin(name)?;
                let boards = arch.get("boards");
                if json {
                    listed.push(serde_json::json!({
                        "name": name,
                        "machine": arch.machine().name(),
                        "title": arch.machine().title(),
                        "boards": boards,
                    }));
                    continue;
                }
                let boards = boards
                    .map(|boards| match boards.to_string().as_str() {
                        "1" => " (1 board)".to_string(),
                        n => format!(" ({n} boards)"),
                    })
                    .unwrap_or_default();
                outln!("{name:<8} {}{boards}", arch.machine().title());
            }
            if json {
                outln!("{}", serde_json::to_string_pretty(&listed)?);
            }
        }
    }
    Ok(())
}
