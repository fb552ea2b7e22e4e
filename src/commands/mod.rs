//! One module per subcommand.

pub mod arch;
pub mod corpus;
pub mod count;
pub mod culling;
pub mod demo;
pub mod fidelity;
pub mod latency;
pub mod raster_args;
pub mod replay;
pub mod sensitivity;
pub mod sweep;
pub mod timeline;
pub mod trace;
pub mod workload_args;

/// `--jobs N` of every command that runs replays at once (`sweep`, `sensitivity`, `latency`,
/// `culling compare`): a whole number of at least 1, refused as the flag is read (each
/// command had checked it in words of its own, `sweep`'s parser in its own).
pub fn at_least_one_job(text: &str) -> Result<usize, String> {
    match text.trim().parse::<usize>().map_err(|e| e.to_string())? {
        0 => Err("give at least 1".to_string()),
        jobs => Ok(jobs),
    }
}

/// The first of `items` that repeats an earlier one: in a list given on the command line
/// where each must come once (`latency --engines`, `culling compare`'s machines).
pub fn first_repeated<T: PartialEq>(items: &[T]) -> Option<&T> {
    let mut seen = items.iter().enumerate();
    seen.find(|&(i, item)| items[..i].contains(item))
        .map(|(_, item)| item)
}

/// `flag`'s output `path`, when given, checked before the work that makes it
/// ([`occsim_sweep::output::check_writable`]): a missing directory is an error now, not after
/// minutes of replays.
pub fn check_output(path: Option<&std::path::Path>, flag: &str) -> anyhow::Result<()> {
    use anyhow::Context;
    match path {
        Some(path) => occsim_sweep::output::check_writable(path).with_context(|| flag.to_string()),
        None => Ok(()),
    }
}

/// The largest settings file (an architecture, a corpus, a camera path) read: each is a few
/// KB, so a file past this is not one, and is refused before it fills memory (/dev/zero had
/// been read for 2 GB).
pub const MAX_SETTINGS_FILE_BYTES: u64 = 16 << 20;

/// The UTF-8 text of the settings file `path` (`what` it is, for errors): at most
/// [`MAX_SETTINGS_FILE_BYTES`].
pub fn read_settings_file(path: &std::path::Path, what: &str) -> anyhow::Result<String> {
    use anyhow::Context;
    use std::io::Read;
    let name = path.display();
    occsim_sweep::output::note_input(path);
    let mut bytes = Vec::new();
    std::fs::File::open(path)
        .with_context(|| format!("cannot open {what} {name}"))?
        .take(MAX_SETTINGS_FILE_BYTES + 1)
        .read_to_end(&mut bytes)
        .with_context(|| format!("cannot read {what} {name}"))?;
    anyhow::ensure!(
        bytes.len() as u64 <= MAX_SETTINGS_FILE_BYTES,
        "{name}: larger than {} MiB (is it the {what}?)",
        MAX_SETTINGS_FILE_BYTES >> 20
    );
    String::from_utf8(bytes).map_err(|e| {
        anyhow::anyhow!(
            "{name}: not UTF-8 text at byte {} (is it the {what}?)",
            e.utf8_error().valid_up_to()
        )
    })
}
