//! Progress bars on long work: drawn on stderr when it is a terminal, hidden otherwise (so
//! pipes, files and tests see nothing).

pub use indicatif::ProgressBar;
use indicatif::ProgressStyle;
use std::io::{IsTerminal, Read};

/// A bar of `total` steps of `unit` (hidden off a terminal).
pub fn bar(total: u64, unit: &str) -> ProgressBar {
    if !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(total);
    let template = format!("{{msg}} {{wide_bar}} {{pos}}/{{len}} {unit} (eta {{eta}})");
    if let Ok(style) = ProgressStyle::with_template(&template) {
        bar.set_style(style);
    }
    bar
}

/// A bar counting bytes read from a file of `total` bytes.
pub fn bytes_bar(total: u64) -> ProgressBar {
    if !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(total);
    if let Ok(style) =
        ProgressStyle::with_template("{msg} {wide_bar} {bytes}/{total_bytes} (eta {eta})")
    {
        bar.set_style(style);
    }
    bar
}

/// A reader that moves `bar` by the bytes it reads.
pub struct Counted<R> {
    pub inner: R,
    pub bar: ProgressBar,
}

/// A pass over the file is done when its reader goes: the bar leaves the terminal clean.
impl<R> Drop for Counted<R> {
    fn drop(&mut self) {
        self.bar.finish_and_clear();
    }
}

impl<R: Read> Read for Counted<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.bar.inc(n as u64);
        Ok(n)
    }
}
