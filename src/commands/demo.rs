//! `occsim demo`: the README's first command.

#[derive(clap::Args)]
pub struct DemoArgs {}

pub fn run(_args: DemoArgs) -> anyhow::Result<()> {
    super::count::run(super::count::CountArgs {
        scene: "demo".into(),
        json: false,
    })
}
