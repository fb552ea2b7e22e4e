//! `occsim`: the command line. Thin: parsing arguments, file IO and printing; the work is
//! done by the traces, sim and rtl-model crates.

/// `println!` that returns an error instead of panicking when stdout is closed (`| head`).
macro_rules! outln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        writeln!(std::io::stdout().lock(), $($arg)*)?
    }};
}

/// `print!` that returns an error instead of panicking when stdout is closed.
macro_rules! out {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        write!(std::io::stdout().lock(), $($arg)*)?
    }};
}

mod commands;

mod scene_input;

use clap::{Parser, Subcommand};

/// Cycle-level simulator of occlusion-query hardware (Bartz, Meissner, Huettner 1998).
#[derive(Parser)]
#[command(name = "occsim", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the built-in demo scene end to end and print what its queries cost.
    Demo(commands::demo::DemoArgs),
    /// Run a scene through the golden model and print every query's answer (a samples query's count, an any query's 0 or 1, a brief or verbose query's tiles).
    Count(commands::count::CountArgs),
    /// Make, inspect and dump fragment traces (.occt).
    #[command(subcommand)]
    Trace(commands::trace::TraceCommand),
    /// Replay a trace on a machine model, cycle by cycle, and report what each query cost.
    Replay(commands::replay::ReplayArgs),
    /// Tabulate (and plot) query latency per engine count: drain, local and global merge.
    Latency(commands::latency::LatencyArgs),
    /// Run every fidelity level on one trace: wall time, cycles, latency and error.
    Fidelity(commands::fidelity::FidelityArgs),
    /// Show the built-in architectures and their parameters.
    Arch(commands::arch::ArchArgs),
    /// Compare the culling drivers on a walkthrough.
    #[command(subcommand)]
    Culling(CullingCommand),
    /// Replay a trace over the cartesian product of parameter values (`--set k=v1,v2`).
    Sweep(Box<commands::sweep::SweepArgs>),
    /// Vary every inferred (I) parameter over its plausible range and report each headline
    /// result as a band, with the parameters that move it most first.
    Sensitivity(commands::sensitivity::SensitivityArgs),
}

#[derive(Subcommand)]
enum CullingCommand {
    /// Run every culling driver on the same walkthrough and print what each draws, what its
    /// queries cost and the simulated cycles per frame.
    Compare(Box<commands::culling::CompareArgs>),
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    remove_temporaries_on_interrupt();
    let outcome = match cli.command {
        Command::Demo(args) => commands::demo::run(args),
        Command::Count(args) => commands::count::run(args),
        Command::Trace(command) => commands::trace::run(command),
        Command::Replay(args) => commands::replay::run(args),
        Command::Latency(args) => commands::latency::run(args),
        Command::Arch(args) => commands::arch::run(args),
        Command::Sweep(args) => commands::sweep::run(*args),
        Command::Sensitivity(args) => commands::sensitivity::run(args),
        Command::Culling(CullingCommand::Compare(args)) => commands::culling::run(*args),
        Command::Fidelity(args) => commands::fidelity::run(args),
    };
    if occsim_sweep::output::stopping() {
        // A signal came: its handler has removed the temporaries and is ending the process
        // by the signal. Whatever the command came to meanwhile (its outputs in place, or
        // a write refused as the process stops) is not its to report: it had exited 1
        // with "the process is stopping", or 0, racing the handler.
        loop {
            std::thread::park();
        }
    }
    match outcome {
        Ok(()) => std::process::ExitCode::SUCCESS,
        // A closed pipe (`occsim count ... | head`) is the reader's choice, not a failure.
        Err(error) if is_broken_pipe(&error) => std::process::ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("occsim: error: {error:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

/// On SIGINT, SIGTERM or SIGHUP: remove the temporary files of the writes under way (they
/// will never finish), then end as the signal would have ended the process. A signal the
/// process was started ignoring stays ignored: `nohup` ignores SIGHUP, and a shell its
/// scripts' background jobs' SIGINT, so that a long sweep outlives its terminal.
fn remove_temporaries_on_interrupt() {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
    let handled: Vec<i32> = [SIGINT, SIGTERM, SIGHUP]
        .into_iter()
        .filter(|&signal| !ignored_at_start(signal))
        .collect();
    let Ok(mut signals) = signal_hook::iterator::Signals::new(handled) else {
        // Without the handler an interrupt leaves its temporary; the next write removes it.
        return;
    };
    std::thread::spawn(move || {
        if let Some(signal) = signals.forever().next() {
            occsim_sweep::output::remove_temporaries();
            let _ = signal_hook::low_level::emulate_default_handler(signal);
            std::process::exit(128 + signal);
        }
    });
}

/// Whether `signal`'s disposition is to be ignored (as the process was started, before it
/// installs any handler).
fn ignored_at_start(signal: i32) -> bool {
    // SAFETY: with no new action given, sigaction only writes the current one into `current`,
    // a plain C struct for which all zeroes is a valid value.
    unsafe {
        let mut current: libc::sigaction = std::mem::zeroed();
        libc::sigaction(signal, std::ptr::null(), &mut current) == 0
            && current.sa_sigaction == libc::SIG_IGN
    }
}

fn is_broken_pipe(error: &anyhow::Error) -> bool {
    error.chain().any(|cause| {
        cause
            .downcast_ref::<std::io::Error>()
            .is_some_and(|e| e.kind() == std::io::ErrorKind::BrokenPipe)
    })
}
