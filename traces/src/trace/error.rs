//! What can go wrong reading or writing a trace, always with the byte offset (reading) or the
//! event number (writing) where it went wrong. The caller adds the file name.

use thiserror::Error;

#[derive(Debug, Error)]
pub enum TraceError {
    /// The I/O error's words in the message, not also as its source: an error chain printed
    /// whole (`anyhow`'s `{:#}`) had said "No space left on device" twice.
    #[error("byte {offset}: {io}")]
    Io { offset: u64, io: std::io::Error },
    #[error("byte {offset}: trace truncated (file ends inside {inside})")]
    Truncated { offset: u64, inside: &'static str },
    #[error("byte 0: not an occsim trace (wrong magic number)")]
    BadMagic,
    #[error(
        "byte {offset}: unsupported trace format version {version} (this reader knows {known})"
    )]
    UnsupportedVersion {
        offset: u64,
        version: u16,
        known: u16,
    },
    #[error("byte {offset}: bad trace header: {reason}")]
    BadHeader { offset: u64, reason: String },
    /// A buffer of the header's viewport (the window index's depths, the writer's).
    #[error(transparent)]
    ViewportBuffer(#[from] crate::golden::ViewportBufferTooLarge),
    #[error("byte {offset}: bad block header: {reason}")]
    BadBlock { offset: u64, reason: String },
    #[error(
        "byte {offset}: block checksum mismatch (stored {stored:#010x}, computed {computed:#010x})"
    )]
    ChecksumMismatch {
        offset: u64,
        stored: u32,
        computed: u32,
    },
    #[error("byte {offset}: block does not decompress: {reason}")]
    Decompress { offset: u64, reason: String },
    /// The block at `offset` decompressed, but its events are malformed at `payload_offset`
    /// (a position in the decompressed payload).
    #[error("byte {offset}: corrupt block payload at decoded byte {payload_offset}: {reason}")]
    Corrupt {
        offset: u64,
        payload_offset: usize,
        reason: String,
    },
    #[error("byte {offset}: bad summary: {reason}")]
    BadSummary { offset: u64, reason: String },
    #[error("byte {offset}: unexpected data after the end of the trace")]
    TrailingData { offset: u64 },
    /// The writer was given an event stream it will not store (event numbers count from 0).
    #[error("event {event}: {reason}")]
    InvalidEvent { event: u64, reason: String },
}

/// Why reading a trace into a sink stopped: the trace (with its byte offset) or the sink.
#[derive(Debug, Error)]
pub enum ReadError<E> {
    #[error(transparent)]
    Trace(#[from] TraceError),
    #[error(transparent)]
    Sink(E),
}

impl ReadError<std::convert::Infallible> {
    /// The trace's error, when the sink cannot fail.
    pub fn into_trace(self) -> TraceError {
        match self {
            ReadError::Trace(error) => error,
            ReadError::Sink(never) => match never {},
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::SceneError;

    /// Printed whole, as the command line prints an error and its sources, an I/O error's
    /// words come once (a full disk had said "No space left on device" twice).
    #[test]
    fn an_io_error_is_told_once_in_its_chain() {
        let full = || std::io::Error::from_raw_os_error(28);
        let trace = TraceError::Io {
            offset: 5,
            io: full(),
        };
        let scene = SceneError::Io {
            file: "s.scene".into(),
            io: full(),
        };
        for error in [&trace as &dyn std::error::Error, &scene] {
            let mut chain = error.to_string();
            let mut source = error.source();
            while let Some(cause) = source {
                chain += &format!(": {cause}");
                source = cause.source();
            }
            assert_eq!(chain.matches(&full().to_string()).count(), 1, "{chain}");
        }
    }
}
