//! A small Value Change Dump (IEEE 1364 §18) writer: buffered by the caller's writer, only
//! changes written.
//!
//! Format: `$version`, `$timescale 1ps`, nested `$scope module NAME $end` with
//! `$var wire|reg WIDTH CODE NAME $end`, `$enddefinitions $end`; then `#TIME` lines (strictly
//! increasing, written only when some value changed at that time) each followed by the
//! changes: `0C`/`1C` for 1-bit signals, `bVALUE CODE` (binary, no leading zeros) for wider
//! ones. The first timestamp carries every signal's value. Identifier codes are printable
//! ASCII 33..=126 in base 94.
//!
//! Speed: [`VcdWriter::change`] is an inlined compare with the last value written; only a
//! change goes to the (out-of-line) formatter. That formats into a fixed buffer with slack
//! past its spill mark, so it writes whole 8- and 16-byte groups (8 binary digits from a
//! 256-entry table, the pre-encoded ` CODE\n` tail) and advances by the bytes that count:
//! no per-bit loop, no variable-length copy.

use crate::bits::mask;
use std::io::{self, Write};

/// Bytes gathered before one write to the destination.
const BUFFER_BYTES: usize = 1 << 16;
/// Bytes one line's writes may touch: a value line's whole groups (`b`, 64 digits, a
/// 16-byte tail: 81) or a timestamp line (`#`, 20 digits, newline: 22).
const LINE_SCRATCH: usize = 128;
/// Room past the spill mark: a timestamp line and then a value line's scratch fit in it.
const SLACK_BYTES: usize = 2 * LINE_SCRATCH;

/// Declared kind of a signal.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VarKind {
    Wire,
    Reg,
}

/// Handle of a declared signal.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SignalId(pub usize);

/// The ASCII binary digits of every byte value, most significant bit first.
const BINARY_DIGITS: [[u8; 8]; 256] = {
    let mut table = [[0u8; 8]; 256];
    let mut value = 0;
    while value < 256 {
        let mut bit = 0;
        while bit < 8 {
            table[value][bit] = b'0' + ((value >> (7 - bit)) & 1) as u8;
            bit += 1;
        }
        value += 1;
    }
    table
};

/// Two ASCII decimal digits of every value 0..100.
const DECIMAL_PAIRS: [[u8; 2]; 100] = {
    let mut table = [[0u8; 2]; 100];
    let mut value = 0;
    while value < 100 {
        table[value] = [b'0' + (value / 10) as u8, b'0' + (value % 10) as u8];
        value += 1;
    }
    table
};

struct Signal {
    /// The value last written, or anything while `unwritten` is 1.
    last: u64,
    /// 1 until the signal's first value is written (so a 64-bit signal needs no sentinel).
    unwritten: u64,
    /// All ones in the signal's width.
    mask: u64,
    /// Groups of 8 binary digits a value takes at most; 0 for a 1-bit signal.
    digit_groups: u32,
    /// What follows the value: ` CODE\n` (`CODE\n` for a 1-bit signal), zero padded.
    tail: [u8; 16],
    tail_len: usize,
}

pub struct VcdWriter<W: Write> {
    out: W,
    signals: Vec<Signal>,
    defining: bool,
    time: u64,
    /// `time` is not yet written: the next change writes it first.
    time_pending: bool,
    time_written: Option<u64>,
    error: Option<io::Error>,
    /// Lines gathered before they go to `out` in large writes: `buffer[..filled]`, the rest
    /// scratch (`BUFFER_BYTES + SLACK_BYTES` long).
    buffer: Vec<u8>,
    filled: usize,
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
            time_pending: true,
            time_written: None,
            error: None,
            buffer: vec![0; BUFFER_BYTES + SLACK_BYTES],
            filled: 0,
        };
        vcd.put(&format!("$version {version} $end\n$timescale 1ps $end\n"));
        vcd
    }

    /// Append header text of any length.
    fn put(&mut self, text: &str) {
        let bytes = text.as_bytes();
        if self.filled + bytes.len() > BUFFER_BYTES {
            self.spill();
        }
        if bytes.len() > BUFFER_BYTES {
            self.write_out(bytes);
        } else {
            self.buffer[self.filled..self.filled + bytes.len()].copy_from_slice(bytes);
            self.filled += bytes.len();
        }
    }

    fn write_out(&mut self, bytes: &[u8]) {
        if self.error.is_none() {
            if let Err(e) = self.out.write_all(bytes) {
                self.error = Some(e);
            }
        }
    }

    fn spill(&mut self) {
        if self.error.is_none() {
            if let Err(e) = self.out.write_all(&self.buffer[..self.filled]) {
                self.error = Some(e);
            }
        }
        self.filled = 0;
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
        // A usize needs at most 10 base-94 characters: the tail fits 16 bytes.
        let tail_text = if width == 1 {
            format!("{code}\n")
        } else {
            format!(" {code}\n")
        };
        let mut tail = [0u8; 16];
        tail[..tail_text.len()].copy_from_slice(tail_text.as_bytes());
        self.signals.push(Signal {
            last: 0,
            unwritten: 1,
            mask: mask(width),
            digit_groups: if width == 1 { 0 } else { width.div_ceil(8) },
            tail,
            tail_len: tail_text.len(),
        });
        SignalId(self.signals.len() - 1)
    }

    pub fn end_definitions(&mut self) {
        self.put("$enddefinitions $end\n");
        self.defining = false;
    }

    /// Following changes happen at `time` (ps), which must not go back.
    #[inline]
    pub fn set_time(&mut self, time: u64) {
        debug_assert!(!self.defining);
        debug_assert!(self.time_written.is_none_or(|t| time >= t));
        self.time = time;
        self.time_pending = self.time_written != Some(time);
    }

    /// The signal holds `value` (masked to its width) from the current time on.
    #[inline(always)]
    pub fn change(&mut self, id: SignalId, value: u64) {
        let signal = &self.signals[id.0];
        let value = value & signal.mask;
        if (value ^ signal.last) | signal.unwritten != 0 {
            self.write_change(id.0, value);
        }
    }

    /// Write a changed value (masked), after the pending timestamp if any.
    #[inline(never)]
    fn write_change(&mut self, index: usize, value: u64) {
        if self.time_pending {
            self.write_time();
        }
        let signal = &mut self.signals[index];
        signal.last = value;
        signal.unwritten = 0;
        let buffer = &mut self.buffer[self.filled..self.filled + LINE_SCRATCH];
        let mut at;
        if signal.digit_groups == 0 {
            buffer[0] = b'0' + value as u8;
            at = 1;
        } else {
            buffer[0] = b'b';
            let digits = 64 - (value | 1).leading_zeros() as usize;
            // The most significant digit at bit 63; whole groups from the top, the bytes
            // past the last digit overwritten by the tail or left as scratch.
            let aligned = value << (64 - digits);
            for group in 0..signal.digit_groups as usize {
                let byte = (aligned >> (56 - 8 * group)) as u8;
                buffer[1 + 8 * group..9 + 8 * group].copy_from_slice(&BINARY_DIGITS[byte as usize]);
            }
            at = 1 + digits;
        }
        buffer[at..at + 16].copy_from_slice(&signal.tail);
        at += signal.tail_len;
        self.filled += at;
        if self.filled >= BUFFER_BYTES {
            self.spill();
        }
    }

    /// `#TIME\n` for the current time, its decimal digits written two at a time from the
    /// last one back.
    fn write_time(&mut self) {
        let mut t = self.time;
        let mut length = 1;
        while length < 20 && t >= 10u64.pow(length as u32) {
            length += 1;
        }
        let buffer = &mut self.buffer[self.filled..self.filled + LINE_SCRATCH];
        buffer[0] = b'#';
        let mut end = 1 + length;
        buffer[end] = b'\n';
        while t >= 100 {
            buffer[end - 2..end].copy_from_slice(&DECIMAL_PAIRS[(t % 100) as usize]);
            end -= 2;
            t /= 100;
        }
        if t >= 10 {
            buffer[end - 2..end].copy_from_slice(&DECIMAL_PAIRS[t as usize]);
        } else {
            buffer[end - 1] = b'0' + t as u8;
        }
        self.filled += 2 + length;
        self.time_written = Some(self.time);
        self.time_pending = false;
    }

    /// Write a last timestamp `time` (if later than every change) so that viewers show the
    /// dump up to it.
    pub fn end_at(&mut self, time: u64) {
        if self.time_written.is_none_or(|t| time > t) {
            self.put(&format!("#{time}\n"));
            self.time_written = Some(time);
            self.time_pending = false;
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

    #[test]
    fn wide_values_and_long_timestamps_are_exact() {
        let mut vcd = VcdWriter::new(Vec::new(), "t");
        let wide = vcd.var(VarKind::Reg, "w", 64);
        let bit = vcd.var(VarKind::Wire, "b", 1);
        vcd.end_definitions();
        vcd.set_time(0);
        vcd.change(wide, u64::MAX); // first value: written although it is all ones
        vcd.set_time(9);
        vcd.change(wide, 1 << 63);
        vcd.set_time(10);
        vcd.change(wide, 0);
        vcd.change(bit, 0);
        vcd.set_time(99);
        vcd.change(wide, 0); // unchanged: no timestamp
        vcd.set_time(100);
        vcd.change(bit, 3); // masked to 1
        vcd.set_time(u64::MAX - 1);
        vcd.change(wide, 0b1011);
        vcd.end_at(u64::MAX);
        let text = String::from_utf8(vcd.finish().unwrap()).unwrap();
        let body = text.split_once("$enddefinitions $end\n").unwrap().1;
        let ones = "1".repeat(64);
        let top = format!("1{}", "0".repeat(63));
        assert_eq!(
            body,
            format!(
                "#0\nb{ones} !\n#9\nb{top} !\n#10\nb0 !\n0\"\n#100\n1\"\n\
                 #18446744073709551614\nb1011 !\n#18446744073709551615\n"
            )
        );
    }

    #[test]
    fn every_width_and_value_spills_intact() {
        // Far more than one buffer of lines; the expected text comes from `format!`.
        let mut vcd = VcdWriter::new(Vec::new(), "t");
        let ids: Vec<_> = (1..=64).map(|w| vcd.var(VarKind::Reg, "s", w)).collect();
        vcd.end_definitions();
        let header_end = "$enddefinitions $end\n";
        let mut expected = String::new();
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut last = vec![None; 64];
        for time in 0..400u64 {
            vcd.set_time(time * 14999);
            let mut stamped = false;
            for (w, &id) in ids.iter().enumerate() {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                let value = (state >> (state % 64)) & mask(w as u32 + 1);
                vcd.change(id, value);
                if last[w] != Some(value) {
                    if !stamped {
                        expected += &format!("#{}\n", time * 14999);
                        stamped = true;
                    }
                    let code = identifier(w);
                    expected += &if w == 0 {
                        format!("{value}{code}\n")
                    } else {
                        format!("b{value:b} {code}\n")
                    };
                    last[w] = Some(value);
                }
            }
        }
        let text = String::from_utf8(vcd.finish().unwrap()).unwrap();
        assert!(text.len() > 2 * BUFFER_BYTES);
        assert_eq!(text.split_once(header_end).unwrap().1, expected);
    }
}
