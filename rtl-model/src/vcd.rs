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
//! Speed (a whole-run dump is dominated by this writer): signals are given in blocks
//! ([`VcdWriter::change_block`], `N` consecutive signals, `N <= 64`). Inlined into the caller,
//! a block is one unrolled, branch-free compare of the values (still in registers, unmasked)
//! with those last given, gathering a bit per difference; the set bits alone are visited
//! (no mispredicted branch per unchanged signal). A changed value is formatted into a fixed
//! buffer with slack past its spill mark, so the formatter writes whole groups (8 binary
//! digits per table entry, 4 groups for signals up to 32 bits and 8 above, then the
//! pre-encoded 16-byte ` CODE\n` tail; a 1-bit line is the same with no `b`) and advances
//! by the bytes that count: no per-bit loop, no variable-length copy, no bounds checks.
//! Timestamps are written 8 digits at a time from a 100-entry pair table.

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

/// What the writer keeps per signal besides the compare's last given value: one cache
/// line's worth, read only when a value was given that differs.
struct Line {
    /// The value last written (masked).
    last: u64,
    /// All ones in the signal's width.
    mask: u64,
    /// No value written yet (a 64-bit signal has no spare value for a sentinel).
    unwritten: bool,
    /// Bytes before the digits: 1 (`b`) for a wide signal, 0 for a 1-bit one.
    prefix: usize,
    /// Wider than 32 bits: up to 8 groups of 8 digits instead of 4.
    wide: bool,
    /// What follows the value: ` CODE\n` (`CODE\n` for a 1-bit signal), zero padded.
    tail: [u8; 16],
    tail_len: usize,
}

pub struct VcdWriter<W: Write> {
    out: W,
    /// Per signal, by id: the value last given (unmasked, so the compare needs no mask).
    given: Vec<u64>,
    /// Per signal, by id: what writing a line needs.
    lines: Vec<Line>,
    /// Signals with no value written yet.
    unwritten_count: usize,
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

/// Decimal digits of `value` (at least 1): one more than a guess of log10 from the bit
/// length (log10(2) ~ 1233 / 4096, never too low), corrected by one comparison.
#[inline(always)]
fn decimal_digits(value: u64) -> usize {
    const POWERS: [u64; 20] = {
        let mut powers = [1u64; 20];
        let mut i = 1;
        while i < 20 {
            powers[i] = powers[i - 1] * 10;
            i += 1;
        }
        powers
    };
    let value = value | 1; // same digit count, and 0 has one digit
    let guess = (((64 - value.leading_zeros()) * 1233) >> 12) as usize;
    guess + 1 - (value < POWERS[guess]) as usize
}

/// `value` (< 10^8) as exactly 8 decimal digits.
#[inline(always)]
fn write_eight_digits(out: &mut [u8], value: u64) {
    let (high, low) = ((value / 10_000) as usize, (value % 10_000) as usize);
    out[0..2].copy_from_slice(&DECIMAL_PAIRS[high / 100]);
    out[2..4].copy_from_slice(&DECIMAL_PAIRS[high % 100]);
    out[4..6].copy_from_slice(&DECIMAL_PAIRS[low / 100]);
    out[6..8].copy_from_slice(&DECIMAL_PAIRS[low % 100]);
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
            given: Vec::new(),
            lines: Vec::new(),
            unwritten_count: 0,
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
        let code = identifier(self.given.len());
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
        self.given.push(0);
        self.lines.push(Line {
            last: 0,
            mask: mask(width),
            unwritten: true,
            prefix: (width > 1) as usize,
            wide: width > 32,
            tail,
            tail_len: tail_text.len(),
        });
        self.unwritten_count += 1;
        SignalId(self.given.len() - 1)
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
    #[inline]
    pub fn change(&mut self, id: SignalId, value: u64) {
        self.change_block(id, &[value]);
    }

    /// Signals `first .. first + N` (N <= 64) hold `values` (each masked to its width) from
    /// the current time on; lines are written in signal order. Inlined into the caller, a
    /// block is one unrolled, branch-free compare of the values (still in registers) with
    /// those last given, gathering a bit per difference; only a block with a difference
    /// calls the writer, which visits the set bits.
    #[inline(always)]
    pub fn change_block<const N: usize>(&mut self, first: SignalId, values: &[u64; N]) {
        const { assert!(N <= 64, "a block has at most 64 signals") };
        let given: &mut [u64; N] = (&mut self.given[first.0..first.0 + N])
            .try_into()
            .expect("a slice of N");
        let mut changed = 0u64;
        for bit in 0..N {
            changed |= ((values[bit] != given[bit]) as u64) << bit;
        }
        if self.unwritten_count != 0 {
            for (bit, line) in self.lines[first.0..first.0 + N].iter().enumerate() {
                changed |= (line.unwritten as u64) << bit;
            }
        }
        if changed != 0 {
            self.write_changed(first.0, values, changed);
        }
    }

    /// Take the values of signals `first + i` for the bits `i` set in `changed`, writing
    /// those whose masked value changed.
    #[inline(always)]
    fn write_changed(&mut self, first: usize, values: &[u64], mut changed: u64) {
        while changed != 0 {
            let offset = changed.trailing_zeros() as usize;
            changed &= changed - 1;
            let index = first + offset;
            let value = values[offset];
            self.given[index] = value;
            let line = &self.lines[index];
            let value = value & line.mask;
            if value != line.last || line.unwritten {
                self.write_change(index, value);
            }
        }
    }

    /// Write a changed value (masked), after the pending timestamp if any.
    #[inline(always)]
    fn write_change(&mut self, index: usize, value: u64) {
        if self.time_pending {
            self.write_time();
        }
        let line = &mut self.lines[index];
        line.last = value;
        if line.unwritten {
            line.unwritten = false;
            self.unwritten_count -= 1;
        }
        // A fixed-size window (with the offsets below bounded by construction, no bounds
        // checks are left in the formatting).
        let buffer: &mut [u8; LINE_SCRATCH] = (&mut self.buffer
            [self.filled..self.filled + LINE_SCRATCH])
            .try_into()
            .expect("a window of LINE_SCRATCH bytes");
        // `b`, overwritten by the digits of a 1-bit signal (no prefix).
        buffer[0] = b'b';
        let digits = 64 - (value | 1).leading_zeros() as usize;
        // The most significant digit at bit 63, then whole groups of 8 from the top (4 of
        // them unless the signal is wider than 32 bits): the bytes past the last digit are
        // overwritten by the tail or left as scratch.
        let groups = (value << (64 - digits)).to_be_bytes();
        let at = line.prefix & 1;
        for (group, &byte) in groups[..4].iter().enumerate() {
            buffer[at + 8 * group..at + 8 * group + 8]
                .copy_from_slice(&BINARY_DIGITS[byte as usize]);
        }
        if line.wide {
            for (group, &byte) in groups.iter().enumerate().skip(4) {
                buffer[at + 8 * group..at + 8 * group + 8]
                    .copy_from_slice(&BINARY_DIGITS[byte as usize]);
            }
        }
        let at = at + digits;
        buffer[at..at + 16].copy_from_slice(&line.tail);
        self.filled += at + line.tail_len;
        if self.filled >= BUFFER_BYTES {
            self.spill();
        }
    }

    /// `#TIME\n` for the current time. The digits are written in groups of 8 (two
    /// independent chains of pairs each) from the last group back.
    #[inline(never)]
    fn write_time(&mut self) {
        let t = self.time;
        let length = decimal_digits(t);
        let buffer = &mut self.buffer[self.filled..self.filled + LINE_SCRATCH];
        buffer[0] = b'#';
        buffer[1 + length] = b'\n';
        let digits = &mut buffer[1..1 + length];
        let mut rest = t;
        let mut end = length;
        while end > 8 {
            write_eight_digits(&mut digits[end - 8..end], rest % 100_000_000);
            rest /= 100_000_000;
            end -= 8;
        }
        let mut rest = rest as u32;
        while end >= 2 {
            digits[end - 2..end].copy_from_slice(&DECIMAL_PAIRS[(rest % 100) as usize]);
            rest /= 100;
            end -= 2;
        }
        if end == 1 {
            digits[0] = b'0' + rest as u8;
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
    fn decimal_digit_counts() {
        for (value, digits) in [(0, 1), (9, 1), (10, 2), (99, 2), (100, 3), (999_999, 6)] {
            assert_eq!(decimal_digits(value), digits);
        }
        let mut power = 1u64;
        for digits in 1..20 {
            assert_eq!(decimal_digits(power), digits);
            assert_eq!(decimal_digits(power * 10 - 1), digits);
            power *= 10;
        }
        assert_eq!(decimal_digits(power), 20);
        assert_eq!(decimal_digits(u64::MAX), 20);
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
        let mut time = 0;
        for step in 0..400u64 {
            // Timestamps of 1 to 15 digits, some just below powers of ten.
            time += step * step * step * 14_999 + (step % 3) * 99_999_999;
            vcd.set_time(time);
            let mut stamped = false;
            for (w, &id) in ids.iter().enumerate() {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                let value = (state >> (state % 64)) & mask(w as u32 + 1);
                vcd.change(id, value);
                if last[w] != Some(value) {
                    if !stamped {
                        expected += &format!("#{time}\n");
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
