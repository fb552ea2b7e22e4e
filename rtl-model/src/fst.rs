//! An FST (GTKWave's Fast Signal Trace) encoder behind the shared
//! [`crate::wave::WaveWriter`], through the `fst-writer` crate: the same scopes, signals and
//! changes as the VCD, compressed in value-change sections of at most [`SECTION_BYTES`] of
//! buffered changes. The time unit is 1 ps. FST's header is rewritten at the end, so the
//! destination must seek.
//!
//! Errors are kept, not raised: the first one stops the encoding and [`WaveEncoder::finish`]
//! returns it.

use crate::wave::{VarKind, WaveEncoder};
use fst_writer::{
    FstBodyWriter, FstFileType, FstHeaderWriter, FstInfo, FstScopeType, FstSignalId, FstSignalType,
    FstVarDirection, FstVarType, FstWriteError,
};
use std::io::{self, Seek, Write};

/// Changes buffered in memory before they are compressed and written as one section.
pub const SECTION_BYTES: usize = 8 << 20;

enum Stage<W: Write + Seek> {
    Declaring(FstHeaderWriter<W>),
    Dumping(FstBodyWriter<W>),
    /// An error stopped the encoding (kept in `error`).
    Stopped,
}

pub struct FstEncoder<W: Write + Seek> {
    stage: Stage<W>,
    /// Per signal, by id: the FST's handle and the width in bits.
    signals: Vec<(FstSignalId, u32)>,
    error: Option<FstWriteError>,
    /// A value's binary digits, most significant first.
    digits: [u8; 64],
}

impl<W: Write + Seek> FstEncoder<W> {
    /// Start a dump into `out`, its version string `version`.
    pub fn new(out: W, version: &str) -> FstEncoder<W> {
        let info = FstInfo {
            start_time: 0,
            timescale_exponent: -12,
            version: version.to_owned(),
            date: String::new(),
            file_type: FstFileType::Verilog,
        };
        let mut fst = FstEncoder {
            stage: Stage::Stopped,
            signals: Vec::new(),
            error: None,
            digits: [b'0'; 64],
        };
        match FstHeaderWriter::new(out, &info) {
            Ok(header) => fst.stage = Stage::Declaring(header),
            Err(e) => fst.error = Some(e),
        }
        fst
    }

    /// Keep the first error and stop.
    #[cold]
    fn fail(&mut self, error: FstWriteError) {
        self.stage = Stage::Stopped;
        self.error.get_or_insert(error);
    }

    fn declaring(&mut self, f: impl FnOnce(&mut FstHeaderWriter<W>) -> fst_writer::Result<()>) {
        if let Stage::Declaring(header) = &mut self.stage {
            if let Err(e) = f(header) {
                self.fail(e);
            }
        }
    }
}

impl<W: Write + Seek> WaveEncoder for FstEncoder<W> {
    type Output = W;

    fn scope(&mut self, name: &str) {
        self.declaring(|h| h.scope(name, "", FstScopeType::Module));
    }

    fn upscope(&mut self) {
        self.declaring(|h| h.up_scope());
    }

    fn var(&mut self, kind: VarKind, name: &str, width: u32) {
        let tpe = match kind {
            VarKind::Wire => FstVarType::Wire,
            VarKind::Reg => FstVarType::Reg,
        };
        let mut id = None;
        self.declaring(|h| {
            let signal = FstSignalType::bit_vec(width);
            id = Some(h.var(name, signal, tpe, FstVarDirection::Implicit, None)?);
            Ok(())
        });
        if let Some(id) = id {
            self.signals.push((id, width));
        }
    }

    fn end_definitions(&mut self) {
        match std::mem::replace(&mut self.stage, Stage::Stopped) {
            Stage::Declaring(header) => match header.finish() {
                Ok(body) => self.stage = Stage::Dumping(body),
                Err(e) => self.fail(e),
            },
            other => self.stage = other,
        }
    }

    fn time(&mut self, time: u64) {
        if let Stage::Dumping(body) = &mut self.stage {
            // fst-writer writes a section only right before a new time.
            let outcome = if body.size() >= SECTION_BYTES {
                body.flush()
            } else {
                Ok(())
            };
            if let Err(e) = outcome.and_then(|()| body.time_change(time)) {
                self.fail(e);
            }
        }
    }

    fn value(&mut self, id: usize, value: u64) {
        if let Stage::Dumping(body) = &mut self.stage {
            let (signal, width) = self.signals[id];
            let digits = &mut self.digits[..width as usize];
            for (i, digit) in digits.iter_mut().enumerate() {
                *digit = b'0' + ((value >> (width as usize - 1 - i)) & 1) as u8;
            }
            if let Err(e) = body.signal_change(signal, digits) {
                self.fail(e);
            }
        }
    }

    fn end_at(&mut self, time: u64) {
        self.time(time);
    }

    /// Write the last section and the header; return the destination, flushed.
    fn finish(mut self) -> io::Result<W> {
        if let Stage::Declaring(_) = self.stage {
            self.end_definitions();
        }
        let outcome = match std::mem::replace(&mut self.stage, Stage::Stopped) {
            Stage::Dumping(body) if self.error.is_none() => body.finish(),
            _ => Err(self
                .error
                .take()
                .unwrap_or_else(|| io::Error::other("the FST encoding stopped").into())),
        };
        let mut out = outcome.map_err(io::Error::other)?;
        out.flush()?;
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wave::WaveWriter;

    #[test]
    fn an_fst_begins_with_its_header_block() {
        // Two signals; `b` is given 0x15 at 0 (masked to 4 bits: 0b0101 = 5), 5 again at 15
        // (no change), then 2 at 30; `a` 1 at 0 and 0 at 30.
        let mut fst = WaveWriter::with_encoder(FstEncoder::new(io::Cursor::new(Vec::new()), "t"));
        fst.scope("top");
        let a = fst.var(VarKind::Wire, "a", 1);
        let b = fst.var(VarKind::Reg, "b", 4);
        fst.upscope();
        fst.end_definitions();
        fst.set_time(0);
        fst.change(a, 1);
        fst.change(b, 0x15);
        fst.set_time(15);
        fst.change(b, 5);
        fst.set_time(30);
        fst.change(a, 0);
        fst.change(b, 2);
        fst.end_at(45);
        let bytes = fst.finish().unwrap().into_inner();
        // FST's magic: a header block (type 0) of 329 bytes (the format's fixed header).
        assert_eq!(bytes[0], 0);
        assert_eq!(u64::from_be_bytes(bytes[1..9].try_into().unwrap()), 329);
        // Reading it back is checked against the VCD in occsim-sim's waveform tests.
    }
}
