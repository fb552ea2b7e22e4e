//! A small Value Change Dump (IEEE 1364 §18) writer: buffered by the caller's writer, only
//! changes written.
//!
//! Format: `$version`, `$timescale 1ps`, nested `$scope module NAME $end` with
//! `$var wire|reg WIDTH CODE NAME $end`, `$enddefinitions $end`; then `#TIME` lines (strictly
//! increasing, written only when some value changed at that time) each followed by the
//! changes: `0C`/`1C` for 1-bit signals, `bVALUE CODE` (binary, no leading zeros) for wider
//! ones. The first timestamp carries every signal's value. Identifier codes are printable
//! ASCII 33..=126 in base 94.

use crate::bits::mask;
use std::io::{self, Write};

/// Bytes gathered before one write to the destination.
const BUFFER_BYTES: usize = 1 << 16;

/// Declared kind of a signal.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VarKind {
    Wire,
    Reg,
}

/// Handle of a declared signal.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SignalId(pub usize);

struct Signal {
    code: String,
    width: u32,
    last: Option<u64>,
}

pub struct VcdWriter<W: Write> {
    out: W,
    signals: Vec<Signal>,
    defining: bool,
    time: u64,
    time_written: Option<u64>,
    error: Option<io::Error>,
    /// Value lines gathered before they go to `out` in large writes.
    buffer: Vec<u8>,
}

fn identifier(mut n: usize) -> String {
    let mut code = String::new();
    loop {
        code.push((33 + (n % 94) as u8) as char);
        n /= 94;
        if n == 0 {
            return code;
        }
        n -= 1;
    }
}

impl<W: Write> VcdWriter<W> {
    /// Start a dump whose time unit is 1 ps.
    pub fn new(out: W, version: &str) -> VcdWriter<W> {
        let mut vcd = VcdWriter {
            out,
            signals: Vec::new(),
            defining: true,
            time: 0,
            time_written: None,
            error: None,
            buffer: Vec::with_capacity(BUFFER_BYTES),
        };
        vcd.put(&format!("$version {version} $end\n$timescale 1ps $end\n"));
        vcd
    }

    fn put(&mut self, text: &str) {
        self.buffer.extend_from_slice(text.as_bytes());
        self.spill_if_full();
    }

    #[inline]
    fn spill_if_full(&mut self) {
        if self.buffer.len() >= BUFFER_BYTES {
            self.spill();
        }
    }

    fn spill(&mut self) {
        if self.error.is_none() {
            if let Err(e) = self.out.write_all(&self.buffer) {
                self.error = Some(e);
            }
        }
        self.buffer.clear();
    }

    pub fn scope(&mut self, name: &str) {
        debug_assert!(self.defining);
        self.put(&format!("$scope module {name} $end\n"));
    }

    pub fn upscope(&mut self) {
        self.put("$upscope $end\n");
    }

    /// Declare a signal `width` bits wide (1..=64).
    pub fn var(&mut self, kind: VarKind, name: &str, width: u32) -> SignalId {
        assert!(self.defining && (1..=64).contains(&width));
        let code = identifier(self.signals.len());
        let kind = match kind {
            VarKind::Wire => "wire",
            VarKind::Reg => "reg",
        };
        self.put(&format!("$var {kind} {width} {code} {name} $end\n"));
        self.signals.push(Signal {
            code,
            width,
            last: None,
        });
        SignalId(self.signals.len() - 1)
    }

    pub fn end_definitions(&mut self) {
        self.put("$enddefinitions $end\n");
        self.defining = false;
    }

    /// Following changes happen at `time` (ps), which must not go back.
    pub fn set_time(&mut self, time: u64) {
        debug_assert!(!self.defining);
        debug_assert!(self.time_written.is_none_or(|t| time >= t));
        self.time = time;
    }

    /// The signal holds `value` (masked to its width) from the current time on.
    #[inline]
    pub fn change(&mut self, id: SignalId, value: u64) {
        let signal = &mut self.signals[id.0];
        let value = value & mask(signal.width);
        if signal.last == Some(value) {
            return;
        }
        signal.last = Some(value);
        let width = signal.width;
        if self.time_written != Some(self.time) {
            let mut digits = [0u8; 21];
            let mut at = digits.len();
            let mut t = self.time;
            loop {
                at -= 1;
                digits[at] = b'0' + (t % 10) as u8;
                t /= 10;
                if t == 0 {
                    break;
                }
            }
            self.buffer.push(b'#');
            self.buffer.extend_from_slice(&digits[at..]);
            self.buffer.push(b'\n');
            self.time_written = Some(self.time);
        }
        // Built by hand in a stack buffer: this is the dump's hot path.
        let mut line = [0u8; 80];
        let mut n = 0;
        if width == 1 {
            line[0] = b'0' + value as u8;
            n = 1;
        } else {
            line[0] = b'b';
            let top = 63 - (value | 1).leading_zeros();
            for bit in (0..=top).rev() {
                n += 1;
                line[n] = b'0' + (value >> bit & 1) as u8;
            }
            n += 1;
            line[n] = b' ';
            n += 1;
        }
        let code = self.signals[id.0].code.as_bytes();
        line[n..n + code.len()].copy_from_slice(code);
        n += code.len();
        line[n] = b'\n';
        self.buffer.extend_from_slice(&line[..n + 1]);
        self.spill_if_full();
    }

    /// Write a last timestamp `time` (if later than every change) so that viewers show the
    /// dump up to it.
    pub fn end_at(&mut self, time: u64) {
        if self.time_written.is_none_or(|t| time > t) {
            self.put(&format!("#{time}\n"));
            self.time_written = Some(time);
        }
    }

    /// Flush and return the writer, or the first write error.
    pub fn finish(mut self) -> io::Result<W> {
        self.spill();
        if let Some(e) = self.error.take() {
            return Err(e);
        }
        self.out.flush()?;
        Ok(self.out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_header_and_only_changes() {
        let mut vcd = VcdWriter::new(Vec::new(), "test");
        vcd.scope("top");
        let a = vcd.var(VarKind::Wire, "a", 1);
        let b = vcd.var(VarKind::Reg, "b", 4);
        vcd.upscope();
        vcd.end_definitions();
        vcd.set_time(0);
        vcd.change(a, 1);
        vcd.change(b, 0x15); // masked to 4 bits
        vcd.set_time(15);
        vcd.change(a, 1);
        vcd.change(b, 5);
        vcd.set_time(30);
        vcd.change(a, 0);
        let text = String::from_utf8(vcd.finish().unwrap()).unwrap();
        assert_eq!(
            text,
            "$version test $end\n$timescale 1ps $end\n$scope module top $end\n\
             $var wire 1 ! a $end\n$var reg 4 \" b $end\n$upscope $end\n$enddefinitions $end\n\
             #0\n1!\nb101 \"\n#30\n0!\n"
        );
    }

    #[test]
    fn identifiers_are_distinct() {
        let codes: std::collections::HashSet<_> = (0..20000).map(identifier).collect();
        assert_eq!(codes.len(), 20000);
        assert_eq!(identifier(0), "!");
        assert_eq!(identifier(93), "~");
    }
}
