//! `occsim trace gen|info|dump`. (Wired once the trace format lands.)

#[derive(clap::Subcommand)]
pub enum TraceCommand {}

pub fn run(command: TraceCommand) -> anyhow::Result<()> {
    match command {}
}
